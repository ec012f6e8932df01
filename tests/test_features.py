"""Per-frame image features: background subtraction, distance maps, edges, Lab, edge-enhancing diffusion.

Constructed scenes with known answers (a textured room plate, a person-like coloured figure, a shadow
that must stay background, exposure changes, sensor noise), checks against simple references (SciPy
EDT, SciPy banded solver, an explicit diffusion scheme) and, when present, the rendered sample scene.
"""
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy import linalg, ndimage

from markerless_mocap.core.evidence import (BackgroundModel, FeatureInputError, ViewFeatures, compute_view_features,
                                            diffusion_explicit_reference, distance_to_mask, edge_enhancing_diffusion,
                                            lab_ab, silhouette_iou, sobel_edges)
from markerless_mocap.core.evidence.diffusion import thomas_solve

WALK = Path(__file__).resolve().parents[1] / "sample_scenes" / "walk"


# ---------------------------------------------------------------- synthetic scene
def textured_plate(h, w, rng):
    """A cluttered room: multi-scale colour texture, furniture-like blocks, a darker floor."""
    plate = np.zeros((h, w, 3), np.float32)
    for sigma, amp in ((2, 10), (8, 18), (30, 25)):
        noise = cv2.GaussianBlur(rng.normal(0, 1, (h, w, 3)).astype(np.float32), (0, 0), sigma)
        plate += amp * noise / noise.std()
    plate += np.array([120, 130, 140], np.float32)
    for _ in range(8):
        y0, x0 = rng.integers(0, h - 20), rng.integers(0, w - 20)
        y1, x1 = y0 + rng.integers(10, h // 3), x0 + rng.integers(10, w // 3)
        plate[y0:y1, x0:x1] = plate[y0:y1, x0:x1] * 0.5 + rng.uniform(40, 210, 3)
    plate[int(h * 0.75):] *= 0.8
    return np.clip(plate, 15, 240)


def person_mask(h, w, cx, cy):
    m = np.zeros((h, w), np.uint8)
    s = h / 240
    cv2.ellipse(m, (int(cx), int(cy)), (int(22 * s), int(45 * s)), 0, 0, 360, 1, -1)
    cv2.circle(m, (int(cx), int(cy - 60 * s)), int(14 * s), 1, -1)
    cv2.rectangle(m, (int(cx - 18 * s), int(cy + 20 * s)), (int(cx - 6 * s), int(cy + 90 * s)), 1, -1)
    cv2.rectangle(m, (int(cx + 6 * s), int(cy + 20 * s)), (int(cx + 18 * s), int(cy + 90 * s)), 1, -1)
    cv2.line(m, (int(cx - 20 * s), int(cy - 25 * s)), (int(cx - 45 * s), int(cy + 15 * s)), 1, int(8 * s))
    return m.astype(bool)


def render_frame(plate, cx, cy, rng, gain=1.0, noise=3.0, shadow=0.75):
    """Person at (cx, cy) casting a soft shadow (x `shadow`) on the floor and a wall; exposure x gain."""
    h, w = plate.shape[:2]
    s = h / 240
    mask = person_mask(h, w, cx, cy)
    shade = np.zeros((h, w), np.uint8)
    cv2.ellipse(shade, (int(cx + 40 * s), int(cy + 88 * s)), (int(45 * s), int(10 * s)), 0, 0, 360, 1, -1)
    cv2.ellipse(shade, (int(cx + 60 * s), int(cy + 20 * s)), (int(12 * s), int(50 * s)), -30, 0, 360, 1, -1)
    factor = np.where(shade > 0, np.float32(shadow), np.float32(1.0))
    img = plate * cv2.GaussianBlur(factor, (0, 0), 2)[:, :, None]
    colours = np.empty((h, w, 3), np.float32)
    colours[:] = (40, 40, 190)                       # red shirt (BGR)
    colours[int(cy + 20 * s):] = (120, 60, 30)       # dark-blue trousers
    colours[:int(cy - 45 * s)] = (120, 150, 210)     # skin
    colours += cv2.GaussianBlur(rng.normal(0, 1, (h, w, 3)).astype(np.float32), (0, 0), 2) * 25
    img[mask] = colours[mask]
    img = img * gain + rng.normal(0, noise, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8), mask, (shade > 0) & ~mask


@pytest.fixture(scope="module")
def room():
    rng = np.random.default_rng(1)
    plate = textured_plate(240, 320, rng)
    shot = np.clip(plate + rng.normal(0, 3, plate.shape), 0, 255).astype(np.uint8)   # the plate is noisy too
    return plate, shot


# ---------------------------------------------------------------- silhouettes
@pytest.mark.parametrize("gain", [1.0, 0.8, 1.2])
def test_plate_silhouette_matches_truth_and_ignores_shadow(room, gain):
    plate, shot = room
    model = BackgroundModel.from_plate(shot)
    img, truth, shadow = render_frame(plate, 144, 108, np.random.default_rng(7), gain=gain)
    sil = model.silhouette(img)
    assert sil.dtype == bool and sil.shape == truth.shape
    assert silhouette_iou(sil, truth) >= 0.95
    assert np.count_nonzero(sil & shadow) <= 0.02 * np.count_nonzero(shadow)


def test_shadow_would_be_foreground_without_the_shadow_test(room):
    """The shadow test matters: a plain colour distance calls the shadow foreground."""
    plate, shot = room
    img, truth, shadow = render_frame(plate, 144, 108, np.random.default_rng(7))
    diff = np.linalg.norm(img.astype(np.float32) - shot.astype(np.float32), axis=2) > 20
    assert np.count_nonzero(diff & shadow) > 0.5 * np.count_nonzero(shadow)


def test_deep_shadow_on_textured_floor_is_rejected_by_texture_correlation():
    """A shadow darker than the colour test's shadow band (x0.6 < shadow_min) on a plank-like floor:
    the grain stays correlated with the plate, so it is still background; without the texture test
    the whole shadow would be foreground."""
    rng = np.random.default_rng(0)
    h, w = 240, 320
    yy, xx = np.mgrid[:h, :w]
    grain = 0.75 + 0.25 * np.sin(xx * 0.9 + 3 * np.sin(yy * 0.05)) * np.cos(yy * 0.3)
    plate = np.dstack([70 * grain, 120 * grain, 170 * grain]).astype(np.float32)
    shot = np.clip(plate + rng.normal(0, 2, plate.shape), 0, 255).astype(np.uint8)
    truth = person_mask(h, w, 150, 100)
    shade = np.zeros((h, w), np.uint8)
    cv2.ellipse(shade, (200, 190), (60, 14), 0, 0, 360, 1, -1)
    img = plate * np.where(shade > 0, 0.6, 1.0)[:, :, None]
    img[truth] = (90, 70, 60)
    img = np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8)
    shadow = (shade > 0) & ~truth
    sil = BackgroundModel.from_plate(shot).silhouette(img)
    assert silhouette_iou(sil, truth) >= 0.95
    assert np.count_nonzero(sil & shadow) < 0.1 * np.count_nonzero(shadow)
    colour_only = BackgroundModel.from_plate(shot, texture_ncc_min=0).silhouette(img)
    assert np.count_nonzero(colour_only & shadow) > 0.9 * np.count_nonzero(shadow)


