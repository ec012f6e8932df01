"""The installable zips: build one per platform (linux-x64, windows-x64, macos-arm64) with cp311 and cp313
wheels (from dist/wheels-cache, else PyPI once per machine), check that each manifest lists only its
platform and its wheels, install the linux-x64 zip into a fresh bpy process, restart, and use the bundled
cv2/scipy/numba/dask/distributed from the extension's own site-packages. The windows-x64 and macos-arm64 zips are
installed and enabled with Blender's platform check told their platform (tools/install_probe.py
install-as): Blender unpacks no foreign wheel, so the add-on runs on this Python's own packages.

`bash setup.sh test` runs this file on bpy 5.0.1 (Python 3.11, .venv) and again on bpy 5.2.3 (Python
3.13, .venv313): the same zips must install and work in both."""
import hashlib
import importlib.util
import json
import os
import re
import subprocess
import sys
import time
import tomllib
import zipfile
from pathlib import Path

import pytest

from markerless_mocap.operators import cli, cmd_build
from markerless_mocap.operators.cmd_build import build_extension
from markerless_mocap.tools import extension_builder, staging, wheels

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "markerless_mocap"
PLATFORM = "linux-x64"  # the one this machine loads
FOREIGN = ("windows-x64", "macos-arm64")
CACHE = REPO / "dist" / "wheels-cache"
PROBE = REPO / "tools" / "install_probe.py"
HAVE_BPY = importlib.util.find_spec("bpy") is not None
needs_bpy = pytest.mark.skipif(not HAVE_BPY, reason="bpy (and its extension builder) is not installed")

# Pins the zip must carry for the Python running the tests (numpy is Blender's own, never bundled).
RUNNING_PYTHON = tuple(sys.version_info[:2])
PINS = wheels.read_pins(wheels.requirements_file(REPO, RUNNING_PYTHON))
PINS_BY_PYTHON = wheels.read_pins_by_python(REPO, wheels.DEFAULT_PYTHON_VERSIONS)
# dask + distributed (the batch runner) and their dependencies; importlib-metadata (with zipp and
# lazy-importer) only where dask asks for it, before Python 3.12.
DASK_DISTS = {"dask", "distributed", "click", "cloudpickle", "fsspec", "jinja2", "markupsafe", "locket", "msgpack",
              "packaging", "partd", "psutil", "pyyaml", "sortedcontainers", "tblib", "toolz", "tornado", "zict"}
DASK_DISTS_BEFORE_312 = {"importlib-metadata", "zipp", "lazy-importer"}
# compiled: a wheel per platform and Python; abi3: one per platform for every Python; the rest pure (any)
PER_PYTHON_DISTS = {"msgpack", "pyyaml", "markupsafe"}
ABI3_DISTS = {"tornado", "psutil"}


def expected_dists(python):
    """What the zip must carry for one Blender Python (numpy is Blender's own, never bundled)."""
    return ({"opencv-contrib-python-headless", "scipy", "numba", "llvmlite"} | DASK_DISTS
            | (DASK_DISTS_BEFORE_312 if tuple(python) < (3, 12) else set()))


def installed_dists(python):
    """What Blender with this Python installs from a zip serving every Python: its own wheels, and the pure ones
    another Python needs (a wheel has no marker Blender reads; importlib-metadata on 3.13 only sits unused)."""
    pure_elsewhere = set().union(*(expected_dists(p) for p in wheels.DEFAULT_PYTHON_VERSIONS)) & (
        DASK_DISTS_BEFORE_312 | DASK_DISTS) - PER_PYTHON_DISTS - ABI3_DISTS
    return expected_dists(python) | pure_elsewhere


def _dist(name):
    """The distribution of a wheel file or an unpacked .dist-info folder, canonicalized."""
    name = Path(name).name
    if name.endswith(".whl"):
        return wheels.parse_wheel_filename(name)[0]
    return wheels.canonicalize_name(name.removesuffix(".dist-info").rsplit("-", 1)[0])


def operator_classes_in_source():
    """Every `class MOCAP_OT_...` defined in operators/*.py (what the add-on must register)."""
    found = set()
    for path in sorted((REPO / "operators").glob("*.py")):
        found.update(re.findall(r"^\s*class\s+(MOCAP_OT_\w+)\s*[(:]", path.read_text(), re.MULTILINE))
    return sorted(found)


