"""Limb recovery after each frame's search and local fit: fast limbs outrun the particles' prediction, the
learned landmarks do not. A limb whose landmarks disagree with the estimate is fitted to the triangulated
landmarks (the keypoint proposal); a limb whose landmarks have disagreed for several frames is searched again
on its own (core/tracking/limb_search.py). Either is kept only when it lowers the energy, so a wrong landmark
costs time, not accuracy.
"""
import numpy as np

from .limb_search import limb_dofs, search_limbs

# A limb is off when its landmarks lie this far from it (median over views, in units of the person's size in the
# view); off for RECOVERY_FRAMES frames in a row, it is searched again [DESIGN].
RECOVERY_DISTANCE = 0.1
RECOVERY_FRAMES = 3
# Or when its elbow or wrist (knee or ankle) lies this far from the landmark triangulated over the views: one
# or two views agreeing with a wrong place hide a lost hand from the median (docs/defaults.md,
# "RECOVERY_DISTANCE_3D").
RECOVERY_DISTANCE_3D = 0.15  # metres
MIN_TRIANGULATED = 6  # landmarks a proposal needs
# Each recovery search its own seed, from the run's seed and the frame: a resumed run searches as an unbroken one.
FRAME_SEED_STRIDE = 7919


class LimbRecovery:
    """The keypoint proposal and the limb searches of one track. `energy_fn`: the batch energy of relative poses;
    `polish`: the local fit of a relative pose on the current frame (or None); `follow(step)`: moves the
    optimiser's particles by the step a kept proposal took."""

    def __init__(self, body, cameras, energy, space, root, seed, energy_fn, polish, follow):
        self.body, self.cameras, self.energy, self.space, self.root = body, list(cameras), energy, space, root
        self.seed = seed
        self.energy_fn, self.polish, self.follow = energy_fn, polish, follow
        self.limbs = limb_dofs(body.dofs)
        self.off_frames = {}  # limb -> frames in a row its landmarks disagreed (carried in the checkpoint)
        self.proposals = []  # {"limbs", "kept"} per keypoint proposal
        self.recoveries = []  # {"frame", "limbs", "kept"} per limb search

    def limbs_off(self, estimate):
        """{limb: distance} of the landmarks from the limbs of `estimate` (relative), in the views."""
        from ..evidence.keypoints import limb_disagreement

        pose = self.root.to_absolute(estimate)
        return limb_disagreement(self.energy.project_rig_points(pose[None])[0], self.energy.keypoints,
                                 self.energy.rig_points)

    def keypoint_proposal(self, estimate, energy, evaluations, off):
        """The limbs whose landmarks disagree with `estimate` (`off`: limbs_off), fitted to the triangulated
        landmarks (from the estimate and from the limbs at rest: limb_landmark_fit) and polished; kept when that
        lowers the energy. Returns (estimate, energy, evaluations)."""
        from ..evidence.keypoint_fit import limb_distances_3d, limb_landmark_fit, triangulated_landmarks

        rig = self.energy.rig_points
        X, ok = triangulated_landmarks(self.cameras, self.energy.keypoints, rig)
        if ok.sum() < MIN_TRIANGULATED:
            return estimate, energy, evaluations
        off_3d = limb_distances_3d(rig, rig.world(self.body, self.root.to_absolute(estimate)[None])[0], X, ok)
        off_limbs = [limb for limb in self.limbs if off.get(limb, 0.0) > RECOVERY_DISTANCE
                     or off_3d.get(limb, 0.0) > RECOVERY_DISTANCE_3D]
        if not off_limbs:
            return estimate, energy, evaluations
        dofs = np.concatenate([self.limbs[limb] for limb in off_limbs])
        fitted = limb_landmark_fit(self.body, rig, self.root.to_absolute(estimate), X, ok, dofs)
        candidate = self.root.to_relative(fitted)
        if self.polish is not None:
            candidate = self.polish(candidate)
        candidate_energy = float(self.energy_fn(candidate[None])[0])
        evaluations += 1
        kept = bool(candidate_energy < energy)
        self.proposals.append({"limbs": off_limbs, "kept": kept})
        if kept:
            self.follow(candidate - estimate)
            return candidate, candidate_energy, evaluations
        return estimate, energy, evaluations

    def recover(self, estimate, energy, evaluations, frame):
        """First the keypoint proposal; then each limb whose landmarks have disagreed for RECOVERY_FRAMES frames
        searched again on its own. Returns (estimate, energy, evaluations)."""
        estimate, energy, evaluations = self.keypoint_proposal(estimate, energy, evaluations,
                                                               self.limbs_off(estimate))
        for limb, distance in self.limbs_off(estimate).items():
            self.off_frames[limb] = self.off_frames.get(limb, 0) + 1 if distance > RECOVERY_DISTANCE else 0
        lost = {limb: idx for limb, idx in self.limbs.items() if self.off_frames.get(limb, 0) >= RECOVERY_FRAMES}
        if not lost:
            return estimate, energy, evaluations
        found, found_energy, used = search_limbs(self.energy_fn, self.space, estimate, lost,
                                                 seed=self.seed + FRAME_SEED_STRIDE * int(frame), polish=self.polish)
        self.recoveries.append({"frame": int(frame), "limbs": sorted(lost), "kept": bool(found_energy < energy)})
        for limb in lost:
            self.off_frames[limb] = 0
        if found_energy < energy:
            self.follow(found - estimate)
            return found, float(found_energy), evaluations + used
        return estimate, energy, evaluations + used
