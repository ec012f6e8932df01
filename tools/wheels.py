"""Collect the PyPI wheels the extension bundles, per Blender platform and Python version.

Blender installs an extension's wheels itself (no pip at install time), so the zip must carry
every dependency, unmodified from PyPI, except what Blender ships (numpy). Wheels are kept in
a cache folder: a file already there is used as is, so a second build needs no network, and a
wheel fetched by hand can be dropped into the cache when PyPI is unreachable.
"""
import importlib.metadata
import shutil
import subprocess
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from email.parser import Parser
from pathlib import Path

try:
    from packaging.markers import default_environment
    from packaging.requirements import Requirement
    from packaging.specifiers import SpecifierSet
    from packaging.utils import canonicalize_name, parse_wheel_filename
    from packaging.version import Version
except ImportError:  # packaging comes with pytest in the venv; pip always vendors it
    from pip._vendor.packaging.markers import default_environment
    from pip._vendor.packaging.requirements import Requirement
    from pip._vendor.packaging.specifiers import SpecifierSet
    from pip._vendor.packaging.utils import canonicalize_name, parse_wheel_filename
    from pip._vendor.packaging.version import Version

# Packages bundled in the zip (their pins come from requirements.txt); their dependencies follow.
# dask and distributed run chunks of takes on local processes or a cluster (`batch`, the Track panel);
# their compiled dependencies (msgpack, pyyaml, markupsafe) need a wheel per platform and Python,
# tornado and psutil are abi3, the rest pure.
BUNDLED = ("opencv-contrib-python-headless", "scipy", "numba", "dask", "distributed")
# Blender ships these: bundling a second copy would shadow Blender's own.
PROVIDED_BY_BLENDER = frozenset({"numpy"})


@dataclass(frozen=True)
class PlatformSpec:
    pip_tags: tuple  # --platform values, oldest OS first: pip then prefers the most compatible wheel
    markers: dict  # PEP 508 marker values of that platform
    blender_tag_ok: object  # wheel platform tag -> bool, the rule Blender applies when installing


PLATFORMS = {
    "linux-x64": PlatformSpec(
        # Blender 4.2+ needs glibc 2.28, so manylinux_2_28 wheels are fine where 2014 ones are missing.
        ("manylinux2014_x86_64", "manylinux_2_28_x86_64"),
        {"sys_platform": "linux", "platform_system": "Linux", "platform_machine": "x86_64", "os_name": "posix"},
        lambda tag: tag.startswith("manylinux") and tag.endswith("_x86_64"),
    ),
    "windows-x64": PlatformSpec(
        ("win_amd64",),
        {"sys_platform": "win32", "platform_system": "Windows", "platform_machine": "AMD64", "os_name": "nt"},
        lambda tag: tag == "win_amd64",
    ),
    "macos-arm64": PlatformSpec(
        ("macosx_11_0_arm64", "macosx_12_0_arm64", "macosx_13_0_arm64", "macosx_14_0_arm64"),
        {"sys_platform": "darwin", "platform_system": "Darwin", "platform_machine": "arm64", "os_name": "posix"},
        lambda tag: tag.startswith("macosx_") and tag.endswith(("_arm64", "_universal2")),
    ),
}


class BuildInputError(ValueError):
    """A build input (requirements.txt, platform name, Python version) is wrong."""


class WheelUnavailableError(FileNotFoundError):
    """A wheel is neither in the cache nor downloadable."""


def parse_platforms(text):
    names = [p.strip() for p in text.split(",") if p.strip()]
    unknown = [p for p in names if p not in PLATFORMS]
    if unknown or not names:
        raise BuildInputError(
            f"unknown platform(s) {unknown or text!r}: use a comma-separated list of {', '.join(PLATFORMS)}"
        )
    return names


def parse_python_versions(text):
    versions = []
    for part in (p.strip() for p in text.split(",")):
        try:
            major, minor = (int(x) for x in part.split("."))
        except ValueError:
            raise BuildInputError(f"bad Python version {part!r}: write it as 3.11 (several: 3.11,3.13)") from None
        versions.append((major, minor))
    return versions


# Blender's Python versions the zip serves, each with the requirements file that pins its wheels:
# 3.11 for Blender 4.2-5.0 (numpy 1.26), 3.13 for Blender 5.1-5.2 (numpy 2.x).
REQUIREMENTS_FOR_PYTHON = {(3, 11): "requirements.txt", (3, 13): "requirements-py313.txt"}
DEFAULT_PYTHON_VERSIONS = tuple(REQUIREMENTS_FOR_PYTHON)