def offline_pip(monkeypatch):
    """Make any pip download fail at once, without network (pip reads these from the environment)."""
    monkeypatch.setenv("PIP_INDEX_URL", "file:///nonexistent-index")
    monkeypatch.setenv("PIP_EXTRA_INDEX_URL", "file:///nonexistent-index")
    monkeypatch.setenv("PIP_FIND_LINKS", "")


@pytest.fixture(scope="module")
def build(tmp_path_factory):
    if not HAVE_BPY:
        pytest.skip("bpy is not installed")
    out = tmp_path_factory.mktemp("dist")
    started = time.time()
    messages = []
    zips = build_extension(out, cache_dir=CACHE, log=messages.append)  # the default: one zip per platform
    by_platform = {}
    for path, platforms in zips.items():
        assert len(platforms) == 1, zips
        by_platform[platforms[0]] = path
    assert sorted(by_platform) == sorted([PLATFORM, *FOREIGN])
    return {"zip": by_platform[PLATFORM], "zips": by_platform, "started": started, "messages": messages}


def _zip_manifest(zf):
    return tomllib.loads(zf.read("blender_manifest.toml").decode("utf-8"))


# --- what is inside the zip -------------------------------------------------------------------

@pytest.mark.slow
@needs_bpy
@pytest.mark.parametrize("platform", [PLATFORM, *FOREIGN])
def test_each_zip_lists_only_its_platform_and_exactly_the_wheels_it_carries(build, platform):
    zip_path = build["zips"][platform]
    assert zip_path.name == f"{PACKAGE}-{_version()}-{platform.replace('-', '_')}.zip"
    with zipfile.ZipFile(zip_path) as zf:
        manifest = _zip_manifest(zf)
        names = set(zf.namelist())
    assert manifest["platforms"] == [platform]
    assert "generated" not in manifest.get("build", {})  # the plain keys say it; no per-platform override
    listed = manifest["wheels"]
    assert all(w.startswith("./wheels/") for w in listed), listed
    in_zip = {n for n in names if n.endswith(".whl")}
    assert {w[2:] for w in listed} == in_zip
    assert wheels.DEFAULT_PYTHON_VERSIONS == ((3, 11), (3, 13))
    for python in wheels.DEFAULT_PYTHON_VERSIONS:  # Blender 4.2-5.0 and Blender 5.1-5.2
        dists = {}
        for w in in_zip:
            if not wheels.wheel_fits(Path(w).name, platform, python):
                continue
            name, version, _, _ = wheels.parse_wheel_filename(Path(w).name)
            assert name not in dists, f"two wheels of {name} for Python {python}: {in_zip}"
            dists[name] = str(version)
            tags = {(t.abi, t.platform) for t in wheels.parse_wheel_filename(Path(w).name)[3]}
            if name in PER_PYTHON_DISTS:
                assert all(abi == f"cp{python[0]}{python[1]}" and plat != "any" for abi, plat in tags), w
            elif name in ABI3_DISTS:
                assert all(abi == "abi3" and plat != "any" for abi, plat in tags), w
            elif name in DASK_DISTS | DASK_DISTS_BEFORE_312:
                assert tags == {("none", "any")}, w
        assert set(dists) == installed_dists(python), \
            f"Python {python}: numpy must not be bundled; cv2/scipy/numba/llvmlite and dask's wheels must"
        for name in ("opencv-contrib-python-headless", "scipy", "numba", "dask", "distributed"):
            assert dists[name] == PINS_BY_PYTHON[python][name], (python, name)
        if python == RUNNING_PYTHON:  # llvmlite is numba's dependency: the version the tests here run with
            from importlib.metadata import version
            assert dists["llvmlite"] == version("llvmlite")
    # Every wheel is one this platform's Blender would install: no other platform's wheel rides along.
    assert all(any(wheels.wheel_fits(Path(w).name, platform, py) for py in wheels.DEFAULT_PYTHON_VERSIONS)
               for w in in_zip), "a wheel no supported Blender on this platform would install"
    size_mb = zip_path.stat().st_size / 1e6
    assert size_mb < cmd_build.UPLOAD_LIMIT_MB
    assert any(str(zip_path) in m and f"{size_mb:.1f} MB" in m for m in build["messages"]), build["messages"]
    print(f"{platform} zip: {size_mb:.1f} MB")


