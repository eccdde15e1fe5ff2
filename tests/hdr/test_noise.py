"""Tests for jaxgfx.hdr.noise: Poisson-Gaussian model and photon transfer fit."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxgfx.hdr.noise import NoiseModel, fit_photon_transfer

FULL_WELL = 1000.0  # electrons at signal 1.0  -> gain = 1e-3 per electron
READ_E = 3.0  # read noise, electrons          -> read_variance = 9e-6
GAIN = 1.0 / FULL_WELL
READ_VAR = (READ_E / FULL_WELL) ** 2


def _frames(seed, n, h=64, w=64, c=3, top=0.95):
    """n identical Poisson-Gaussian exposures of a ramp scene, in [0, 1] units.

    NumPy's generator with a fixed seed (jax.random.poisson is ~100x slower on CPU)."""
    rng = np.random.default_rng(seed)
    ramp = np.linspace(0.01, top, h * w).reshape(h, w)
    lam = np.broadcast_to(ramp[None, :, :, None], (n, h, w, c)) * FULL_WELL
    e = rng.poisson(lam) + READ_E * rng.standard_normal(lam.shape)
    return jnp.asarray((e / FULL_WELL).astype(np.float32))


_fit_pairs = jax.jit(lambda f: fit_photon_transfer(f, method="pairs"))
_fit_stack = jax.jit(lambda f: fit_photon_transfer(f, method="stack"))


@pytest.mark.parametrize("method,n,n_keys", [("pairs", 2, 12), ("stack", 4, 8)])
def test_ptc_recovers_gain_and_standard_error_is_calibrated(method, n, n_keys):
    fit = _fit_pairs if method == "pairs" else _fit_stack
    g, gse, r, rse = [], [], [], []
    for i in range(n_keys):
        model, info = fit(_frames(100 + i, n))
        g.append(model.gain)
        gse.append(info["gain_se"])
        r.append(info["read_variance_raw"])
        rse.append(info["read_variance_se"])
    g, gse, r, rse = (np.asarray(jnp.stack(v)) for v in (g, gse, r, rse))
    # every estimate within 4 standard errors of the truth
    assert np.all(np.abs(g - GAIN) < 4 * gse)
    assert np.all(np.abs(r - READ_VAR) < 4 * rse)
    # mean over keys*channels within 4 s.e. of the mean (unbiased)
    m = g.size
    assert abs(g.mean() - GAIN) < 4 * gse.mean() / np.sqrt(m)
    assert abs(r.mean() - READ_VAR) < 4 * rse.mean() / np.sqrt(m)
    # reported standard error matches the empirical spread (within a factor 1.5)
    assert 1 / 1.5 < g.std(ddof=1) / gse.mean() < 1.5
    assert 1 / 1.5 < r.std(ddof=1) / rse.mean() < 1.5


def test_ptc_raw_units_with_clipping_excluded():
    black, white = 64.0, 1023.0
    x = _frames(3, 2, c=1, top=1.3)  # 25% of the scene overexposed
    raw = jnp.clip(black + x * (white - black), 0.0, white)
    model, info = fit_photon_transfer(raw, black=black, white=white)
    assert abs(float(model.gain[0]) - GAIN) < 4 * float(info["gain_se"][0])
    np.testing.assert_allclose(model.white_level, [white])
    np.testing.assert_allclose(model.black_level, [black])
    # without excluding clipped pixels the top bins collapse and the gain is biased low
    bad, _ = fit_photon_transfer(raw, black=black, white=white, saturation=2.0)
    assert float(bad.gain[0]) < GAIN - 5 * float(info["gain_se"][0])
    # raw-unit fit (no white): gain scales by the range, read variance by its square
    raw_ok = black + x[..., :1] * 0.7 * (white - black)
    m_dn, i_dn = fit_photon_transfer(raw_ok, black=black)
    k = 0.7 * (white - black)
    assert abs(float(m_dn.gain[0]) - GAIN * k) < 4 * float(i_dn["gain_se"][0])


# 3.6 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_ptc_float32_fit_of_clipped_bins_matches_float64(x64):
    """Clipped pixels left in (saturation=2) give zero-variance bins whose IRLS weights span
    ~1e18: the float32 line fit must still agree with the same fit in float64 (the textbook
    normal equations gave read variance 0 and covariance 0 in float32, or NaN without FMA)."""
    black, white = 64.0, 1023.0
    x = _frames(3, 2, c=1, top=1.3)
    raw = np.asarray(jnp.clip(black + x * (white - black), 0.0, white), np.float64)
    kw = dict(black=black, white=white, saturation=2.0)
    _, i32 = fit_photon_transfer(jnp.asarray(raw, jnp.float32), **kw)
    _, i64 = fit_photon_transfer(jnp.asarray(raw, jnp.float64), **kw)
    assert i32["cov"].dtype == jnp.float32 and i64["cov"].dtype == jnp.float64
    assert float(i64["read_variance_raw"][0]) > 1e-3  # the clipped bins bias it far up
    for k in ("gain_raw", "read_variance_raw"):
        np.testing.assert_allclose(i32[k], i64[k], rtol=2e-2, atol=1e-6)
    np.testing.assert_allclose(i32["cov"], i64["cov"], rtol=2e-2)
    assert np.all(np.isfinite(np.asarray(i32["gain_se"]))) and float(i32["gain_se"][0]) > 0


