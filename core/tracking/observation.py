"""Observing a frame: the features the energy compares poses with, the learned evidence (landmarks and person
masks from crops placed where the person is expected) and the finer silhouettes of the local fit.

The next frame can be observed in a worker thread while this one is finished: its crops need only where the
person will be, which the search's estimate (or, earlier, the last frames' steps) tells well enough, and the
main thread's local fit leaves the second core free (docs/defaults.md, "observe_early").
"""
import threading
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from ..evidence import BackgroundModel, compute_view_features
from ..evidence.appearance import OUTLINE_VISIBILITY, clothes_signature
from ..evidence.mask_cleanup import check_mask
from ..evidence.view_features import feature_size, resize_mask


class LazyBackgrounds(Mapping):
    """Camera name -> BackgroundModel, each made by make(read(name)) when first asked for (under a lock: the
    prefetch worker may ask). build_all() makes the missing ones at once: their frames read one camera after
    the other (the capture's reader serves one thread), then the clip medians two cameras at a time (NumPy
    work that releases the GIL)."""

    def __init__(self, names, read, make, ready=None):
        self._names = list(names)
        self._read, self._make = read, make
        self._models = dict(ready or {})
        self._lock = threading.Lock()

    def __getitem__(self, name):
        with self._lock:
            if name not in self._models:
                if name not in self._names:
                    raise KeyError(name)
                self._models[name] = self._make(self._read(name))
            return self._models[name]

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)

    def build_all(self):
        from concurrent.futures import ThreadPoolExecutor

        with self._lock:
            missing = [n for n in self._names if n not in self._models]
            if missing:
                frames = [self._read(n) for n in missing]
                with ThreadPoolExecutor(max_workers=min(2, len(missing))) as pool:
                    self._models.update(zip(missing, pool.map(self._make, frames)))

    @property
    def built(self):
        """Names of the cameras whose model exists."""
        return [n for n in self._names if n in self._models]


def background_models(capture, mode, n_frames, build_now):
    """Each camera's BackgroundModel: from its plate, else from the clip (the median of `n_frames` frames spread
    over it). A clip median costs seconds per camera on HD footage and is needed only where the learned mask is
    not used, so it is made when first asked for unless `build_now` (then at once, on both cores)."""
    plates = {}
    for cam in capture.cameras:
        plate = (capture.backgrounds or {}).get(cam.name)
        if mode in ("auto", "plate") and plate is not None:
            plates[cam.name] = BackgroundModel.from_plate(plate)
        elif mode == "plate":
            raise FileNotFoundError(f"no background plate for camera {cam.name!r}: expected "
                                    f"background/{cam.name}.png in the capture, or use --background median")
    method = "median" if mode == "auto" else mode

    def clip_frames(name):
        n = capture.frames.n_frames
        picks = np.unique(np.linspace(0, n - 1, min(n_frames, n)).round().astype(int))
        return [capture.frames.read_camera(name, int(f)) for f in picks]

    models = LazyBackgrounds([c.name for c in capture.cameras], clip_frames,
                             lambda frames: BackgroundModel.from_frames(frames, method=method), plates)
    if build_now:
        models.build_all()  # the cameras without a plate (none: nothing to do)
    return models


# ---- where the person is expected: the poses a frame's crops are placed around (absolute poses)
def carried_on(last, steps):
    """Constant velocity: the poses (k+1) b - k a for each k in `steps`, from the last two poses [a, b];
    from one pose, that pose alone."""
    if len(last) < 2:
        return np.stack(last)
    a, b = last
    return np.stack([(1 + k) * b - k * a for k in steps])


def expected_poses(last, default_pose):
    """This frame's: the last estimate and its constant-velocity step (`last`: up to two); before any, the
    subject as placed."""
    return default_pose[None] if not last else carried_on(last, (0, 1))


def guide_after_search(last, searched):
    """Frame t+1's, from frame t's search: around that estimate and one more step of the same size (`last`: the
    estimate of t-1, if any)."""
    return carried_on(list(last[-1:]) + [searched], (0, 1))


def guide_before_search(last):
    """Frame t+1's before frame t is solved (`last`: the estimates of t-2 and t-1): the last step carried on to t
    and to t+1."""
    return carried_on(last, (1, 2))


