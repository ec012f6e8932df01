"""Energy terms on a flat two-part 'body' with hand-derived answers; fast vs reference on the real body."""
import numpy as np
import pytest

from markerless_mocap.core.energy import likelihood as lk
from markerless_mocap.core.capture.camera import Camera
from markerless_mocap.core.evidence.view_features import ViewFeatures, distance_to_mask
from markerless_mocap.core.body.rotations import rotvec_to_matrix

from test_render import look_at


# ---------------------------------------------------------------------------------------- a flat rigid body
class FlatBody:
    """Pose = translation (3) + rotation vector (3) of a rigid mesh; default pose = zeros."""

    n_dof = 6
    translation_dofs = np.array([0, 1, 2])
    root_rotation_dofs = np.array([3, 4, 5])

    def default_pose(self):
        return np.zeros(6)

    def deform(self, poses, vertices):
        poses = np.atleast_2d(poses)
        R = rotvec_to_matrix(poses[:, 3:6])
        return np.einsum("pij,vj->pvi", R, vertices) + poses[:, None, :3]


class FlatProxy:
    """Two 0.5 x 1.0 m rectangles side by side at 10 m: part 0 on the left, part 1 on the right.

    Through CAPTURE (80x48, f=200) at energy scale 0.5 (40x24, f=100, c=0.5) part 0 covers columns 11..15,
    part 1 columns 16..20, both rows 5..14 (corners fall on half pixels, so no ties)."""

    def __init__(self):
        xs, y0, y1 = [1.0, 1.5, 2.0], 0.4, 1.4
        self.vertices = np.array([[x, y, 10.0] for x in xs for y in (y0, y1)])  # 0,1 | 2,3 | 4,5
        self.faces = np.array([[0, 2, 3], [0, 3, 1], [2, 4, 5], [2, 5, 3]])
        self.face_part = np.array([0, 0, 1, 1])
        self.part_names = ["left", "right"]
        self.part_area_share = np.array([0.5, 0.5])

    def deform(self, body, poses, root_anchor=None):
        return body.deform(poses, self.vertices)


CAPTURE = Camera("cap", [[200, 0, 1.5], [0, 200, 1.5], [0, 0, 1]], [], np.eye(3), np.zeros(3), 80, 48)
COLOR_A, COLOR_B = (20.0, -30.0), (-50.0, 60.0)


def flat_features(shift_px=4):
    """Energy-resolution features: the template square moved `shift_px` to the right, its outline as edges,
    colour A left of column 16 and B from there on."""
    sil = np.zeros((24, 40), bool)
    sil[5:15, 11 + shift_px:21 + shift_px] = True
    edges = sil & ~np.pad(sil, 1)[2:, 1:-1] | sil & ~np.pad(sil, 1)[:-2, 1:-1] \
        | sil & ~np.pad(sil, 1)[1:-1, 2:] | sil & ~np.pad(sil, 1)[1:-1, :-2]
    ab = np.zeros((24, 40, 2), np.float32)
    ab[:, :16] = COLOR_A
    ab[:, 16:] = COLOR_B
    return ViewFeatures(sil, distance_to_mask(sil), edges, np.minimum(distance_to_mask(edges), 10.0), ab, 0.5)


def flat_model(weights, backend="numpy", **kw):
    model = lk.EnergyModel(FlatBody(), FlatProxy(), [CAPTURE], weights, scale=0.5, backend=backend, cull=0, **kw)
    model.set_frame([flat_features()])
    return model


ALL_IMAGE_TERMS = ["silh", "silh_ch", "edge", "edge_ch", "color"]


# ---------------------------------------------------------------------------------------- known answers
@pytest.mark.parametrize("backend", ["numpy", "fast"])
def test_flat_body_terms_have_the_hand_derived_values(backend):
    model = flat_model(lk.LikelihoodWeights(silh=1, silh_ch=1, edge=1, edge_ch=1, color=1), backend)
    assert model.reference_area.tolist() == [100]
    # Outline ring 36 px + the internal part boundary (columns 15 and 16, rows 6..13) 16 px.
    assert model.reference_boundary == 52
    model.init_color_model(np.zeros(6))
    t = model.terms(np.zeros(6))
    assert t["silh"][0] == pytest.approx(80 / 100)  # XOR of two 10x10 squares 4 px apart
    # (10 rows x (1+2+3+4)) / (2 x 100) twice = 1.0 energy px = 2.0 capture px.
    assert t["silh_ch"][0] == pytest.approx(2.0)
    # Template boundary on an observed edge: column 15 (10 px) + rows 5 and 14 at columns 16..20 (10 px).
    assert t["edge"][0] == pytest.approx((52 - 20) / 52)
    assert t["color"][0] == pytest.approx(0.0, abs=1e-12)  # the model is this frame at this pose
    # e^Ch against a brute-force distance to the observed outline.
    feat = flat_features()
    labels, _, boundary = model.render(np.zeros(6), 0)
    ey, ex = np.nonzero(feat.edges)
    by, bx = np.nonzero(boundary)
    d = np.sqrt(((by[:, None] - ey) ** 2 + (bx[:, None] - ex) ** 2).min(axis=1))
    assert t["edge_ch"][0] == pytest.approx(np.minimum(d, 10.0).sum() / 10.0 / 52)