@pytest.mark.slow
@needs_bpy
def test_zips_differ_only_in_their_wheels_and_manifest(build):
    """The add-on's files are the same in every platform's zip, so what installs and enables from the
    linux-x64 zip here is what the others carry."""
    contents = {}
    for platform, path in build["zips"].items():
        with zipfile.ZipFile(path) as zf:
            contents[platform] = {i.filename: i.CRC for i in zf.infolist()
                                  if not i.filename.startswith("wheels/") and i.filename != "blender_manifest.toml"}
    assert len(contents[PLATFORM]) > 10
    for platform in FOREIGN:
        assert contents[platform] == contents[PLATFORM], platform


@pytest.mark.slow
@needs_bpy
def test_zip_wheels_are_byte_identical_to_the_downloaded_ones(build):
    for path in build["zips"].values():
        with zipfile.ZipFile(path) as zf:
            for name in (n for n in zf.namelist() if n.endswith(".whl")):
                cached = CACHE / Path(name).name
                assert hashlib.sha256(zf.read(name)).digest() == hashlib.sha256(cached.read_bytes()).digest(), name


@pytest.mark.slow
@needs_bpy
def test_zip_holds_the_package_sources_and_nothing_of_the_dev_tree(build):
    with zipfile.ZipFile(build["zip"]) as zf:
        names = set(zf.namelist())
        assert {"__init__.py", "blender_manifest.toml"} <= names  # at the root, as Blender wants
        # folders of the repository root only (core/results/ is the package's own and ships)
        dev_only = {"tests", "tools", "dist", ".git", ".venv", ".ci", "sample_scenes", "results"}

        def dev_file(parts):
            return parts[0] in dev_only or "__pycache__" in parts

        leaked = [n for n in names if dev_file(Path(n).parts) or Path(n).name.startswith(".")
                  or n in ("setup.sh", "requirements.txt", "requirements-py313.txt", "pyproject.toml")]
        assert not leaked
        # Simple reference: every .py file of the package (outside dev-only folders) is shipped,
        # unchanged. Files edited after the build started (other work in the checkout) are skipped.
        checked = 0
        for path in REPO.rglob("*.py"):
            rel = path.relative_to(REPO)
            if dev_file(rel.parts) or any(p.startswith(".") for p in rel.parts):
                continue
            if path.stat().st_mtime >= build["started"] - 1:
                continue
            assert rel.as_posix() in names, f"{rel} missing from the zip"
            assert zf.read(rel.as_posix()) == path.read_bytes(), f"{rel} differs in the zip"
            checked += 1
        assert checked >= 4


# --- install into a fresh Blender --------------------------------------------------------------

def _probe(args, user_dir):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user_dir))
    proc = subprocess.run([sys.executable, "-P", str(PROBE), *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=600)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("PROBE-JSON ")]
    assert proc.returncode == 0 and lines, f"probe failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return json.loads(lines[-1][len("PROBE-JSON "):])


@pytest.fixture(scope="module")
def installed(build, tmp_path_factory):
    user_dir = tmp_path_factory.mktemp("blender_user")
    classes = operator_classes_in_source()
    first = _probe(["install", build["zip"], PACKAGE, *classes], user_dir)
    again = _probe(["restart", PACKAGE, *classes], user_dir)
    return {"install": first, "restart": again, "classes": classes}


@pytest.mark.slow
@pytest.mark.bpy
@needs_bpy
def test_install_enables_the_addon_and_registers_every_operator(installed):
    for phase in ("install", "restart"):
        report = installed[phase]
        assert not report["errors"], report["errors"]
        assert report["enabled_in_preferences"], phase
        assert report["addon_utils_check"] == [True, True], phase
        assert report["registered_classes"] == installed["classes"], phase
        assert len(report["mocap_ops"]) >= len(installed["classes"]), phase
    assert installed["install"]["install_result"] == ["FINISHED"]
    assert installed["install"]["blender"].startswith(str(PINS["bpy"]))  # 5.0.1 in .venv, 5.2.3 in .venv313


