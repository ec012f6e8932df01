"""The first frame: where the person stands and how, from the subject's rough placement. The learned landmarks,
triangulated, place the body first when they agree; a global ISA search then looks around that placement, and
each limb is searched again on its own (core/tracking/limb_search.py)."""
import numpy as np

from ..optimizers.isa import InteractingSimulatedAnnealing
from .limb_search import limb_dofs, search_limbs

# After a landmark fit the global search need only look this far around it (half widths).
KEYPOINT_INIT_TRANSLATION = 0.08  # metres
KEYPOINT_INIT_YAW = float(np.deg2rad(8.0))
KEYPOINT_INIT_MAX_RMS = 0.12  # metres: a worse fit means the landmarks disagree; keep the rough placement
MIN_KEYPOINT_POINTS = 6  # triangulated landmarks a fit needs to place a body
SEARCH_SPREAD_SCALES = 4  # the joints' spread around the neutral posture, in per-DOF scales (20 degrees)
SEARCH_TILT = float(np.deg2rad(8.0))  # the root's spread about the horizontal axes: people stand upright


def neutral_joints(body, prior, rough):
    """The rough placement with the joints of a typical posture: the per-DOF median of the prior's training poses
    (a person standing or walking), not the rig's rest pose (often an A- or T-pose)."""
    x = np.array(rough, dtype=np.float64)
    if prior is not None:
        for group, idx in prior.groups.items():
            x[idx] = np.median(prior.samples[group], axis=0)
    return body.clamp(x)


def keypoint_start(body, cameras, energy, start):
    """(pose, fit) of the first frame from the triangulated landmarks (core/evidence/keypoint_fit.py): the pose is
    None when too few landmarks triangulate or the fit leaves them far apart; fit: {"points", "rms_m"}."""
    from ..evidence.keypoint_fit import pose_from_keypoints

    pose, n_points, rms = pose_from_keypoints(body, cameras, energy.keypoints, energy.rig_points, start)
    fit = {"points": n_points, "rms_m": rms}
    return (pose if n_points >= MIN_KEYPOINT_POINTS and rms < KEYPOINT_INIT_MAX_RMS else None), fit


def search_first_frame(body, space, settings, energy, x0, half_width, yaw_spread, polish=None):
    """The global search around `x0` (relative), then each limb on its own (settings.init_limbs); `energy`: the
    batch energy of relative poses; polish: the local fit applied to each limb's candidate. Returns (relative
    estimate, evaluations)."""
    searcher = InteractingSimulatedAnnealing(space, seed=settings.seed, n=min(settings.particles,
                                                                              settings.init_particles),
                                             schedule=settings.schedule)
    spread = space.scale * SEARCH_SPREAD_SCALES
    tilt, yaw = body.root_rotation_dofs[:2], body.root_rotation_dofs[2]  # rotation vector in world axes, Z up
    spread[tilt] = SEARCH_TILT
    spread[yaw] = yaw_spread
    result = searcher.global_init(energy, x0, spread, n=settings.init_particles, iterations=settings.init_iterations,
                                  joints="around", translation_dofs=body.translation_dofs,
                                  translation_half_width=half_width, yaw_dof=None)
    estimate, evaluations = result.estimate, result.evaluations
    if settings.init_limbs:
        estimate, _, used = search_limbs(energy, space, estimate, limb_dofs(body.dofs), seed=settings.seed,
                                         polish=polish)
        evaluations += used
    return estimate, evaluations