def requirements_file(repo_root, python_version):
    name = REQUIREMENTS_FOR_PYTHON.get(tuple(python_version))
    if name is None:
        known = ", ".join(f"{a}.{b}" for a, b in REQUIREMENTS_FOR_PYTHON)
        raise BuildInputError(f"no requirements file pins the wheels for Python {python_version[0]}."
                              f"{python_version[1]}: the build knows {known}")
    return Path(repo_root) / name


def read_pins_by_python(repo_root, python_versions):
    """{(major, minor): pins} from each Python version's requirements file."""
    return {tuple(v): read_pins(requirements_file(repo_root, v)) for v in python_versions}


def read_pins(requirements_path):
    """{canonical name: version} for every `name==version` line of requirements.txt."""
    path = Path(requirements_path)
    if not path.is_file():
        raise BuildInputError(f"{path} not found: the build reads the pinned versions of the bundled wheels from it")
    pins = {}
    for line in path.read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if "==" in line:
            name, version = line.split("==", 1)
            pins[canonicalize_name(name)] = version.strip()
    missing = [n for n in BUNDLED if canonicalize_name(n) not in pins]
    if missing:
        raise BuildInputError(f"{path} does not pin {', '.join(missing)} (add e.g. `scipy==1.15.3` lines)")
    return pins


def _python_fits(tag, python_version):
    major, minor = python_version
    if tag.interpreter in (f"py{major}", f"py{major}{minor}"):
        return True
    if tag.interpreter == f"cp{major}{minor}":
        return True
    # Stable ABI: a cp37-abi3 wheel serves every later CPython 3.
    if tag.abi == "abi3" and tag.interpreter.startswith(f"cp{major}"):
        return int(tag.interpreter[len(f"cp{major}"):] or 0) <= minor
    return False


def _os_requirement(platform_tag):
    """Oldest OS a wheel platform tag needs, as a sortable tuple (glibc or macOS version)."""
    legacy = {"manylinux1": (2, 5), "manylinux2010": (2, 12), "manylinux2014": (2, 17)}
    head = platform_tag.split("_")
    if head[0] in legacy:
        return legacy[head[0]]
    if head[0] in ("manylinux", "macosx") and len(head) > 2 and head[1].isdigit() and head[2].isdigit():
        return int(head[1]), int(head[2])
    return (0, 0)


def wheel_fits(filename, platform, python_version):
    """Would Blender on `platform` with this Python install the wheel `filename`?"""
    rule = PLATFORMS[platform].blender_tag_ok
    _, _, _, tags = parse_wheel_filename(filename)
    return any(_python_fits(t, python_version) and (t.platform == "any" or rule(t.platform)) for t in tags)


def _min_os(filename):
    _, _, _, tags = parse_wheel_filename(filename)
    return min(_os_requirement(t.platform) for t in tags)


def find_cached(cache_dir, name, specifier, platform, python_version):
    """Best cached wheel: highest version satisfying `specifier`, then the least demanding OS tag."""
    best = None
    for path in Path(cache_dir).glob("*.whl"):
        try:
            wheel_name, version, _, _ = parse_wheel_filename(path.name)
        except Exception:  # not a wheel name: ignore rather than fail the build
            continue
        if wheel_name != canonicalize_name(name) or version not in specifier:
            continue
        if not wheel_fits(path.name, platform, python_version):
            continue
        key = (version, tuple(-x for x in _min_os(path.name)))
        if best is None or key > best[0]:
            best = (key, path)
    return None if best is None else best[1]


