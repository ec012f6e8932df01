"""Comments point to the measurements behind a value as (docs/NAME.md, "SECTION"): every such pointer names a
document that exists and a section heading in it, so the reason for a constant never points into the void."""
import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
POINTER = re.compile(r"docs/([a-z0-9_-]+\.md), \"([^\"]+)\"")


def tracked_python_files():
    try:
        out = subprocess.run(["git", "ls-files", "*.py"], cwd=REPO, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("git is not available to list the tracked files")
    return [REPO / p for p in out.split()]


def pointers():
    found = []
    for path in tracked_python_files():
        if path.name == Path(__file__).name:  # this file's own example of a broken pointer
            continue
        text = re.sub(r"\s*\n\s*#\s*", " ", path.read_text())  # a pointer may wrap across comment lines
        found += [(path.relative_to(REPO), doc, section) for doc, section in POINTER.findall(text)]
    return found


def headings(doc):
    return {line.lstrip("#").strip() for line in (REPO / "docs" / doc).read_text().splitlines()
            if line.startswith("#")}


def test_every_pointer_names_an_existing_section():
    found = pointers()
    assert len(found) >= 20, "the code's pointers to docs/ were not found: has the pointer format changed?"
    missing = [f"{path}: docs/{doc}, {section!r}" for path, doc, section in found
               if not (REPO / "docs" / doc).exists() or section not in headings(doc)]
    assert missing == []


def test_a_broken_pointer_is_caught(tmp_path):
    assert POINTER.findall('# why (docs/defaults.md, "NO_SUCH_CONSTANT")') == [("defaults.md", "NO_SUCH_CONSTANT")]
    assert "NO_SUCH_CONSTANT" not in headings("defaults.md")
