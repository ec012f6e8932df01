"""The posed body as a plain image mask per camera (painter's order), for overlays and coverage figures."""
import cv2
import numpy as np


def triangles_far_to_near(camera, vertices, faces):
    """Sub-pixel triangle corners (4 fractional bits) and the order to paint them, far to near, in front
    of the camera only."""
    uv, depth = camera.project_with_depth(vertices)
    front = np.all(depth[faces] > 1e-3, axis=1)
    order = [f for f in np.argsort(-depth[faces].mean(axis=1)) if front[f]]
    return np.round(uv[faces] * 16).astype(np.int32), order


def model_mask(camera, vertices, faces):
    """bool HxW: where the posed body covers camera's image (for overlays and coverage figures)."""
    pts, order = triangles_far_to_near(camera, vertices, faces)
    mask = np.zeros((camera.height, camera.width), np.uint8)
    for f in order:
        cv2.fillConvexPoly(mask, pts[f], 255, shift=4)
    return mask > 0
