"""`build`: the installable extension zips, with the PyPI wheels of cv2/scipy/numba/dask bundled.

Steps: stage the package as the manifest's [build] section selects it, collect the wheels for
each platform (from the cache, else PyPI), then for each zip list its platform(s) and wheels in
the staged manifest and let Blender's own blender_ext.py validate and zip it. One zip per
platform by default (what the Blender extensions platform takes, and a user downloads one
platform's wheels); `--all-platforms` makes one zip for all. The helpers live in tools/, which is
not shipped in the zip: this command only works from the source repository.
"""
import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
# The Blender extensions platform rejects uploads above 300 MB; a per-platform zip over it is a failed build.
UPLOAD_LIMIT_MB = 300


def add_arguments(parser):
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "dist",
                        help="folder for the zip(s) (default: dist/ in the repository)")
    parser.add_argument("--platforms", default=None,
                        help="comma-separated Blender platforms, e.g. linux-x64,windows-x64,macos-arm64 "
                             "(default: the manifest's platforms)")
    parser.add_argument("--wheels-cache", type=Path, default=REPO_ROOT / "dist" / "wheels-cache",
                        help="folder of downloaded wheels reused by later builds; put hand-downloaded "
                             ".whl files here when PyPI is unreachable (default: dist/wheels-cache)")
    parser.add_argument("--python-versions", default="3.11,3.13",
                        help="Blender's Python version(s) to bundle wheels for: 3.11 for Blender 4.2-5.0 (pinned "
                             "in requirements.txt), 3.13 for Blender 5.1-5.2 (requirements-py313.txt). "
                             "Default: 3.11,3.13")
    parser.add_argument("--all-platforms", action="store_true",
                        help="write one zip holding every platform's wheels (about 670 MB: too large for the "
                             f"Blender extensions platform's {UPLOAD_LIMIT_MB} MB limit, fine for Install from "
                             "Disk) instead of one zip per platform")
    # One zip per platform used to need this flag; it is the default now, and scripts passing it still run.
    parser.add_argument("--split-platforms", action="store_true", help=argparse.SUPPRESS)


def run(args):
    try:
        from ..tools import wheels
    except ImportError:
        print("build: the build tools (tools/) are not here; run the build from the source repository "
              "(bash setup.sh build)", file=sys.stderr)
        return 2
    if args.all_platforms and args.split_platforms:
        print("build: --all-platforms and --split-platforms contradict each other: give one "
              "(one zip per platform is the default)", file=sys.stderr)
        return 1
    try:
        build_extension(
            out_dir=args.out,
            platforms=wheels.parse_platforms(args.platforms) if args.platforms else None,
            python_versions=wheels.parse_python_versions(args.python_versions),
            cache_dir=args.wheels_cache,
            all_platforms=args.all_platforms,
        )
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        print(f"build: {exc}", file=sys.stderr)
        return 1
    return 0


class BuildFailedError(RuntimeError):
    """Blender's validator or builder rejected the staged package."""


class ZipTooLargeError(BuildFailedError):
    """A per-platform zip is over the extensions platform's upload limit."""


def zip_name(manifest, platforms):
    """Blender's own naming (as its --split-platforms writes): id-version-linux_x64.zip; id-version.zip for all."""
    stem = f"{manifest['id']}-{manifest['version']}"
    if len(platforms) == 1:
        return f"{stem}-{platforms[0].replace('-', '_')}.zip"
    return f"{stem}.zip"


