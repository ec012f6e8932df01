"""Run by the real-Blender stage: `blender -b walk/subject.blend --python cluster_take.py -- CAPTURE OUT`.

What a user does to send a take to local processes from the Track panel: Run On 'Local Processes', two processes,
short chunks, press Track. The panel then follows the batch from a `bpy.app.timers` callback; background Blender runs
no timers, so this script calls that same callback on the main thread at the interval it asks for, until it has keyed
the stitched take. The armature must be keyed on every frame of the range, the take's result folder written with the
seams' disagreement in its report, and (Fit the Actor's Build being on by default, the take 20 frames long) the actor
fitted first into the take's actor.json, which the chunks tracked with and the keys were made from.
"""
import json
import sys
import time
from pathlib import Path

import bpy

capture, out = sys.argv[sys.argv.index("--") + 1:][:2]
track_batch = next(module for name, module in sys.modules.items() if name.endswith(".operators.track_batch"))
scene = bpy.context.scene
m = scene.mocap
m.capture_dir = capture
m.output_dir = out
m.use_frame_range, m.frame_start, m.frame_end = True, 0, 19
m.preset = "preview"
m.run_on, m.local_workers, m.chunk_frames = "local", 2, 10  # two chunks (at least twice the overlap each)
t0 = time.time()
result = bpy.ops.mocap.track()
statuses = [m.status]
interval = 0.2 if result == {"FINISHED"} else None
while interval is not None and time.time() - t0 < 900:
    time.sleep(interval)
    interval = track_batch.poll(scene.name)
    if m.status != statuses[-1]:
        statuses.append(m.status)
arm = next(o for o in scene.objects if o.type == "ARMATURE")
action = arm.animation_data.action if arm.animation_data else None
keyed = sorted({int(round(k.co[0])) for fc in (action.fcurves if action else []) for k in fc.keyframe_points})
take = Path(out) / Path(capture).name
report_file = take / "report.json"
seams = json.loads(report_file.read_text()).get("batch", {}) if report_file.is_file() else {}
ok = (result == {"FINISHED"} and interval is None and not m.last_error and keyed == list(range(1, 21))
      and (take / "joints.npz").is_file() and (take / "actor.json").is_file()
      and seams.get("overlap_mean_joint_mm") is not None
      and any(s.startswith("Running: chunk") for s in statuses))
print(f"STAGE cluster take from the Track panel: {'keyed' if ok else 'FAILED'} frames {keyed[:1]}..{keyed[-1:]} "
      f"after {time.time() - t0:.0f} s on 2 local processes; actor fitted: {(take / 'actor.json').is_file()}; "
      f"seams {seams.get('overlap_mean_joint_mm')} mm; "
      f"status {m.status!r} {m.last_error}")
print("STAGE-JSON " + json.dumps({"result": sorted(result), "statuses": statuses, "keyed": keyed, "batch": seams}))
sys.exit(0 if ok else 1)
