"""The first frame's second stage: each limb searched on its own, the rest of the body held.

A global search over all 30 DOF with a few hundred particles settles the root and the trunk but
often leaves an arm in a wrong basin (swung forward across the torso, where the silhouettes barely
change), with an energy above the truth's: a search failure. A limb has 4 or 5 DOF, and an
annealing search over those alone, uniform within the joint limits, finds the basin reliably
(docs/defaults.md, "init_limbs").
This is partitioned sampling in spirit (MacCormick and Isard 2000, Deutscher and Reid's partitioned
APF), used once, where the global search needs it; tracking then follows each limb from there.
A limb's new pose is kept only if it lowers the energy of the whole body.
"""
import numpy as np

from ..optimizers import PoseSpace
from ..optimizers.isa import InteractingSimulatedAnnealing

# Joint roles (rig_presets.ROLE_SPECS) searched together, root of the chain first.
LIMB_ROLES = {
    "left arm": ("l_shoulder", "l_elbow"),
    "right arm": ("r_shoulder", "r_elbow"),
    "left leg": ("l_hip", "l_knee", "l_ankle"),
    "right leg": ("r_hip", "r_knee", "r_ankle"),
}
LIMB_PARTICLES = 200  # the paper's per-frame budget (200 x 15) for each limb
LIMB_ITERATIONS = 15


def limb_dofs(dofs):
    """{limb: DOF indices} for the limbs whose roles the rig has (a rig without arms has no arm)."""
    limbs = {}
    for limb, roles in LIMB_ROLES.items():
        idx = [i for i, d in enumerate(dofs) if d.role in roles]
        if idx:
            limbs[limb] = np.array(idx)
    return limbs


def subspace(space, idx):
    """The pose space of the DOFs `idx` alone."""
    return PoseSpace(space.lower[idx], space.upper[idx], space.scale[idx], [space.names[i] for i in idx],
                     space.translation[idx])


def search_limbs(energy, space, x, limbs, *, seed=0, particles=LIMB_PARTICLES, iterations=LIMB_ITERATIONS,
                 polish=None):
    """Search each limb of pose `x` in turn; returns (pose, energy, evaluations).

    energy: batch energy (P, D) -> (P,); limbs: {name: DOF indices}; polish: optional local fit
    applied to each candidate (pose -> pose) before it is judged against the current pose.
    """
    x = space.clamp(np.asarray(x, float)[None])[0]
    best = float(energy(x[None])[0])
    evaluations = 1
    for k, idx in enumerate(limbs.values()):
        def limb_energy(X_limb, x=x, idx=idx):
            X = np.repeat(x[None], len(X_limb), axis=0)
            X[:, idx] = X_limb
            return energy(X)

        searcher = InteractingSimulatedAnnealing(subspace(space, idx), seed=seed + 1000 * (k + 1), n=particles,
                                                 schedule="ess")
        result = searcher.global_init(limb_energy, x[idx], n=particles, iterations=iterations, joints="uniform")
        candidate = x.copy()
        candidate[idx] = result.estimate
        if polish is not None:
            candidate = polish(candidate)
        e = float(energy(candidate[None])[0])
        evaluations += result.evaluations + 1
        if e < best:
            x, best = candidate, e
    return x, best, evaluations
