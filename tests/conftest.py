"""Shared test set-up.

* The repository root is the extension package `markerless_mocap`, whatever the clone's folder
  is called: a temporary folder holding a symlink of that name goes on sys.path first.
* Blender writes nothing to the user's config: BLENDER_USER_RESOURCES points at a temporary
  folder before bpy is imported.
* `addon` loads the add-on the way a real install does (a local extension repository).
"""
import os
import sys
import tempfile
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "markerless_mocap"

_tmp_root = Path(tempfile.mkdtemp(prefix="mocap_tests_"))
_pkg_parent = _tmp_root / "pkg"
_pkg_parent.mkdir()
(_pkg_parent / PACKAGE).symlink_to(REPO_ROOT, target_is_directory=True)
sys.path.insert(0, str(_pkg_parent))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_tmp_root / "blender_user"))
# Motion models (prior, dynamics) are cached per rig; keep the tests' cache out of the user's home.
os.environ.setdefault("MOCAP_CACHE_DIR", str(_tmp_root / "cache"))

SAMPLE_SCENES = REPO_ROOT / "sample_scenes"


@pytest.fixture
def tmp_out(tmp_path):
    return tmp_path


@pytest.fixture
def bpy_module():
    """bpy with an empty scene before and after the test."""
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_homefile(use_empty=True)
    yield bpy
    bpy.ops.wm.read_homefile(use_empty=True)


_ADDON_REPO = "mocapdev"


@pytest.fixture(scope="session")
def addon_module_name():
    """Enable the add-on from the source tree as a local extension; return its module name."""
    bpy = pytest.importorskip("bpy")
    import addon_utils

    repos = bpy.context.preferences.extensions.repos
    if not any(r.module == _ADDON_REPO for r in repos):
        repos.new(name=_ADDON_REPO, module=_ADDON_REPO, custom_directory=str(_pkg_parent), source="USER")
    name = f"bl_ext.{_ADDON_REPO}.{PACKAGE}"
    addon_utils.enable(name, default_set=True, handle_error=None)
    yield name
    addon_utils.disable(name)
