"""Run by the real-Blender stage: open every sample scene's subject.blend and say what is in it."""
import sys
from pathlib import Path

import bpy

root = Path(sys.argv[sys.argv.index("--") + 1])
failed = 0
for path in sorted(root.glob("*/subject.blend")):
    try:
        bpy.ops.wm.open_mainfile(filepath=str(path))
    except RuntimeError as exc:
        print(f"STAGE subject {path.parent.name}: DOES NOT OPEN: {exc}")
        failed += 1
        continue
    arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    ok = len(arms) == 1 and len(arms[0].data.bones) == 31 and len(meshes) == 1 and len(meshes[0].data.vertices) > 2000
    failed += not ok
    print(f"STAGE subject {path.parent.name}: {'opens' if ok else 'WRONG CONTENT'} in Blender "
          f"{bpy.app.version_string} (saved by {'.'.join(map(str, bpy.data.version))}): "
          f"{len(arms[0].data.bones) if arms else 0} bones, {len(meshes[0].data.vertices) if meshes else 0} vertices")
sys.exit(1 if failed else 0)
