"""Run by the real-Blender stage in the UI (under Xvfb):

    blender SUBJECT.blend --enable-event-simulate --python drive_ui.py -- CAPTURE OUT

Drives the Mocap sidebar the way a user would, through operators and timers: Import the capture, Check the
rig, Track with Fit the Actor's Build: the actor's calibration first (modal, 3 frames), then Track by itself (the
modal operator, a few frames, with the calibration), Esc to cancel (a simulated key press, as a user's would
arrive), Resume for two more frames, Resume again with another Smoothing value (the finished take smoothed again),
then Export FBX and BVH. Takes a screenshot at each step into OUT, writes OUT/ui_report.json and quits; the stage
checks the report. Everything here runs on Blender's main thread (timers).

With `--full-take` after OUT it tracks the whole take with the default settings instead (Import, Check, Track to
the end, the actor's build fitted first as by default, no Esc) and takes one screenshot of the finished take: the
README's picture (`bash tests/real_blender/stage.sh --readme-screenshot`).
"""
import json
import subprocess
import sys
import time
import traceback
from pathlib import Path

import bpy

ADDON = "bl_ext.mocapdev.markerless_mocap"  # the module enable_addon.py installs the checkout as
CAPTURE, OUT = (Path(p) for p in sys.argv[sys.argv.index("--") + 1:][:2])
FULL_TAKE = "--full-take" in sys.argv[sys.argv.index("--") + 1:]
OUT.mkdir(parents=True, exist_ok=True)
report = {"blender": bpy.app.version_string, "steps": [], "status_lines": [], "errors": [], "screenshots": []}
state = {"t0": time.perf_counter(), "ticks": [], "step": 0}


def log(message):
    stamp = time.perf_counter() - state["t0"]
    print(f"STAGE-UI {stamp:6.1f}s {message}", flush=True)
    report["steps"].append(f"{stamp:.1f}s {message}")