@pytest.mark.slow
@pytest.mark.bpy
@needs_bpy
@pytest.mark.parametrize("platform", FOREIGN)
def test_other_platforms_zip_installs_and_enables_where_blender_takes_it_for_its_platform(build, platform,
                                                                                            tmp_path):
    """This Linux cannot load Windows or macOS wheels. Plain install: Blender refuses the zip (its manifest
    names only that platform). With Blender's platform check told that platform (install_probe install-as),
    the zip installs and enables, every operator registers, and only the pure-Python wheels are unpacked: Blender
    picks wheels by this machine's own tag, which none of the zip's compiled wheels fits."""
    classes = operator_classes_in_source()
    refused = _probe(["install", build["zips"][platform], PACKAGE, *classes], tmp_path / "plain")
    assert not refused["enabled_in_preferences"] and not refused["package_dir_exists"]
    report = _probe(["install-as", platform, build["zips"][platform], PACKAGE, *classes], tmp_path / "as")
    assert report["as_platform"] == platform
    assert not report["errors"], report["errors"]
    assert report["install_result"] == ["FINISHED"], report
    assert report["package_dir_exists"] and report["enabled_in_preferences"]
    assert report["addon_utils_check"] == [True, True]
    assert report["registered_classes"] == classes
    with zipfile.ZipFile(build["zips"][platform]) as zf:
        pure = {_dist(n) for n in zf.namelist() if n.endswith("-none-any.whl")
                and wheels.wheel_fits(Path(n).name, PLATFORM, RUNNING_PYTHON)}
    assert "dask" in pure and not pure & (PER_PYTHON_DISTS | ABI3_DISTS)
    assert {_dist(d) for d in report["unpacked"]} == pure, report["unpacked"]
    assert report["blender"].startswith(str(PINS["bpy"]))


def test_manifest_covers_every_blender_the_wheels_serve():
    """4.2 LTS to 5.2 LTS: the version range, and one requirements file per Blender Python version."""
    manifest = tomllib.loads((REPO / "blender_manifest.toml").read_text())
    as_tuple = lambda text: tuple(int(x) for x in text.split("."))
    assert as_tuple(manifest["blender_version_min"]) <= (4, 2, 0)
    bpy_pins = [as_tuple(pins["bpy"]) for pins in PINS_BY_PYTHON.values()]
    assert bpy_pins == [(5, 0, 1), (5, 2, 3)]
    assert all(pin < as_tuple(manifest["blender_version_max"]) for pin in bpy_pins)  # max is exclusive
    assert as_tuple(manifest["blender_version_max"]) == (5, 3, 0)


@pytest.mark.slow
@pytest.mark.bpy
@needs_bpy
def test_bundled_wheels_import_from_the_extension_site_packages(installed):
    report = installed["restart"]
    site = Path(report["extensions_dir"]) / ".local" / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}"
    # the linux-x64 wheels for this Python, and nothing else (numpy is Blender's own)
    assert {_dist(d) for d in report["unpacked"]} == installed_dists(RUNNING_PYTHON), report["unpacked"]
    expected_versions = {"cv2": PINS["opencv-contrib-python-headless"], "scipy": PINS["scipy"],
                         "numba": PINS["numba"], "dask": PINS["dask"], "distributed": PINS["distributed"]}
    assert set(report["modules"]) == set(expected_versions)
    for name, version in expected_versions.items():
        info = report["modules"][name]
        assert Path(info["file"]).is_relative_to(site), f"{name} came from {info['file']}, not {site}"
        assert version.startswith(info["version"]), (name, info["version"])
        assert info["works"], name


def test_operators_exist_in_the_package():
    assert operator_classes_in_source(), "no `class MOCAP_OT_...` in operators/*.py: nothing for users to run"


# --- cache, errors, manifest editing -------------------------------------------------------------

def _version():
    return tomllib.loads((REPO / "blender_manifest.toml").read_text())["version"]


def _wheel_names(path):
    with zipfile.ZipFile(path) as zf:
        return {n for n in zf.namelist() if n.endswith(".whl")}