def test_median_model_from_moving_subject(room):
    plate, _ = room
    rng = np.random.default_rng(3)
    frames, truths = [], []
    for k in range(20):   # walks across the room while the exposure drifts by +-10 %
        img, truth, _ = render_frame(plate, 320 * (0.15 + 0.7 * k / 19), 108, rng, gain=1 + 0.1 * np.sin(k))
        frames.append(img)
        truths.append(truth)
    model = BackgroundModel.from_frames(frames)
    ious = [silhouette_iou(model.silhouette(f), t) for f, t in zip(frames, truths)]
    assert min(ious) >= 0.95, ious
    # The estimated empty scene is the plate, not a ghost of the person.
    assert np.median(np.abs(model.background - plate)) < 4.0


def test_from_frames_subsamples_and_rejects_bad_input(room):
    plate, shot = room
    with pytest.raises(FeatureInputError, match="at least 3 frames"):
        BackgroundModel.from_frames([shot, shot])
    with pytest.raises(FeatureInputError, match="unknown background method"):
        BackgroundModel.from_frames([shot] * 3, method="average")
    with pytest.raises(FeatureInputError, match="same size|one size"):
        BackgroundModel.from_frames([shot, shot, shot[:100]])


def test_bad_images_give_clear_errors(room):
    _, shot = room
    model = BackgroundModel.from_plate(shot)
    with pytest.raises(FeatureInputError, match="same resolution"):
        model.silhouette(cv2.resize(shot, (160, 120)))
    with pytest.raises(FeatureInputError, match="HxWx3"):
        model.silhouette(shot[:, :, 0])
    with pytest.raises(FeatureInputError, match="outside \\[0, 1\\]"):
        model.silhouette(shot.astype(np.float32))
    with pytest.raises(FeatureInputError, match="unknown background option"):
        BackgroundModel.from_plate(shot, chroma_threshold=3)