def download(cache_dir, name, specifier, platform, python_version, log=print):
    """Fetch one wheel from PyPI into the cache (via a private temp folder, so parallel builds never
    see a half-written file) and return its path."""
    spec = PLATFORMS[platform]
    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    py = f"{python_version[0]}.{python_version[1]}"
    with tempfile.TemporaryDirectory(dir=cache_dir, prefix=".download-") as tmp:
        cmd = [sys.executable, "-m", "pip", "download", "--disable-pip-version-check", "--quiet",
               "--retries", "2", "--timeout", "30", "--only-binary=:all:", "--no-deps",
               "--python-version", py, "--dest", tmp]
        for tag in spec.pip_tags:
            cmd += ["--platform", tag]
        cmd.append(f"{name}{specifier}")
        log(f"  downloading {name}{specifier} for {platform} (Python {py}) ...")
        proc = subprocess.run(cmd, capture_output=True, text=True)
        got = [p for p in Path(tmp).glob("*.whl") if wheel_fits(p.name, platform, python_version)]
        if proc.returncode != 0 or len(got) != 1:
            said = [ln for ln in (proc.stderr + proc.stdout).splitlines() if ln.startswith("ERROR")]
            raise WheelUnavailableError(
                f"could not download a wheel of {name}{specifier} for {platform} (Python {py}, platform tags "
                f"{', '.join(spec.pip_tags)}): {' '.join(said) or 'pip gave no wheel'}. Check the network "
                f"connection to PyPI, or download the .whl file by hand into a folder and pass it with "
                f"--wheels-cache DIR (current cache: {cache_dir})."
            )
        target = cache_dir / got[0].name
        shutil.move(str(got[0]), str(target))
        return target


def wheel_requirements(wheel_path):
    """Requirement objects of the wheel's METADATA (Requires-Dist)."""
    try:
        with zipfile.ZipFile(wheel_path) as zf:
            meta_name = next(n for n in zf.namelist() if n.endswith(".dist-info/METADATA") and n.count("/") == 1)
            meta = Parser().parsestr(zf.read(meta_name).decode("utf-8"))
    except (zipfile.BadZipFile, StopIteration):
        raise WheelUnavailableError(f"{wheel_path} is not a valid wheel (truncated download?): delete it and "
                                    "build again to download it afresh") from None
    return [Requirement(r) for r in meta.get_all("Requires-Dist") or []]


def _marker_env(platform, python_version):
    env = default_environment()
    env.update(PLATFORMS[platform].markers)
    env["python_version"] = f"{python_version[0]}.{python_version[1]}"
    env["python_full_version"] = env["python_version"] + ".0"
    env["implementation_name"] = env["platform_python_implementation"] = "cpython"
    env["extra"] = ""
    return env


def _pin_for(req, pins):
    """Exact version for a dependency: requirements.txt, else the version installed beside it here
    (what the tests ran with), else the open specifier (newest matching wheel)."""
    name = canonicalize_name(req.name)
    for version in (pins.get(name), _installed_version(name)):
        if version and Version(version) in req.specifier:
            return SpecifierSet(f"=={version}")
    return req.specifier


def _installed_version(name):
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


def collect(pins, platforms, python_versions, cache_dir, log=print):
    """All wheels to bundle, as cache paths, with their dependencies; downloads what is missing.

    pins: {name: version} for every Python version, or {(major, minor): {name: version}} per version.
    Returns (wheels, notes): notes are warnings for the user (e.g. a Blender-provided package
    whose version a wheel does not accept)."""
    wheels, notes = [], []
    per_python = bool(pins) and all(isinstance(k, tuple) for k in pins)
    for platform in platforms:
        for python_version in python_versions:
            version_pins = pins[tuple(python_version)] if per_python else pins
            env = _marker_env(platform, python_version)
            queue = [(n, SpecifierSet(f"=={version_pins[canonicalize_name(n)]}")) for n in BUNDLED]
            seen = set()
            while queue:
                name, specifier = queue.pop(0)
                if canonicalize_name(name) in seen:
                    continue
                seen.add(canonicalize_name(name))
                path = find_cached(cache_dir, name, specifier, platform, python_version)
                if path is None:
                    path = download(cache_dir, name, specifier, platform, python_version, log)
                wheels.append(path)
                for req in wheel_requirements(path):
                    if req.marker is not None and not req.marker.evaluate(env):
                        continue
                    dep = canonicalize_name(req.name)
                    if dep in PROVIDED_BY_BLENDER:
                        have = version_pins.get(dep) if per_python else _installed_version(dep)
                        if have and Version(have) not in req.specifier:
                            notes.append(f"{path.name} wants {req.name}{req.specifier}, but {have} is "
                                         f"{'pinned for it' if per_python else 'installed here'}")
                        continue
                    queue.append((req.name, _pin_for(req, version_pins)))
    unique = sorted(set(wheels), key=lambda p: p.name)
    return unique, sorted(set(notes))
