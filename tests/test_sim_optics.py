"""The simulator's camera optics and sensor: lens blur, vignetting, motion blur, gain, signal-dependent noise."""

import copy
import dataclasses

import numpy as np
import pytest
import yaml

from stablemarks.errors import ConfigError
from stablemarks.sim import Renderer, builtin_scenarios, load_scenario, parse_scenario, simulate_run
from stablemarks.sim.render import blur_kernels, expose, vignetting_map
from stablemarks.sim.scenario import SCENARIO_DIR, Lighting, Optics

NO_OPTICS = Optics.ideal()


@pytest.fixture(scope="module")
def lab():
    return load_scenario("lab")


def quiet(scenario, **optics):
    """``scenario`` with only the given optics, no sensor noise and no exposure jitter."""
    return dataclasses.replace(scenario, optics=dataclasses.replace(NO_OPTICS, **optics), image_noise=0.0,
                               lighting=dataclasses.replace(scenario.lighting, exposure_sigma=0.0))


def step_image(shape=(60, 80), column=40, lo=50.0, hi=200.0, axis=1):
    """A float32 image whose brightness steps from ``lo`` to ``hi`` between pixel ``column - 1`` and ``column``."""
    image = np.full(shape, lo, dtype=np.float32)
    if axis == 1:
        image[:, column:] = hi
    else:
        image[column:, :] = hi
    return image


def profile_moments(image, axis=1):
    """Centroid and variance [px] of the mean derivative profile of a step image across ``axis``."""
    d = np.diff(image.astype(float), axis=axis).mean(axis=1 - axis)
    j = np.arange(len(d)) + 0.5  # the difference between pixels j and j + 1 sits at j + 0.5
    mean = (j * d).sum() / d.sum()
    return mean, ((j - mean) ** 2 * d).sum() / d.sum()


def test_every_scenario_gets_the_realistic_defaults():
    d = Optics()
    assert 0.4 <= d.blur_sigma <= 0.7 and 0.2 <= d.vignetting <= 0.3
    assert d.motion_blur > 0 and d.gain_sigma > 0 and d.shot_noise > 0
    for name in builtin_scenarios():
        assert load_scenario(name).optics == d, name


def test_zero_optics_reproduce_the_ideal_renderer_exactly(lab):
    sc = dataclasses.replace(lab, optics=NO_OPTICS)
    run = simulate_run(sc)
    renderer = Renderer(sc)
    k = 7
    X, pan = run.poses[k].as_array(), run.pans[k]
    frame = renderer.render(X, pan, run.frame_rng(k))
    # The renderer before the optics: exposure gain, then constant Gaussian noise, left then right.
    rng = run.frame_rng(k)
    left, right = renderer.render_clean(X, pan)
    gain = float(np.exp(rng.normal(0.0, sc.lighting.exposure_sigma)))
    old = [np.clip(np.rint(c * gain + rng.normal(0.0, sc.image_noise, c.shape)), 0, 255).astype(np.uint8)
           for c in (left, right)]
    np.testing.assert_array_equal(frame.left, old[0])
    np.testing.assert_array_equal(frame.right, old[1])
    assert frame.truth.exposure == gain and frame.truth.gain == 1.0 and frame.truth.motion_blur == 0.0


@pytest.mark.parametrize("sigma", [0.5, 1.0, 1.5])
def test_lens_blur_widens_an_edge_by_its_sigma(lab, sigma):
    sc = quiet(lab, blur_sigma=sigma)
    (out,), drawn = expose((step_image(),), sc, np.random.default_rng(0))
    assert drawn == type(drawn)(1.0, 1.0, 0.0)
    centre, var = profile_moments(out)
    assert centre == pytest.approx(39.5, abs=0.02)  # the edge stays where it was
    # The edge's profile is the point spread function: its variance is σ² (the sampled kernel's for small σ).
    kernel = blur_kernels(sigma, 0.0)[0].astype(float)
    j = np.arange(len(kernel)) - len(kernel) // 2
    assert var == pytest.approx((kernel * j**2).sum(), rel=0.05)  # (8-bit rounding adds a little)
    assert var == pytest.approx(sigma**2, rel=0.15 if sigma < 1 else 0.05)
    # Vertically the same.
    (out_v,), _ = expose((step_image(axis=0, column=30),), sc, np.random.default_rng(0))
    assert profile_moments(out_v, axis=0)[1] == pytest.approx(var, rel=1e-6)