def test_empty_scene_gives_empty_silhouette(room):
    plate, shot = room
    frame = np.clip(plate * 0.9 + np.random.default_rng(5).normal(0, 3, plate.shape), 0, 255).astype(np.uint8)
    assert np.count_nonzero(BackgroundModel.from_plate(shot).silhouette(frame)) == 0


def test_silhouette_iou_known_values():
    a = np.zeros((10, 10), bool)
    b = np.zeros((10, 10), bool)
    a[:, :5] = True
    b[:, 2:6] = True    # intersection 3 columns, union 6 columns
    assert silhouette_iou(a, b) == pytest.approx(0.5)
    assert silhouette_iou(a, a) == 1.0
    assert silhouette_iou(np.zeros((4, 4), bool), np.zeros((4, 4), bool)) == 1.0
    with pytest.raises(FeatureInputError, match="differ in size"):
        silhouette_iou(a, b[:5])


def _video_frame(path, index):
    cap = cv2.VideoCapture(str(path))
    frame = None
    for _ in range(index + 1):
        ok, frame = cap.read()
        assert ok, f"cannot read frame {index} of {path}"
    cap.release()
    return frame


@pytest.mark.slow
@pytest.mark.skipif(not (WALK / "background").is_dir(), reason="sample scene 'walk' not present")
def test_rendered_walk_scene_with_plates():
    """Cycles renders (shadows, mild noise, mp4 coding) against the true masks: mean IoU >= 0.85."""
    ious = []
    for cam in ("cam1", "cam2", "cam3", "cam4"):
        model = BackgroundModel.from_plate(cv2.imread(str(WALK / "background" / f"{cam}.png")))
        for k in (0, 30, 59):
            truth = cv2.imread(str(WALK / "gt_masks" / cam / f"{k:04d}.png"), cv2.IMREAD_GRAYSCALE) > 127
            ious.append(silhouette_iou(model.silhouette(_video_frame(WALK / "videos" / f"{cam}.mp4", k)), truth))
    assert np.mean(ious) >= 0.85 and min(ious) >= 0.75, ious


# ---------------------------------------------------------------- distance maps and edges
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_distance_map_equals_exact_edt(seed):
    rng = np.random.default_rng(seed)
    mask = rng.random((60, 80)) < 0.02
    mask[rng.integers(0, 60), rng.integers(0, 80)] = True
    expected = ndimage.distance_transform_edt(~mask)
    got = distance_to_mask(mask)
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, expected, atol=1e-3)
    assert np.all(got[mask] == 0)