@pytest.mark.slow
@needs_bpy
def test_second_build_is_offline_and_fast(build, tmp_path, monkeypatch, capsys):
    offline_pip(monkeypatch)
    t0 = time.perf_counter()
    code = cli.main(["build", "--out", str(tmp_path), "--platforms", PLATFORM])
    elapsed = time.perf_counter() - t0
    out = capsys.readouterr().out
    assert code == 0, out
    assert "downloading" not in out
    zip_path = tmp_path / f"{PACKAGE}-{_version()}-linux_x64.zip"
    assert re.search(rf"{re.escape(str(zip_path))}\s+{zip_path.stat().st_size / 1e6:.1f} MB  linux-x64\n", out), out
    assert f"each under the {cmd_build.UPLOAD_LIMIT_MB} MB upload limit" in out
    assert _wheel_names(zip_path) == _wheel_names(build["zip"])
    with zipfile.ZipFile(zip_path) as zf:
        assert _zip_manifest(zf)["platforms"] == [PLATFORM]
    print(f"cached build took {elapsed:.1f} s")


@pytest.mark.slow
@needs_bpy
def test_all_platforms_option_makes_one_zip_with_every_platforms_wheels(build, tmp_path, monkeypatch, capsys):
    offline_pip(monkeypatch)
    assert cli.main(["build", "--out", str(tmp_path), "--all-platforms"]) == 0
    out = capsys.readouterr().out
    zip_path = tmp_path / f"{PACKAGE}-{_version()}.zip"
    assert [p.name for p in tmp_path.glob("*.zip")] == [zip_path.name]
    with zipfile.ZipFile(zip_path) as zf:
        manifest = _zip_manifest(zf)
    assert manifest["platforms"] == [PLATFORM, *FOREIGN]
    assert _wheel_names(zip_path) == set().union(*(_wheel_names(p) for p in build["zips"].values()))
    assert {w[2:] for w in manifest["wheels"]} == _wheel_names(zip_path)
    assert f"{zip_path}  " in out and " MB" in out
    assert f"over the {cmd_build.UPLOAD_LIMIT_MB} MB upload limit" in out and "Install from Disk" in out


@pytest.mark.slow
@needs_bpy
def test_zip_over_the_upload_limit_fails_the_build_and_says_which(build, tmp_path, monkeypatch, capsys):
    offline_pip(monkeypatch)
    linux_mb = build["zip"].stat().st_size / 1e6
    monkeypatch.setattr(cmd_build, "UPLOAD_LIMIT_MB", int(linux_mb) - 1)  # just under this zip's size
    assert cli.main(["build", "--out", str(tmp_path), "--platforms", PLATFORM]) == 1
    captured = capsys.readouterr()
    name = f"{PACKAGE}-{_version()}-linux_x64.zip"
    assert f"{name} ({linux_mb:.1f} MB)" in captured.err
    assert f"accepts up to {int(linux_mb) - 1} MB" in captured.err and "--python-versions" in captured.err
    assert f"{linux_mb:.1f} MB  linux-x64" in captured.out  # every zip's size is printed before the failure


def test_missing_wheel_names_package_platform_and_the_cache_option(tmp_path, monkeypatch):
    offline_pip(monkeypatch)
    with pytest.raises(wheels.WheelUnavailableError) as err:
        wheels.download(tmp_path, "scipy", wheels.SpecifierSet("==1.15.3"), "windows-x64", (3, 11), log=lambda m: None)
    text = str(err.value)
    assert "scipy==1.15.3" in text and "windows-x64" in text and "--wheels-cache" in text
    assert not list(tmp_path.glob("*.whl"))


def test_corrupt_cached_wheel_is_named_with_the_fix(tmp_path, monkeypatch):
    offline_pip(monkeypatch)
    bad = tmp_path / "opencv_contrib_python_headless-4.11.0.86-cp37-abi3-manylinux_2_17_x86_64.manylinux2014_x86_64.whl"
    bad.write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(wheels.WheelUnavailableError) as err:
        wheels.collect(PINS, [PLATFORM], [(3, 11)], tmp_path, log=lambda m: None)
    assert bad.name in str(err.value) and "delete it" in str(err.value)


def test_bad_platform_is_a_clear_cli_error(capsys):
    assert cli.main(["build", "--platforms", "linux-x64,amiga-68k"]) == 1
    err = capsys.readouterr().err
    assert "amiga-68k" in err and "linux-x64, windows-x64, macos-arm64" in err


