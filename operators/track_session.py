"""One tracking run, shared by the command line and the modal Track operator.

Construction and `key`/`finish` run on Blender's main thread (they touch bpy); `solve_next` is pure
engine work and may run in a worker thread. Every solved frame is written to the result folder at
once (joints, poses, report, checkpoint), so a cancelled or crashed run loses nothing and `resume`
continues exactly where it stopped.
"""
import threading
from pathlib import Path

import numpy as np

from ..addon import scene_bridge
from ..core.capture.capture import load_capture
from ..core.evidence.learned import model_path, require_model
from ..core.energy.likelihood import resolve_weights
from ..core.results.result_folder import ResultWriter, atomic_path
from ..core.tracking.foot_contact import CONTACT_SPEED, FootContactError, check_speed
from ..core.tracking.fast_arms import FAST_ARM_FROM, FAST_ARM_TO
from ..core.tracking.smoothing import DEFAULT_CUTOFF_HZ, MIN_RUN, check_cutoff, smooth_poses
from ..core.tracking.settings import TrackingSettings
from ..core.tracking.tracker import Tracker


def build_motion_models(body, capture_folder, fps, seed=0, progress=None):
    """Anatomical prior + AR(3) dynamics from the bundled CMU clips, leaving out the clip window a
    bundled sample scene was made from."""
    from ..core.tracking.motion_library import build_motion_models as build, scene_exclusion

    return build(body, fps=fps, exclude=scene_exclusion(capture_folder), seed=seed, progress=progress)


def _blender_version():
    import bpy

    return bpy.app.version_string


