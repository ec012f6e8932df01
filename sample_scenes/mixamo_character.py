"""Build sample_scenes/characters/mixamo.blend: the bundled CC0 MakeHuman body with MakeHuman's Mixamo-named
rig and skin weights (makehuman/rigs/rig.mixamo.json, weights.mixamo.json) instead of the CMU rig of the
sample subjects: a character with other bone names, bone count and bone placement, to receive the tracked
motion (tools/character_check.py, tests/test_character_motion.py). Armature 'Armature' + mesh 'Body' in
the rest pose at the origin, unclothed colours as the subjects'.

Like generate.py, this reads the shared data folder; the product does not.

    .venv/bin/python sample_scenes/mixamo_character.py --data ../shared/data [--out PATH]

bpy from PyPI saves as Blender 5.0, whose files Blender 4.2-4.4 cannot open. So, as for the subjects, the
character is kept as plain data too and the committed .blend is built from it by the oldest real Blender at
hand (tools/portable_subject.py):

    .venv/bin/python tools/portable_subject.py dump sample_scenes/characters/mixamo.blend \
        sample_scenes/characters/mixamo_source.json.gz
    bash tests/real_blender/stage.sh --resave-subjects
"""
import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(HERE))

import bpy  # noqa: E402

import subject  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"), help="folder with makehuman/")
    ap.add_argument("--out", type=Path, default=HERE / "characters" / "mixamo.blend")
    args = ap.parse_args(argv)
    data = subject.load_subject_data(args.data, rig_name="mixamo")
    bpy.ops.wm.read_homefile(use_empty=True)
    arm, body = subject.build_subject(bpy, data)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(args.out), compress=True)
    print(f"{args.out}: {len(arm.data.bones)} bones, {len(body.data.vertices)} vertices")


if __name__ == "__main__":
    main()
