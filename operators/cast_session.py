"""Several actors tracked at once, for the command line and the Track panel.

One TrackSession per armature, each writing its own result folder OUT/actors/<armature>/ in the single-actor
layout (joints, poses, report, checkpoint, BVH, FBX, overlays), solved frame by frame in one loop where each
actor sees the others' bodies (core/tracking/cast.py). OUT/report.json lists the actors and their folders
(docs/several-actors.md). Like TrackSession, `solve_next` is engine work; the rest runs on the main thread.
"""
from dataclasses import dataclass
from pathlib import Path

from ..core.atomic_files import atomic_path, write_json
from ..core.errors import InputError
from ..core.results.result_folder import (ACTORS_FOLDER, actor_folder_name, actor_result_folder,
                                              require_writable_folder)
from ..core.tracking.cast import others_of
from .track_session import TrackSession


@dataclass
class CastEstimate:
    """One frame of every actor: their FrameEstimates, in armature order."""
    estimates: list

    @property
    def frame(self):
        return self.estimates[0].frame

    @property
    def seconds(self):
        return sum(e.seconds for e in self.estimates)

    @property
    def energy(self):
        return sum(e.energy for e in self.estimates)


class CastError(InputError, ValueError):
    """The armatures given for several actors cannot be tracked together (the message says why)."""


def cast_folders(names):
    """Each actor's result folder name under actors/; a CastError when the armatures cannot be tracked together
    (checked before any actor's build is fitted)."""
    if len(names) < 2:
        raise CastError("several actors need at least two armatures; track one with the usual command")
    folders = [actor_folder_name(n) for n in names]
    if len(set(names)) != len(names):
        raise CastError(f"an armature is given twice ({', '.join(names)}): name each actor's armature once")
    if len(set(folders)) != len(folders):
        raise CastError(f"the armatures {names} give the same result folder name: rename them (each actor's "
                        "result folder is named after its armature)")
    return folders


class CastSession:
    def __init__(self, scene, armatures, capture_dir, out_dir, actors=None, **options):
        """`actors`: per armature an actor calibration (core/actor/actor_file.load_actor's dict) or None."""
        folders = cast_folders([a.name for a in armatures])
        self.out = require_writable_folder(out_dir)
        self.folders = folders
        self.sessions = []
        try:
            for armature, folder, actor in zip(armatures, folders, actors or [None] * len(armatures)):
                self.sessions.append(TrackSession(scene, armature, capture_dir, actor_result_folder(self.out, folder),
                                                  actor=actor, **options))
        except Exception:
            self.close()
            raise
        frames = {tuple(s.frames) for s in self.sessions}
        if len(frames) != 1:  # a resumed cast whose actors stopped at different frames
            self.close()
            raise CastError("the actors' result folders hold different frames: resume them with the same --frames "
                            "or start a new result folder")
        self.write_report()

    def close(self):
        for s in self.sessions:
            s.capture.close()

    # ---- progress
    @property
    def n_total(self):
        return self.sessions[0].n_total

    @property
    def n_done(self):
        return min(s.n_done for s in self.sessions)

    def cancel(self):
        for s in self.sessions:
            s.cancel()

    @property
    def cancelled(self):
        return any(s.cancelled for s in self.sessions)

    # ---- solving (engine only)
    def prepare(self):
        for s in self.sessions:
            s.prepare()

    @property
    def frames(self):
        """The frames left to solve (every actor's)."""
        return self.sessions[0].frames

    @property
    def settings(self):
        return self.sessions[0].settings

    def scene_frame(self, capture_frame):
        return self.sessions[0].scene_frame(capture_frame)

    def solve_next(self):
        """Solve the next frame for every actor, in armature order: a CastEstimate, or None when done."""
        if self.cancelled or not self.sessions[0].frames:
            return None
        self.prepare()
        trackers = [s.tracker for s in self.sessions]
        frame = self.sessions[0].frames[0]
        estimates = []
        for i, session in enumerate(self.sessions):
            session.tracker.set_others(others_of(trackers, i, frame))
            estimates.append(session.solve_next())
        return CastEstimate(estimates)

    # ---- Blender side (main thread)
    def key(self, estimate):
        for session, est in zip(self.sessions, estimate.estimates):
            session.key(est)

    def key_all(self):
        for session in self.sessions:
            session.key_all()

    def finish(self, export=True, overlays=True, save_blend=True):
        """Each actor's result folder finished as a single actor's is, but one tracked.blend with every actor
        keyed, in OUT; returns {armature: written files} and "blend"."""
        written = {s.armature.name: s.finish(export=export, overlays=overlays, save_blend=False)
                   for s in self.sessions}
        if overlays:
            written["overlay"] = self.write_overlays()
        if save_blend:
            import bpy

            with atomic_path(self.out / "tracked.blend") as tmp:
                bpy.ops.wm.save_as_mainfile(filepath=str(tmp), copy=True)
            written["blend"] = self.out / "tracked.blend"
        self.write_report()
        return written

    def write_overlays(self):
        """OUT/overlay/<camera>.mp4: every actor over the footage, each in its own colour."""
        from ..core.results.overlay import OverlayWriter, actor_colours

        first = self.sessions[0]
        proxies = [s.prepare().proxy for s in self.sessions]
        colours = actor_colours(len(self.sessions), max(len(p.part_names) for p in proxies))
        takes = [s.finished_poses() for s in self.sessions]
        writer = OverlayWriter(self.out, first.capture.cameras, first.capture.frames.fps)
        try:
            for k, est in enumerate(first.writer.estimates):
                bodies = [(p.deform(s.body, poses[k][None])[0], p.faces, p.face_part, c)
                          for s, p, poses, c in zip(self.sessions, proxies, takes, colours)]
                writer.add_bodies(first.capture.frames.read(est.frame), bodies, label=f"frame {est.frame}")
        finally:
            writer.close()
        return writer.folder

    def write_report(self):
        report = {"actors": [{"armature": s.armature.name, "folder": f"{ACTORS_FOLDER}/{folder}",
                              "frames_solved": s.n_done} for s, folder in zip(self.sessions, self.folders)],
                  "capture": str(Path(self.sessions[0].capture_dir).resolve()),
                  "layout": "one single-actor result folder per armature under actors/ (docs/several-actors.md)"}
        write_json(self.out / "report.json", report)
