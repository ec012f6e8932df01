"""Which bones of a rig carry the tracker's degrees of freedom, recognised by bone names.

A *role* is one joint of the 30-DOF layout of algorithms.md section 1.2 (root, spine, neck,
shoulders, elbows, hips, knees, ankles). A preset maps each role to one or more bones of a
naming scheme; a role spread over several bones (a spine of three bones) turns each bone by an
equal share of the angle. Axes are anatomical, defined in the body frame of the rest pose
(see body.BodyFrame), so the same preset works whatever the bones' roll is.
"""
from dataclasses import dataclass

from ..errors import InputError

# Each rotational DOF is named by the way it moves the bone's far end for a positive angle:
#   "forward", "-forward", "up", "left": body-frame directions of the rest pose;
#   "out": away from the midline (left for a left limb, right for a right one);
#   "along": a twist about the bone itself (mirrored on the right so internal rotation is positive).
# The rotation axis is then (bone direction) x (motion direction), so it is always
# perpendicular to the bone: no singular axis in the rest pose, whether the rig rests in an
# A-pose or a T-pose, and whatever the bones' roll is.


@dataclass(frozen=True)
class AxisSpec:
    name: str
    motion: str
    lower_deg: float
    upper_deg: float


@dataclass(frozen=True)
class RoleSpec:
    role: str
    side: str  # "", "l" or "r"
    kind: str  # "root", "ball", "hinge"
    axes: tuple  # in multiplication order: R = R(axes[0]) @ R(axes[1]) @ ...
    prior_group: str  # "head", "upper", "lower" (eq. 13); "" for the root


def _ball(role, side, group, flex, abd, twist):
    return RoleSpec(role, side, "ball", (flex, abd, twist), group)


# Limits are relative to the rig's rest pose and deliberately generous: the anatomical prior
# (trained from real motion) says what is plausible; limits only forbid the impossible.
# Hinge limits are anatomical (0 = straight) and get shifted by the rest pose's bend.
_SHOULDER = (AxisSpec("flex", "forward", -90, 180), AxisSpec("abd", "out", -120, 150),
             AxisSpec("twist", "along", -100, 100))
_HIP = (AxisSpec("flex", "forward", -40, 125), AxisSpec("abd", "out", -45, 60),
        AxisSpec("twist", "along", -50, 50))
ROLE_SPECS = (
    RoleSpec("root", "", "root", (), ""),
    _ball("spine", "", "upper", AxisSpec("flex", "forward", -30, 60), AxisSpec("bend", "left", -35, 35),
          AxisSpec("twist", "along", -45, 45)),
    _ball("neck", "", "head", AxisSpec("flex", "forward", -50, 60), AxisSpec("bend", "left", -45, 45),
          AxisSpec("twist", "along", -75, 75)),
    _ball("l_shoulder", "l", "upper", *_SHOULDER),
    RoleSpec("l_elbow", "l", "hinge", (AxisSpec("flex", "forward", 0, 150),), "upper"),
    _ball("r_shoulder", "r", "upper", *_SHOULDER),
    RoleSpec("r_elbow", "r", "hinge", (AxisSpec("flex", "forward", 0, 150),), "upper"),
    _ball("l_hip", "l", "lower", *_HIP),
    RoleSpec("l_knee", "l", "hinge", (AxisSpec("flex", "-forward", 0, 150),), "lower"),
    RoleSpec("l_ankle", "l", "ball_1", (AxisSpec("flex", "up", -45, 30),), "lower"),  # toes up
    _ball("r_hip", "r", "lower", *_HIP),
    RoleSpec("r_knee", "r", "hinge", (AxisSpec("flex", "-forward", 0, 150),), "lower"),
    RoleSpec("r_ankle", "r", "ball_1", (AxisSpec("flex", "up", -45, 30),), "lower"),
)
ROLE_BY_NAME = {spec.role: spec for spec in ROLE_SPECS}


def _sided(prefix_l, prefix_r, stem):
    return {"l": f"{prefix_l}{stem}", "r": f"{prefix_r}{stem}"}


def _limb_roles(left, right, names):
    """names: role stem -> bone stem, e.g. {"shoulder": "Arm"} with left='Left', right='Right'."""
    out = {}
    for stem, bone in names.items():
        out[f"l_{stem}"] = (f"{left}{bone}",) if isinstance(bone, str) else tuple(f"{left}{b}" for b in bone)
        out[f"r_{stem}"] = (f"{right}{bone}",) if isinstance(bone, str) else tuple(f"{right}{b}" for b in bone)
    return out


# Presets: role -> bone names (in chain order when several). Rigify uses a suffix for the side.
PRESETS = {
    "cmu": {
        "root": ("Hips",),
        "spine": ("LowerBack", "Spine", "Spine1"),
        "neck": ("Neck", "Neck1"),
        **_limb_roles("Left", "Right", {"shoulder": "Arm", "elbow": "ForeArm", "hip": "UpLeg",
                                        "knee": "Leg", "ankle": "Foot"}),
    },
    "mixamo": {
        "root": ("mixamorig:Hips",),
        "spine": ("mixamorig:Spine", "mixamorig:Spine1", "mixamorig:Spine2"),
        "neck": ("mixamorig:Neck",),
        **_limb_roles("mixamorig:Left", "mixamorig:Right", {"shoulder": "Arm", "elbow": "ForeArm",
                                                            "hip": "UpLeg", "knee": "Leg", "ankle": "Foot"}),
    },
    "rigify": {
        "root": ("DEF-spine",),
        "spine": ("DEF-spine.001", "DEF-spine.002", "DEF-spine.003"),
        "neck": ("DEF-spine.004", "DEF-spine.005"),
        "l_shoulder": ("DEF-upper_arm.L",), "r_shoulder": ("DEF-upper_arm.R",),
        "l_elbow": ("DEF-forearm.L",), "r_elbow": ("DEF-forearm.R",),
        "l_hip": ("DEF-thigh.L",), "r_hip": ("DEF-thigh.R",),
        "l_knee": ("DEF-shin.L",), "r_knee": ("DEF-shin.R",),
        "l_ankle": ("DEF-foot.L",), "r_ankle": ("DEF-foot.R",),
    },
}


def _strip_namespace(name):
    # Mixamo exports come as "mixamorig:Hips", "mixamorig1:Hips", "mixamorig9:Hips"...
    if ":" in name:
        return "mixamorig:" + name.split(":", 1)[1]
    return name


class RigMappingError(InputError):
    """The armature's bones cannot be mapped onto the tracker's skeleton."""


def match_preset(bone_names):
    """Return (preset name, role -> tuple of actual bone names) for the best-fitting preset.

    Raises RigMappingError naming the missing bones of the closest preset.
    """
    normalised = {_strip_namespace(n): n for n in bone_names}
    best = None
    for preset, roles in PRESETS.items():
        missing = [b for bones in roles.values() for b in bones if b not in normalised]
        found = sum(len(bones) for bones in roles.values()) - len(missing)
        if best is None or found > best[1]:
            best = (preset, found, missing)
        if not missing:
            return preset, {role: tuple(normalised[b] for b in bones) for role, bones in roles.items()}
    preset, _, missing = best
    raise RigMappingError(
        f"the armature does not match any known rig naming (closest: {preset!r}); missing bones: "
        f"{', '.join(missing)}. Rename these bones, or set rotation locks / Limit Rotation constraints "
        f"on the bones that should move (see README, 'Preparing your rig')."
    )