def test_motion_blur_is_horizontal_drawn_per_frame_and_unbiased(lab):
    sc = quiet(lab, motion_blur=4.0)
    lengths = []
    for seed in range(6):
        (h, v), drawn = expose((step_image(), step_image(axis=0, column=30)), sc, np.random.default_rng(seed))
        lengths.append(drawn.motion_blur)
        assert 0.0 <= drawn.motion_blur <= 4.0
        centre, var = profile_moments(h)
        assert centre == pytest.approx(39.5, abs=0.02)
        kernel = blur_kernels(0.0, drawn.motion_blur)[0].astype(float)
        j = np.arange(len(kernel)) - len(kernel) // 2
        assert var == pytest.approx((kernel * j**2).sum(), rel=0.05, abs=0.01)
        # A box of length L has variance L²/12, plus up to about 1/6 px² of reading the pixels as a linear ramp.
        assert drawn.motion_blur**2 / 12 - 0.02 <= var <= drawn.motion_blur**2 / 12 + 0.25
        # A horizontal edge is not smeared at all.
        assert profile_moments(v, axis=0)[1] == pytest.approx(0.0, abs=1e-9)
    assert len(set(lengths)) == 6 and max(lengths) > 1.0


def test_vignetting_darkens_the_corners_by_the_configured_fraction(lab):
    sc = quiet(lab, vignetting=0.25)
    cam = sc.camera
    flat = np.full((cam.height, cam.width), 200.0, dtype=np.float32)
    (out,), _ = expose((flat,), sc, np.random.default_rng(0))
    out = out.astype(float)
    centre = out[int(cam.cv), int(cam.cu)]
    assert centre == 200
    for corner in (out[0, 0], out[0, -1], out[-1, 0], out[-1, -1]):
        assert corner / centre == pytest.approx(0.75, abs=0.5 / 200 + 1e-9)
    # Radial and monotonic: along the diagonal from the centre to a corner the light only falls.
    v = vignetting_map((cam.height, cam.width), cam.cu, cam.cv, 0.25)
    diag = v[np.linspace(cam.cv, 0, 50).astype(int), np.linspace(cam.cu, 0, 50).astype(int)]
    assert np.all(np.diff(diag) <= 1e-7) and v.max() == pytest.approx(1.0, abs=1e-5)
    # cos⁴-like: halfway to the corner it keeps much more than half of the loss.
    mid = v[int(cam.cv / 2), int(cam.cu / 2)]
    assert 0.9 < mid < 0.96


def test_noise_variance_grows_with_intensity(lab):
    sc = dataclasses.replace(quiet(lab, shot_noise=3.0), image_noise=1.0)
    levels = (20.0, 100.0, 220.0)
    images = tuple(np.full((240, 320), level, dtype=np.float32) for level in levels)
    out, _ = expose(images, sc, np.random.default_rng(3))
    measured = [o.astype(float).var() for o in out]
    for level, var in zip(levels, measured, strict=True):
        expected = 1.0 + 9.0 * level / 255 + 1 / 12  # read² + shot²·I/255 + rounding to integers
        assert var == pytest.approx(expected, rel=0.05), level
    assert measured[0] < measured[1] < measured[2]
    # Without shot noise it is the same everywhere.
    out, _ = expose(images, dataclasses.replace(sc, optics=NO_OPTICS), np.random.default_rng(3))
    flat = [o.astype(float).var() for o in out]
    assert max(flat) / min(flat) < 1.1


