"""The other tracked actors, as one actor's tracker sees them in a frame: where their bodies are in each view, and
which of this frame's landmarks are theirs.

Given the others' poses, the silhouette of all actors together does not depend on this actor's body where another
body is (that pixel is a body pixel whoever is in front), so those pixels count for nothing in this actor's
silhouette and edge terms (core/render/reference.py, OTHERS) and offer no contour to its local fit. A landmark the
single-person model put nearer another actor's point than this actor's predicted one is not this actor's; a view
whose landmarks mostly went to others is a view where the two cannot be told apart this frame, and loses all its
landmarks (docs/how-it-tracks.md, "Several actors"; docs/defaults.md, "Several actors: a shared view").
"""
from dataclasses import dataclass

import cv2
import numpy as np

from ..evidence.keypoints import rig_keypoints
from ..evidence.landmark_consensus import AGREE_SHARE, without_landmarks
from ..render import project_views, rasterize

# The others' bodies are marked this many energy pixels wider than rendered: their estimate is a couple of
# centimetres off, and a rim of theirs left unmarked would read as this actor's evidence [DESIGN].
OTHERS_MARGIN_PX = 2


@dataclass
class OtherActor:
    body: object
    proxy: object
    pose: np.ndarray  # absolute pose this frame: solved, or predicted when not solved yet
    rig_points: object = None  # its landmarks' rig points (core/evidence/keypoints.rig_keypoints), made if None


def _drawn(uv, z, faces, width, height):
    """(H,W) bool: the pixel centres one posed mesh covers; numba's kernel when it imports (50 times faster here,
    the same pixels but for ties on a triangle's edge), else the reference rasteriser."""
    try:
        from ..render import fast
    except ImportError:
        return rasterize(uv, z, faces, np.ones(len(faces), dtype=np.int16), width, height) > 0
    return fast.coverage(uv, z, faces, width, height)


class OtherActors:
    """The actors other than the one being solved, in one frame."""

    def __init__(self, actors):
        self.actors = list(actors)
        self._vertices = [a.proxy.deform(a.body, np.atleast_2d(a.pose))[0] for a in self.actors]
        self._masks = {}  # the same frame is asked for at the same resolution several times (search, local fits)

    def __len__(self):
        return len(self.actors)

    def masks(self, cameras, shape, margin_px=OTHERS_MARGIN_PX):
        """(C,H,W) bool: the union of the others' bodies in each of `cameras` (already at the wanted resolution),
        widened by `margin_px`, in arrays of `shape` (the padded size of the energy's targets)."""
        key = (tuple(shape), int(margin_px), tuple((c.width, c.height, float(c.K[0, 0])) for c in cameras))
        if key in self._masks:
            return self._masks[key]
        out = np.zeros(shape, dtype=bool)
        kernel = None if margin_px <= 0 else cv2.getStructuringElement(
            cv2.MORPH_ELLIPSE, (2 * margin_px + 1, 2 * margin_px + 1))
        for vertices, actor in zip(self._vertices, self.actors):
            uv, z = project_views(vertices[None], cameras)
            faces = np.asarray(actor.proxy.faces, dtype=np.int64)
            for c, cam in enumerate(cameras):
                drawn = _drawn(uv[0, c], z[0, c], faces, cam.width, cam.height)
                if kernel is not None:
                    drawn = cv2.dilate(drawn.astype(np.uint8), kernel) > 0
                out[c, :cam.height, :cam.width] |= drawn
        self._masks[key] = out
        return out

    def landmark_points(self, cameras):
        """(A,C,K,2) capture pixels of each other actor's landmark rig points."""
        out = []
        for actor in self.actors:
            rig = actor.rig_points if actor.rig_points is not None else rig_keypoints(actor.body)
            points = rig.world(actor.body, np.atleast_2d(actor.pose))[0]
            out.append(np.stack([cam.project(points) for cam in cameras]))
        return np.stack(out)


def closer_to_others(landmarks, own, others, swap, own_tolerance=None):
    """(C,K) bool: landmarks (C,K,2) nearer one of the others' points (A,C,K,2) than this actor's (C,K,2); each
    compared with the point it stands for and its mirror (single-view models swap sides). A landmark within
    own_tolerance (C,) pixels of this actor's point stays this actor's: where two hands meet (a handshake) it is
    both actors' evidence."""
    def nearest(points):  # (..., C, K, 2) -> (..., C, K) distance to point k or its mirror
        d = np.linalg.norm(points - landmarks, axis=-1)
        return np.minimum(d, np.linalg.norm(points[..., swap, :] - landmarks, axis=-1))

    mine = nearest(np.asarray(own))
    theirs = nearest(np.asarray(others)).min(axis=0) < mine
    if own_tolerance is not None:
        theirs &= mine > np.asarray(own_tolerance, dtype=np.float64)[:, None]
    return theirs


def associate_landmarks(targets, own, others, swap):
    """KeypointTargets without the landmarks that are other actors', and (C,) bool: the views whose landmarks
    mostly were (those lose all of theirs). `own`: (C,K,2) this actor's predicted points."""
    tolerance = AGREE_SHARE * np.asarray(targets.person_px, dtype=np.float64)
    theirs = closer_to_others(targets.uv, own, others, swap, tolerance) & (targets.weight > 0)
    return without_landmarks(targets, theirs)
