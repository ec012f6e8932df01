"""Calibrate the actor: track the first frames with the user's rig, fit the proportions to their landmarks,
save actor.json. Shared by `calibrate`, `track --calibrate` and the Calibrate button (Subject panel)."""
from pathlib import Path

import numpy as np

from ..core.actor.frames import DEFAULT_FRAMES
from .worker_job import WorkerJob


def calibration_frames(all_frames, count=DEFAULT_FRAMES):
    """The frames to calibrate on when none are chosen: the first `count` of the take."""
    return list(all_frames)[:count]


def calibrate_actor(scene, armature, capture_dir, out_dir, settings=None, frames=None, log=None, step=None,
                    progress=None, symmetric=True, silhouettes=True, measured=None):
    """Track `frames` (default: the first DEFAULT_FRAMES) with the rig into OUT/calibration_frames/, fit the
    proportions to the landmarks, then (silhouettes=True) refine them against the person masks of the same
    frames, apply the lengths the user measured ({segment or "height": metres}), write OUT/actor.json.
    Returns (ProportionsFit, path of actor.json)."""
    from ..core.actor.measured_lengths import with_measured

    session = open_calibration(scene, armature, capture_dir, out_dir, settings, frames, log, step)
    fit = with_measured(fit_calibration(session, log, progress, symmetric, silhouettes), session.character,
                        measured)
    return fit, save_calibration(fit, out_dir, armature.name, capture_dir)


def open_calibration(scene, armature, capture_dir, out_dir, settings=None, frames=None, log=None, step=None):
    """Main thread (reads the rig from Blender): the session that tracks the calibration frames into
    OUT/calibration_frames/ (default: the take's first DEFAULT_FRAMES)."""
    from .track_session import TrackSession

    if frames is not None:
        require_enough_frames(list(frames), capture_dir)  # before the session opens the capture or the folder
    session = TrackSession(scene, armature, capture_dir, Path(out_dir) / "calibration_frames", settings,
                           frames=frames, log=log, step=step)
    if frames is None:  # the first frames of the take
        session.all_frames = session.frames = calibration_frames(session.all_frames)
        try:
            require_enough_frames(session.frames, capture_dir)  # a take shorter than that
        except Exception:
            session.capture.close()
            raise
    return session


def require_enough_frames(frames, capture_dir):
    """Too few frames to calibrate on: the user's range (or a very short take), said before anything is tracked."""
    from ..core.actor.frames import MIN_FRAMES
    from ..core.actor.landmark_fit import ProportionsFitError

    if len(frames) < MIN_FRAMES:
        given = ("none" if not frames else f"1 (frame {frames[0]})" if len(frames) == 1
                 else f"{len(frames)} (frames {frames[0]}-{frames[-1]})")
        raise ProportionsFitError(f"the calibration needs at least {MIN_FRAMES} frames; it was given {given} of "
                                  f"{capture_dir}: choose a longer range; {DEFAULT_FRAMES} frames (the default) "
                                  "measure the lengths best")


def fit_calibration(session, log=None, progress=None, symmetric=True, silhouettes=True):
    """Any thread (no bpy): track the session's frames (not keyed: the rig keeps the user's animation), fit the
    proportions to their landmarks, refine them against the person masks; closes the capture. Returns the
    ProportionsFit, or None when the session was cancelled first."""
    from ..core.actor.landmark_fit import ProportionsFitError, fit_proportions

    log = log or (lambda msg: None)
    try:
        progress = progress or (lambda est: log(f"calibration: frame {est.frame} solved"))
        while (est := session.solve_next()) is not None:
            progress(est)
        if getattr(session, "cancelled", False):
            return None
        est = session.writer.estimates
        if not est or est[0].landmarks is None:
            raise ProportionsFitError("calibration needs the learned landmarks: track with a likelihood that has "
                                      "'kp' (the default lsilh+edge+kp)")
        landmarks = np.array([e.landmarks for e in est])
        visibility = np.array([e.landmark_visibility for e in est])
        fit = fit_proportions(session.character, session.capture.cameras, landmarks, visibility,
                              np.array([e.pose for e in est]), frames=[e.frame for e in est], symmetric=symmetric,
                              model=session.settings.landmarks)
        if silhouettes:
            from ..core.actor.silhouette_fit import calibration_targets, refine_fit

            log("calibration: refining the proportions against the person masks")
            used = [[e.frame for e in est].index(f) for f in fit.frames]
            # one pass of the learned evidence over the frames serves the refinement and the check after it
            targets = calibration_targets(session.tracker, session.character, fit.frames, fit.poses,
                                          landmarks[used], visibility[used])
            fit = refine_fit(fit, session.character, session.tracker, landmarks[used], visibility[used], log=log,
                             targets=targets)
            fit = _chosen_body(fit, session, targets, np.array([e.pose for e in est])[used], log)
    finally:
        session.capture.close()
    return fit


