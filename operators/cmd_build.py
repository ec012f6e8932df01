"""`build`: the installable extension zip(s), with the PyPI wheels of cv2/scipy/numba bundled.

Steps: stage the package as the manifest's [build] section selects it, collect the wheels for
each platform (from the cache, else PyPI), list them in the staged manifest, then let Blender's
own blender_ext.py validate and zip it. The helpers live in tools/, which is not shipped in the
zip: this command only works from the source repository.
"""
import shutil
import sys
import tempfile
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]


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
    parser.add_argument("--split-platforms", action="store_true",
                        help="write one (much smaller) zip per platform instead of one zip for all")


def run(args):
    try:
        from ..tools import wheels
    except ImportError:
        print("build: the build tools (tools/) are not here; run the build from the source repository "
              "(bash setup.sh build)", file=sys.stderr)
        return 2
    try:
        zips = build_extension(
            out_dir=args.out,
            platforms=wheels.parse_platforms(args.platforms) if args.platforms else None,
            python_versions=wheels.parse_python_versions(args.python_versions),
            cache_dir=args.wheels_cache,
            split_platforms=args.split_platforms,
        )
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        print(f"build: {exc}", file=sys.stderr)
        return 1
    for path in zips:
        print(f"{path}  {path.stat().st_size / 1e6:.1f} MB")
    return 0


class BuildFailedError(RuntimeError):
    """Blender's validator or builder rejected the staged package."""


def build_extension(out_dir, platforms=None, python_versions=((3, 11), (3, 13)), cache_dir=None,
                    split_platforms=False, repo_root=REPO_ROOT, log=print):
    """Build the zip(s) into out_dir and return their paths."""
    from ..tools import extension_builder, staging, wheels

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
    wheel_paths, notes = wheels.collect(pins, platforms, list(python_versions), cache_dir, log)
    t_wheels = time.perf_counter()
    for note in notes:
        log(f"warning: {note}")

    with tempfile.TemporaryDirectory(prefix="mocap_build_") as tmp:
        stage = Path(tmp) / manifest["id"]
        staging.stage_package(repo_root, stage, manifest, extension_builder.path_matcher)
        (stage / "wheels").mkdir()
        for path in wheel_paths:
            # a hard link is instant and the builder only reads the file; copy across file systems
            try:
                (stage / "wheels" / path.name).hardlink_to(path)
            except OSError:
                shutil.copy2(path, stage / "wheels" / path.name)
        manifest_text = (Path(repo_root) / "blender_manifest.toml").read_text()
        (stage / "blender_manifest.toml").write_text(staging.manifest_with_wheels(
            manifest_text, [f"./wheels/{p.name}" for p in wheel_paths], platforms))

        ok, output = extension_builder.run("validate", *tag_args, stage)
        if not ok:
            raise BuildFailedError(f"Blender's validator rejected the staged package (wheels added):\n{output}")
        build_args = ["build", "--source-dir", stage, "--output-dir", out_dir, *tag_args]
        if split_platforms:
            build_args.append("--split-platforms")
        ok, output = extension_builder.run(*build_args)
        if not ok:
            raise BuildFailedError(f"Blender's extension builder failed:\n{output}")

    stem = f"{manifest['id']}-{manifest['version']}"
    if split_platforms:
        zips = [out_dir / f"{stem}-{p.replace('-', '_')}.zip" for p in platforms]
    else:
        zips = [out_dir / f"{stem}.zip"]
    for path in zips:
        if not path.is_file():
            raise BuildFailedError(f"the builder reported success but {path} is missing:\n{output}")
        ok, output = extension_builder.run("validate", *tag_args, path)
        if not ok:
            raise BuildFailedError(f"Blender's validator rejected the built zip {path}:\n{output}")
    t_end = time.perf_counter()
    log(f"built {len(zips)} zip(s) in {t_end - t0:.1f} s (wheels {t_wheels - t0:.1f} s, "
        f"stage+zip+validate {t_end - t_wheels:.1f} s)")
    return zips
