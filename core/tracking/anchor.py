"""The root anchor (algorithms.md 1.4): the optimisers see the root rotation relative to a rotation near the
subject's, so their particle arithmetic stays Euclidean and never meets the pi wrap of rotation vectors, even
when the subject turns around. The anchor follows the subject; the poses kept between frames are re-expressed
whenever it moves."""
import numpy as np

from ..body.rotations import matrix_to_rotvec, rotvec_to_matrix

# How far the estimate may turn from the anchor before the anchor follows: far from the wrap at pi.
REANCHOR_ANGLE = np.deg2rad(20.0)


class RootAnchor:
    """The anchor rotation (3x3) and the conversions of poses (..., D) between absolute and relative to it."""

    def __init__(self, root_rotation_dofs, matrix=None):
        self.dofs = root_rotation_dofs
        self.matrix = np.eye(3) if matrix is None else np.asarray(matrix, dtype=np.float64)

    def to_absolute(self, poses, matrix=None):
        """Relative poses -> absolute ones, relative to `matrix` (default: the anchor)."""
        matrix = self.matrix if matrix is None else matrix
        poses = np.array(poses, dtype=np.float64, copy=True)
        poses[..., self.dofs] = matrix_to_rotvec(rotvec_to_matrix(poses[..., self.dofs]) @ matrix)
        return poses

    def to_relative(self, poses, matrix=None):
        """Absolute poses -> relative to `matrix` (default: the anchor)."""
        matrix = self.matrix if matrix is None else matrix
        poses = np.array(poses, dtype=np.float64, copy=True)
        poses[..., self.dofs] = matrix_to_rotvec(rotvec_to_matrix(poses[..., self.dofs]) @ matrix.T)
        return poses

    def follow(self, relative_estimate, optimizer, history):
        """Move the anchor onto `relative_estimate` once it has turned REANCHOR_ANGLE away, re-expressing every
        pose the optimiser carries and `history` (relative poses). Returns the history, re-expressed if it moved."""
        if np.linalg.norm(relative_estimate[self.dofs]) < REANCHOR_ANGLE:
            return history
        old = self.matrix
        new = rotvec_to_matrix(relative_estimate[self.dofs]) @ old
        self.matrix = new

        def convert(poses):
            return self.to_relative(self.to_absolute(poses, old), new)

        optimizer.map_poses(convert)
        return [convert(h) for h in history]