def test_distance_map_of_empty_mask_is_beyond_the_image():
    d = distance_to_mask(np.zeros((30, 40), bool))
    assert np.all(d >= 50.0)


def test_rectangle_edges_lie_on_its_border():
    img = np.full((120, 160, 3), 60, np.uint8)
    img[30:90, 40:120] = (200, 180, 160)
    inside = np.zeros((120, 160), bool)
    inside[30:90, 40:120] = True
    border = inside & ~ndimage.binary_erosion(inside)
    edges = sobel_edges(img, inside, percentile=90)
    dist_to_border = ndimage.distance_transform_edt(~border)
    assert edges.any()
    assert dist_to_border[edges].max() <= 1.5           # every edge pixel hugs the border
    dist_to_edge = ndimage.distance_transform_edt(~edges)
    assert dist_to_edge[border].max() <= 1.0             # and the whole border is covered


def test_flat_image_has_no_edges():
    assert not sobel_edges(np.full((40, 50, 3), 128, np.uint8)).any()


def test_lab_ab_native_units():
    img = np.zeros((2, 2, 3), np.uint8)
    img[0, 0] = (0, 0, 255)      # pure red: a ~ 80, b ~ 67 (sRGB, D65)
    img[0, 1] = (128, 128, 128)  # grey: a = b = 0
    ab = lab_ab(img)
    assert ab.shape == (2, 2, 2) and ab.dtype == np.float32
    assert ab[0, 0, 0] == pytest.approx(80.1, abs=1.0) and ab[0, 0, 1] == pytest.approx(67.2, abs=1.0)
    assert np.abs(ab[0, 1]).max() < 0.01


def test_compute_view_features_at_half_resolution(room):
    plate, shot = room
    img, truth, _ = render_frame(plate, 144, 108, np.random.default_rng(7))
    feats = compute_view_features(img, BackgroundModel.from_plate(shot), scale=0.5, diffuse=False)
    assert isinstance(feats, ViewFeatures)
    assert feats.silhouette.shape == feats.edges.shape == feats.edge_dt.shape == (120, 160)
    assert feats.lab_ab.shape == (120, 160, 2) and feats.lab_ab.dtype == np.float32
    small_truth = cv2.resize(truth.astype(np.float32), (160, 120), interpolation=cv2.INTER_AREA) >= 0.5
    assert silhouette_iou(feats.silhouette, small_truth) >= 0.93
    np.testing.assert_allclose(feats.silhouette_dt,
                               ndimage.distance_transform_edt(~feats.silhouette), atol=1e-3)
    assert feats.edge_dt.max() <= 10.0 + 1e-6            # 20 px at full resolution -> 10 px at half
    np.testing.assert_allclose(feats.edge_dt, np.minimum(ndimage.distance_transform_edt(~feats.edges), 10.0),
                               atol=1e-3)
    # Integer frames are resampled before they become float (HD footage); against the float-first
    # resampling that costs at most the uint8 rounding of a pixel (under 1 a/b unit, of about +-128).
    small = cv2.resize(img, (160, 120), interpolation=cv2.INTER_AREA).astype(np.float32) / 255
    np.testing.assert_allclose(feats.lab_ab, lab_ab(small), atol=1e-3)
    small_float = cv2.resize(img.astype(np.float32) / 255, (160, 120), interpolation=cv2.INTER_AREA)
    np.testing.assert_allclose(feats.lab_ab, lab_ab(small_float), atol=1.0)
    with pytest.raises(FeatureInputError, match="scale"):
        compute_view_features(img, BackgroundModel.from_plate(shot), scale=2.0)


