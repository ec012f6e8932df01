"""Run by the real-Blender stage: open every sample scene's subject.blend, and every character that receives
the motion (sample_scenes/characters/*.blend), and say what is in it."""
import sys
from pathlib import Path

import bpy

root = Path(sys.argv[sys.argv.index("--") + 1])
failed = 0
# (file, label, bones expected: the subjects' CMU-named rig has 31; a character any number above 15)
files = [(p, f"subject {p.parent.name}", 31) for p in sorted(root.glob("*/subject.blend"))]
files += [(p, f"character {p.stem}", None) for p in sorted(root.glob("characters/*.blend"))]
for path, label, n_bones in files:
    try:
        bpy.ops.wm.open_mainfile(filepath=str(path))
    except RuntimeError as exc:
        print(f"STAGE {label}: DOES NOT OPEN: {exc}")
        failed += 1
        continue
    arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    bones = len(arms[0].data.bones) if arms else 0
    # one skinned body per armature (several in a scene with several actors)
    ok = (len(arms) >= 1 and all((len(a.data.bones) == n_bones) if n_bones else len(a.data.bones) > 15 for a in arms)
          and len(meshes) == len(arms) and all(len(m.data.vertices) > 2000 for m in meshes))
    failed += not ok
    print(f"STAGE {label}: {'opens' if ok else 'WRONG CONTENT'} in Blender "
          f"{bpy.app.version_string} (saved by {'.'.join(map(str, bpy.data.version))}): "
          f"{len(arms)} armature(s) of {bones} bones, {len(meshes[0].data.vertices) if meshes else 0} vertices")
sys.exit(1 if failed else 0)
