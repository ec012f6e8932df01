"""Run by the real-Blender stage: `blender -b SCENE/subject.blend --python cluster_take.py -- CAPTURE OUT`.

What a user does to send a take to local processes from the Track panel: Run On 'Local Processes', press Track. The
panel then follows the batch from a `bpy.app.timers` callback; background Blender runs no timers, so this script
calls that same callback on the main thread at the interval it asks for, until it has keyed the result.

- One armature (walk): two processes, chunks of 10 over frames 0-19. The armature must be keyed on every frame of
  the range, the take's result folder written with the seams' disagreement in its report, and (Fit the Actor's
  Build being on by default, the take 20 frames long) the actor fitted first into the take's actor.json, which the
  chunks tracked with and the keys were made from.
- Several armatures (duet): Track Every Armature, the last actor's height measured on its armature, one process,
  frames 0-2: one chunk tracking both actors, after a fit of each actor's build (tests/test_batch_cast.py cuts such a
  take into several chunks); each armature must be keyed on every frame from its own result folder, and the measured
  height must have reached that actor's fit.
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
names = sorted(o.name for o in scene.objects if o.type == "ARMATURE")
several = len(names) > 1
m.capture_dir = capture
m.output_dir = out
m.preset = "preview"
if several:
    m.every_armature = True
    m.use_frame_range, m.frame_start, m.frame_end, m.calibrate_frames = True, 0, 2, 3
    scene.objects[names[-1]].mocap_measured.actor_height = 1.62
    m.run_on, m.local_workers = "local", 1
else:
    m.use_frame_range, m.frame_start, m.frame_end = True, 0, 19
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
took = time.time() - t0
ended = result == {"FINISHED"} and interval is None and not m.last_error
take = Path(out) / Path(capture).name
keyed = {}
for name in names:
    action = scene.objects[name].animation_data.action if scene.objects[name].animation_data else None
    keyed[name] = sorted({int(round(k.co[0])) for fc in (action.fcurves if action else []) for k in fc.keyframe_points})
if several:
    folders = all((take / "actors" / name / "joints.npz").is_file() for name in names)
    fit = take / "actors" / names[-1] / "actor.json"
    height = round(json.loads(fit.read_text()).get("height_m"), 4) if fit.is_file() else None
    ok = ended and len(names) == 2 and all(k == [1, 2, 3] for k in keyed.values()) and folders and height == 1.62
    print(f"STAGE cluster cast from the Track panel: {'keyed both' if ok else 'FAILED'} ({', '.join(names)}: frames "
          f"{[k[:1] + k[-1:] for k in keyed.values()]}) after {took:.0f} s on a local process; {names[-1]}'s "
          f"measured height in its fit: {height}; status {m.status!r} {m.last_error}")
    seams = None
else:
    (frames,) = keyed.values()
    report_file = take / "report.json"
    seams = json.loads(report_file.read_text()).get("batch", {}) if report_file.is_file() else {}
    ok = (ended and frames == list(range(1, 21)) and (take / "joints.npz").is_file()
          and (take / "actor.json").is_file() and seams.get("overlap_mean_joint_mm") is not None
          and any(s.startswith("Running: chunk") for s in statuses))
    print(f"STAGE cluster take from the Track panel: {'keyed' if ok else 'FAILED'} frames {frames[:1]}..{frames[-1:]} "
          f"after {took:.0f} s on 2 local processes; actor fitted: {(take / 'actor.json').is_file()}; "
          f"seams {seams.get('overlap_mean_joint_mm')} mm; status {m.status!r} {m.last_error}")
print("STAGE-JSON " + json.dumps({"result": sorted(result), "statuses": statuses, "keyed": keyed, "batch": seams}))
sys.exit(0 if ok else 1)
