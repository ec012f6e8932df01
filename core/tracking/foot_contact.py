"""Where the feet touch the floor in a finished take: the feet's contact points, the floor, the contacts.

Each foot has two contact points, the ankle (the foot bone's head) and the ball of the foot (the toe bone's head),
each with its clearance: its height above the sole when the rig stands at rest (the lowest mesh vertex of the
foot). A point is on the floor when its height above the floor less its clearance is near zero.

The floor is the calibration's z = 0 unless the take says otherwise: a robust level plane through the lowest
points of the feet on the frames where they are slow. When it lies within FLOOR_TOLERANCE of z = 0 (most captures:
the calibration was made on the floor), z = 0 stays the floor; otherwise (a calibration origin off the floor) the
fitted plane is the floor.

A contact of one point is a run of frames where it is within CONTACT_HEIGHT of the floor and slower than the
contact speed along it (over SPEED_WINDOW frames either side); one-frame gaps are filled, runs shorter than
MIN_CONTACT_FRAMES dropped.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

# A point within this of the floor (its height less its clearance) may be planted: the tracked feet sit within
# 1-2 cm of their true height (docs/defaults.md, "CONTACT_HEIGHT").
CONTACT_HEIGHT = 0.03
# ... and planted when slower than this along the floor (m/s): a walking foot's stance against its swing at
# 1-4 m/s (docs/defaults.md, "CONTACT_SPEED").
CONTACT_SPEED = 0.15
# The speed is the distance moved over this many frames either side: a jittering foot goes back and forth, a
# stepping one goes somewhere (docs/defaults.md, "CONTACT_SPEED").
SPEED_WINDOW = 2
MIN_CONTACT_FRAMES = 3  # shorter runs are a swing's turning point, not a step (docs/defaults.md, "CONTACT_SPEED")
# The fitted floor replaces z = 0 when it lies farther than this from it (metres). It is level: the feet's tilt is
# biased by the gait and the tracking by 2.5-5.5 degrees on level floors (docs/defaults.md, "FLOOR_TOLERANCE").
FLOOR_TOLERANCE = 0.03
MIN_FLOOR_POINTS = 10  # slow foot frames needed to fit a floor at all


class FootContactError(InputError):
    """The rig has no feet the contacts can be found on."""


def check_speed(speed):
    """The contact speed threshold (m/s) as a float, or a FootContactError naming the fix."""
    value = float(speed)
    if not np.isfinite(value) or value <= 0:
        raise FootContactError(f"foot locking threshold {value:g} m/s: give a positive speed (a foot slower than it "
                               "near the floor is planted), or turn foot locking off")
    return value


@dataclass
class Foot:
    """One foot: its contact points (bone indices whose heads touch the floor), their clearances and the leg's
    DOFs (the hip's, the knee's, the ankle's)."""
    side: str               # "left" / "right"
    points: np.ndarray      # (2,) or (1,) bone indices: the ankle, then the ball of the foot where the rig has one
    names: list             # the points' bone names
    clearance: np.ndarray   # (len(points),) metres above the sole at rest
    leg_dofs: np.ndarray    # DOF indices of the leg
    leg_bones: np.ndarray   # bones whose heads the leg's DOFs move (the knee and below)
    knee: int               # the knee's bone index (its head is the knee joint)


def feet(body):
    """The body's two feet (Foot), from its joint roles: the l_/r_ankle bone's head and its child's (the toes)."""
    from ..evidence.keypoints import KeypointMapError, end_bone

    sk = body.skeleton
    rest = body.default_pose()
    joints = body.joint_positions(rest[None])[0]
    verts = body.deform(rest[None])[0] if len(body.vertices) else np.zeros((0, 3))
    vertex_part = body.bone_part[np.argmax(body.weights, axis=1)] if len(body.vertices) else np.zeros(0, int)
    out = []
    for side, s in (("left", "l"), ("right", "r")):
        roles = [f"{s}_hip", f"{s}_knee", f"{s}_ankle"]
        missing = [r for r in roles if r not in body.roles]
        if missing:
            raise FootContactError(f"the rig has no {', '.join(missing)} joint: foot locking needs the legs' hip, "
                                   "knee and ankle bones (turn foot locking off for this rig)")
        ankle = sk.index[body.roles[f"{s}_ankle"][0]]
        points = [ankle]
        try:
            points.append(int(end_bone(body, f"{s}_ankle")))
        except KeypointMapError:  # no toe bone: the ankle alone
            pass
        points = np.array(points, dtype=np.int64)
        part = body.part_names.index(f"{s}_ankle")
        sole = verts[vertex_part == part]
        lowest = sole[:, 2].min() if len(sole) else joints[points, 2].min()
        clearance = joints[points, 2] - lowest
        leg_dofs = np.array([i for i, d in enumerate(body.dofs) if d.role in roles], dtype=np.int64)
        knee = sk.index[body.roles[f"{s}_knee"][0]]
        below = np.array([b for b in range(sk.n_bones) if sk.is_ancestor(knee, b)], dtype=np.int64)
        out.append(Foot(side, points, [sk.bone_names[b] for b in points], clearance, leg_dofs, below, knee))
    return out


@dataclass
class Floor:
    """The plane n . p = offset (n the unit normal, upwards); `source`: "calibration" (z = 0) or "capture" (fitted
    to the take); `fit`: what the fit found (also when z = 0 was kept)."""
    normal: np.ndarray
    offset: float
    source: str
    fit: dict

    def height(self, points):
        return np.asarray(points) @ self.normal - self.offset

    def to_dict(self):
        return {"source": self.source, "normal": [round(float(v), 6) for v in self.normal],
                "offset_m": round(float(self.offset), 5), "fit": self.fit}


CALIBRATION_FLOOR = (np.array([0.0, 0.0, 1.0]), 0.0)


def along_floor_speed(positions, fps, normal, window=1):
    """(F,...,3) positions -> (F,...) speed along the floor (m/s): the distance moved from `window` frames before to
    `window` frames after each frame (fewer at the ends), over the time between them."""
    p = np.asarray(positions, dtype=np.float64)
    F = len(p)
    if F < 2:
        return np.zeros(p.shape[:-1])
    t = np.arange(F)
    before, after = np.maximum(t - window, 0), np.minimum(t + window, F - 1)
    v = (p[after] - p[before]) / ((after - before) / fps).reshape((F,) + (1,) * (p.ndim - 1))
    v = v - (v @ normal)[..., None] * normal
    return np.linalg.norm(v, axis=-1)


def _sole_points(joints, foot_list):
    """(F, n_feet, 3): per frame and foot, the contact point nearest the floor, lowered by its clearance."""
    out = []
    for foot in foot_list:
        p = joints[:, foot.points] - foot.clearance[None, :, None] * CALIBRATION_FLOOR[0]
        lowest = np.argmin(p[..., 2], axis=1)
        out.append(p[np.arange(len(p)), lowest])
    return np.stack(out, axis=1)


def fit_floor(joints, foot_list, fps, speed=CONTACT_SPEED):
    """The floor for a take's joints (F,B,3): z = 0, or the level plane the slow feet stand on when that is
    clearly not z = 0 (the module docstring)."""
    normal0, offset0 = CALIBRATION_FLOOR
    sole = _sole_points(np.asarray(joints, dtype=np.float64), foot_list)  # (F, feet, 3)
    slow = along_floor_speed(sole, fps, normal0, SPEED_WINDOW) < speed
    heights = sole[slow][:, 2]
    if len(heights) < MIN_FLOOR_POINTS:
        return Floor(normal0, offset0, "calibration",
                     {"points": int(len(heights)), "note": "too few slow foot frames to fit a floor"})
    keep = np.ones(len(heights), bool)
    for _ in range(5):  # the median, dropping heights far off it (a foot on a step, a raised toe)
        level = float(np.median(heights[keep]))
        scatter = 1.4826 * float(np.median(np.abs(heights[keep] - level)))
        new = np.abs(heights - level) <= 3 * scatter + 1e-3
        if new.sum() < MIN_FLOOR_POINTS or np.array_equal(new, keep):
            break
        keep = new
    level = float(np.mean(heights[keep]))
    fit = {"points": int(keep.sum()), "height_m": round(level, 4), "scatter_m": round(scatter, 4)}
    if abs(level) <= FLOOR_TOLERANCE:
        return Floor(normal0, offset0, "calibration", fit)
    return Floor(normal0, level, "capture", fit)


@dataclass
class Contact:
    """A run of frames (indices into the take, inclusive `first`, exclusive `stop`) where one point is planted."""
    foot: int    # index into feet()
    point: int   # index into that foot's points
    first: int
    stop: int

    def to_dict(self, foot_list, frames):
        return {"bone": foot_list[self.foot].names[self.point], "frames": [int(frames[self.first]),
                                                                            int(frames[self.stop - 1])]}


def runs(mask):
    """[(start, stop), ...] of the True runs of a 1-D boolean array."""
    m = np.r_[False, np.asarray(mask, bool), False].astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def planted(heights, speeds, height=CONTACT_HEIGHT, speed=CONTACT_SPEED, min_frames=MIN_CONTACT_FRAMES):
    """(F,) heights above the floor less the clearance, (F,) speeds along it -> (F,) planted: both under their
    thresholds, gaps of one frame filled, runs shorter than min_frames dropped."""
    mask = (np.asarray(heights) < height) & (np.asarray(speeds) < speed)
    gaps = [(a, b) for a, b in runs(~mask) if b - a == 1 and a > 0 and b < len(mask)]
    for a, b in gaps:
        mask[a:b] = True
    for a, b in runs(mask):
        if b - a < min_frames:
            mask[a:b] = False
    return mask


def detect_contacts(joints, foot_list, floor, fps, frames=None, height=CONTACT_HEIGHT, speed=CONTACT_SPEED):
    """Every contact (Contact) of every foot point in a take's joints (F,B,3); runs of consecutive `frames` apart
    (a gap in the frame numbers is not a stance)."""
    joints = np.asarray(joints, dtype=np.float64)
    F = len(joints)
    frames = np.arange(F) if frames is None else np.asarray(frames)
    breaks = np.r_[0, np.flatnonzero(np.diff(frames) != 1) + 1, F]
    out = []
    for k, foot in enumerate(foot_list):
        for j, bone in enumerate(foot.points):
            for a, b in zip(breaks[:-1], breaks[1:]):
                p = joints[a:b, bone]
                h = floor.height(p) - foot.clearance[j]
                mask = planted(h, along_floor_speed(p, fps, floor.normal, SPEED_WINDOW), height, speed)
                out.extend(Contact(k, j, a + s, a + e) for s, e in runs(mask))
    return out


__all__ = ["CONTACT_HEIGHT", "CONTACT_SPEED", "Contact", "Floor", "Foot", "FootContactError", "along_floor_speed",
           "check_speed", "detect_contacts", "feet", "fit_floor", "planted", "runs"]
