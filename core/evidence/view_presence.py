"""Which views can see the person this frame. A person walking out of one camera's picture (or a view
whose footage goes black) must not drag the pose out of that camera's frustum: such a view is left out
of the image terms for the frame, and tracking goes on with the others."""
import numpy as np

# a view is left out when fewer than this share of the predicted joints fall inside its image
MIN_SHARE_INSIDE = 0.5
# ... or when its silhouette is no person: less than this share of the person's expected area (the
# person cropped out, a blank frame against no plate) or more than that share of the whole picture
# (a blank or flashed frame against a plate, a background model that failed)
MIN_SILHOUETTE_OF_PERSON = 0.1
MAX_SILHOUETTE_OF_PICTURE = 0.5


def share_inside(camera, joints):
    """Share of the 3D points (N,3) in front of the camera that project inside its image."""
    joints = np.asarray(joints, dtype=np.float64).reshape(-1, 3)
    depth = (joints @ camera.R.T + camera.t)[:, 2]
    uv = camera.project(joints)
    inside = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < camera.width) & (uv[:, 1] >= 0) & (uv[:, 1] < camera.height)
    return float(inside.mean()) if len(joints) else 0.0


def views_in_play(cameras, predicted_joints, evidence=None, silhouette_area=None, person_area=None,
                  picture_area=None, min_share=MIN_SHARE_INSIDE):
    """(C,) bool: the person's predicted joints are mostly inside the view; with learned evidence, the
    model found a person there (presence); given the silhouette areas (C,) with the person's expected
    area and the picture's (same pixels), the silhouette is person-sized. If no view qualifies, all are
    kept: better every view than none."""
    keep = np.array([share_inside(cam, predicted_joints) >= min_share for cam in cameras])
    if evidence is not None:
        keep &= np.array([bool(ev.found) for ev in evidence])
    if silhouette_area is not None:
        area = np.asarray(silhouette_area, dtype=np.float64)
        keep &= area >= MIN_SILHOUETTE_OF_PERSON * np.asarray(person_area, dtype=np.float64)
        keep &= area <= MAX_SILHOUETTE_OF_PICTURE * np.asarray(picture_area, dtype=np.float64)
    return keep if keep.any() else np.ones(len(cameras), bool)
