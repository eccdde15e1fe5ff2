"""Statistical tests for jaxgfx.image.noise (fixed keys, tolerances = 5 sd of the estimator).

Sample sizes are chosen so that 5 sd is small: >= 2^18 samples put 5 sd of a sample variance at
< 1.4 % and of a binomial fraction at < 3 %, so a 5 % error in a variance or a rate fails
(``_check_mean_var`` and ``_check_binomial`` refuse sample sizes that could not tell).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import trim_mean

from jaxgfx.image.noise import (
    add_gaussian_noise,
    add_impulse_noise,
    add_poisson_gaussian_noise,
    add_salt_and_pepper,
    temporal_average,
)
from jaxgfx.testing import check_grads_jit

KEY = jax.random.key(42)


def _check_mean_var(samples, mean, var, n_sd=5.0):
    """Sample mean/variance vs expected; sd(mean) = sqrt(var/n), sd(var) ≈ var·sqrt(2/(n-1))."""
    s = np.asarray(samples, np.float64).ravel()
    n = s.size
    assert n_sd * np.sqrt(2.0 / (n - 1)) < 0.025, "too few samples to see a 5 % variance error"
    assert abs(s.mean() - mean) < n_sd * np.sqrt(var / n)
    assert abs(s.var(ddof=1) - var) < n_sd * var * np.sqrt(2.0 / (n - 1))


def _check_binomial(k, n, p, n_sd=5.0, resolve=0.05):
    assert n_sd * np.sqrt((1 - p) / (n * p)) < resolve, "too few trials to see a 5 % rate error"
    assert abs(k - n * p) < n_sd * np.sqrt(n * p * (1 - p)) + 1e-9


def test_gaussian_noise_statistics_per_channel_sigma():
    x = jnp.full((512, 512, 3), 0.5)
    sig = jnp.array([0.05, 0.1, 0.2])
    y = jax.jit(lambda k, x, s: add_gaussian_noise(k, x, sigma=s))(KEY, x, sig)
    assert y.shape == x.shape and y.dtype == jnp.float32
    for c in range(3):
        _check_mean_var(y[..., c], 0.5, float(sig[c]) ** 2)
    y2 = add_gaussian_noise(KEY, x, sigma=sig)  # jit == eager, same key same noise
    np.testing.assert_allclose(np.asarray(y), np.asarray(y2), atol=1e-7)
    yc = add_gaussian_noise(KEY, x, sigma=sig, clip=True)
    assert float(yc.min()) >= 0.0 and float(yc.max()) <= 1.0


@pytest.mark.slow  # ~2 s CPU (compile); run with -m slow
def test_gaussian_noise_vmap_keys_are_independent():
    keys = jax.random.split(KEY, 4)
    ys = jax.vmap(lambda k: add_gaussian_noise(k, jnp.zeros((32, 32)), sigma=1.0))(keys)
    # correlation of independent N(0,1) fields: sd 1/sqrt(n)
    r = np.corrcoef(np.asarray(ys).reshape(4, -1))
    assert np.all(np.abs(r[np.triu_indices(4, 1)]) < 5 / 32)


def test_gaussian_noise_grads(x64):
    x = jnp.linspace(0.0, 1.0, 12).reshape(3, 4)
    check_grads_jit(lambda x, s: add_gaussian_noise(KEY, x, sigma=s), (x, 0.1), 1)
    y0 = add_gaussian_noise(KEY, x, sigma=0.0)
    assert bool(jnp.all(y0 == x))
    g = jax.jit(jax.grad(lambda s: add_gaussian_noise(KEY, x, sigma=s).sum()))(
        0.0
    )  # σ → 0: dy/dσ = z
    z = (add_gaussian_noise(KEY, x, sigma=1.0) - x).sum()
    np.testing.assert_allclose(float(g), float(z), rtol=1e-12)


def test_gaussian_noise_huge_sigma_and_batch():
    y = add_gaussian_noise(KEY, jnp.zeros((2, 256, 256, 1)), sigma=1e30)
    assert np.all(np.isfinite(np.asarray(y)))
    _check_mean_var(np.asarray(y) / 1e30, 0.0, 1.0)
    assert not np.allclose(np.asarray(y[0]), np.asarray(y[1]))  # batch items get fresh noise


def test_salt_and_pepper_binomial_fractions():
    n = 1024 * 1024  # 5 sd of the hit count = 1.5 % of it: a 5 % rate error fails by 3x
    x = jnp.full((1024, 1024), 0.5)
    y = jax.jit(lambda k, x: add_salt_and_pepper(k, x, amount=0.1, salt_vs_pepper=0.7))(KEY, x)
    hit = np.asarray(y != 0.5)
    _check_binomial(hit.sum(), n, 0.1)
    salt = np.asarray(y == 1.0).sum()
    _check_binomial(salt, hit.sum(), 0.7)
    assert set(np.unique(np.asarray(y))) <= {0.0, 0.5, 1.0}


def test_salt_and_pepper_whole_pixels_vs_per_channel():
    x = jnp.full((512, 512, 3), 0.5)
    y = add_salt_and_pepper(KEY, x, amount=0.2)
    hit = np.asarray(y != 0.5)
    assert np.all(hit.all(-1) == hit.any(-1))  # all channels of a pixel together
    assert np.all(np.ptp(np.asarray(y), axis=-1) == 0)
    _check_binomial(hit[..., 0].sum(), 512 * 512, 0.2)
    yc = add_salt_and_pepper(KEY, x, amount=0.2, per_channel=True)
    hc = np.asarray(yc != 0.5)
    _check_binomial(hc.sum(), hc.size, 0.2)
    # independent channels: P(all three hit) = 0.2^3 (2100 expected: resolves 11 %)
    _check_binomial(hc.all(-1).sum(), 512 * 512, 0.008, resolve=0.11)


def test_impulse_noise():
    x = jnp.zeros((512, 512, 3))
    y = jax.jit(lambda k, x: add_impulse_noise(k, x, amount=0.05, value=0.9))(KEY, x)
    hit = np.asarray(y[..., 0] != 0)
    _check_binomial(hit.sum(), 512 * 512, 0.05)
    np.testing.assert_allclose(np.asarray(y)[hit], 0.9)
    assert float(add_impulse_noise(KEY, x, amount=0.0).max()) == 0.0


@pytest.mark.parametrize(
    "method",
    # jax.random.poisson takes ~5 s of CPU to compile: the exact sampler runs with -m slow
    [pytest.param("exact", marks=pytest.mark.slow), "gaussian"],
)
def test_poisson_gaussian_mean_variance(method):
    gain, read = 0.01, 0.01
    # one compiled program (gain, read_sigma traced) for both levels
    f = jax.jit(
        lambda k, x, g, r: add_poisson_gaussian_noise(k, x, gain=g, read_sigma=r, method=method)
    )
    for level in (0.05, 0.4):
        y = f(KEY, jnp.full((512, 512), level), gain, read)
        _check_mean_var(y, level, gain * level + read**2)
    if method == "exact":
        # no read noise: y / gain are integer electron counts; zero signal is noiseless
        x = jnp.asarray(np.random.default_rng(0).random((64, 64)), jnp.float32)
        e = np.asarray(f(KEY, x, 0.05, 0.0)) / 0.05
        np.testing.assert_allclose(e, np.round(e), atol=1e-4)
        assert float(jnp.abs(f(KEY, jnp.zeros((64, 64)), 0.05, 0.0)).max()) == 0.0


def test_poisson_gaussian_approx_grads(x64):
    x = jnp.array([[0.0, 0.1], [0.5, 1.0]])

    def f(x, g, r):
        return add_poisson_gaussian_noise(KEY, x, gain=g, read_sigma=r, method="gaussian")

    check_grads_jit(f, (x[1:], 0.01, 0.02), 1)
    gx, gg, gr = jax.jit(jax.grad(lambda *a: f(*a).sum(), argnums=(0, 1, 2)))(x, 0.01, 0.0)
    assert all(np.all(np.isfinite(np.asarray(v))) for v in (gx, gg, gr))


def test_temporal_average_reduces_variance_by_n():
    n = 16
    frames = jax.vmap(lambda k: add_gaussian_noise(k, jnp.full((512, 512), 0.3), sigma=0.2))(
        jax.random.split(KEY, n)
    )
    avg = temporal_average(frames)
    _check_mean_var(avg, 0.3, 0.2**2 / n)


def test_temporal_average_methods_match_numpy_scipy(rng):
    frames = rng.random((7, 5, 6, 3)).astype(np.float32)
    for method, ref in (
        ("mean", frames.mean(0)),
        ("median", np.median(frames, 0)),
        ("trimmed", trim_mean(frames, 0.2, axis=0)),
    ):
        out = temporal_average(frames, method=method, trim=0.2)
        np.testing.assert_allclose(np.asarray(out), ref, rtol=1e-6)
    out = temporal_average(np.moveaxis(frames, 0, -1), axis=-1, method="trimmed", trim=0.3)
    np.testing.assert_allclose(np.asarray(out), trim_mean(frames, 0.3, axis=0), rtol=1e-6)


@pytest.mark.slow  # ~2 s CPU (compile); run with -m slow
def test_temporal_median_removes_impulses():
    clean = jnp.full((32, 32), 0.25)
    keys = jax.random.split(KEY, 9)
    frames = jax.vmap(lambda k: add_impulse_noise(k, clean, amount=0.1))(keys)
    # a pixel fails only if >= 5 of 9 frames are hit: P = sum_{k>=5} Binom(9, 0.1) ≈ 9e-4
    bad = np.asarray(temporal_average(frames, method="median") != 0.25).sum()
    assert bad <= 5
    assert float(jnp.abs(temporal_average(frames) - 0.25).max()) > 0.05  # the mean is not robust


def test_temporal_average_grad(x64):
    frames = jnp.asarray(np.random.default_rng(3).random((5, 3, 4)))
    g = jax.jit(jax.grad(lambda f: temporal_average(f).sum()))(frames)
    np.testing.assert_allclose(np.asarray(g), 0.2)
    check_grads_jit(lambda f: temporal_average(f, method="trimmed", trim=0.2), (frames,), 1)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: add_gaussian_noise(KEY, np.zeros((4, 4)), sigma=-0.1), "sigma"),
        (lambda: add_salt_and_pepper(KEY, np.zeros((4, 4)), amount=1.5), "amount"),
        (lambda: add_salt_and_pepper(KEY, np.zeros((4, 4)), amount=-0.1), "amount"),
        (
            lambda: add_salt_and_pepper(KEY, np.zeros((4, 4)), amount=0.1, salt_vs_pepper=2),
            "salt_vs_pepper",
        ),
        (lambda: add_impulse_noise(KEY, np.zeros((4, 4)), amount=2.0), "amount"),
        (lambda: add_poisson_gaussian_noise(KEY, np.ones(3), gain=0.0, read_sigma=0), "gain"),
        (
            lambda: add_poisson_gaussian_noise(KEY, np.ones(3), gain=1.0, read_sigma=-1),
            "read_sigma",
        ),
        (
            lambda: add_poisson_gaussian_noise(KEY, np.ones(3), gain=1, read_sigma=0, method="x"),
            "method",
        ),
        (lambda: temporal_average(np.zeros((3, 4, 4)), method="mode"), "method"),
        (lambda: temporal_average(np.zeros((3, 4, 4)), method="trimmed", trim=0.5), "trim"),
        (lambda: temporal_average(np.zeros((3, 4, 4)), axis=3), "axis"),
    ],
)
def test_bad_input_raises(call, match):
    with pytest.raises(ValueError, match=match):
        call()
