"""No document, comment, test or tool names the team's numbered work periods (the word for one followed by its
number, or a capital S and the number as a tag): a reader outside the team cannot tell what they are. Figures
carry a date and a commit id instead (docs/measurements.md).

Every text file git knows of (tracked, or new and not ignored) is read; binary files and tests/data are skipped.
"""
import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# The word, singular or plural, in any case, then its number after a space, a hyphen or nothing.
SESSION_WORD = re.compile(r"\bsessions?[ -]?\d+", re.IGNORECASE)
# A capital S and one or two digits used as a tag: possessive, in brackets, after "in", "since" and the like, or
# before a colon and a figure or a word such as "code". A bare one is left alone: NumPy's byte-string dtypes,
# HumanEva's subjects.
SESSION_TAG = re.compile(
    r"\bS\d{1,2}'s\b"
    r"|\(S\d{1,2}\)"
    r"|\b(?:in|since|before|after|until|from|of|by)\s+S\d{1,2}\b"
    r"|\bS\d{1,2}(?=:\s*\d|\s+(?:code|figures?|runs?|notes?|tables?|calibrations?|results?)\b)")
SKIPPED = ("tests/data/",)


def work_period_refs(text):
    """The work-period references in `text`, as (line number, the matched text)."""
    hits = []
    for number, line in enumerate(text.splitlines(), 1):
        for pattern in (SESSION_WORD, SESSION_TAG):
            hits.extend((number, m.group(0)) for m in pattern.finditer(line))
    return hits


def _text(path):
    """The file's text, or None for a binary (a NUL byte, or not UTF-8) or vanished file."""
    try:
        data = path.read_bytes()
    except (FileNotFoundError, IsADirectoryError):
        return None
    if b"\0" in data[:8192]:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


def _repository_files():
    if shutil.which("git") is None:
        pytest.skip("git is not installed: the repository's file list cannot be read")
    result = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"], cwd=REPO,
                            capture_output=True)
    if result.returncode != 0:
        pytest.skip(f"not a git checkout ({result.stderr.decode(errors='replace').strip()})")
    names = [n for n in result.stdout.decode("utf-8", errors="replace").split("\0") if n]
    return sorted({n for n in names if not n.startswith(SKIPPED)})


def test_the_pattern_catches_work_period_references():
    # assembled from parts so this file does not hold what it looks for
    word, tag = "Sess" + "ion", "S" + "18"
    caught = [f"{word.lower()} 18's code", f"{word}-27", f"{word}s 19-27", f"{word.lower()}18", f"{tag}'s figures",
              f"measured in {tag}", f"({tag})", f"{tag}: 25.1 / 24.4 mm", f"{tag} code"]
    for text in caught:
        assert work_period_refs(text), text


def test_the_pattern_leaves_legitimate_text_alone():
    fine = ['np.zeros(3, dtype="S16")', "HumanEva's subjects S1, S2 and S3", "the session's log callback",
            "TrackSession(settings)", "a new session", "sessions of the user", "Esc cancels the session",
            "2026-11-25 (3184f8c)", "CalibrationJob asks its session whether it was cancelled"]
    for text in fine:
        assert not work_period_refs(text), text


def test_no_file_names_a_work_period():
    found = []
    for name in _repository_files():
        text = _text(REPO / name)
        if text is None:
            continue
        found.extend(f"{name}:{number}: {match}" for number, match in work_period_refs(text))
    assert not found, ("numbered work-period references (use a date and a commit id instead):\n"
                       + "\n".join(found))
