"""The engine's packages import one way only (docs/architecture.md): a package may import the shared helpers
at core/'s root and the packages below it in LAYERS, never one above it; core/ never imports bpy or the
Blender side (addon/, operators/)."""
import ast
import sys
from pathlib import Path

import pytest

CORE = Path(__file__).resolve().parents[1] / "core"
# Lowest first; the order docs/architecture.md draws.
LAYERS = ["capture", "body", "mocap", "render", "evidence", "energy", "optimizers", "tracking", "actor", "results",
          "batch"]
ROOT_HELPERS = {"jit", "blas_threads", "atomic_files", "errors", "registry"}


def _package_of(path):
    rel = path.relative_to(CORE)
    return rel.parts[0] if len(rel.parts) > 1 else None


def _imported_core_modules(path):
    """(line, dotted name under core) of every import in `path` that reaches into core/, lazy ones included."""
    here = path.relative_to(CORE).with_suffix("").parts
    package = list(here[:-1]) if here[-1] != "__init__" else list(here[:-1])
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            up = node.level - 1
            if up > len(package):
                out.append((node.lineno, "<outside core>." + (node.module or "")))
                continue
            base = package[: len(package) - up]
            parts = base + (node.module.split(".") if node.module else [])
            if not parts:  # `from .. import x` at core's root: x is the module
                out.extend((node.lineno, a.name) for a in node.names)
            elif not node.module and len(base) == 0:
                out.extend((node.lineno, a.name) for a in node.names)
            else:
                out.append((node.lineno, ".".join(parts)))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
            for name in names:
                if name.split(".")[0] in ("bpy", "mathutils", "gpu", "bmesh"):
                    out.append((node.lineno, "<blender>." + name))
                elif name.startswith("markerless_mocap"):
                    out.append((node.lineno, "<absolute>." + name))
    return out


def layer_violations():
    problems = []
    for path in sorted(CORE.rglob("*.py")):
        mine = _package_of(path)
        for line, target in _imported_core_modules(path):
            where = f"core/{path.relative_to(CORE)}:{line} imports {target}"
            first = target.split(".")[0]
            if first.startswith("<"):
                problems.append(where + " (core imports nothing of Blender or the add-on, and only relatively)")
            elif first in ROOT_HELPERS or first == mine:
                continue
            elif first not in LAYERS:
                problems.append(where + f" ({first!r} is neither a package of LAYERS nor a root helper)")
            elif mine is None:
                problems.append(where + " (a root helper imports no package)")
            elif LAYERS.index(first) > LAYERS.index(mine):
                problems.append(where + f" ({first} sits above {mine})")
    return problems


def test_core_imports_only_downwards():
    assert layer_violations() == []


def test_every_package_of_core_has_its_place():
    packages = {p.name for p in CORE.iterdir() if (p / "__init__.py").exists()}
    assert packages == set(LAYERS)
    helpers = {p.stem for p in CORE.glob("*.py")} - {"__init__"}
    assert helpers <= ROOT_HELPERS, f"modules at core/'s root that belong in a package: {helpers - ROOT_HELPERS}"


def test_the_check_catches_an_upward_import(tmp_path, monkeypatch):
    """The check itself: a module of energy/ that imports tracking/ is reported."""
    fake = tmp_path / "core"
    for pkg in ("energy", "tracking"):
        (fake / pkg).mkdir(parents=True)
        (fake / pkg / "__init__.py").write_text("")
    (fake / "energy" / "bad.py").write_text("def f():\n    from ..tracking.tracker import Tracker\n")
    (fake / "tracking" / "fine.py").write_text("from ..energy import bad\n")
    monkeypatch.setattr(sys.modules[__name__], "CORE", fake)
    problems = layer_violations()
    assert len(problems) == 1 and "energy/bad.py:2 imports tracking.tracker" in problems[0]


@pytest.mark.parametrize("pkg", LAYERS)
def test_each_package_says_what_it_owns(pkg):
    doc = (CORE.parents[0] / "docs" / "architecture.md").read_text()
    assert f"`core/{pkg}/`" in doc