def build_extension(out_dir, platforms=None, python_versions=((3, 11), (3, 13)), cache_dir=None,
                    all_platforms=False, repo_root=REPO_ROOT, log=print, limit_mb=None):
    """Build one zip per platform (or one for all) into out_dir and return {zip path: its platforms}.

    Logs each zip with its size; raises ZipTooLargeError after building when a per-platform zip is
    over limit_mb (the all-platform zip is not meant for upload, so it only gets a note)."""
    from ..tools import extension_builder, staging, wheels

    limit_mb = UPLOAD_LIMIT_MB if limit_mb is None else limit_mb
    t0 = time.perf_counter()
    manifest = staging.read_manifest(repo_root)
    declared = manifest.get("platforms", list(wheels.PLATFORMS))
    platforms = list(platforms or declared)
    undeclared = [p for p in platforms if p not in declared]
    if undeclared:
        raise staging.ManifestError(f"platform(s) {undeclared} are not in blender_manifest.toml's platforms "
                                    f"{declared}: build for those, or add them to the manifest")
    cache_dir = Path(cache_dir or repo_root / "dist" / "wheels-cache")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    tag_args = []
    tags = extension_builder.valid_tags_path()
    if tags is not None:
        tag_args = ["--valid-tags", tags]  # the tag list Blender's own `extension build` checks
    # Check the repository's manifest before minutes of downloads, naming the file to fix.
    ok, output = extension_builder.run("validate", *tag_args, repo_root)
    if not ok:
        raise BuildFailedError(f"Blender's validator rejected {Path(repo_root) / 'blender_manifest.toml'}; "
                               f"fix it there:\n{output}")

    pins = wheels.read_pins_by_python(repo_root, python_versions)
    log(f"collecting wheels for {', '.join(platforms)} (cache: {cache_dir})")
    wheels_of, all_notes = {}, set()
    for platform in platforms:
        wheels_of[platform], notes = wheels.collect(pins, [platform], list(python_versions), cache_dir, log)
        all_notes.update(notes)
    t_wheels = time.perf_counter()
    for note in sorted(all_notes):
        log(f"warning: {note}")
    if all_platforms:
        groups = [(platforms, sorted({w for p in platforms for w in wheels_of[p]}, key=lambda w: w.name))]
    else:
        groups = [([p], wheels_of[p]) for p in platforms]

    zips = {}
    manifest_text = (Path(repo_root) / "blender_manifest.toml").read_text()
    with tempfile.TemporaryDirectory(prefix="mocap_build_") as tmp:
        stage = Path(tmp) / manifest["id"]
        staging.stage_package(repo_root, stage, manifest, extension_builder.path_matcher)
        for group_platforms, group_wheels in groups:
            # The same staged sources for every zip; only the wheels folder and the manifest change.
            shutil.rmtree(stage / "wheels", ignore_errors=True)
            (stage / "wheels").mkdir()
            for path in group_wheels:
                # a hard link is instant and the builder only reads the file; copy across file systems
                try:
                    (stage / "wheels" / path.name).hardlink_to(path)
                except OSError:
                    shutil.copy2(path, stage / "wheels" / path.name)
            (stage / "blender_manifest.toml").write_text(staging.manifest_with_wheels(
                manifest_text, [f"./wheels/{p.name}" for p in group_wheels], group_platforms))
            label = ", ".join(group_platforms)
            ok, output = extension_builder.run("validate", *tag_args, stage)
            if not ok:
                raise BuildFailedError(f"Blender's validator rejected the staged package for {label} "
                                       f"(wheels added):\n{output}")
            target = out_dir / zip_name(manifest, group_platforms)
            ok, output = extension_builder.run("build", "--source-dir", stage, "--output-filepath", target,
                                               *tag_args)
            if not ok:
                raise BuildFailedError(f"Blender's extension builder failed for {label}:\n{output}")
            if not target.is_file():
                raise BuildFailedError(f"the builder reported success but {target} is missing:\n{output}")
            ok, output = extension_builder.run("validate", *tag_args, target)
            if not ok:
                raise BuildFailedError(f"Blender's validator rejected the built zip {target}:\n{output}")
            zips[target] = list(group_platforms)
    t_end = time.perf_counter()
    log(f"built {len(zips)} zip(s) in {t_end - t0:.1f} s (wheels {t_wheels - t0:.1f} s, "
        f"stage+zip+validate {t_end - t_wheels:.1f} s):")
    width = max(len(str(path)) for path in zips)
    too_large = []
    for path, zip_platforms in zips.items():
        size_mb = path.stat().st_size / 1e6
        log(f"  {str(path):<{width}}  {size_mb:6.1f} MB  {', '.join(zip_platforms)}")
        if size_mb >= limit_mb and len(zip_platforms) == 1:
            too_large.append(f"{path.name} ({size_mb:.1f} MB)")
    if too_large:
        raise ZipTooLargeError(
            f"too large for the Blender extensions platform, which accepts up to {limit_mb} MB: "
            f"{', '.join(too_large)}. Bundle fewer Python versions (--python-versions) or fewer dependencies; "
            f"the zip(s) are in {out_dir} and still install with Install from Disk")
    if len(groups) == 1 and len(platforms) > 1:
        size_mb = next(iter(zips)).stat().st_size / 1e6
        if size_mb >= limit_mb:
            log(f"  over the {limit_mb} MB upload limit of the Blender extensions platform: this zip is for "
                "Install from Disk (the per-platform zips, the default, are for the platform)")
    else:
        log(f"  each under the {limit_mb} MB upload limit of the Blender extensions platform")
    return zips