class Observation(NamedTuple):
    features: list  # ViewFeatures per camera, at the energy's resolution
    evidence: list | None  # ViewEvidence per camera (learned landmarks and mask); None without learned evidence
    fine_silhouettes: list | None  # per camera at the local fit's resolution; None when it is the energy's


class FrameObserver:
    """Observes frames for the energy. It reads nothing of the tracker's state, only the capture, the background
    models and the landmark model, so the next frame can be observed in its worker thread (prefetch / take)."""

    def __init__(self, capture, body, backgrounds, scales, learned_evidence, learned_mask, diffuse, clothes=False,
                 landmarks="full"):
        self.capture, self.body, self.backgrounds = capture, body, backgrounds
        self.clothes = clothes  # the signature of the clothes under each view's landmarks (clothes_check.py)
        self.scales = list(scales)  # the energy's resolution, then the local fit's if it is finer
        self.learned_evidence = learned_evidence  # run the landmark model
        self.learned_mask = learned_mask  # its person mask is the silhouette (else background subtraction)
        self.diffuse = diffuse  # the colour term's diffused images
        self.landmarks = landmarks  # which landmark model (core/evidence/learned.py, LANDMARK_MODEL_FILES)
        self.landmark_model = None  # loaded on first use
        self._pool = None  # the worker
        self._pending = None  # (frame, guide, future)

    def observe(self, frame, guide_poses):
        """`frame`'s Observation, the learned model's crops placed around `guide_poses` (absolute)."""
        images = self.capture.frames.read(frame)
        cams = self.capture.cameras
        evidence = self.evidence(images, guide_poses) if self.learned_evidence else None
        learned = evidence if evidence is not None and self.learned_mask else [None] * len(cams)
        masks = []  # per camera: a silhouette per scale
        for cam, ev in zip(cams, learned):
            shape = images[cam.name].shape
            if ev is not None and ev.found:  # the model's mask, sampled straight at each feature resolution
                masks.append([ev.mask_at(feature_size(shape, s)) for s in self.scales])
            else:
                sil = check_mask(self.backgrounds[cam.name].silhouette(images[cam.name]))
                masks.append([resize_mask(sil, feature_size(shape, s)) for s in self.scales])
        fine = [m[1] for m in masks] if len(self.scales) > 1 else None
        feats = [compute_view_features(images[cam.name], None, scale=self.scales[0], diffuse=self.diffuse,
                                       silhouette=m[0])
                 for cam, m in zip(cams, masks)]
        return Observation(feats, evidence, fine)

    def evidence(self, images, guide_poses):
        """Learned evidence per view, from crops around the projected joints of `guide_poses`."""
        from ..evidence.crops import evidence_around
        from ..evidence.learned import LandmarkModel, model_path

        if self.landmark_model is None:
            self.landmark_model = LandmarkModel(model_path(self.landmarks))
        cams = self.capture.cameras
        frames = [images[cam.name] for cam in cams]
        evidence = evidence_around(self.landmark_model, self.body, cams, frames, guide_poses,
                                   foreground=lambda i: self.backgrounds[cams[i].name].silhouette(frames[i]))
        if self.clothes:  # here, in the worker, while the main thread solves the frame before
            for ev, image in zip(evidence, frames):
                if ev.found:
                    ev.clothes = clothes_signature(image, ev.keypoints, ev.visibility >= OUTLINE_VISIBILITY)
        return evidence

    # ---- the worker
    def prefetch(self, frame, guide):
        """Start observing `frame` around `guide` in the worker."""
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mocap-observe")
        self._pending = (int(frame), guide, self._pool.submit(self.observe, frame, guide))

    def take(self, frame, guide_poses):
        """The prefetched Observation of `frame` around `guide_poses` (the same object), or None. Waits for any
        prefetch still running (the frame reader and the landmark model serve one thread at a time)."""
        pending, self._pending = self._pending, None
        if pending is None:
            return None
        p_frame, p_guide, future = pending
        if p_frame != int(frame) or p_guide is not guide_poses:
            try:
                future.result()
            except Exception:  # noqa: BLE001  (a frame nobody asks for: its error does not matter)
                pass
            return None
        return future.result()

    def finish(self):
        """Wait for a prefetch still running and stop the worker (before the capture is closed)."""
        self.take(-1, None)
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    @property
    def stopped(self):
        """No worker and nothing observed ahead."""
        return self._pool is None and self._pending is None