def test_exposure_and_gain_scale_both_images_of_a_frame_alike(lab):
    sc = dataclasses.replace(quiet(lab, gain_sigma=0.1),
                             lighting=dataclasses.replace(lab.lighting, exposure_sigma=0.05))
    flat = (np.full((100, 100), 100.0, dtype=np.float32), np.full((100, 100), 150.0, dtype=np.float32))
    gains = []
    for seed in range(8):
        (left, right), drawn = expose(flat, sc, np.random.default_rng(seed))
        factor = drawn.exposure * drawn.gain
        gains.append(drawn.gain)
        assert left.mean() == pytest.approx(100 * factor, abs=0.5)
        assert right.mean() == pytest.approx(150 * factor, abs=0.5)
    assert np.std(np.log(gains)) > 0.03 and len(set(gains)) == 8


def test_gain_amplifies_the_noise_too(lab):
    sc = dataclasses.replace(quiet(lab, gain_sigma=0.5), image_noise=3.0)
    flat = (np.full((200, 200), 60.0, dtype=np.float32),)
    for seed in range(4):
        (out,), drawn = expose(flat, sc, np.random.default_rng(seed))
        assert out.astype(float).std() == pytest.approx(3.0 * drawn.gain, rel=0.06)


def test_rendering_with_optics_is_deterministic_per_seed(lab):
    run = simulate_run(lab)
    renderer = Renderer(lab)
    a, b = run.render(4, renderer), run.render(4, Renderer(lab))
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.right, b.right)
    assert (a.truth.exposure, a.truth.gain, a.truth.motion_blur) == (b.truth.exposure, b.truth.gain,
                                                                     b.truth.motion_blur)
    other = simulate_run(lab, lab.seed + 1).render(4, renderer)
    assert not np.array_equal(a.left, other.left)
    assert a.truth.to_dict()["gain"] == a.truth.gain and "motion_blur" in a.truth.to_dict()


def test_default_optics_keep_the_images_close_to_the_ideal_ones(lab):
    """The optics change the look of a frame a little, not its content: same world, same edges."""
    run = simulate_run(lab)
    k = 10
    real = run.render(k, Renderer(lab))
    ideal = run.render(k, Renderer(dataclasses.replace(lab, optics=NO_OPTICS)))
    diff = real.left.astype(float) - ideal.left.astype(float)
    assert abs(np.median(diff)) < 20 and np.percentile(np.abs(diff), 50) < 15
    assert real.truth.edges == ideal.truth.edges


@pytest.fixture(scope="module")
def lab_data():
    return yaml.safe_load((SCENARIO_DIR / "lab.yaml").read_text())


@pytest.mark.parametrize("key, value, message", [
    ("blur_sigma", -1, "lab.yaml: optics.blur_sigma: expected a non-negative number, got -1"),
    ("vignetting", 0.95, "lab.yaml: optics.vignetting: expected a number in [0, 0.9], got 0.95"),
    ("motion_blur", "a lot", "lab.yaml: optics.motion_blur: expected a non-negative number, got 'a lot'"),
    ("gain_sigma", True, "lab.yaml: optics.gain_sigma: expected a non-negative number, got True"),
    ("shot_noise", -0.5, "lab.yaml: optics.shot_noise: expected a non-negative number, got -0.5"),
    ("flare", 1.0, "lab.yaml: optics.flare: unknown field (known: blur_sigma, vignetting, motion_blur, "
                   "gain_sigma, shot_noise)"),
])
def test_optics_fields_are_validated(lab_data, key, value, message):
    data = copy.deepcopy(lab_data)
    data["optics"] = {key: value}
    with pytest.raises(ConfigError) as err:
        parse_scenario(data, "lab.yaml")
    assert str(err.value) == message


def test_optics_section_is_read(lab_data):
    data = copy.deepcopy(lab_data)
    data["optics"] = {"blur_sigma": 0.7, "vignetting": 0.3}
    sc = parse_scenario(data, "lab.yaml")
    assert sc.optics == Optics(blur_sigma=0.7, vignetting=0.3)
    data["optics"] = {k: 0 for k in ("blur_sigma", "vignetting", "motion_blur", "gain_sigma", "shot_noise")}
    assert parse_scenario(data, "lab.yaml").optics == NO_OPTICS
    assert isinstance(sc.lighting, Lighting)
    with pytest.raises(ConfigError, match=r"^lab\.yaml: optics: expected a mapping, got 3$"):
        parse_scenario({**lab_data, "optics": 3}, "lab.yaml")
