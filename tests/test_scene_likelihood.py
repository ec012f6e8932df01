"""The likelihood on the rendered sample scenes: silhouettes against the true masks, and every
named likelihood prefers the ground-truth pose to random perturbations of it (issue: >= 95% of 500
perturbations of 5 cm / 10 degrees per DOF)."""
from functools import lru_cache

import cv2
import numpy as np
import pytest

from scene_helpers import ground_truth_poses, scene_dir

pytest.importorskip("bpy")

from markerless_mocap.core.capture.capture import load_capture  # noqa: E402
from markerless_mocap.core.evidence import BackgroundModel, compute_view_features, silhouette_iou  # noqa: E402
from markerless_mocap.core.evidence.learned import LandmarkModel, crop_around, locate  # noqa: E402
from markerless_mocap.core.energy.likelihood import LIKELIHOODS, EnergyModel, default_pose_at  # noqa: E402
from markerless_mocap.core.tracking.motion_library import build_motion_models, scene_exclusion  # noqa: E402
from markerless_mocap.core.body.proxy import make_proxy  # noqa: E402

SCENES = ("walk", "playground")


@lru_cache(maxsize=1)
def landmark_model():
    return LandmarkModel()

def gt_masks(name):
    """{(camera, frame): bool mask} from gt_masks/<cam>/<frame>.png."""
    out = {}
    for path in sorted((scene_dir(name) / "gt_masks").glob("*/*.png")):
        out[(path.parent.name, int(path.stem))] = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) > 127
    return out


def mean_iou(capture, masks, model_for):
    ious = []
    for (cam, frame), truth in masks.items():
        image = capture.frames.read(frame)[cam]
        ious.append(silhouette_iou(model_for(cam).silhouette(image), truth))
    return float(np.mean(ious)), float(np.min(ious))


def sequence_model(capture, cam):
    n = capture.frames.n_frames
    frames = [capture.frames.read_camera(cam, int(f)) for f in np.linspace(0, n - 1, 25).round()]
    return BackgroundModel.from_frames(frames)


def test_silhouettes_with_plates_match_the_true_masks():
    capture = load_capture(scene_dir("walk"))
    assert capture.backgrounds, "the walk scene ships background plates"
    mean, worst = mean_iou(capture, gt_masks("walk"), lambda cam: BackgroundModel.from_plate(capture.backgrounds[cam]))
    print(f"walk, with plates: mean IoU {mean:.3f}, worst {worst:.3f}")
    assert mean >= 0.85


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENES)
def test_silhouettes_without_plates_match_the_true_masks(name):
    capture = load_capture(scene_dir(name))
    models = {}
    mean, worst = mean_iou(capture, gt_masks(name),
                           lambda cam: models.setdefault(cam, sequence_model(capture, cam)))
    print(f"{name}, background from the sequence: mean IoU {mean:.3f}, worst {worst:.3f}")
    assert mean >= 0.75


@pytest.fixture(scope="module", params=SCENES)
def scene_energy(request):
    name = request.param
    body, frames, gt, _ = ground_truth_poses(name)
    capture = load_capture(scene_dir(name))
    prior, _ = build_motion_models(body, fps=capture.frames.fps, exclude=scene_exclusion(scene_dir(name)))
    proxy = make_proxy(body)
    if capture.backgrounds:
        backgrounds = {c: BackgroundModel.from_plate(capture.backgrounds[c]) for c in capture.camera_names}
    else:
        backgrounds = {c: sequence_model(capture, c) for c in capture.camera_names}
    return name, body, gt, capture, prior, proxy, backgrounds


@pytest.mark.parametrize("likelihood", sorted(LIKELIHOODS))
def test_ground_truth_beats_random_perturbations(scene_energy, likelihood):
    name, body, gt, capture, prior, proxy, backgrounds = scene_energy
    energy = EnergyModel(body, proxy, capture.cameras, likelihood, prior=prior)
    energy.set_reference_pose(default_pose_at(body, gt[0]))

    def features(frame):
        """The frame's features, and its learned evidence (crops around the previous frame's true pose,
        as the tracker places them around its last estimate) when the likelihood uses it."""
        images = capture.frames.read(frame)
        evidence, masks = None, [None] * len(capture.cameras)
        if energy.weights.needs_learned_evidence:
            joints = body.joint_positions(gt[max(0, frame - 1)][None])[0]
            boxes = [crop_around(c.project(joints)) for c in capture.cameras]
            evidence = locate(landmark_model(), [images[c.name] for c in capture.cameras], boxes)
            if energy.weights.mask == "learned":
                masks = [ev.mask for ev in evidence]
        return [compute_view_features(images[c.name], backgrounds[c.name], scale=energy.scale,
                                      diffuse=energy.weights.color > 0, silhouette=m)
                for c, m in zip(capture.cameras, masks)], evidence

    if energy.weights.color:
        energy.set_frame(*features(0))
        energy.init_color_model(gt[0])
    rng = np.random.default_rng(11)
    scale = np.where(np.isin(np.arange(body.n_dof), body.translation_dofs), 0.05, np.deg2rad(10.0))
    wins = []
    for frame in (10, 30, 50):
        energy.set_frame(*features(frame))
        perturbed = body.clamp(gt[frame] + rng.normal(0, 1, (500, body.n_dof)) * scale)
        e_true = energy(gt[frame][None])[0]
        wins.append(float((energy(perturbed) > e_true).mean()))
    print(f"{name} {likelihood}: ground truth beats {np.round(wins, 3)} of 500 perturbations")
    assert min(wins) >= 0.95