def test_cache_lookup_prefers_pinned_version_then_oldest_os(tmp_path):
    names = [
        "scipy-1.15.3-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl",
        "scipy-1.15.3-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl",
        "scipy-1.15.2-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl",
        "scipy-1.15.3-cp312-cp312-manylinux_2_17_x86_64.manylinux2014_x86_64.whl",
        "scipy-1.15.3-cp311-cp311-musllinux_1_2_x86_64.whl",
        "scipy-1.15.3-cp311-cp311-macosx_14_0_arm64.whl",
        "scipy-1.15.3-cp311-cp311-macosx_12_0_arm64.whl",
        "not-a-wheel.whl",
    ]
    for n in names:
        (tmp_path / n).write_bytes(b"")
    pick = lambda spec, plat: wheels.find_cached(tmp_path, "scipy", wheels.SpecifierSet(spec), plat, (3, 11))
    assert pick("==1.15.3", "linux-x64").name == names[1]
    assert pick(">=1.15", "linux-x64").name == names[1]
    assert pick("<1.15.3", "linux-x64").name == names[2]
    assert pick("==1.15.3", "macos-arm64").name == names[6]
    assert pick("==1.15.3", "windows-x64") is None


def test_wheel_fits_agrees_with_blenders_platform_rule():
    """Reference: blender_ext.py's own wheel-platform -> Blender-platform mapping (platform part),
    plus the Python-tag rule spelled out by hand."""
    if not HAVE_BPY:
        pytest.skip("bpy is not installed")
    import importlib.util as iu
    spec = iu.spec_from_file_location("_blender_ext_ref", extension_builder.blender_ext_path())
    ref = iu.module_from_spec(spec)
    spec.loader.exec_module(ref)
    platform_tags = ["manylinux_2_17_x86_64.manylinux2014_x86_64", "manylinux_2_28_x86_64", "manylinux2014_aarch64",
                     "win_amd64", "win32", "win_arm64", "macosx_11_0_arm64", "macosx_10_9_x86_64",
                     "macosx_10_9_universal2", "any"]
    for ptag in platform_tags:
        fname = f"pkg-1.0-cp311-cp311-{ptag}.whl"
        for plat in wheels.PLATFORMS:
            expected = ptag == "any" or any(plat in ref.blender_platforms_from_wheel_platform(t)
                                            for t in ptag.split("."))
            assert wheels.wheel_fits(fname, plat, (3, 11)) == expected, (fname, plat)
    python_cases = {("cp311-cp311", (3, 11)): True, ("cp311-cp311", (3, 13)): False,
                    ("cp312-cp312", (3, 11)): False, ("cp37-abi3", (3, 11)): True, ("cp37-abi3", (3, 13)): True,
                    ("cp313-abi3", (3, 11)): False, ("py3-none", (3, 11)): True, ("py2.py3-none", (3, 13)): True}
    for (tag, py), expected in python_cases.items():
        assert wheels.wheel_fits(f"pkg-1.0-{tag}-win_amd64.whl", "windows-x64", py) == expected, (tag, py)


MANIFEST_WITH_OLD_LISTS = """schema_version = "1.0.0"
id = "x"  # comment [with brackets]
platforms = [
  "linux-x64",  # ]
  "windows-x64",
]
wheels = ["./wheels/old-1.0-py3-none-any.whl"]
version = "0.1.0"

[permissions]
files = "Read [things]"
"""


@pytest.mark.parametrize("text", [(REPO / "blender_manifest.toml").read_text(), MANIFEST_WITH_OLD_LISTS])
def test_staged_manifest_gets_wheels_and_platforms_and_keeps_the_rest(text):
    new_wheels = ["./wheels/a-1.0-cp311-cp311-win_amd64.whl", "./wheels/b-2.0-cp37-abi3-win_amd64.whl"]
    result = tomllib.loads(staging.manifest_with_wheels(text, new_wheels, ["windows-x64"]))
    before = tomllib.loads(text)
    assert result.pop("wheels") == new_wheels
    assert result.pop("platforms") == ["windows-x64"]
    before.pop("wheels", None)
    before.pop("platforms", None)
    assert result == before
