"""A capture folder with some cameras left out: the same take seen by fewer views, to measure what a camera costs
(docs/measurements.md, "Other people in the room": the crossing take without cam1).

    .venv/bin/python tools/capture_without.py sample_scenes/crossing OUT --drop cam1

OUT gets the calibration of the cameras kept (calibration.toml, whatever format the capture's was in) and every
other file of the capture, except the left-out cameras' footage, background plates, true masks and previews: any
entry of videos/, background/, gt_masks/ or preview/ named after a left-out camera (cam1.mp4, cam1.png, cam1/).
"""
import argparse
import re
import shutil
import sys
import tomllib
from pathlib import Path

from markerless_mocap.core.capture.calibration import (_camera_tables, find_calibration_file, read_calibration,
                                                       require_two_cameras, write_toml_calibration)

PER_CAMERA_FOLDERS = ("videos", "background", "gt_masks", "preview")


def capture_without(capture, out, drop):
    """Copy `capture` to `out` without the cameras named in `drop`; returns the names of the cameras kept."""
    capture, out, drop = Path(capture), Path(out), set(drop)
    calibration = find_calibration_file(capture)
    cameras = read_calibration(calibration)
    unknown = drop - {cam.name for cam in cameras}
    if unknown:
        raise SystemExit(f"{calibration}: no camera named {', '.join(sorted(unknown))}; its cameras are "
                         f"{', '.join(cam.name for cam in cameras)}")
    kept = [cam for cam in cameras if cam.name not in drop]
    require_two_cameras(calibration, kept)
    if out.exists():
        raise SystemExit(f"{out} exists; give a new folder")
    calibration_files = {calibration.name, "intri.yml", "extri.yml"}
    shutil.copytree(capture, out, ignore=lambda folder, names: _left_out(Path(folder), names, capture, drop,
                                                                         calibration_files))
    _write_calibration(calibration, kept, drop, out / "calibration.toml")
    return [cam.name for cam in kept]


def _write_calibration(source, kept, drop, path):
    """A TOML calibration loses the left-out cameras' tables and nothing else (its numbers as written, so a take
    tracked from it is the take from the original's cameras); any other format, or tables this cannot tell
    apart, is written anew from the cameras read."""
    if source.suffix == ".toml":
        blocks = re.split(r"(?m)^(?=\[)", source.read_text(encoding="utf-8"))
        path.write_text("".join(b for b in blocks if not _camera_named(b, drop)), encoding="utf-8")
        if [cam.name for cam in read_calibration(path)] == [cam.name for cam in kept]:
            return
    write_toml_calibration(kept, path)


def _camera_named(block, drop):
    """Whether a TOML block holds a left-out camera's table, found and named as the calibration reader does."""
    try:
        doc = tomllib.loads(block)
    except tomllib.TOMLDecodeError:
        return False
    return any(str(table.get("name", key)) in drop for key, table in _camera_tables(doc))


def _left_out(folder, names, capture, drop, calibration_files):
    if folder == capture:
        return [n for n in names if n in calibration_files]
    if folder.parent == capture and folder.name in PER_CAMERA_FOLDERS:
        return [n for n in names if Path(n).stem in drop or n in drop]
    return []


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("capture", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--drop", action="append", required=True, help="a camera to leave out (repeat for several)")
    args = parser.parse_args(argv)
    kept = capture_without(args.capture, args.out, args.drop)
    print(f"{args.out}: cameras {', '.join(kept)}")


if __name__ == "__main__":
    sys.exit(main())
