"""The local fit after the search: ICP with twists (core/optimizers/icp.py) on the silhouettes' rims and the
learned landmarks, from the search's estimate [DESIGN, after Gall et al.'s multi-layer framework, IJCV 2010:
a global stochastic optimisation, then a local fit]. The particles settle the ambiguous directions (which arm
is where); the local fit then gets closer to the energy's minimum than the particles stop.
"""
import numpy as np

from .other_actors import OTHERS_MARGIN_PX

# Low: a strong prior walks fitted limbs towards common poses (docs/defaults.md, "LOCAL_FIT_PRIOR_WEIGHT").
LOCAL_FIT_PRIOR_WEIGHT = 0.25


class LocalFit:
    """ICP on one frame's observation, at the local fit's resolution when it has finer silhouettes."""

    def __init__(self, body, proxy, cameras, energy, space, root, scale, refine_scale, iterations=None):
        self.body, self.proxy, self.cameras = body, proxy, list(cameras)
        self.energy, self.space, self.root = energy, space, root  # root: the RootAnchor poses are relative to
        self.scale, self.refine_scale = scale, refine_scale
        self.iterations = iterations  # None: IcpSettings' own

    def problem(self, observation, views_in_play, fine=False, others=None):
        """The frame's IcpProblem: at the energy's resolution, or (fine) on the finer silhouettes. The views left
        out this frame (`views_in_play` False) offer no contour; nor do other actors' bodies (`others`: an
        OtherActors, core/tracking/other_actors.py)."""
        from ..optimizers.icp import IcpProblem

        scale = self.refine_scale if fine else self.scale
        cameras = [c.scaled(scale) for c in self.cameras]
        silhouettes = observation.fine_silhouettes if fine else [f.silhouette for f in observation.features]
        if views_in_play is not None:
            silhouettes = [s if keep else np.zeros_like(s) for s, keep in zip(silhouettes, views_in_play)]
        energy = self.energy
        keypoints = energy.keypoints if observation.evidence is not None and energy.weights.keypoint else None
        masks = None
        if others:
            shape = (len(cameras), max(c.height for c in cameras), max(c.width for c in cameras))
            padded = others.masks(cameras, shape, margin_px=round(OTHERS_MARGIN_PX * scale / self.scale))
            masks = [padded[c, :cam.height, :cam.width] for c, cam in enumerate(cameras)]
        return IcpProblem(body=self.body, proxy=self.proxy, cameras=cameras, silhouettes=list(silhouettes),
                          others=masks, to_absolute=self.root.to_absolute, prior=getattr(energy, "prior", None),
                          keypoints=None if keypoints is None else keypoints.scaled(scale),
                          rig_points=energy.rig_points if keypoints is not None else None)

    def fit(self, estimate, observation, views_in_play, others=None):
        """The local fit of `estimate` (relative) on the frame; returns the fitted relative pose."""
        from ..optimizers.icp import IcpSettings, IcpSolver

        fine = observation.fine_silhouettes is not None
        settings = IcpSettings(prior_weight=LOCAL_FIT_PRIOR_WEIGHT)
        if self.iterations is not None:
            settings = settings.with_iterations(self.iterations)
        settings = settings.at_resolution(self.refine_scale / self.scale) if fine else settings
        problem = self.problem(observation, views_in_play, fine, others)
        return IcpSolver(problem, self.space, settings).fit(estimate).pose