@pytest.mark.parametrize("backend", ["numpy", "fast"])
def test_colour_term_is_zero_for_the_model_one_for_disjoint_colours_and_unseen_parts(backend):
    model = flat_model(lk.LikelihoodWeights(color=1), backend)
    model.init_color_model(np.zeros(6))
    assert model.color_count.tolist() == [50, 50]
    poses = np.zeros((3, 6))
    poses[1, 0] = 0.5  # 5 px right: the left part now shows colour B, the right part still B
    poses[2, 0] = 100.0  # out of view: every part has < 20 px
    v = model.terms(poses)["color"]
    assert v == pytest.approx([0.0, 0.5, 1.0])


def test_adaptation_follows_eq_12_with_sample_sizes():
    h = np.zeros((1, 2, 64))
    h[0, :, 3] = 1.0
    new = np.zeros((1, 2, 64))
    new[0, :, 7] = 1.0
    hist, count = lk.adapt_histograms(h, np.array([100.0]), new, np.array([50.0]), 0.2)
    # ((1-0.2) 100 h + 0.2 50 h_new) / (80 + 10)
    assert hist[0, 0, 3] == pytest.approx(80 / 90)
    assert hist[0, 0, 7] == pytest.approx(10 / 90)
    assert count[0] == pytest.approx(90)
    # A part unseen in both keeps its model; one unseen in the new frame keeps it too (M_hat = 0).
    hist, count = lk.adapt_histograms(h, np.array([0.0]), new, np.array([0.0]), 0.2)
    assert np.array_equal(hist, h)
    hist, count = lk.adapt_histograms(h, np.array([100.0]), new, np.array([0.0]), 0.5)
    assert np.array_equal(hist, h) and count[0] == 50


def test_adapt_color_model_moves_the_model_toward_the_estimate():
    model = flat_model(lk.LikelihoodWeights(color=1, adaptation=0.25))
    model.init_color_model(np.zeros(6))
    shifted = np.zeros(6)
    shifted[0] = 0.5  # left part sees colour B (50 px), right part B too
    model.adapt_color_model(shifted)
    bin_a, bin_b = lk.render.ab_to_bins(COLOR_A[0]), lk.render.ab_to_bins(COLOR_B[0])
    left = model.color_model[0, 0]
    assert left[bin_a] == pytest.approx(0.75 * 50 / (0.75 * 50 + 0.25 * 50))
    assert left[bin_b] == pytest.approx(0.25)
    assert model.color_count[0] == pytest.approx(50)


def test_features_at_capture_resolution_are_resampled_to_the_same_energy():
    small = flat_features()
    up = lambda a: np.kron(a, np.ones((2, 2), dtype=a.dtype))  # noqa: E731  exact 2x upsampling
    big_sil = up(small.silhouette)
    big = ViewFeatures(big_sil, distance_to_mask(big_sil), up(small.edges), distance_to_mask(up(small.edges)),
                       np.repeat(np.repeat(small.lab_ab, 2, 0), 2, 1), 1.0)
    w = lk.LikelihoodWeights(silh=1, silh_ch=1, edge=1, edge_ch=1, color=1)
    a, b = flat_model(w), flat_model(w)
    b.set_frame([big])
    a.init_color_model(np.zeros(6))
    b.init_color_model(np.zeros(6))
    poses = np.random.default_rng(0).normal(0, [0.2, 0.2, 0.5, 0.05, 0.05, 0.1], (5, 6))
    ta, tb = a.terms(poses), b.terms(poses)
    for name in ta:
        assert np.allclose(ta[name], tb[name]), name


def test_weighted_sum_and_batch_equal_single_calls():
    from markerless_mocap.core.energy.prior import AnatomicalPrior

    prior = AnatomicalPrior.fit(np.random.default_rng(1).normal(0, 0.3, (50, 6)), {"a": [0, 1, 2], "b": [3, 4, 5]})
    w = lk.LikelihoodWeights(silh=3, silh_ch=0.5, edge=2, edge_ch=1.5, color=7, anat=0.25)
    model = flat_model(w, "fast", prior=prior)
    model.init_color_model(np.zeros(6))
    poses = np.random.default_rng(2).normal(0, [0.2, 0.2, 0.5, 0.05, 0.05, 0.1], (7, 6))
    batch = model(poses)
    single = np.array([model(p[None])[0] for p in poses])
    assert np.array_equal(batch, single)
    t = model.terms(poses)
    assert batch == pytest.approx(sum(getattr(w, n) * v for n, v in t.items()))
    assert t["anat"] == pytest.approx(prior.energy(poses))


