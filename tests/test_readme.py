"""The README runs as written: its cheap commands are taken from its fenced blocks and run on this checkout
(every `markerless_mocap ... --help`, and `evaluate` on the bundled result folder), every option it shows exists
in the command's real help, every relative link and image points at a file, and it stays short enough to read."""
import importlib.util
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
MAX_LINES = 350
PYTHON = ".venv/bin/python"  # as the README writes it; the tests run the interpreter they run in
COMMAND = re.compile(r"markerless_mocap\s+(?P<command>[a-z]+)\b(?P<rest>.*)")
OPTION = re.compile(r"(?<![\w-])(--[a-z][a-z0-9-]*)(?:[ =]([^\s-]\S*))?")  # an option, and its value if any
SUBCOMMANDS = ("track", "evaluate", "calibrate", "compare", "bench", "demo", "build")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _readme():
    return README.read_text(encoding="utf-8")


def fenced_blocks(text):
    """The fenced code blocks of a Markdown text, each as its list of lines."""
    blocks, block = [], None
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            if block is None:
                block = []
            else:
                blocks.append(block)
                block = None
        elif block is not None:
            block.append(line)
    return blocks


def commands(text):
    """The shell commands of the fenced blocks, continuation lines joined and trailing comments dropped."""
    found = []
    for block in fenced_blocks(text):
        pending = ""
        for line in block:
            line = line.split("  #")[0].rstrip() if "  #" in line else line.rstrip()
            if line.endswith("\\"):
                pending += line[:-1] + " "
                continue
            whole = (pending + line).strip()
            pending = ""
            if whole:
                found.append(whole)
    return found


def _environment():
    """The environment a subprocess needs to import `markerless_mocap` from where this test imports it."""
    spec = importlib.util.find_spec("markerless_mocap")
    env = dict(os.environ)
    if spec is not None and spec.submodule_search_locations:
        parent = str(Path(list(spec.submodule_search_locations)[0]).parent)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (parent, env.get("PYTHONPATH", "")) if p)
    return env


def _run(argv, timeout=300):
    return subprocess.run(argv, cwd=REPO, env=_environment(), capture_output=True, text=True, timeout=timeout)


def _argv(command):
    """A README command line as the argument list to run: the venv's python is this interpreter."""
    words = shlex.split(command)
    assert words[0] == PYTHON, f"README runs {words[0]!r}, not {PYTHON}: {command}"
    return [sys.executable, *words[1:]]


def _help_commands():
    return [c for c in commands(_readme()) if c.startswith(PYTHON) and c.split()[-1] == "--help"]


_HELP = {}


def _help(command):
    """`markerless_mocap COMMAND --help` as printed (cached: several checks read it)."""
    if command not in _HELP:
        argv = [sys.executable, "-m", "markerless_mocap"] + ([command] if command else []) + ["--help"]
        run = _run(argv)
        assert run.returncode == 0, f"{' '.join(argv[1:])} failed:\n{run.stderr}"
        _HELP[command] = run.stdout
    return _HELP[command]


def test_the_readme_is_short():
    lines = _readme().count("\n")
    assert lines < MAX_LINES, f"README.md has {lines} lines; keep it under {MAX_LINES} (the rest belongs in docs/)"


def test_the_two_set_up_commands_each_have_their_own_block():
    blocks = [[line.strip() for line in b if line.strip()] for b in fenced_blocks(_readme())]
    for command in ("bash setup.sh demo", "bash setup.sh test"):
        assert [command] in blocks, f"README.md has no fenced block holding just `{command}`"


def test_every_relative_link_and_image_exists():
    missing = []
    for target in LINK.findall(_readme()):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):  # a web address, mail, or an anchor here
            continue
        path = (README.parent / target.split("#")[0]).resolve()
        if not path.exists():
            missing.append(target)
    assert not missing, f"README.md links to files that are not there: {missing}"


