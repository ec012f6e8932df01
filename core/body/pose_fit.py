"""Fit DOF vectors to target bone positions (and optionally orientations).

Used to bring motion-capture clips into the tracker's DOF space (anatomical prior, dynamics)
and to express ground-truth joint positions as poses. Damped Gauss-Newton with a finite-difference
Jacobian computed in ONE batched FK call per iteration, warm-started frame to frame.
"""
import numpy as np

from .rotations import best_rotation, matrix_to_rotvec


def _residuals(body, poses, target_heads, target_rots, rot_bones, rot_weight, hold_weight=0.0):
    M = body.pose_matrices(poses)  # (P,B,4,4)
    res = [(M[:, :, :3, 3] - target_heads).reshape(len(poses), -1)]
    if target_rots is not None and len(rot_bones):
        diff = M[:, rot_bones, :3, :3] - target_rots[rot_bones]
        res.append(rot_weight * diff.reshape(len(poses), -1))
    if hold_weight:
        # A weak pull of every joint angle towards the rest pose: angles the targets do not see
        # (a neck twist when only bone heads are given) stay at rest instead of drifting to a limit.
        res.append(hold_weight * np.delete(poses, body.translation_dofs, axis=1))
    return np.concatenate(res, axis=1)


def fit_pose(body, target_heads, x0, target_rots=None, rot_bones=(), rot_weight=0.1, iterations=12,
             hold_weight=0.0):
    """One frame: x minimising |heads(x) - target|^2 (+ weighted orientation residuals), within limits.

    hold_weight (metres per radian) pulls the joint angles towards the rest pose; 0.01 leaves the
    observed angles within a fraction of a percent and holds the unobserved ones at rest."""
    x = np.clip(np.asarray(x0, dtype=np.float64).copy(), body.lower, body.upper)
    rot_bones = np.asarray(rot_bones, dtype=np.int64)
    D = body.n_dof
    eps = 1e-5
    damping = 1e-3
    args = (target_heads, target_rots, rot_bones, rot_weight, hold_weight)
    r = _residuals(body, x[None], *args)[0]
    cost = r @ r
    for _ in range(iterations):
        previous = cost
        probes = x[None] + np.vstack([np.zeros(D), eps * np.eye(D)])
        R = _residuals(body, probes, *args)
        J = (R[1:] - R[0]).T / eps  # (n_res, D)
        JtJ = J.T @ J
        g = J.T @ R[0]
        improved = False
        for _ in range(6):
            step = np.linalg.solve(JtJ + damping * (np.diag(np.diag(JtJ)) + 1e-9 * np.eye(D)), -g)
            x_new = np.clip(x + step, body.lower, body.upper)
            r_new = _residuals(body, x_new[None], *args)[0]
            if r_new @ r_new < cost:
                x, cost = x_new, r_new @ r_new
                damping = max(damping / 3, 1e-7)
                improved = True
                break
            damping *= 10
        if not improved or np.linalg.norm(step) < 1e-7 or previous - cost < 1e-6 * previous:
            break
    head_residual = _residuals(body, x[None], target_heads, None, (), 0.0)[0]
    return x, float(np.sqrt(head_residual @ head_residual / max(1, len(target_heads))))


def initial_root(body, target_heads, pose=None):
    """Root translation + rotation vector that best align `pose` (default: the rest pose; its root rotation zero)
    with target head positions: the pose with them set."""
    x = body.default_pose() if pose is None else np.array(pose, dtype=np.float64)
    heads = body.joint_positions(x[None])[0]
    r = body.root_bone
    rotation = best_rotation(heads - heads[r], target_heads - target_heads[r])
    x[body.translation_dofs] = target_heads[r]
    x[body.root_rotation_dofs] = matrix_to_rotvec(rotation)
    return x


def fit_pose_sequence(body, heads, rotations=None, rot_bones=(), x0=None, iterations=12, rot_weight=0.1,
                      hold_weight=0.0):
    """(F,B,3) world heads [+ (F,B,3,3) world bone rotations] -> (F,D) poses and per-frame RMS residual."""
    poses, errors = [], []
    x = initial_root(body, heads[0]) if x0 is None else np.asarray(x0, dtype=np.float64)
    for f in range(len(heads)):
        rots = None if rotations is None else rotations[f]
        x, err = fit_pose(body, heads[f], x, rots, rot_bones, rot_weight=rot_weight, iterations=iterations,
                          hold_weight=hold_weight)
        poses.append(x)
        errors.append(err)
    return np.array(poses), np.array(errors)


def poses_from_joints(body, names, positions, hold_weight=0.01):
    """Named bone-head positions (F,J,3), e.g. a gt_joints.npz, -> (F,D) poses and per-frame RMS residual.

    Every bone of the body must have a position; angles the heads do not determine (a neck twist)
    are held at rest."""
    names = list(names)
    missing = [b for b in body.skeleton.bone_names if b not in names]
    if missing:
        raise ValueError(f"the joint file has no positions for the bones {', '.join(missing[:6])}"
                         f"{' ...' if len(missing) > 6 else ''}: a pose can only be fitted to a file that holds "
                         f"every bone head of the subject (as the sample scenes' gt_joints.npz does)")
    order = [names.index(b) for b in body.skeleton.bone_names]
    return fit_pose_sequence(body, np.asarray(positions)[:, order], hold_weight=hold_weight)
