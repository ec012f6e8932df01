"""Someone else in a view's crop: the landmark model sees one person per crop, whoever is most visible in it, and
its mask and landmarks follow that person. Where the crop's person mask holds many pixels far from the body
expected there (a passer-by beside, behind or in front of the actor), those pixels are painted over with the crop's
background colour and the model looks again: what is left of that person is what overlaps the actor
(docs/how-it-tracks.md, "Other people in the room"; the figures: docs/defaults.md, "Crowded crops").
"""
import cv2
import numpy as np

from .learned import INPUT_SIZE, MASK_THRESHOLD

# Mask pixels farther than this (a share of the crop's side; the body spans about 1 / 1.35 of it, so 18 px of 256
# are about 7 % of the body's height) from the body expected in the crop are someone else's [DESIGN] ...
STRANGER_MARGIN = 0.07
# ... once they cover at least this share of the expected body's area in the crop [DESIGN]: with nobody else
# there no view of crossing_dev_alone comes near it (docs/defaults.md, "Crowded crops").
STRANGER_SHARE = 0.15


def expected_body(vertices_list, faces, camera, box):
    """(INPUT_SIZE, INPUT_SIZE) bool: where the posed meshes `vertices_list` ((V,3) each) fall in the crop."""
    out = np.zeros((INPUT_SIZE, INPUT_SIZE), np.uint8)
    for vertices in vertices_list:
        uv = box.to_crop(camera.project(vertices))
        if not np.all(np.isfinite(uv)):
            continue
        triangles = np.round(uv[faces] * 4).astype(np.int32)  # 2 bits of sub-pixel precision
        cv2.fillPoly(out, list(triangles), 1, lineType=cv2.LINE_8, shift=2)
    return out > 0


def stranger_pixels(crop_prob, expected, margin=STRANGER_MARGIN):
    """(crop bool mask of the person pixels far from the expected body, their area over the body's)."""
    radius = max(1, int(round(margin * INPUT_SIZE)))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    near = cv2.dilate(expected.astype(np.uint8), kernel) > 0
    far = (np.asarray(crop_prob) >= MASK_THRESHOLD) & ~near
    return far, float(far.sum()) / max(float(expected.sum()), 1.0)


def painted_over(image, box, far, crop_prob):
    """A copy of `image` with the crop's pixels `far` (grown by a few pixels) painted in the median colour of the
    crop's background (its mask below 0.2)."""
    matrix = box.image_to_crop_matrix()
    h, w = image.shape[:2]
    crop = cv2.warpAffine(image, matrix, (INPUT_SIZE, INPUT_SIZE), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REPLICATE)
    background = np.asarray(crop_prob) < 0.2
    fill = np.median(crop[background], axis=0) if background.any() else np.median(crop.reshape(-1, 3), axis=0)
    grown = cv2.dilate(far.astype(np.uint8), np.ones((5, 5), np.uint8))
    in_image = cv2.warpAffine(grown, matrix, (w, h), flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=0) > 0
    out = image.copy()
    out[in_image] = fill.astype(image.dtype)
    return out


def look_past_strangers(model, images, evidence, cameras, vertices_list, faces, margin=STRANGER_MARGIN,
                        share=STRANGER_SHARE):
    """`evidence` (ViewEvidence per view) with the views whose crop held someone else looked at again with that
    person painted over; returns (evidence, [indices of the views looked at again])."""
    again, painted, boxes = [], [], []
    for i, (ev, cam) in enumerate(zip(evidence, cameras)):
        if not ev.found or ev.crop_prob is None or ev.box is None:
            continue
        far, part = stranger_pixels(ev.crop_prob, expected_body(vertices_list, faces, cam, ev.box), margin)
        if part >= share:
            again.append(i)
            painted.append(painted_over(images[i], ev.box, far, ev.crop_prob))
            boxes.append(ev.box)
    if not again:
        return evidence, []
    evidence = list(evidence)
    for i, ev in zip(again, model.evidence(painted, boxes)):
        if ev.found:
            evidence[i] = ev
    return evidence, again