def test_named_likelihoods_and_clear_errors():
    assert lk.LIKELIHOODS["silh+edge"].active_terms() == ["silh", "edge", "anat"]
    assert lk.LIKELIHOODS["silhch+color"].adaptation == 0.2
    with pytest.raises(lk.LikelihoodError, match="silhch"):
        lk.resolve_weights("silhouette")
    model = lk.EnergyModel(FlatBody(), FlatProxy(), [CAPTURE], lk.LikelihoodWeights(silh=1, color=1), scale=0.5,
                           backend="numpy")
    with pytest.raises(lk.LikelihoodError, match="set_frame"):
        model(np.zeros(6))
    with pytest.raises(lk.LikelihoodError, match="one ViewFeatures per camera"):
        model.set_frame([flat_features(), flat_features()])
    model.set_frame([flat_features()])
    with pytest.raises(lk.LikelihoodError, match="init_color_model"):
        model(np.zeros(6))
    with pytest.raises(lk.LikelihoodError, match="DOF"):
        model.terms(np.zeros(5), ["silh"])
    model.set_reference_pose(np.array([50.0, 0, 0, 0, 0, 0]))
    with pytest.raises(lk.LikelihoodError, match="not visible"):
        model.terms(np.zeros(6), ["silh"])
    with pytest.warns(RuntimeWarning, match="prior"):
        lk.EnergyModel(FlatBody(), FlatProxy(), [CAPTURE], "silh", scale=0.5, backend="numpy")


# ---------------------------------------------------------------------------------------- real body
def test_fast_and_reference_energies_agree_on_the_body(bpy_module):
    from rig_helpers import load_subject, subject_blend_path

    if not subject_blend_path().is_file():
        pytest.skip(f"no sample subject at {subject_blend_path()} (set MOCAP_TEST_SUBJECT)")

    from markerless_mocap.addon.scene_bridge import body_from_blender
    from markerless_mocap.core.body.proxy import make_proxy

    arm, mesh = load_subject(bpy_module)
    body = body_from_blender(arm, mesh)
    proxy = make_proxy(body, 2000)
    x0 = body.default_pose()
    cams = [look_at(f"c{i}", x0[:3] + [3.5 * np.cos(a), 3.5 * np.sin(a), 0.3], x0[:3], 550, 640, 480)
            for i, a in enumerate(np.deg2rad([20, 110, 200, 290]))]
    rng = np.random.default_rng(5)
    lo = np.where(np.isfinite(body.lower), body.lower, -0.3)
    hi = np.where(np.isfinite(body.upper), body.upper, 0.3)
    observed = x0.copy()
    observed[6:] = rng.uniform(lo[6:], hi[6:]) * 0.3
    w = lk.LikelihoodWeights(silh=1, silh_ch=1, edge=1, edge_ch=1, color=1)
    models = {b: lk.EnergyModel(body, proxy, cams, w, backend=b) for b in ("numpy", "fast")}
    ref = models["numpy"]
    assert ref.cull == models["fast"].cull
    feats = []
    for v in range(len(cams)):
        labels, sil, boundary = ref.render(observed, v)
        ab = np.stack([labels * 9.0 - 60, 40 - labels * 7.0], axis=-1).astype(np.float32)
        feats.append(ViewFeatures(sil, distance_to_mask(sil), boundary, np.minimum(distance_to_mask(boundary), 10),
                                  ab, 0.5))
    for m in models.values():
        m.set_frame(feats)
        m.init_color_model(observed)
    poses = np.tile(observed, (4, 1))
    poses[1:, 6:] += rng.normal(0, 0.15, (3, body.n_dof - 6))
    poses[1:, :3] += rng.normal(0, 0.03, (3, 3))
    t_ref, t_fast = ref.terms(poses), models["fast"].terms(poses)
    for name in t_ref:
        assert np.allclose(t_fast[name], t_ref[name], rtol=0.01, atol=1e-9), name
    # At the observed pose the template reproduces the observation: every term at its minimum.
    assert t_ref["silh"][0] == 0 and t_ref["silh_ch"][0] == 0 and t_ref["edge"][0] == 0
    assert t_ref["color"][0] == pytest.approx(0, abs=1e-9)
    assert np.all(t_ref["silh"][1:] > 0.02)


def test_every_named_likelihood_is_offered_in_the_panel_and_on_the_command_line():
    pytest.importorskip("bpy")
    from markerless_mocap.addon.properties import LIKELIHOODS as PANEL
    from markerless_mocap.operators.cmd_track import LIKELIHOOD_NAMES

    assert sorted(item[0] for item in PANEL) == sorted(lk.LIKELIHOODS) == sorted(LIKELIHOOD_NAMES)