def test_the_readme_shows_every_command_help():
    shown = {c.split()[3] if len(c.split()) > 4 else "" for c in _help_commands()}
    assert "" in shown, "README.md should show `python -m markerless_mocap --help`"
    assert {"track", "evaluate", "calibrate"} <= shown, shown


@pytest.mark.parametrize("command", _help_commands())
def test_a_help_command_runs_as_written(command):
    run = _run(_argv(command))
    assert run.returncode == 0, f"{command}\n{run.stderr}"
    assert "usage:" in run.stdout, run.stdout


def _documented_options():
    """(command, option, its value) for every option the README's fenced commands give a sub-command, for inline
    code that starts with a sub-command, and for `bash setup.sh build ...` in fenced blocks or inline code
    (setup.sh hands those to `markerless_mocap build`)."""
    text = _readme()
    lines = commands(text) + re.findall(r"`(bash setup\.sh build[^`]*)`", text)
    # inline code that names a sub-command first, e.g. `track --calibrate-measured`
    lines += ["markerless_mocap " + s for s in re.findall(rf"`((?:{'|'.join(SUBCOMMANDS)}) [^`]*)`", text)]
    found = []
    for line in lines:
        match = COMMAND.search(line)
        if match:
            command, rest = match.group("command"), match.group("rest")
        elif line.startswith("bash setup.sh build"):
            command, rest = "build", line[len("bash setup.sh build"):]
        else:
            continue
        for option, value in OPTION.findall(rest):
            if option != "--help":
                found.append((command, option, value.strip("[]")))
    return found


def test_every_option_the_readme_shows_exists():
    documented = _documented_options()
    assert any(c == "track" and o == "--smooth" for c, o, _ in documented), "the track synopsis was not found"
    missing = []
    for command, option, value in documented:
        text = _help(command)
        if not re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", text):
            missing.append(f"{command} {option}")
            continue
        if "|" in value:  # a choice list: each choice named must be one the command takes
            for choice in value.split("|"):
                if choice not in ("", "...") and not re.search(rf"[{{,]{re.escape(choice)}[,}}]", text):
                    missing.append(f"{command} {option} {choice}")
    assert not missing, f"README.md shows options the commands do not take: {missing}"


def _accuracy_row(scene):
    """The README accuracy table's (default: mean of the seeds, mean without foot locking, the default per seed) for
    `scene`."""
    for line in _readme().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[0] == scene and len(cells) >= 5:
            seeds = [float(x) for x in re.findall(r"\d+\.\d", cells[-1])]
            return float(cells[-3]), float(cells[-2]), seeds
    raise AssertionError(f"README.md's accuracy table has no row for {scene}")


def test_the_accuracy_rows_agree_with_their_seeds():
    for scene in ("walk", "playground", "busy"):
        mean, _, seeds = _accuracy_row(scene)
        assert len(seeds) == 3, (scene, seeds)
        assert abs(sum(seeds) / 3 - mean) < 0.1, (scene, mean, seeds)


def test_evaluate_on_the_bundled_result_prints_the_readme_figure(tmp_path):
    runs = [c for c in commands(_readme()) if " evaluate " in c and "example_result" in c]
    assert runs, "README.md shows no `evaluate` on the bundled result folder"
    argv = _argv(runs[0])
    result = Path(argv[argv.index("--result") + 1])
    assert (REPO / result / "joints.npz").is_file(), f"{result} is not bundled: the README's command cannot run"
    # the per-frame plot goes to a temporary folder, not into the checkout's result folder
    run = _run(argv + ["--plot", str(tmp_path / "error_per_frame.png")])
    assert run.returncode == 0, run.stderr
    printed = re.search(r"3D error over 15 joints: (\d+\.\d+)", run.stdout)
    assert printed, run.stdout
    default_seed0 = _accuracy_row("walk")[2][0]
    assert abs(float(printed.group(1)) - default_seed0) <= 0.1 + 1e-9, (
        f"evaluate prints {printed.group(1)} mm on the bundled walk result; README.md's accuracy table says "
        f"{default_seed0} mm for walk, seed 0, with the defaults")
