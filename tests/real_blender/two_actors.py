"""Run by the real-Blender stage in the UI under Xvfb:
`blender duet/subject.blend --python two_actors.py -- CAPTURE OUT` (with `-b`: the operator's synchronous path).

What a user does in the Subject and Track panels for several actors: tick 'Track Every Armature', set the capture
and output folders and a short frame range, measure one actor's height on its armature, choose the Heavy landmark
model (not the Preview preset's: the property must reach both actors' fits and tracking), press Track with Fit the
Actor's Build on (the default) and 3 calibration frames: each actor's build is fitted in turn (in the UI the modal
calibration, one actor after the other), then both are tracked (the modal Track), watched from a timer as the
window keeps drawing. Both actors' fits must be saved in their result folders (actors/<armature>/actor.json, made
on this capture; the measured actor's with its measured height), both armatures keyed on every tracked frame, each
actor's result folder written and tracked with the heavy model, the UI never stalled more than 5 s.
"""
import json
import sys
import time
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
m.fit_actor_build, m.calibrate_frames = True, 3
m.landmarks = "heavy"
MEASURED = {armatures[-1]: 1.62}  # one actor's measured height, on its own armature (Subject panel, under its name)
for name, height in MEASURED.items():
    bpy.context.scene.objects[name].mocap_measured.actor_height = height
state = {"ticks": [], "calibrating_seen": False}


def check_and_end(result):
    """Print what was keyed where (STAGE lines the stage greps) and end Blender, 0 when both actors are keyed."""
    report = {"armatures": armatures, "result": sorted(result), "status": m.status, "error": m.last_error,
              "keys": {}, "modal": not bpy.app.background, "calibrating_seen": state["calibrating_seen"]}
    for name in armatures:
        arm = bpy.context.scene.objects[name]
        frames = []
        for f in range(bpy.context.scene.frame_start, bpy.context.scene.frame_end + 1):
            bpy.context.scene.frame_set(f)
            frames.append([round(v, 4) for v in (arm.matrix_world @ arm.pose.bones["Hips"].matrix).translation])
        fit = Path(out) / "actors" / name / "actor.json"
        saved = json.loads(fit.read_text()) if fit.is_file() else {}
        made_on = saved.get("capture")
        if name in MEASURED:  # the measured height is this actor's, not the footage's
            height = saved.get("height_m")
            report.setdefault("measured_height_m", {})[name] = None if height is None else round(height, 4)
        tracked = Path(out) / "actors" / name / "report.json"
        model = json.loads(tracked.read_text()).get("settings", {}).get("landmarks") if tracked.is_file() else None
        report["keys"][name] = {"keyed": arm.animation_data is not None and arm.animation_data.action is not None,
                                "landmarks": model,
                                "hips": frames, "folder": (Path(out) / "actors" / name / "joints.npz").is_file(),
                                "fitted": made_on is not None and Path(made_on).resolve() == Path(capture).resolve()}
    gaps = [b - a for a, b in zip(state["ticks"], state["ticks"][1:])]
    report["max_ui_gap_s"] = round(max(gaps), 2) if gaps else None
    # in the UI Track hands over to the modal calibration (FINISHED), which starts the modal Track once both are fitted
    started = ["FINISHED"]
    ok = (report["result"] == started and len(armatures) == 2 and m.status.startswith("Tracked 3 frames")
          and (bpy.app.background or state["calibrating_seen"])
          and all(k["keyed"] and k["folder"] and k["fitted"] and k["landmarks"] == "heavy"
                  for k in report["keys"].values())
          and (Path(out) / "tracked.blend").is_file()
          and all(abs((report.get("measured_height_m", {}).get(n) or 0) - h) < 1e-3 for n, h in MEASURED.items())
          and (bpy.app.background or (report["max_ui_gap_s"] is not None and report["max_ui_gap_s"] < 5)))
    hips = [report["keys"][n]["hips"][0] for n in armatures]
    apart = sum((a - b) ** 2 for a, b in zip(*hips)) ** 0.5 if len(hips) == 2 else 0.0
    ok = ok and apart > 0.3  # each keyed on its own person, not both on one
    how = "modal, in the UI" if not bpy.app.background else "in the background"
    print(f"STAGE two actors from the Track panel ({how}): {'keyed both' if ok else 'FAILED'} ({', '.join(armatures)}; "
          f"{m.status!r}; builds fitted: {sum(k['fitted'] for k in report['keys'].values())}, measured heights kept: "
          f"{report.get('measured_height_m')}; landmark models "
          f"{[k['landmarks'] for k in report['keys'].values()]}; hips {apart:.2f} m apart "
          f"at the first frame; longest UI gap {report['max_ui_gap_s']} s) "
          f"{m.last_error}", flush=True)
    print("STAGE-JSON " + json.dumps(report), flush=True)
    if bpy.app.background:
        sys.exit(0 if ok else 1)
    bpy.ops.wm.quit_blender()  # the stage reads the verdict from the STAGE line


def press_track():
    win = bpy.context.window_manager.windows[0]
    area = max((a for a in win.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=win, screen=win.screen, area=area, region=region):
        state["result"] = bpy.ops.mocap.track("INVOKE_DEFAULT")
    state["t0"] = time.perf_counter()
    bpy.app.timers.register(watch, first_interval=0.2)


def watch():
    """Every 0.2 s while the modal calibration, then the modal Track, run: the UI must keep ticking."""
    state["ticks"].append(time.perf_counter())
    state["calibrating_seen"] |= m.is_calibrating
    if (m.is_calibrating or m.is_tracking) and time.perf_counter() - state["t0"] < 420:
        return 0.2
    check_and_end(state["result"])
    return None


if bpy.app.background:
    check_and_end(bpy.ops.mocap.track())
else:
    bpy.app.timers.register(press_track, first_interval=1.0)
