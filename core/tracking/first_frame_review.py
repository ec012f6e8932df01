"""The first frame looked at again once the second is solved. The first frame is searched from the subject's rough
placement; the second starts from a solved pose and its search often finds what the first missed (a leg the
wrong way round, a hand left at the hip). So the second frame's pose, fitted locally to the first frame's images,
replaces the first frame's when it explains them better and moves some joint by more than REVIEW_DISTANCE: the
first keyed frame is then right, and the next frame's prediction no longer starts from a wrong limb.
Measured in docs/measurements.md, "The first frame looked at again". A run resumed right after its first frame
(`--resume`) has no first-frame images left to look at and keeps that frame as solved.
"""
from dataclasses import dataclass

import numpy as np

# A first frame whose joints all lie within this of the reviewed pose is kept as it is [DESIGN]: the local fit
# from the second frame's pose nearly always lowers the first frame's energy a little, and replacing a right
# first frame with an equally right one would only move every later frame within its seed's spread.
REVIEW_DISTANCE = 0.1  # metres


@dataclass
class FirstFrameEvidence:
    """What the energy saw on the first frame, kept until the second is solved."""
    observation: object  # observation.Observation
    targets: object  # the energy's image targets (the other actors set apart)
    keypoints: object  # its landmarks (others' and disagreeing ones left out)
    views_in_play: np.ndarray
    others: object  # other_actors.OtherActors at the first frame, or None


def reviewed(body, first_pose, first_energy, candidate_pose, candidate_energy):
    """The review's verdict on the first frame: {"energy_before", "energy_after", "largest_joint_move_m"} when
    `candidate_pose` (absolute) replaces `first_pose`, else None."""
    moved = float(np.linalg.norm(body.joint_positions(np.atleast_2d(candidate_pose))[0]
                                 - body.joint_positions(np.atleast_2d(first_pose))[0], axis=1).max())
    if not (candidate_energy < first_energy and moved > REVIEW_DISTANCE):
        return None
    return {"energy_before": float(first_energy), "energy_after": float(candidate_energy),
            "largest_joint_move_m": round(moved, 4)}
