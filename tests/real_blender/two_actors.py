"""Run by the real-Blender stage: `blender -b duet/subject.blend --python two_actors.py -- CAPTURE OUT`.

What a user does in the Subject and Track panels for several actors: tick 'Track Every Armature', set the capture
and output folders and a short frame range, press Track (the operator the button runs; in background mode it runs
its synchronous path). Both armatures must be keyed on every tracked frame, each actor's result folder written.
"""
import json
import sys
from pathlib import Path

import bpy

capture, out = sys.argv[sys.argv.index("--") + 1:][:2]
m = bpy.context.scene.mocap
armatures = sorted(o.name for o in bpy.context.scene.objects if o.type == "ARMATURE")
m.every_armature = True
m.capture_dir = capture
m.output_dir = out
m.use_frame_range, m.frame_start, m.frame_end = True, 0, 2
m.preset = "preview"
result = bpy.ops.mocap.track()
report = {"armatures": armatures, "result": sorted(result), "status": m.status, "error": m.last_error, "keys": {}}
for name in armatures:
    arm = bpy.context.scene.objects[name]
    frames = []
    for f in range(bpy.context.scene.frame_start, bpy.context.scene.frame_end + 1):
        bpy.context.scene.frame_set(f)
        frames.append([round(v, 4) for v in (arm.matrix_world @ arm.pose.bones["Hips"].matrix).translation])
    report["keys"][name] = {"keyed": arm.animation_data is not None and arm.animation_data.action is not None,
                            "hips": frames, "folder": (Path(out) / "actors" / name / "joints.npz").is_file()}
ok = (report["result"] == ["FINISHED"] and len(armatures) == 2
      and all(k["keyed"] and k["folder"] for k in report["keys"].values()) and (Path(out) / "tracked.blend").is_file())
hips = [report["keys"][n]["hips"][0] for n in armatures]
apart = sum((a - b) ** 2 for a, b in zip(*hips)) ** 0.5 if len(hips) == 2 else 0.0
ok = ok and apart > 0.3  # each keyed on its own person, not both on one
print(f"STAGE two actors from the Track panel: {'keyed both' if ok else 'FAILED'} ({', '.join(armatures)}; "
      f"{m.status!r}; hips {apart:.2f} m apart at the first frame) {m.last_error}")
print("STAGE-JSON " + json.dumps(report))
sys.exit(0 if ok else 1)
