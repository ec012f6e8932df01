"""Overlay images: the tracked body drawn over the footage, one video per camera, to check by eye."""
import colorsys
import os
from pathlib import Path

import cv2
import numpy as np

from ..atomic_files import partial_path
from ..render.model_mask import triangles_far_to_near


def part_colours(n):
    """Distinct BGR colours per body part."""
    return [tuple(int(255 * c) for c in colorsys.hsv_to_rgb(i / max(n, 1), 0.8, 1.0))[::-1] for i in range(n)]


def actor_colours(n_actors, n_parts):
    """Per actor, one colour for all its parts (BGR), lighter and darker by part so the limbs stay apart."""
    hues = [(0.08 + i / max(n_actors, 1)) % 1.0 for i in range(n_actors)]
    return [[tuple(int(255 * c) for c in colorsys.hsv_to_rgb(h, 0.85, 0.65 + 0.35 * (p % 3) / 2))[::-1]
             for p in range(n_parts)] for h in hues]


def draw_body(image, camera, vertices, faces, face_part, colours, alpha=0.45):
    """Painter's algorithm (far to near) with per-part colours, blended over `image` (BGR uint8)."""
    pts, order = triangles_far_to_near(camera, vertices, faces)
    layer = image.copy()
    mask = np.zeros(image.shape[:2], np.uint8)
    for f in order:
        cv2.fillConvexPoly(layer, pts[f], colours[face_part[f]], lineType=cv2.LINE_AA, shift=4)
        cv2.fillConvexPoly(mask, pts[f], 255, shift=4)
    out = image.copy()
    sel = mask > 0
    out[sel] = (alpha * layer[sel] + (1 - alpha) * image[sel]).astype(np.uint8)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(out, contours, -1, (0, 255, 255), 1, cv2.LINE_AA)
    return out


def draw_landmarks(image, uv, visibility, min_visibility=0.5):
    """The learned landmarks the frame was solved with: person's left in green, right in magenta."""
    radius = max(3, round(max(image.shape[:2]) / 240))  # visible on HD footage too
    for k, (point, vis) in enumerate(zip(uv, visibility)):
        if vis < min_visibility or not np.all(np.isfinite(point)):
            continue
        colour = (0, 255, 0) if k % 2 == 1 else (255, 0, 255) if k > 0 else (255, 255, 255)
        cv2.circle(image, (int(round(point[0])), int(round(point[1]))), radius, colour, -1, cv2.LINE_AA)
    return image


class OverlayWriter:
    """One mp4 per camera in <out>/overlay/, a frame appended per solved frame."""

    def __init__(self, out_dir, cameras, fps):
        self.folder = Path(out_dir) / "overlay"
        self.folder.mkdir(parents=True, exist_ok=True)
        self.cameras = cameras
        self.fps = fps
        self.writers = {}

    def add(self, images, vertices, faces, face_part, n_parts, label="", landmarks=None, visibility=None):
        self.add_bodies(images, [(vertices, faces, face_part, part_colours(n_parts))], label, landmarks, visibility)

    def add_bodies(self, images, bodies, label="", landmarks=None, visibility=None):
        """One frame with several bodies, (vertices, faces, face_part, colour per part) each, the farthest from
        each camera drawn first."""
        for c, cam in enumerate(self.cameras):
            img = images[cam.name]
            depth = [float(cam.to_camera(b[0])[:, 2].mean()) for b in bodies]
            for i in np.argsort(depth)[::-1]:
                vertices, faces, face_part, colours = bodies[i]
                img = draw_body(img, cam, vertices, faces, face_part, colours)
            if landmarks is not None:
                draw_landmarks(img, landmarks[c], visibility[c])
            if label:
                cv2.putText(img, label, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
            w = self.writers.get(cam.name)
            if w is None:
                # written under a temporary name and renamed by close(): a kill leaves no half-written video
                path = partial_path(self.folder / f"{cam.name}.mp4")
                w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, (img.shape[1], img.shape[0]))
                self.writers[cam.name] = w
            w.write(img)

    def close(self):
        for name, w in self.writers.items():
            w.release()
            os.replace(partial_path(self.folder / f"{name}.mp4"), self.folder / f"{name}.mp4")
        self.writers = {}


def contact_sheet(rows, cell_height=360, label_rows=None):
    """A grid image: rows of equally tall cells (BGR images of any size), each row labelled on its left."""
    out_rows = []
    for r, cells in enumerate(rows):
        resized = [cv2.resize(c, (max(1, round(c.shape[1] * cell_height / c.shape[0])), cell_height),
                              interpolation=cv2.INTER_AREA) for c in cells]
        row = np.hstack(resized)
        if label_rows is not None:
            cv2.putText(row, label_rows[r], (8, cell_height - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2,
                        cv2.LINE_AA)
        out_rows.append(row)
    width = max(r.shape[1] for r in out_rows)
    return np.vstack([np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0))) for r in out_rows])
