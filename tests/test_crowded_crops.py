"""Someone else in a view's crop (core/evidence/crowded_crops.py): painted over, and the landmark model looks again."""
import numpy as np
import pytest
from scene_helpers import ground_truth_poses, scene_dir

from markerless_mocap.core.evidence.crowded_crops import painted_over, stranger_pixels
from markerless_mocap.core.evidence.learned import INPUT_SIZE, CropBox


def test_only_the_far_pixels_are_painted_in_the_backgrounds_colour():
    image = np.full((200, 300, 3), (10, 20, 30), np.uint8)
    image[50:150, 100:140] = 200  # the actor
    image[60:140, 200:230] = 90  # someone else
    box = CropBox(150.0, 100.0, 256.0)  # one image pixel per crop pixel
    prob = np.zeros((INPUT_SIZE, INPUT_SIZE), np.float32)
    uv = box.to_crop(np.array([[100, 50], [140, 150], [200, 60], [230, 140]]))
    (ax0, ay0), (ax1, ay1), (bx0, by0), (bx1, by1) = np.round(uv).astype(int)
    prob[ay0:ay1, ax0:ax1] = 0.9
    prob[by0:by1, bx0:bx1] = 0.9
    expected = np.zeros_like(prob, bool)
    expected[ay0:ay1, ax0:ax1] = True
    far, share = stranger_pixels(prob, expected)
    assert far[by0:by1, bx0:bx1].all() and not far[ay0:ay1, ax0:ax1].any()
    assert share == pytest.approx(30 * 80 / (40 * 100), rel=0.05)
    out = painted_over(image, box, far, prob)
    assert (out[60:140, 200:230] == (10, 20, 30)).all()  # the background's median colour
    np.testing.assert_array_equal(out[50:150, 100:140], image[50:150, 100:140])
    untouched = np.ones(image.shape[:2], bool)
    untouched[55:145, 195:235] = False  # the painted person and the few pixels it is grown by
    np.testing.assert_array_equal(out[untouched], image[untouched])


@pytest.fixture(scope="module")
def crossing_at_frame_10():
    """crossing_dev's actor where frame 9's truth puts it, and the landmark model's first look at frame 10."""
    pytest.importorskip("bpy")
    from markerless_mocap.core.body.proxy import make_proxy
    from markerless_mocap.core.evidence.learned import LandmarkModel

    body, _, poses, _ = ground_truth_poses("crossing_dev")
    return body, make_proxy(body), poses[[9]], LandmarkModel()


def _look(scene, body, proxy, guide, model):
    from markerless_mocap.core.capture.capture import load_capture
    from markerless_mocap.core.evidence.crops import evidence_around
    from markerless_mocap.core.evidence.crowded_crops import look_past_strangers

    capture = load_capture(scene_dir(scene))
    images = capture.frames.read(10)
    frames = [images[c.name] for c in capture.cameras]
    first = evidence_around(model, body, capture.cameras, frames, guide)
    vertices = list(proxy.deform(body, guide))
    again, looked = look_past_strangers(model, frames, first, capture.cameras, vertices, np.asarray(proxy.faces))
    return capture.cameras, first, again, looked, vertices


def test_a_passer_by_in_the_crop_is_painted_over_and_leaves_the_mask(crossing_at_frame_10):
    """Frame 10 of crossing_dev: the passer-by walks between the actor and cam1, and cam1's person mask is mostly
    theirs. Looked at again with them painted over, the mask keeps far less of them; the same frame without the
    passer-by (crossing_dev_alone) is not looked at again."""
    from markerless_mocap.core.evidence.crowded_crops import expected_body

    body, proxy, guide, model = crossing_at_frame_10
    cameras, first, again, looked, vertices = _look("crossing_dev", body, proxy, guide, model)
    assert "cam1" in [cameras[i].name for i in looked]
    for i in looked:
        expected = expected_body(vertices, np.asarray(proxy.faces), cameras[i], first[i].box)
        before = stranger_pixels(first[i].crop_prob, expected)[1]
        after = stranger_pixels(again[i].crop_prob, expected)[1]
        assert after < 0.5 * before, (cameras[i].name, before, after)
    untouched = [i for i in range(len(cameras)) if i not in looked]
    assert all(again[i] is first[i] for i in untouched)

    _, alone_first, alone_again, alone_looked, _ = _look("crossing_dev_alone", body, proxy, guide, model)
    assert alone_looked == [] and all(a is b for a, b in zip(alone_first, alone_again))