def ui():
    win = bpy.context.window_manager.windows[0]
    area = max((a for a in win.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == "WINDOW")
    return win, area, region


def override():
    win, area, region = ui()
    return bpy.context.temp_override(window=win, screen=win.screen, area=area, region=region,
                                     scene=win.scene, view_layer=win.view_layer)


def screenshot(name):
    """The X display as the user sees it (ImageMagick; Blender's own screenshot reads a black front
    buffer under Xvfb + llvmpipe)."""
    path = OUT / f"{name}.png"
    proc = subprocess.run(["import", "-window", "root", str(path)], capture_output=True, text=True, timeout=30)
    if proc.returncode != 0:
        raise RuntimeError(f"screenshot failed: {proc.stderr.strip()}")
    report["screenshots"].append(path.name)
    log(f"screenshot {path.name}")


def props():
    return bpy.context.window_manager.windows[0].scene.mocap


def finish(code=0):
    report["seconds"] = round(time.perf_counter() - state["t0"], 1)
    ticks = state["ticks"]
    gaps = [b - a for a, b in zip(ticks, ticks[1:])]
    report["timer_ticks_while_tracking"] = len(ticks)
    report["max_ui_gap_s"] = round(max(gaps), 2) if gaps else None
    (OUT / "ui_report.json").write_text(json.dumps(report, indent=1))
    log(f"done ({'ok' if not report['errors'] else 'errors'})")
    bpy.ops.wm.quit_blender()


def guarded(fn):
    def run():
        try:
            return fn()
        except Exception as exc:
            report["errors"].append(f"{fn.__name__}: {type(exc).__name__}: {exc}")
            traceback.print_exc()
            finish(1)
            return None
    return run


@guarded
def step_setup():
    win, area, _ = ui()
    area.spaces.active.show_region_ui = True
    m = props()
    m.capture_dir = str(CAPTURE)
    m.output_dir = str(OUT / "ui_result")
    if FULL_TAKE:  # every frame, the defaults as a new user has them
        log(f"sidebar open; capture folder, output folder; preset {m.preset}, {m.particles} x {m.iterations}")
        bpy.app.timers.register(step_tab, first_interval=0.5)
        return
    m.use_frame_range, m.frame_start, m.frame_end = True, 0, 29
    m.preset = "preview"  # the Preset menu as a user picks it: the budget fields follow it
    report["preset"] = {"name": m.preset, "budget": [m.particles, m.iterations],
                        "local_fit_fine": m.tracking_settings().fine_refine}
    m.particles, m.iterations = 30, 4
    log(f"sidebar open; capture folder, output folder, frames 0-29; preset {report['preset']}, then 30 x 4 set")
    bpy.app.timers.register(step_tab, first_interval=0.5)


@guarded
def step_tab():
    """Switch the sidebar to the Mocap tab as a user can: Ctrl+wheel over the tab strip cycles the tabs
    (Region.active_panel_category is read-only in 4.3). Events are handled between timer calls: one step
    per call until the tab is Mocap."""
    win, area, _ = ui()
    sidebar = next(r for r in area.regions if r.type == "UI")
    state["tab_tries"] = state.get("tab_tries", 0) + 1
    if sidebar.active_panel_category != "Mocap" and state["tab_tries"] <= 8:
        x, y = sidebar.x + sidebar.width - 8, sidebar.y + sidebar.height // 2  # over the tab strip
        win.event_simulate(type="MOUSEMOVE", value="NOTHING", x=x, y=y)
        win.event_simulate(type="WHEELDOWNMOUSE", value="PRESS", x=x, y=y, ctrl=True)
        return 0.3
    report["sidebar_tab"] = sidebar.active_panel_category
    log(f"sidebar tab: {sidebar.active_panel_category} after {state['tab_tries'] - 1} Ctrl+wheel steps")
    bpy.app.timers.register(step_import, first_interval=0.5)


@guarded
def step_import():
    with override():
        result = bpy.ops.mocap.import_capture()
    coll = bpy.data.collections.get("Mocap Cameras")
    cams = sorted(o.name for o in coll.objects if o.type == "CAMERA") if coll else []
    report["import"] = {"result": sorted(result), "cameras": cams}
    log(f"Import Capture: {sorted(result)}, collection 'Mocap Cameras' with {len(cams)} cameras {cams}")
    if cams:  # look through the first camera: its video is the background, the subject over it
        win, area, _ = ui()
        win.scene.camera = bpy.data.objects[cams[0]]
        area.spaces.active.region_3d.view_perspective = "CAMERA"
        with override():
            bpy.ops.view3d.view_center_camera()
    bpy.app.timers.register(step_check, first_interval=1.0)


@guarded
def step_check():
    screenshot("01_imported")
    with override():
        result = bpy.ops.mocap.check_subject()
    m = props()
    report["check"] = {"result": sorted(result), "dofs": m.subject_dofs, "preset": m.subject_preset}
    log(f"Check rig: {sorted(result)}, {m.subject_dofs} DOF, preset {m.subject_preset}")
    bpy.app.timers.register(step_track_whole_take if FULL_TAKE else step_calibrate, first_interval=1.0)


def invoke_modal(operator, name, started_key, watcher):
    """Invoke a modal operator as a click does, note when, and watch it every 0.2 s; returns its result."""
    with override():
        result = sorted(operator("INVOKE_DEFAULT"))
    log(f"{name} invoked: {result}")
    state[started_key] = time.perf_counter()
    bpy.app.timers.register(watcher, first_interval=0.2)
    return result


@guarded
def step_calibrate():
    """Track with Fit the Actor's Build (on by default) on 3 calibration frames, with a measured height and forearm:
    Track runs the calibration first (the modal operator; the UI keeps ticking), the calibrated height and forearm
    show (the measured ones), then Track starts by itself with them."""
    props().calibrate_frames = 3
    props().actor_height = 1.55
    props().actor_forearm = 0.25  # Measured Lengths > Forearm
    screenshot("02_checked")
    result = invoke_modal(bpy.ops.mocap.track, "Track (the actor's build first)", "calibrate_started",
                          step_watch_calibration)
    report["calibrate"] = {"track_click": result, "status_lines": [], "ticks": 0,
                           "invoke": ["RUNNING_MODAL"] if props().is_calibrating else result}


@guarded
def step_watch_calibration():
    m = props()
    cal = report["calibrate"]
    cal["ticks"] += 1
    if m.calibration_status and (not cal["status_lines"] or cal["status_lines"][-1] != m.calibration_status):
        cal["status_lines"].append(m.calibration_status)
        log(f"calibration status: {m.calibration_status}")
    if state.get("shoot_calibrating") and "03_calibrating.png" not in report["screenshots"]:
        screenshot("03_calibrating")  # a tick after the first frame's line: the sidebar has redrawn with it
    state["shoot_calibrating"] = m.calibration_status.startswith("Calibrating: frame")
    if m.is_calibrating:
        if time.perf_counter() - state["calibrate_started"] > 240:
            raise TimeoutError("the calibration did not finish within 240 s")
        return 0.2
    cal.update(summary=m.actor_summary.splitlines(), actor_file=m.actor_file, use_actor=m.use_actor,
               error=m.last_error, seconds=round(time.perf_counter() - state["calibrate_started"], 1))
    log(f"calibrated in {cal['seconds']} s: {cal['summary'][:1]} {m.last_error}")
    screenshot("03_calibrated")
    # the calibration's end started Track with the fit: watch it as if Track had been clicked now
    report["track_invoke"] = ["RUNNING_MODAL"] if m.is_tracking else ["NOT STARTED"]
    log(f"Track after the calibration: {report['track_invoke']}")
    state["track_started"] = time.perf_counter()
    bpy.app.timers.register(step_watch, first_interval=0.2)
    return None


@guarded
def step_watch():
    """Runs every 0.2 s while the modal operator tracks: the UI must keep ticking."""
    m = props()
    state["ticks"].append(time.perf_counter())
    if m.status and (not report["status_lines"] or report["status_lines"][-1] != m.status):
        report["status_lines"].append(m.status)
        log(f"status: {m.status}")
    if m.frames_solved >= 2 and not state.get("seen_two"):
        state["seen_two"] = True
        return 0.3  # let the sidebar redraw with the new count first
    if state.get("seen_two") and "04_tracking.png" not in report["screenshots"]:
        screenshot("04_tracking")
        report["keys_at_screenshot"] = m.frames_solved
        return 1.0  # let the screenshot's frame pass, then press Esc
    if "04_tracking.png" in report["screenshots"] and not state.get("esc_sent"):
        win = bpy.context.window_manager.windows[0]
        win.event_simulate(type="ESC", value="PRESS")
        win.event_simulate(type="ESC", value="RELEASE")
        state["esc_sent"] = time.perf_counter()
        report["frames_at_esc"] = m.frames_solved
        log(f"Esc pressed at {m.frames_solved} frames solved")
        return 0.2
    if state.get("esc_sent") and not m.is_tracking:
        frames = keyed_frames()
        report["cancel"] = {"status": m.status, "frames_solved": m.frames_solved, "keyed_frames": frames,
                            "seconds_after_esc": round(time.perf_counter() - state["esc_sent"], 1)}
        log(f"cancelled: '{m.status}', keyed frames {frames}")
        bpy.app.timers.register(step_resume, first_interval=0.5)
        return None
    if time.perf_counter() - state["track_started"] > 240:
        raise TimeoutError("tracking did not reach 2 frames / did not stop within 240 s")
    return 0.2


@guarded
def step_track_whole_take():
    report["track_invoke"] = invoke_modal(bpy.ops.mocap.track, "Track", "track_started", step_watch_whole_take)


@guarded
def step_watch_whole_take():
    """Waits for the whole take (and its smoothing), then shoots the sidebar showing the finished take."""
    m = props()
    if m.status and (not report["status_lines"] or report["status_lines"][-1] != m.status):
        report["status_lines"].append(m.status)
    if m.is_tracking or m.preparing or m.is_calibrating:  # Fit the Actor's Build runs first
        if time.perf_counter() - state["track_started"] > 900:
            raise TimeoutError("the whole take did not finish within 900 s")
        return 0.5
    if not state.get("settled"):
        state["settled"] = True
        return 2.0  # the sidebar redraws with the final status first
    report["finished"] = {"status": m.status, "frames_solved": m.frames_solved, "keyed_frames": len(keyed_frames()),
                          "error": m.last_error, "seconds": round(time.perf_counter() - state["track_started"], 1)}
    log(f"finished: '{m.status}', {report['finished']['keyed_frames']} frames keyed")
    screenshot("finished_take")
    finish(0)
    return None


def keyed_frames():
    """The scene frames the armature's action holds keys on, read as the add-on reads them (any Blender)."""
    import importlib

    compat = importlib.import_module(f"{ADDON}.addon.anim_compat")
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    return [int(round(f)) for f in compat.keyed_frames(arm)]


def resume_run(key, then):
    """Track again with Resume ticked, as a user does after a cancel; record its status and keys, then `then`."""
    @guarded
    def watch_resumed():
        m = props()
        if m.is_tracking or m.preparing:
            if time.perf_counter() - state[f"{key}_started"] > 240:
                raise TimeoutError(f"the {key} run did not finish within 240 s")
            return 0.2
        report[key].update(status=m.status, frames_solved=m.frames_solved, keyed_frames=keyed_frames(),
                           error=m.last_error)
        log(f"{key}: '{m.status}', keyed frames {report[key]['keyed_frames']}")
        bpy.app.timers.register(then, first_interval=0.5)
        return None

    report[key] = {"invoke": invoke_modal(bpy.ops.mocap.track, f"Track ({key})", f"{key}_started", watch_resumed)}


@guarded
def step_resume():
    """Resume the cancelled take for two more frames: the keys of the earlier frames stay, two are added."""
    m = props()
    m.resume, m.frame_end = True, report["cancel"]["frames_solved"] + 1
    resume_run("resume", step_resmooth)


@guarded
def step_resmooth():
    """Resume the finished take with another Smoothing value: nothing left to solve, the take smoothed again."""
    props().smoothing_hz = 3.0
    resume_run("resmooth", step_export)


@guarded
def step_export():
    screenshot("05_resumed")  # after the cancel and both Resume runs
    with override():
        fbx = bpy.ops.mocap.export_fbx("EXEC_DEFAULT", filepath=str(OUT / "ui_export.fbx"))
        bvh = bpy.ops.mocap.export_bvh("EXEC_DEFAULT", filepath=str(OUT / "ui_export.bvh"))
    report["export"] = {"fbx": sorted(fbx), "bvh": sorted(bvh),
                        "fbx_bytes": (OUT / "ui_export.fbx").stat().st_size if (OUT / "ui_export.fbx").exists() else 0,
                        "bvh_bytes": (OUT / "ui_export.bvh").stat().st_size if (OUT / "ui_export.bvh").exists() else 0}
    log(f"Export: FBX {sorted(fbx)}, BVH {sorted(bvh)}")
    bpy.app.timers.register(step_end, first_interval=0.5)


@guarded
def step_end():
    screenshot("06_exported")
    finish(0)


bpy.app.timers.register(step_setup, first_interval=2.0)