def test_ptc_mask_and_list_input_match_array():
    f = _frames(5, 2)
    m1, _ = _fit_pairs(f)
    m2, _ = fit_photon_transfer([f])
    np.testing.assert_allclose(m1.gain, m2.gain, rtol=1e-6)
    # masking the bottom half == fitting the top half alone (tiled to the same shape)
    top = f[:, :32]
    mask = jnp.zeros((64, 64), bool).at[:32].set(True)
    m3, i3 = fit_photon_transfer(f, mask=mask)
    m4, _ = fit_photon_transfer(jnp.concatenate([top, top], axis=1))
    np.testing.assert_allclose(m3.gain, m4.gain, rtol=2e-2)
    assert np.all(np.asarray(i3["n_bins_used"]) == 32)


def test_noise_model_values_closed_form():
    m = NoiseModel(jnp.array([0.01, 0.02]), jnp.array([1e-4, 4e-4]))
    x = jnp.array([[0.5, 0.25], [-0.1, 0.0]])
    expected = np.array([[0.0051, 0.0054], [1e-4, 4e-4]])
    np.testing.assert_allclose(m.variance(x), expected, rtol=1e-6)
    np.testing.assert_allclose(m.std(x), np.sqrt(expected), rtol=1e-6)
    np.testing.assert_allclose(m.snr(x)[0], [0.5 / np.sqrt(0.0051), 0.25 / np.sqrt(0.0054)])
    jv = jax.jit(lambda mm, xx: mm.snr(xx))(m, x)
    np.testing.assert_allclose(jv, m.snr(x), rtol=1e-6)
    d = m.to_dict()
    assert d["read_noise"] == pytest.approx([0.01, 0.02])


# issue 9: ~4 s of a loaded 2-core default run; float64 FD check; the noise-model closed forms
# stay in the default run
@pytest.mark.slow
def test_noise_model_gradients(x64):
    x = jnp.array([0.3, 0.01, 0.8])

    def f(g, r, x):
        return jnp.sum(NoiseModel(g, r).std(x) ** 1.5 + NoiseModel(g, r).snr(x))

    g = jnp.array([0.1, 0.2, 0.05])  # keep r - eps >= 0
    r = jnp.array([0.01, 0.02, 0.03])
    check_grads(f, (g, r, x), order=2, modes=["rev"], eps=1e-5)
    # zero noise at zero signal: std gradient finite (safe_sqrt), snr 0
    z = jax.grad(lambda g: jnp.sum(NoiseModel(g, jnp.zeros(1)).std(jnp.zeros(1))))(jnp.ones(1))
    assert np.all(np.isfinite(z))
    assert float(NoiseModel(jnp.ones(1), jnp.zeros(1)).snr(jnp.zeros(1))[0]) == 0.0


def test_bad_inputs():
    f = _frames(0, 3, h=8, w=8, c=1)
    with pytest.raises(ValueError, match="method"):
        fit_photon_transfer(f, method="janesick")
    with pytest.raises(ValueError, match="frames_or_pairs.*N == 2"):
        fit_photon_transfer(f, method="pairs")
    with pytest.raises(ValueError, match="frames_or_pairs"):
        fit_photon_transfer(f[:1], method="stack")
    with pytest.raises(ValueError, match="mask"):
        fit_photon_transfer(f[:2], mask=jnp.ones((4, 4), bool))
    with pytest.raises(ValueError, match="n_bins"):
        fit_photon_transfer(f[:2], n_bins=1)
    with pytest.raises(ValueError, match="frames_or_pairs.*bins"):
        fit_photon_transfer(f[:2, :2, :2])
    with pytest.raises(ValueError, match="gain, read_variance"):
        NoiseModel(jnp.ones(2), jnp.ones(3))
    with pytest.raises(ValueError, match="read_variance"):
        NoiseModel(jnp.ones(1), -jnp.ones(1))
    with pytest.raises(ValueError, match="white"):
        fit_photon_transfer(f[:2], black=1.0, white=0.5)