# ---------------------------------------------------------------- edge-enhancing diffusion
def test_thomas_matches_banded_solver():
    rng = np.random.default_rng(0)
    n, k = 37, 5
    upper = -rng.random((n, k))
    lower = -rng.random((n, k))
    diag = 1.0 - upper - lower + rng.random((n, k))
    rhs = rng.normal(size=(n, k))
    x = thomas_solve(lower, diag, upper, rhs)
    for j in range(k):
        banded = np.zeros((3, n))
        banded[0, 1:] = upper[:-1, j]
        banded[1] = diag[:, j]
        banded[2, :-1] = lower[1:, j]
        np.testing.assert_allclose(x[:, j], linalg.solve_banded((1, 1), banded, rhs[:, j]), rtol=1e-10, atol=1e-12)


def _colour_test_image(rng, h=48, w=64):
    yy, xx = np.mgrid[:h, :w]
    ab = np.zeros((h, w, 2))
    ab[..., 0] = np.where(xx < 30, -20.0, 25.0) + np.where((yy - 24) ** 2 + (xx - 45) ** 2 < 100, 30.0, 0.0)
    ab[..., 1] = np.where(yy < 20, 10.0, -15.0)
    return ab + rng.normal(0, 3, ab.shape)


def test_aos_agrees_with_explicit_reference():
    ab = _colour_test_image(np.random.default_rng(0))
    aos = edge_enhancing_diffusion(ab)
    ref = diffusion_explicit_reference(ab, steps=5, tau=2.0, eps=1e-3, p=1.5)
    assert np.abs(aos - ref).mean() < 0.5
    assert np.abs(aos - ref).max() < 5.0


def test_aos_conserves_the_mean_of_each_channel():
    ab = _colour_test_image(np.random.default_rng(1))
    out = edge_enhancing_diffusion(ab, steps=5, tau=2.0)
    np.testing.assert_allclose(out.mean(axis=(0, 1)), ab.mean(axis=(0, 1)), atol=1e-3)


def test_flat_image_is_unchanged():
    flat = np.empty((30, 40, 2))
    flat[..., 0], flat[..., 1] = 12.5, -33.0
    np.testing.assert_allclose(edge_enhancing_diffusion(flat), flat, atol=1e-4)


def test_step_edge_is_preserved_while_noise_is_removed():
    rng = np.random.default_rng(2)
    ab = np.zeros((40, 60, 2))
    ab[:, 30:, 0] = 40.0
    ab[:, 30:, 1] = -20.0
    noisy = ab + rng.normal(0, 2.0, ab.shape)
    out = edge_enhancing_diffusion(noisy)
    jump = out[:, 31:, 0].mean() - out[:, :29, 0].mean()
    assert jump == pytest.approx(40.0, abs=1.0)
    # Sharp: the two columns next to the step still differ by most of it.
    assert np.median(out[:, 30, 0] - out[:, 29, 0]) > 30.0
    assert out[:, 5:25, 0].std() < noisy[:, 5:25, 0].std() / 5


def test_diffusion_accepts_one_channel_and_rejects_bad_parameters():
    img = np.random.default_rng(3).normal(size=(20, 30))
    assert edge_enhancing_diffusion(img).shape == (20, 30)
    with pytest.raises(FeatureInputError, match="tau"):
        edge_enhancing_diffusion(img, tau=0)
    with pytest.raises(FeatureInputError, match="HxWx2"):
        edge_enhancing_diffusion(np.zeros((2, 3, 4, 5)))


def test_strip_wise_temporal_median_equals_numpy_median_of_the_stack():
    from markerless_mocap.core.evidence.background import _temporal_median

    rng = np.random.default_rng(5)
    frames = [rng.uniform(0, 255, (150, 37, 3)).astype(np.float32) for _ in range(7)]
    np.testing.assert_array_equal(_temporal_median(frames, rows_per_strip=64), np.median(np.stack(frames), axis=0))
    ref = np.stack(frames)[..., 0].mean(axis=0)
    dev = _temporal_median(frames, lambda strip, rows: np.abs(strip[..., 0] - ref[rows]), rows_per_strip=16)
    np.testing.assert_array_equal(dev, np.median(np.abs(np.stack(frames)[..., 0] - ref), axis=0))