def _chosen_body(fit, session, targets, rig_poses, log):
    """The fit's segments taken halfway (the trunk/leg split and the hip width set by the person masks; the rig
    scaled to the masks' height where the landmarks misread it), or the rig's own proportions where they match the
    masks better (core/actor/body_choice.py)."""
    from ..core.actor.body_choice import compare_bodies, keep_chosen

    log("calibration: the spine/thigh split, the hip width, the height and the choice between the rig and the "
        "calibrated body, against the person masks")
    comparison = compare_bodies(fit, session.character, session.tracker, targets, rig_poses)
    log(f"calibration: {_CHOICE[comparison.chosen]} ({_mismatches(comparison.mismatch)})"
        f"{_ruled_out(comparison.ruled_out)}")
    return keep_chosen(fit, session.character, comparison)


_CHOICE = {"rig": "kept the rig's proportions",
           "halfway": "took each segment halfway between the fit and the rig scaled to the fitted height",
           "uniform": "took the rig scaled uniformly to the height the person masks read"}


def _ruled_out(ruled_out):
    """Why the rig was not kept although the masks liked it best (`ruled_out`: the bodies set aside,
    core/actor/body_choice.rig_ruled_out), or ''."""
    if not ruled_out:
        return ""
    from ..core.actor.body_choice import RIG_HEIGHT_GATE

    return (f"; not the rig: the landmarks and the person masks both read the height more than "
            f"{100 * RIG_HEIGHT_GATE:.0f} % off the rig's")


def _mismatches(mismatch):
    return "mask mismatch " + ", ".join(f"{name} {value:.3f}" for name, value in mismatch.items())


def save_calibration(fit, out_dir, subject_name, capture_dir):
    """OUT/actor.json of the fit; returns its path."""
    from ..core.actor.actor_file import save_actor

    return save_actor(Path(out_dir) / "actor.json", fit, subject_name=subject_name,
                      capture=Path(capture_dir).resolve())


class CalibrationJob(WorkerJob):
    """The Calibrate button's run in a worker thread, as TrackJob runs Track (operators/worker_job.py): the
    worker only calls fit_calibration. Esc cancels after the frame being solved; nothing is saved then."""
    thread_name = "mocap-calibrate"
    doing = "The calibration"

    def __init__(self, session, n_frames):
        super().__init__()
        self.session, self.n_frames = session, int(n_frames)
        self.solved = 0
        self.status = "starting"
        self.fit = None
        self.error = None  # (message, traceback)

    def start(self):
        self.start_worker()

    def work(self):
        fit = fit_calibration(self.session, log=lambda msg: self.queue.put(("status", str(msg))),
                              progress=lambda est: self.queue.put(("frame", est.frame)))
        self.queue.put(("fit", fit))

    # ---- messages, on the main thread
    def on_frame(self, _frame):
        self.solved += 1
        self.status = f"frame {self.solved} of {self.n_frames} solved"

    def on_status(self, text):
        self.status = text.removeprefix("calibration: ")  # shown under "Calibrating: " already

    def on_fit(self, fit):
        self.fit = fit

    def on_error(self, message, details):
        self.error = (message, details)

    @property
    def fraction(self):
        return min(1.0, self.solved / self.n_frames) if self.n_frames else 0.0

    @property
    def cancelled(self):
        return self.session.cancelled

    def request_cancel(self):
        self.session.cancel()


