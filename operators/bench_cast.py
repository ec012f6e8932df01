"""`bench --two-actors SCENE`: seconds per frame of two actors tracked together against each tracked alone, on the
scene's first frames (the first frame's whole-body search and the frame after it left out: the second frame still
builds what later frames reuse), the default settings. "One actor" is the mean of the two alone."""
import tempfile
import time
from pathlib import Path


def _seconds_per_tracked_frame(session):
    """Wall seconds of each solve_next after the second, averaged; the session is closed after."""
    times = []
    try:
        while True:
            t = time.perf_counter()
            if session.solve_next() is None:
                break
            times.append(time.perf_counter() - t)
    finally:
        for s in getattr(session, "sessions", [session]):
            if s.tracker is not None:
                s.tracker.finish_prefetch()
            s.capture.close()
    return sum(times[2:]) / max(1, len(times) - 2)


def cast_seconds(scene_dir, frames=6, seed=0, landmarks=None):
    """{"one_s_per_frame", "two_s_per_frame", "ratio", "frames", "armatures", "landmarks"} on `scene_dir` (its
    subject.blend holds at least two armatures; the first two by name are timed): `frames` timed frames each, with
    the landmark model `landmarks` (None or "auto": the Full preset's)."""
    import bpy

    from ..addon.scene_bridge import scene_armatures
    from ..core.tracking.options import settings_from_choices
    from .cast_session import CastError, CastSession
    from .track_session import TrackSession

    scene_dir = Path(scene_dir)
    bpy.ops.wm.open_mainfile(filepath=str(scene_dir / "subject.blend"))
    scene = bpy.context.scene
    armatures = scene_armatures(scene)[:2]
    if len(armatures) < 2:
        raise CastError(f"{scene_dir / 'subject.blend'} has fewer than two armatures: --two-actors needs a scene "
                        "with two, such as sample_scenes/duet")
    options = dict(frames=range(frames + 2), smooth_hz=0, foot_lock=False)
    settings = settings_from_choices({"seed": seed, "landmarks": landmarks})
    with tempfile.TemporaryDirectory() as tmp:
        alone = [_seconds_per_tracked_frame(TrackSession(scene, a, scene_dir, Path(tmp) / a.name,
                                                         settings, **options)) for a in armatures]
        one = sum(alone) / len(alone)
        two = _seconds_per_tracked_frame(CastSession(scene, armatures, scene_dir, Path(tmp) / "two",
                                                     settings=settings, **options))
    return {"one_s_per_frame": round(one, 3), "two_s_per_frame": round(two, 3), "ratio": round(two / one, 2),
            "frames": frames, "armatures": [a.name for a in armatures], "landmarks": settings.landmarks}
