"""Blender's own extension validator/builder (blender_ext.py), as shipped inside the bpy wheel.

Using Blender's tool rather than our own zip writer means the zip is checked by exactly the
rules Blender applies at install time (manifest fields, tags, wheel names, platform split).
"""
import importlib.util
import subprocess
import sys
from pathlib import Path

_CLI = ("scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py")
_TAGS = ("scripts", "modules", "_bpy_internal", "extensions", "tags.py")


class BuilderNotFoundError(FileNotFoundError):
    """bpy (and so blender_ext.py) is not installed in this Python."""


def _bpy_version_dirs():
    spec = importlib.util.find_spec("bpy")  # locate without importing bpy (slow, and not needed)
    if spec is None or not spec.submodule_search_locations:
        raise BuilderNotFoundError(
            "the bpy module is not installed in this Python, and the build uses the extension builder it "
            f"ships: run the build with the project's venv (bash setup.sh build), not {sys.executable}"
        )
    root = Path(list(spec.submodule_search_locations)[0])
    # bpy/<major.minor>/scripts/...: newest version folder first
    return sorted((d for d in root.iterdir() if d.is_dir() and d.name[:1].isdigit()), reverse=True)


def blender_ext_path():
    for version_dir in _bpy_version_dirs():
        path = version_dir.joinpath(*_CLI)
        if path.is_file():
            return path
    raise BuilderNotFoundError("bpy is installed but contains no scripts/addons_core/bl_pkg/cli/blender_ext.py: "
                               "reinstall bpy from requirements.txt")


def valid_tags_path():
    """The tag list Blender's own `--command extension build` validates against (None if absent)."""
    for version_dir in _bpy_version_dirs():
        path = version_dir.joinpath(*_TAGS)
        if path.is_file():
            return path
    return None


def run(*args):
    """Run blender_ext.py with these arguments; returns (ok, combined output)."""
    proc = subprocess.run([sys.executable, str(blender_ext_path()), *map(str, args)],
                          capture_output=True, text=True)
    return proc.returncode == 0, (proc.stdout + proc.stderr).strip()


def path_matcher(patterns):
    """Blender's gitignore-style matcher for [build] paths_exclude_pattern (same semantics as the build)."""
    spec = importlib.util.spec_from_file_location("_blender_ext_for_build", blender_ext_path())
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # defines only; its main() runs under __main__ only
    return module.PathPatternMatch(list(patterns))
