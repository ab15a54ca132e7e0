import cv2
import numpy as np
import pytest

from stablemarks.sim import Renderer, frame_truth, load_scenario, render_stereo, simulate_run
from stablemarks.sim.render import _footprint_mean, renderer_for
from stablemarks.sim.scenario import Feature


def edge_column(image, u, v_top, v_bottom, polarity, search=3):
    """Sub-pixel column of the strongest horizontal-derivative response of the given polarity near ``u``.

    Sobel-x over the middle 60 % of the edge's rows, averaged over those rows, parabola through the peak.
    """
    H, W = image.shape
    r0 = max(0, int(np.ceil(v_top + 0.2 * (v_bottom - v_top))))
    r1 = min(H - 1, int(np.floor(v_bottom - 0.2 * (v_bottom - v_top))))
    g = cv2.Sobel(image[r0:r1 + 1].astype(np.float64), cv2.CV_64F, 1, 0, ksize=3).mean(axis=0)
    g = g * (polarity if polarity else 1)
    c = int(round(u))
    lo, hi = max(1, c - search), min(W - 2, c + search)
    window = np.abs(g[lo:hi + 1]) if polarity == 0 else g[lo:hi + 1]
    i = lo + int(np.argmax(window))
    a, b, d = abs(g[i - 1]), abs(g[i]), abs(g[i + 1])
    den = a - 2 * b + d
    return i + (0.5 * (a - d) / den if den else 0.0), float(b)


@pytest.fixture(scope="module")
def lab():
    return load_scenario("lab")


@pytest.fixture(scope="module")
def lab_run(lab):
    return simulate_run(lab)


@pytest.fixture(scope="module")
def lab_frames(lab_run):
    return {k: lab_run.render(k) for k in (0, 20)}


def test_images_are_uint8_pairs(lab, lab_frames):
    frame = lab_frames[0]
    for img in (frame.left, frame.right):
        assert img.dtype == np.uint8 and img.shape == (lab.camera.height, lab.camera.width)
        assert 20 < img.mean() < 220 and img.std() > 10
    assert not np.array_equal(frame.left, frame.right)


def test_rendering_is_deterministic_per_seed(lab, lab_run):
    X, pan = lab_run.poses[3].as_array(), lab_run.pans[3]
    a = render_stereo(lab, X, pan, np.random.default_rng(7))
    b = render_stereo(lab, X, pan, np.random.default_rng(7))
    c = render_stereo(lab, X, pan, np.random.default_rng(8))
    assert np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right)
    assert not np.array_equal(a.left, c.left)
    # Only the noise differs between seeds: the world (textures) is the same.
    diff = a.left.astype(float) - c.left.astype(float)
    assert np.abs(diff.mean()) < 15 and diff.std() < 10


def test_a_fresh_renderer_draws_the_same_world(lab, lab_run):
    X, pan = lab_run.poses[5].as_array(), lab_run.pans[5]
    one = Renderer(lab).render_clean(X, pan)
    two = Renderer(lab).render_clean(X, pan)
    np.testing.assert_array_equal(one[0], two[0])


def test_run_frames_do_not_depend_on_which_frames_are_rendered(lab, lab_run, lab_frames):
    again = simulate_run(lab, lab_run.seed)
    assert again.poses == lab_run.poses and again.odometry == lab_run.odometry and again.pans == lab_run.pans
    np.testing.assert_array_equal(again.render(20).left, lab_frames[20].left)
    other = simulate_run(lab, lab_run.seed + 1)
    assert other.odometry != lab_run.odometry


@pytest.mark.parametrize("k", [0, 20])
def test_true_columns_match_the_edges_in_the_images(lab_frames, k):
    frame = lab_frames[k]
    checked = 0
    for e in frame.truth.edges:
        if e.id.endswith("-p2"):  # the far ends are free edges too, but not among Table 1's features
            continue
        for image, u, visible in ((frame.left, e.u_l, e.visible_l), (frame.right, e.u_r, e.visible_r)):
            if not visible:
                continue
            found, strength = edge_column(image, u, e.v_top, e.v_bottom, e.polarity)
            assert abs(found - u) < 1.0, (e.id, u, found)
            assert strength > 20, e.id  # a real edge, not noise
            checked += 1
    assert checked >= 2 * 14  # all of Table 1 in both images


def test_edges_are_sub_pixel_exact_in_noise_free_images(lab, lab_run):
    k = 10
    renderer = renderer_for(lab)
    left, right = renderer.render_clean(lab_run.poses[k].as_array(), lab_run.pans[k])
    truth = lab_run.render(k, renderer).truth
    errors = []
    for e in truth.edges:
        if e.wall in ("partition", "whiteboard") and e.visible_l and e.visible_r and not e.id.endswith("-p2"):
            for image, u in ((left, e.u_l), (right, e.u_r)):
                errors.append(edge_column(image, u, e.v_top, e.v_bottom, e.polarity)[0] - u)
    errors = np.abs(errors)
    assert len(errors) == 28
    assert errors.max() < 0.25 and np.median(errors) < 0.1


def test_lab_run_keeps_the_features_in_view(lab, lab_run):
    # Paper Sec 6: at 1 m and 2 m the robot still observes every landmark of the two planes.
    world = renderer_for(lab).world
    for k in (0, 10, 20):
        truth = frame_truth(world, lab.camera.with_pan(lab_run.pans[k]), lab_run.poses[k])
        for e in truth.edges:
            if e.wall in ("partition", "whiteboard") and not e.id.endswith("-p2"):
                assert e.visible_l and e.visible_r, (k, e.id)


@pytest.mark.parametrize("kind, extra", [("edge", {"fade": 0.1}), ("bar", {"width": 0.05})])
def test_feature_footprint_means_integrate_the_profile(kind, extra):
    feat = Feature("f", "w", 1.0, (0.0, 1.0), kind, 10.0, **extra)
    edges = np.linspace(0.9, 1.2, 3001)
    centres = 0.5 * (edges[:-1] + edges[1:])
    fine = _footprint_mean(feat, edges[:-1], edges[1:])
    # Averages over wide footprints equal the mean of the fine samples within them.
    lo, hi = edges[::100][:-1], edges[::100][1:]
    coarse = _footprint_mean(feat, lo, hi)
    np.testing.assert_allclose(coarse, fine.reshape(-1, 100).mean(axis=1), atol=1e-9)
    # A footprint left of the step sees nothing, one just right of it the full step.
    assert fine[centres < 0.999].max() == 0.0
    assert fine[np.searchsorted(centres, 1.0005)] == pytest.approx(1.0, abs=1e-3)