class TrackSession:
    def __init__(self, scene, armature_obj, capture_dir, out_dir, settings=None, frames=None, resume=False,
                 mesh_obj=None, frame_offset=None, prior=None, log=None, units=None, step=None, actor=None,
                 smooth_hz=DEFAULT_CUTOFF_HZ, foot_lock=True, foot_lock_speed=CONTACT_SPEED):
        self.scene = scene
        self.armature = armature_obj
        self.settings = settings or TrackingSettings()
        self.log = log or (lambda msg: None)
        # step(text, fraction): the one-off preparation before the first frame, as its own step;
        # step(None, 1.0) when it is over. May be called from the worker thread.
        self.step = step or (lambda text, fraction: None)
        # The user's character; with an actor calibration (the dict of core.actor.actor_file.load_actor) the tracker
        # poses the actor's body instead, and the character is keyed with the actor's rotations.
        self.character = scene_bridge.body_from_blender(armature_obj, mesh_obj, scene)
        self.actor = actor
        self.body = self.character
        if actor is not None:
            from ..core.actor.actor_file import actor_body

            self.body = actor_body(actor, self.character)
        self.capture = load_capture(capture_dir, units=units)
        if resolve_weights(self.settings.likelihood).needs_learned_evidence:
            require_model(model_path(self.settings.landmarks))  # a clear error now, not at the first frame
        footage = self.capture.frames
        try:
            if frames is None:
                self.all_frames = list(range(footage.n_frames))
                note = footage.shorter_footage_note()
                if note:
                    self.log(f"warning: {note}")
            else:
                self.all_frames = footage.require_frames(frames)
        except Exception:
            self.capture.close()
            raise
        # The finished take is low-passed at this cut-off (core/tracking/smoothing.py; 0 or None: keyed as solved).
        self.smooth_hz = float(smooth_hz or 0.0)
        if self.smooth_hz:
            try:
                check_cutoff(self.smooth_hz, self.capture.frames.fps)
            except Exception:
                self.capture.close()
                raise
        # ... then its planted feet are pinned (core/tracking/foot_lock.py) at this contact speed, m/s.
        self.foot_lock = bool(foot_lock)
        try:
            self.foot_lock_speed = check_speed(foot_lock_speed) if self.foot_lock else float(foot_lock_speed)
        except Exception:
            self.capture.close()
            raise
        self.frame_offset = scene.frame_start if frame_offset is None else frame_offset
        self.rough_pose = self.body.default_pose()  # the subject as the user placed it
        self.capture_dir = capture_dir
        self.prior, self.dynamics = prior, None
        self.tracker = None  # built by the first solve_next(), off the main thread (the prior takes a while)
        self.writer = ResultWriter(out_dir, self.body, self.settings, info={
            "capture": str(Path(capture_dir).resolve()), "armature": armature_obj.name,
            "cameras": [c.name for c in self.capture.cameras], "preset": self.body.preset,
            "dof_names": self.body.dof_names}, blender_version=_blender_version())
        if actor is not None:
            self._keep_actor_file(actor)
            self.writer.info["actor"] = {"height_m": actor.get("height_m"), "lengths_m": actor.get("lengths_m"),
                                         "note": "joints.npz and poses.npz are the actor's; the animation files "
                                                 "are the character's (rotations as solved, root path rescaled)"}
        self.frames = list(self.all_frames)
        self._resume_state = None
        if resume:
            done, state = self._load_checkpoint()
            if done:
                self._resume_state = state
                solved = {e.frame for e in done}
                self.frames = [f for f in self.all_frames if f not in solved]
                self.log(f"resuming after frame {done[-1].frame}: {len(done)} frames already solved")
        self._cancel = threading.Event()
        self.smoothed_poses = None  # set by smooth()

    def _load_checkpoint(self):
        """The earlier run's checkpoint (a CheckpointError, the user's to resolve, when it cannot continue)."""
        try:
            return self.writer.load_checkpoint()
        except Exception:
            self.capture.close()
            raise

    def _keep_actor_file(self, actor):
        """The result folder keeps the calibration it was tracked with (evaluate and later takes read it)."""
        import json

        from ..core.actor.actor_file import write_actor

        path = self.writer.out / "actor.json"
        if path.is_file():
            try:
                if json.loads(path.read_text()) == actor:
                    return
            except (OSError, ValueError):
                pass
        write_actor(path, actor)

    def prepare(self):
        """Build the prior, dynamics and tracker (engine only; safe off the main thread)."""
        if self.tracker is not None:
            return self.tracker
        step = self.step
        if self.prior is None:
            step("anatomical prior and dynamics for this rig (cached after the first run)", 0.0)
            # the character's rig: the same angles, and its cache is reused whatever the actor's proportions
            self.prior, self.dynamics = build_motion_models(
                self.character, self.capture_dir, self.capture.frames.fps, self.settings.seed,
                progress=lambda fraction, text: step(text, 0.85 * fraction))
        step("tracker: background models and likelihood", 0.85)
        self.tracker = Tracker(self.body, self.capture, self.settings, prior=self.prior, dynamics=self.dynamics)
        step(None, 1.0)
        self.writer.info["energy_scale"] = self.tracker.scale
        self.writer.info["refine_scale"] = self.tracker.refine_scale if self.tracker.refines else None
        if self._resume_state is not None:
            self.tracker.restore(self._resume_state)
            self.tracker.estimates = list(self.writer.estimates)
        return self.tracker

    @property
    def n_total(self):
        return len(self.all_frames)

    @property
    def n_done(self):
        return len(self.writer.estimates)

    def cancel(self):
        self._cancel.set()

    @property
    def cancelled(self):
        return self._cancel.is_set()

    def solve_next(self):
        """Solve the next frame (engine only, no bpy). Returns its FrameEstimate, or None when done."""
        if not self.frames or self.cancelled:
            return None
        self.prepare()
        frame = self.frames.pop(0)
        if not self.writer.estimates:
            est = self.tracker.initialise(frame, rough_pose=self.rough_pose)
        else:
            est = self.tracker.track(frame, next_frame=self.frames[0] if self.frames else None)
        if self.tracker.keypoint_fit is not None:
            self.writer.info["first_frame_keypoint_fit"] = self.tracker.keypoint_fit
        if self.tracker.recoveries:
            self.writer.info["limb_recoveries"] = self.tracker.recoveries
        if self.tracker.first_frame_review:  # the first frame replaced once the second was solved
            self.writer.info["first_frame_review"] = self.tracker.first_frame_review
        if self.tracker.turns:  # estimates left facing backwards, turned round (core/tracking/turned_round.py)
            self.writer.info.setdefault("turned_round", {}).update({str(f): e for f, e in self.tracker.turns.items()})
        if self.tracker.gated:  # solutions whose root moved faster than a person can, searched again
            self.writer.info["root_gate"] = self.tracker.gated
        if self.tracker.views_shared:  # views whose evidence was another tracked actor's (several actors)
            self.writer.info["views_shared"] = {str(f): names for f, names in self.tracker.views_shared.items()}
        if self.tracker.landmarks_set_aside:  # landmarks the other views disagreed with (another person's)
            self.writer.info["landmarks_set_aside"] = {str(f): n for f, n in self.tracker.landmarks_set_aside.items()}
        if self.tracker.unlike_clothes:  # views whose landmarks outlined clothes unlike the actor's
            self.writer.info["unlike_clothes"] = {str(f): v for f, v in self.tracker.unlike_clothes.items()}
        if self.tracker.views_left_out:  # the person outside a view's picture, or no person found there
            self.writer.info["views_left_out"] = {str(f): names for f, names in self.tracker.views_left_out.items()}
        self.writer.add(est, self.tracker.state())
        return est

    def scene_frame(self, capture_frame):
        return capture_frame + self.frame_offset

    def character_pose(self, pose, first=None):
        """The pose the character is keyed with: the solved pose, or with an actor calibration the actor's
        rotations with the root path rescaled to the character (about the root of `first`, by default the
        first solved frame's pose)."""
        if self.actor is None:
            return pose
        from ..core.actor.proportions import character_poses

        if first is None and self.writer.estimates:
            first = self.writer.estimates[0].pose
        anchor = None if first is None else first[self.body.translation_dofs[:2]]
        return character_poses(self.body, self.character, np.atleast_2d(pose), anchor_xy=anchor)[0]

    def key(self, estimate):
        self._key_pose(estimate.frame, estimate.pose)

    def _key_pose(self, frame, pose, first=None):
        scene_bridge.key_pose(self.armature, self.character, self.character_pose(pose, first), self.scene_frame(frame))

    def smooth(self):
        """Finish the solved take: low-pass it (core/tracking/smoothing.py; the solved poses stay as *_raw.npz),
        then pin its planted feet (core/tracking/foot_lock.py; the take before that stays as *_unpinned.npz);
        joints.npz and poses.npz become the result and the character is keyed with it. Main thread (keys).
        Returns the finished poses, or None when both are off or too few frames are solved. A finished take
        resumed with other options (`track --resume --smooth HZ --no-foot-lock`: nothing left to solve) is
        finished again from the solved poses; with both off, its files go back to the solved poses."""
        est = self.writer.estimates
        frames = np.array([e.frame for e in est])
        poses = np.array([e.pose for e in est])
        smoothing = None
        if self.smooth_hz and len(est) >= MIN_RUN:
            poses = smooth_poses(self.body, poses, frames, self.capture.frames.fps, self.smooth_hz)
            smoothing = {"cutoff_hz": self.smooth_hz,
                         "filter": "Butterworth low-pass, 2nd order, forwards and backwards",
                         "fast_arms_m_s": [FAST_ARM_FROM, FAST_ARM_TO]}
        pinned, locking = self._lock_feet(poses, frames)
        if smoothing is None and locking is None:
            if self.writer.holds_finished_take:  # a finished run smoothed or pinned: the solved take again
                self.writer.write()
            if est and self.writer.info.get("first_frame_review"):  # keyed before the second frame revised it
                self._key_pose(est[0].frame, est[0].pose)
            return None
        joints = self.body.joint_positions(poses)
        if locking is not None:
            poses, joints, unpinned = pinned, self.body.joint_positions(pinned), (poses, joints)
        else:
            unpinned = None
        self.writer.write_finished(poses, joints, smoothing, unpinned, locking)
        for frame, pose in zip(frames, poses):
            self._key_pose(frame, pose, first=poses[0])
        self.smoothed_poses = poses
        return poses

    def _lock_feet(self, poses, frames):
        """(pinned poses, report) of foot locking, or (None, None) when it is off, the take too short or the rig
        has no legs to lock (said in the log)."""
        if not self.foot_lock or len(poses) < MIN_RUN:
            return None, None
        from ..core.tracking.foot_lock import lock_feet

        try:
            return lock_feet(self.body, poses, frames, self.capture.frames.fps, speed=self.foot_lock_speed)
        except FootContactError as exc:
            self.log(f"warning: feet not locked: {exc}")
            return None, None

    def key_all(self):
        for est in self.writer.estimates:
            self.key(est)

    def finish(self, export=True, overlays=True, save_blend=True):
        """Write the result folder's Blender-side files (main thread)."""
        if self.tracker is not None:
            self.tracker.finish_prefetch()  # a cancelled run may leave the next frame being observed
        out = self.writer.out
        written = {"joints": out / "joints.npz", "poses": out / "poses.npz", "report": out / "report.json"}
        est = self.writer.estimates
        if not est:
            return written
        if self.smooth() is not None:
            written.update({name.removesuffix(".npz"): out / name for name in
                            self.writer.RAW_FILES + self.writer.UNPINNED_FILES if (out / name).exists()})
        frames = (self.scene_frame(est[0].frame), self.scene_frame(est[-1].frame))
        self.scene.frame_start, self.scene.frame_end = frames
        if export:
            from .export import export_bvh, export_fbx

            import bpy

            with atomic_path(out / "animation.bvh") as tmp:
                export_bvh(bpy.context, self.armature, tmp, frames, scene=self.scene)
            with atomic_path(out / "animation.fbx") as tmp:
                export_fbx(bpy.context, self.armature, tmp, frames, scene=self.scene)
            written.update(bvh=out / "animation.bvh", fbx=out / "animation.fbx")
        if save_blend:
            import bpy

            with atomic_path(out / "tracked.blend") as tmp:
                bpy.ops.wm.save_as_mainfile(filepath=str(tmp), copy=True)
            written["blend"] = out / "tracked.blend"
        if overlays:
            written["overlay"] = self.write_overlays()
        return written

    def finished_poses(self):
        """The take's poses, one per solved frame: smoothed and foot-locked when that ran, else as solved."""
        solved = self.writer.estimates
        smoothed = self.smoothed_poses
        return smoothed if smoothed is not None and len(smoothed) == len(solved) else [e.pose for e in solved]

    def write_overlays(self):
        from ..core.results.overlay import OverlayWriter

        proxy = self.prepare().proxy
        writer = OverlayWriter(self.writer.out, self.capture.cameras, self.capture.frames.fps)
        solved = self.writer.estimates
        poses = self.finished_poses()
        try:
            for est, pose in zip(solved, poses):
                verts = proxy.deform(self.body, pose[None])[0]
                writer.add(self.capture.frames.read(est.frame), verts, proxy.faces, proxy.face_part,
                           len(proxy.part_names), label=f"frame {est.frame}  V={est.energy:.3f}",
                           landmarks=getattr(est, "landmarks", None),
                           visibility=getattr(est, "landmark_visibility", None))
        finally:
            writer.close()
        return writer.folder
