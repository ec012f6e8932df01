"""Stage the files that go into the extension zip, and write the staged manifest.

The repository manifest stays free of wheel lists (they depend on what was downloaded); the
staged copy gets `wheels = [...]` and the platforms actually built.
"""
import os
import re
import shutil
import tomllib
from pathlib import Path

# Never shipped, whatever the manifest says: hidden files (.gitignore, .pytest_cache), the
# repository's own wheels folder (the staged one is filled from the cache), byte code.
ALWAYS_EXCLUDED = (".*", "/wheels/", "*.pyc")


class ManifestError(ValueError):
    """blender_manifest.toml is missing or lacks what the build needs."""


def read_manifest(repo_root):
    path = Path(repo_root) / "blender_manifest.toml"
    if not path.is_file():
        raise ManifestError(f"{path} not found: run the build from the extension's repository")
    with open(path, "rb") as fh:
        try:
            data = tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise ManifestError(f"{path} is not valid TOML ({exc}): fix the line it names") from None
    for key in ("id", "version"):
        if key not in data:
            raise ManifestError(f"{path} has no `{key}`: add it (see the Blender manual, extension manifest)")
    return data


def stage_package(repo_root, staging_dir, manifest, matcher_factory):
    """Copy the files the manifest's [build] section selects; returns their relative paths."""
    repo_root, staging_dir = Path(repo_root), Path(staging_dir)
    build = manifest.get("build", {})
    exclude = matcher_factory([*build.get("paths_exclude_pattern", []), *ALWAYS_EXCLUDED])
    if "paths" in build:  # explicit list: take it literally (minus the always-excluded)
        candidates = [Path(p) for p in build["paths"]]
        files = []
        for rel in candidates:
            full = repo_root / rel
            files += [f.relative_to(repo_root) for f in full.rglob("*") if f.is_file()] if full.is_dir() else [rel]
        files = [f for f in files if not exclude.test_path(f.as_posix())]
    else:
        files = []
        for dirpath, dirnames, filenames in os.walk(repo_root):
            rel_dir = Path(dirpath).relative_to(repo_root)
            # prune excluded folders here: .venv and .git are huge
            dirnames[:] = sorted(d for d in dirnames if not exclude.test_path((rel_dir / d).as_posix() + "/"))
            files += [rel_dir / f for f in sorted(filenames) if not exclude.test_path((rel_dir / f).as_posix())]
    for rel in files:
        target = staging_dir / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(repo_root / rel, target)
    return files


_TOP_KEY = re.compile(r"^\s*(wheels|platforms)\s*=")
_TABLE = re.compile(r"^\s*\[")


def manifest_with_wheels(text, wheels, platforms):
    """Manifest text with top-level `wheels` and `platforms` replaced (other lines untouched)."""
    lines, out, depth, skipping, inserted = text.splitlines(), [], 0, False, False
    new = [f"platforms = [{', '.join(_q(p) for p in platforms)}]", "wheels = ["]
    new += [f"  {_q(w)}," for w in wheels] + ["]"]
    for line in lines:
        if skipping:  # inside a multi-line array being replaced
            depth += _bracket_balance(line)
            skipping = depth > 0
            continue
        if not inserted and _TABLE.match(line):
            out += new + [""]
            inserted = True
        if not inserted and _TOP_KEY.match(line):
            depth = _bracket_balance(line.split("=", 1)[1])
            skipping = depth > 0
            continue
        out.append(line)
    if not inserted:
        out += new
    result = "\n".join(out) + "\n"
    parsed = tomllib.loads(result)  # guard against a manifest layout this simple editor misreads
    if parsed.get("wheels", []) != list(wheels) or parsed.get("platforms") != list(platforms):
        raise ManifestError("could not write wheels/platforms into the staged blender_manifest.toml: "
                            "keep `platforms = [...]` as a plain top-level key before the first [table]")
    return result


def _q(text):
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _bracket_balance(text):
    text = re.sub(r'"(?:\\.|[^"\\])*"', '""', text).split("#", 1)[0]  # strings, then comments
    return text.count("[") - text.count("]")
