"""Tests for jaxgfx.hdr.raw_calibration on synthetic Poisson-Gaussian Bayer brackets."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxgfx.hdr.raw_calibration import (
    calibrate_raw_stack,
    cfa_channel_names,
    cfa_channels,
    estimate_black_level,
    estimate_exposure_ratios,
    estimate_white_level,
    linearity_check,
    pairwise_exposure_ratio,
)

H = W = 64
BLACK, WHITE = 512.0, 16383.0
DN_PER_E, READ_DN = 0.25, 3.0
NOMINAL = np.array([1 / 100, 1 / 50, 1 / 25, 1 / 12.5])
ACTUAL = NOMINAL * np.array([1.0, 1.03, 0.97, 1.05])
SENS = np.tile(np.array([[0.6, 1.0], [1.0, 0.45]]), (H // 2, W // 2))


def _scene(seed=0):
    rng = np.random.default_rng(seed)
    return np.exp(rng.uniform(np.log(0.01), 0.0, size=(H, W)))


def _shoot(rng, radiance, t, *, peak=2.5, gamma=1.0):
    """One raw Bayer frame in DN: Poisson electrons, Gaussian read noise, rounding, clipping."""
    mean_e = (radiance * SENS * t / NOMINAL[-1] * peak) ** gamma * (WHITE - BLACK) / DN_PER_E
    dn = BLACK + rng.poisson(mean_e) * DN_PER_E + READ_DN * rng.standard_normal((H, W))
    return np.clip(np.round(dn), 0, WHITE)


def _stack(seed=0, times=ACTUAL, **kw):
    rng = np.random.default_rng(1000 + seed)
    e = _scene(seed)
    return np.stack([_shoot(rng, e, t, **kw) for t in times]).astype(np.float32)


@pytest.fixture(scope="module")
def bracket():
    return _stack(0)


def test_cfa_channels_indexing():
    m = jnp.arange(16.0).reshape(4, 4)
    planes = cfa_channels(m, "RGGB")
    np.testing.assert_array_equal(planes[0, 0], [0, 1, 4, 5])
    np.testing.assert_array_equal(planes[..., 3], np.arange(16.0).reshape(4, 4)[1::2, 1::2])
    assert cfa_channel_names("RGGB") == ("R", "G1", "G2", "B")
    assert cfa_channel_names("GBRG") == ("G1", "B", "R", "G2")
    with pytest.raises(ValueError, match="mosaic"):
        cfa_channels(jnp.ones((3, 4)))
    with pytest.raises(ValueError, match="cfa_pattern"):
        cfa_channels(jnp.ones((4, 4)), "RGBW")


# issue 9: ~3 s of a loaded 2-core default run; the white-level and bad-input tests stay in the
# default run
@pytest.mark.slow
def test_black_level_robust_to_hot_pixels():
    rng = np.random.default_rng(7)
    sigma = 3.0
    offsets = np.array([512.0, 511.0, 513.0, 512.5])
    dark = np.tile(offsets.reshape(2, 2), (32, 32))[None] + sigma * rng.standard_normal((4, 64, 64))
    hot = rng.random(dark.shape) < 0.01
    dark = np.where(hot, 4000.0, dark)  # 1 % hot pixels
    est = jax.jit(lambda d: estimate_black_level(d, per_channel_pattern="RGGB"))(dark)
    n = dark.size / 4 * 0.99
    np.testing.assert_allclose(est.se, sigma / np.sqrt(n), rtol=0.1)  # closed form s.e.
    assert np.all(np.abs(np.asarray(est.value) - offsets) < 4 * np.asarray(est.se))
    assert np.all(np.abs(cfa_channels(dark).reshape(-1, 4).mean(0) - offsets) > 10)  # plain mean
    pooled = estimate_black_level(dark[:, :2, :2].ravel()[:3].repeat(2), per_channel_pattern=None)
    assert pooled.value.shape == ()
    with pytest.raises(ValueError, match="dark_frames_or_masked_pixels"):
        estimate_black_level(np.ones((3, 5)))
    with pytest.raises(ValueError, match="n_sigma"):
        estimate_black_level(dark, n_sigma=0)


def test_white_level_pileup_and_unsaturated(bracket):
    wl = jax.jit(lambda s: estimate_white_level(s, per_channel_pattern="RGGB"))(bracket)
    assert np.all(np.asarray(wl.saturated))
    np.testing.assert_array_equal(wl.value, WHITE)  # median of the pile: the clip code
    assert np.all(np.asarray(wl.se) < 1.0)  # DN
    assert np.all(np.asarray(wl.fraction) > 0.001)
    # soft clipping: noise on top of the clip level
    rng = np.random.default_rng(3)
    soft = np.where(
        bracket >= WHITE - 40, WHITE - 40 + 2.0 * rng.standard_normal(bracket.shape), bracket
    )
    ws = estimate_white_level(soft, tolerance=12.0)
    assert bool(ws.saturated[0])
    assert abs(float(ws.value[0]) - (WHITE - 40)) < 4 * float(ws.se[0])
    # a stack that never saturates: reported as such, value is the maximum (a lower bound)
    dim = _stack(0, peak=0.8)
    wd = estimate_white_level(dim, per_channel_pattern="RGGB")
    assert not np.any(np.asarray(wd.saturated))
    np.testing.assert_array_equal(wd.value, cfa_channels(dim).max(axis=(0, 1, 2)))
    assert np.all(np.isnan(np.asarray(wd.se)))
    assert json.dumps(wd.to_dict())


def _np_means(stack, black, white, sat=0.95, lo=0.02):
    y = (np.asarray(cfa_channels(stack)) - black) / (white - black)
    v = np.all((y > lo) & (y < sat), axis=0)
    return np.stack([[y[k][..., c][v[..., c]].mean() for c in range(4)] for k in range(len(y))])


def test_linearity_matches_polyfit_and_detects_nonlinearity(bracket):
    f = jax.jit(lambda s, t: linearity_check(s, t, black=BLACK, white=WHITE, cfa_pattern="RGGB"))
    lin = f(bracket, ACTUAL)
    means = _np_means(bracket, BLACK, WHITE)
    np.testing.assert_allclose(lin.means, means, rtol=1e-5)
    for c in range(4):
        p, cov = np.polyfit(ACTUAL, means[:, c], 1, cov=True)
        np.testing.assert_allclose(lin.slope[c], p[0], rtol=1e-4)
        np.testing.assert_allclose(lin.intercept[c], p[1], atol=1e-5)
        np.testing.assert_allclose(lin.slope_se[c], np.sqrt(cov[0, 0]), rtol=1e-3)
        np.testing.assert_allclose(lin.intercept_se[c], np.sqrt(cov[1, 1]), rtol=1e-3)
    assert np.all(np.asarray(lin.is_linear))
    assert np.all(np.asarray(lin.r2) > 0.9999)
    # nominal EXIF times are off by up to 5 %: the check flags it
    assert not np.any(np.asarray(f(bracket, NOMINAL).is_linear))
    # a compressive sensor (signal^0.9) is not linear; deviation as computed by NumPy
    bent = _stack(0, gamma=0.9)
    lb = f(bent, ACTUAL)
    mb = _np_means(bent, BLACK, WHITE)
    fit = np.array([np.polyval(np.polyfit(ACTUAL, mb[:, c], 1), ACTUAL) for c in range(4)]).T
    np.testing.assert_allclose(lb.max_rel_deviation, np.abs(mb / fit - 1).max(0), rtol=1e-3)
    assert not np.any(np.asarray(lb.is_linear))
    assert "criterion" in lb.to_dict()


# issue 9: ~5 s of a loaded 2-core default run; the no-usable-pixels and bad-input tests stay in
# the default run
@pytest.mark.slow
def test_exposure_ratios_recover_actual_times(bracket):
    f = jax.jit(
        lambda s, t: estimate_exposure_ratios(s, t, black=BLACK, white=WHITE, cfa_pattern="RGGB")
    )
    er = f(bracket, NOMINAL)
    true = ACTUAL / ACTUAL[0]
    assert np.all(np.abs(np.asarray(er.ratios) - true)[1:] < 4 * np.asarray(er.se)[1:])
    np.testing.assert_allclose(er.nominal, NOMINAL / NOMINAL[0], rtol=1e-6)
    dev = np.log2(true / (NOMINAL / NOMINAL[0]))
    assert np.all(np.abs(np.asarray(er.deviation_stops) - dev)[1:] < 4 * er.deviation_se_stops[1:])
    # frame order does not matter; reference="longest" divides by the longest frame
    perm = np.array([2, 0, 3, 1])
    ep = f(bracket[perm], NOMINAL[perm])
    np.testing.assert_allclose(ep.ratios, er.ratios[perm] / er.ratios[2], rtol=1e-5)
    el = estimate_exposure_ratios(
        bracket, NOMINAL, black=BLACK, white=WHITE, cfa_pattern="RGGB", reference="longest"
    )
    np.testing.assert_allclose(el.ratios, er.ratios / er.ratios[-1], rtol=1e-5)
    assert json.dumps(er.to_dict())


def test_pairwise_ratio_standard_error_is_calibrated():
    e = _scene(1)
    rng = np.random.default_rng(5)
    f = jax.jit(lambda a, b: pairwise_exposure_ratio(a, b, black=BLACK, white=WHITE))
    r, se = [], []
    for _ in range(10):
        a = _shoot(rng, e, ACTUAL[1])
        b = _shoot(rng, e, ACTUAL[2])
        ri, si, _ = f(cfa_channels(a), cfa_channels(b))
        r.append(float(ri))
        se.append(float(si))
    r, se = np.array(r), np.array(se)
    true = ACTUAL[2] / ACTUAL[1]
    assert np.all(np.abs(r - true) < 4 * se)
    assert 1 / 1.5 < r.std(ddof=1) / se.mean() < 1.5


def test_pairwise_ratio_robust_to_moving_object():
    e = _scene(2)
    rng = np.random.default_rng(6)
    a = _shoot(rng, e, ACTUAL[1])
    b = _shoot(rng, e, ACTUAL[2])
    b[:16, :16] = np.clip(b[:16, :16] * 0.4, BLACK + 400, None)  # object moved into view
    rob, se, _ = pairwise_exposure_ratio(a, b, black=BLACK, white=WHITE)
    plain, _, _ = pairwise_exposure_ratio(a, b, black=BLACK, white=WHITE, robust=None)
    true = ACTUAL[2] / ACTUAL[1]
    assert abs(float(rob) - true) < 0.01 * true
    assert abs(float(plain) - true) > 0.03 * true


# issue 9: ~5 s of a loaded 2-core default run; float64 FD check of the pairwise ratio fit
@pytest.mark.slow
def test_pairwise_ratio_gradient(x64):
    rng = np.random.default_rng(0)
    a = jnp.asarray(rng.uniform(2000.0, 6000.0, (8, 8)))
    b = 1.9 * (a - BLACK) + BLACK + jnp.asarray(rng.normal(0, 30.0, (8, 8)))

    def f(a, b, black):
        return pairwise_exposure_ratio(a, b, black=black, white=WHITE)[0]

    check_grads(jax.jit(f), (a, b, jnp.asarray(BLACK)), order=1, modes=["rev"], eps=1e-2)
    assert float(f(a, b, BLACK)) == pytest.approx(1.9, rel=0.01)


@pytest.mark.slow  # issue 9: ~7 s of a loaded 2-core run; out of make test
def test_calibrate_raw_stack_report(bracket):
    rng = np.random.default_rng(11)
    e = _scene(0)
    pairs = np.stack([_shoot(rng, e, ACTUAL[2]), _shoot(rng, e, ACTUAL[2])])
    cal = calibrate_raw_stack(bracket, NOMINAL, noise_pairs=pairs)
    assert cal.black_method == "affine_pairs"
    assert np.all(np.abs(np.asarray(cal.black.value) - BLACK) < 4 * np.asarray(cal.black.se))
    np.testing.assert_array_equal(cal.white.value, WHITE)
    gain = DN_PER_E / (WHITE - BLACK)
    g = np.asarray(cal.noise.gain)
    assert np.all(np.abs(g - gain) < 4 * np.asarray(cal.noise_se["gain_se"]))
    d = json.loads(json.dumps(cal.to_dict()))
    assert d["channels"] == ["R", "G1", "G2", "B"]
    assert d["exposure_ratios"]["nominal"] == pytest.approx([1.0, 2.0, 4.0, 8.0])
    assert d["linearity"]["is_linear"] == [False] * 4  # nominal times are off by up to 5 %
    # given levels are used as is
    cal2 = calibrate_raw_stack(bracket[:2], NOMINAL[:2], black=BLACK, white=WHITE)
    assert cal2.linearity is None and cal2.black_method == "given"


# 5.4 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_bad_inputs(bracket):
    kw = dict(black=BLACK, white=WHITE, cfa_pattern="RGGB")
    with pytest.raises(ValueError, match="nominal_times"):
        estimate_exposure_ratios(bracket, -NOMINAL, **kw)
    with pytest.raises(ValueError, match="nominal_times"):
        estimate_exposure_ratios(bracket, NOMINAL[:3], **kw)
    with pytest.raises(ValueError, match="stack"):
        estimate_exposure_ratios(bracket[:1], NOMINAL[:1], **kw)
    with pytest.raises(ValueError, match="reference"):
        estimate_exposure_ratios(bracket, NOMINAL, reference="middle", **kw)
    with pytest.raises(ValueError, match="stack"):
        linearity_check(bracket[:2], NOMINAL[:2], **kw)
    with pytest.raises(ValueError, match="white"):
        linearity_check(bracket, NOMINAL, black=BLACK, white=100.0, cfa_pattern="RGGB")
    with pytest.raises(ValueError, match="b: expected"):
        pairwise_exposure_ratio(bracket[0], bracket[1, :8], black=BLACK, white=WHITE)
    with pytest.raises(ValueError, match="cfa_pattern"):
        calibrate_raw_stack(bracket, NOMINAL, cfa_pattern="XYZW")
    with pytest.raises(ValueError, match="exposure_times"):
        calibrate_raw_stack(bracket, np.zeros(4))
    with pytest.raises(ValueError, match="noise_pairs"):
        calibrate_raw_stack(bracket, NOMINAL, noise_pairs=bracket[:3, None])


# 6.2 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_no_usable_pixels_reported_not_hidden():
    sat = np.full((16, 16), WHITE, np.float32)
    r, se, n = pairwise_exposure_ratio(sat, sat, black=BLACK, white=WHITE)
    assert int(n) == 0 and np.isnan(float(r)) and np.isnan(float(se))
    g = jax.grad(lambda a: pairwise_exposure_ratio(a, sat, black=BLACK, white=WHITE)[0])(sat)
    assert np.all(np.isfinite(g))
    er = estimate_exposure_ratios(
        np.stack([sat * 0.25, sat * 0.5, sat]), [1.0, 2.0, 4.0], black=0.0, white=WHITE
    )
    assert float(er.ratios[1]) == pytest.approx(2.0)  # first pair is fine
    assert np.isnan(float(er.ratios[2]))  # chained through the saturated pair
    lin = linearity_check(np.stack([sat] * 3), [1.0, 2.0, 4.0], black=BLACK, white=WHITE)
    assert int(lin.n_pixels[0]) == 0 and not bool(lin.is_linear[0])