def describe(fit):
    """The fitted height and segment lengths, one line each (for the terminal and the panel)."""
    from ..core.actor.measured_lengths import FOOTAGE_MISS_PERCENT

    L, S = fit.lengths, fit.subject_lengths
    measured = fit.measured or {}
    lines = [f"height {L['height']:.3f} m (rig {S['height']:.3f} m)"
             + (f", measured {measured['height']:.3f} m" if "height" in measured else "")]
    sided = any(k[:2] in ("l_", "r_") for k in fit.proportions.factors)
    for seg in ("spine", "neck", "shoulder_width", "hip_width", "upper_arm", "forearm", "thigh", "shin", "foot"):
        for key in ([f"l_{seg}", f"r_{seg}"] if sided and f"l_{seg}" in L else [seg]):
            lines.append(f"{key.replace('_', ' ')} {L[key] * 100:.1f} cm (rig {S[key] * 100:.1f} cm, "
                         f"x{L[key] / S[key]:.3f}){_how_known(seg, measured, FOOTAGE_MISS_PERCENT)}")
    lines.append(f"landmark residual {fit.rms_before * 1000:.1f} mm with the rig -> {fit.rms_after * 1000:.1f} mm "
                 f"calibrated, {len(fit.frames)} frames")
    if fit.silhouettes:
        refined = fit.silhouettes
        mismatch = refined["mask_mismatch"]
        kept = refined.get("kept_at_landmark_fit", [])
        # a measured segment's length is the tape's, whatever the footage made of it
        moved = [s.replace("_", " ") for s in refined["segments"] if s not in kept and s not in measured]
        kept = [s for s in kept if s not in measured]
        if moved:
            lines.append(f"{' and '.join(moved)} refined against the person masks (mismatch "
                         f"{mismatch['landmark_fit']:.3f} -> {mismatch['refined']:.3f})")
        if kept:
            lines.append(f"{' and '.join(s.replace('_', ' ') for s in kept)} from the landmarks: the masks do not "
                         "pin it down here")
        check = refined.get("body_check")
        if check:
            fitted = check.get("fitted_lengths_m", L)["height"]
            why = "the rig matched the person masks best but is ruled out" if check.get("ruled_out") else \
                "it matches the person masks best"
            lines.append(f"{_CHOICE[check['chosen']]}: {why} ({_mismatches(check['mismatch'])}; the landmark fit's "
                         f"height {fitted:.3f} m){_ruled_out(check.get('ruled_out'))}")
            if check["chosen"] == "halfway":
                lines += _searched_by_masks(check)
            lines += _height_by_masks(check)
    return lines


def _how_known(segment, measured, miss_percent):
    """' as measured', or how far the footage may miss a segment it reads less well than the rest."""
    if segment in measured:
        return " as measured"
    if segment in miss_percent:
        return f" (the footage reads it to ±{miss_percent[segment]:.0f} %)"
    return ""


def _searched_by_masks(check):
    """One line per length the person masks were searched for (the trunk/leg split, the hip width): what they set,
    or that they did not pin it down."""
    from ..core.actor.mask_line_search import pinned_down

    lines = []
    split, hips = check.get("split"), check.get("hip_width")
    if split and not pinned_down(split["grid"]):
        lines.append("spine and thigh split as the uniform scale has them: the person masks do not pin the split "
                     "down here")
    elif split:
        lines.append(f"spine and thigh split by the person masks: the spine {_percent(split['spine_log_change'])} "
                     "against the uniform scale, the thighs making up the height")
    if hips and not pinned_down(hips["grid"]):
        lines.append("hip width halfway: the person masks do not pin it down here")
    elif hips:
        lines.append(f"hip width set by the person masks: {_percent(hips['log_change'])} against halfway")
    return lines


def _height_by_masks(check):
    """The line on where the person masks put the height (core/actor/height_by_masks.py), if they were asked."""
    from ..core.actor.height_by_masks import GATE
    from ..core.actor.mask_line_search import pinned_down

    height = check.get("height")
    if not height:
        return []
    if height["taken"]:
        # the height compared is the landmarks' body after the split and hip width, a little off the fit's own
        return [f"height read by the person masks: {height['masks_height_m']:.3f} m, the landmarks' body's (split "
                f"and hip width set) {height['landmark_height_m']:.3f} m (more than {100 * GATE:.0f} % apart), so "
                "the rig scaled to it stood in for the landmarks' proportions"]
    if not pinned_down(height["grid"]):
        return ["height from the landmarks: the person masks do not pin it down here"]
    return [f"height from the landmarks: the person masks put it at {height['masks_height_m']:.3f} m, within "
            f"{100 * GATE:.0f} %"]


def _percent(log_change):
    return f"{100 * (np.exp(log_change) - 1.0):+.1f} %"
