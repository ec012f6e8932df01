"""Is a rig fit to track a person? Its mesh must move with its bones, and it must stand at a person's
height in metres (the calibration's unit): a rig modelled in centimetres, or scaled at object level
without applying it, is 100x off and would be fitted at the wrong size or not at all."""
import numpy as np

from ..errors import InputError

# a child to a very tall adult, with room for a raised arm or a crouch in the rest pose
PERSON_HEIGHT_M = (0.5, 3.0)
# more than this share of unweighted vertices is a mesh that was never skinned, not a stray vertex
LARGEST_UNWEIGHTED_SHARE = 0.5


class RigCheckError(InputError):
    """The rig cannot be tracked as it is; the message names the object, the problem and the fix."""


def standing_height(world_vertices) -> float:
    """Vertical (Z, Blender's up) extent of the rest mesh in world units."""
    z = np.asarray(world_vertices, dtype=np.float64).reshape(-1, 3)[:, 2]
    return float(z.max() - z.min()) if z.size else 0.0


def require_person_height(height, armature_name, unit_scale=1.0):
    """A RigCheckError unless the rig stands between PERSON_HEIGHT_M (Blender units are taken as metres)."""
    low, high = PERSON_HEIGHT_M
    if low <= height <= high:
        return
    units = "" if unit_scale == 1.0 else f" and set Scene > Units > Unit Scale to 1.0 (it is {unit_scale:g})"
    how = "too small" if height < low else "too large"
    raise RigCheckError(f"armature {armature_name!r} stands {height:.3g} m tall (1 Blender unit = 1 m), {how} "
                        f"for a person ({low:g}-{high:g} m): scale it to the person's height and apply the scale "
                        f"(Ctrl+A > Scale){units}")


def require_skin_weights(weights, mesh_name, armature_name):
    """A RigCheckError when most vertices follow no deforming bone (groups exist but hold no weights)."""
    weights = np.asarray(weights)
    if not len(weights):
        raise RigCheckError(f"mesh {mesh_name!r} has no vertices: skin a body mesh to {armature_name!r}")
    unweighted = int((weights.sum(axis=1) <= 0).sum())
    if unweighted > LARGEST_UNWEIGHTED_SHARE * len(weights):
        raise RigCheckError(f"mesh {mesh_name!r}: {unweighted} of {len(weights)} vertices carry no weight for a "
                            f"deforming bone of {armature_name!r}, so the mesh would not move: skin it "
                            "(Ctrl+P > With Automatic Weights) or weight-paint it")
