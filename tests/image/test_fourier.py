"""Tests for jaxgfx.image.fourier: closed forms on sinusoids and scipy.ndimage as oracle."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage
from scipy.stats import norm

from jaxgfx.image.fourier import (
    fft_filter,
    fourier_bandpass,
    fourier_highpass,
    fourier_lowpass,
    frequency_grid,
    lowpass_transfer,
)
from jaxgfx.testing import check_grads_jit

H, W = 32, 40
KINDS = ["ideal", "gaussian", "butterworth"]


def _cos(ky, kx, h=H, w=W):
    """cos(2π(ky y/h + kx x/w)): radial frequency sqrt((ky/h)² + (kx/w)²) cycles/pixel."""
    yy, xx = np.mgrid[:h, :w]
    return np.cos(2 * np.pi * (ky * yy / h + kx * xx / w))


@pytest.fixture(scope="module")
def img():
    return np.random.default_rng(5).random((H, W, 3)).astype(np.float32)


def test_frequency_grid_matches_numpy():
    fy, fx = frequency_grid((6, 5))
    np.testing.assert_allclose(np.asarray(fy[:, 0]), np.fft.fftfreq(6))
    np.testing.assert_allclose(np.asarray(fx[0]), np.fft.rfftfreq(5))
    _, fxf = frequency_grid((6, 5), real=False)
    np.testing.assert_allclose(np.asarray(fxf[0]), np.fft.fftfreq(5))


@pytest.mark.parametrize("kind", KINDS)
def test_lowpass_scales_sinusoid_by_transfer(kind):
    ky, kx = 3, 4
    f = np.hypot(ky / H, kx / W)
    x = _cos(ky, kx).astype(np.float32)
    c, n = 0.1, 3.0
    y = jax.jit(lambda x, c: fourier_lowpass(x, c, kind=kind, order=n))(x, c)
    closed = {
        "ideal": float(f <= c),
        "gaussian": np.exp(-(f**2) / (2 * c**2)),
        "butterworth": 1 / (1 + (f / c) ** (2 * n)),
    }[kind]
    np.testing.assert_allclose(np.asarray(y), closed * x, atol=2e-6)


def test_ideal_lowpass_removes_exactly_above_cutoff():
    lo, hi = _cos(2, 3), _cos(9, 12)  # r ≈ 0.095 and 0.424 cycles/pixel
    x = (lo + 0.7 * hi).astype(np.float32)
    y = fourier_lowpass(x, 0.2, kind="ideal")
    np.testing.assert_allclose(np.asarray(y), lo, atol=2e-6)
    hp = fourier_highpass(x, 0.2, kind="ideal")
    np.testing.assert_allclose(np.asarray(hp), 0.7 * hi, atol=2e-6)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("padding", ["wrap", "reflect"])
def test_lowpass_plus_highpass_is_identity(img, kind, padding):
    lp = fourier_lowpass(img, 0.12, kind=kind, padding=padding)
    hp = fourier_highpass(img, 0.12, kind=kind, padding=padding)
    np.testing.assert_allclose(np.asarray(lp + hp), img, atol=2e-6)
    assert lp.shape == img.shape and lp.dtype == jnp.float32


@pytest.mark.parametrize("padding, mode", [("wrap", "wrap"), ("reflect", "reflect")])
def test_gaussian_lowpass_equals_spatial_gaussian_blur(img, padding, mode):
    sigma = 2.0  # spatial; σ_f = 1/(2πσ)
    y = fourier_lowpass(img, 1 / (2 * np.pi * sigma), padding=padding)
    ref = np.stack(
        [
            ndimage.gaussian_filter(img[..., c].astype(float), sigma, mode=mode, truncate=8)
            for c in range(3)
        ],
        -1,
    )
    np.testing.assert_allclose(np.asarray(y), ref, atol=1e-5)


def test_reflect_padding_reduces_edge_artefacts():
    ramp = np.tile(np.linspace(0, 1, W, dtype=np.float32), (H, 1))  # discontinuous when wrapped
    sigma = 1 / (2 * np.pi * 0.05)
    err_wrap = np.abs(np.asarray(fourier_lowpass(ramp, 0.05)) - ramp)[:, 0]
    err_refl = np.abs(np.asarray(fourier_lowpass(ramp, 0.05, padding="reflect")) - ramp)[:, 0]
    # mirror about t = -1/2 of a ramp of slope s: blurred edge value s·(E|1/2 + σZ| - 1/2)
    mu, s = 0.5, 1 / (W - 1)
    e_abs = sigma * np.sqrt(2 / np.pi) * np.exp(-(mu**2) / (2 * sigma**2)) + mu * (
        1 - 2 * norm.cdf(-mu / sigma)
    )
    np.testing.assert_allclose(err_refl, s * (e_abs - mu), rtol=0.02)
    assert err_wrap.min() > 5 * err_refl.max()  # wrap mixes in the far edge (value 1)


@pytest.mark.parametrize("kind", KINDS)
def test_bandpass_gain(kind):
    lo, hi, n = 0.08, 0.2, 2.0
    for ky, kx in ((1, 1), (4, 5), (10, 12)):
        f = np.hypot(ky / H, kx / W)
        x = _cos(ky, kx).astype(np.float32)
        g_lp = lambda c: float(lowpass_transfer(ky / H, kx / W, c, kind=kind, order=n))  # noqa: B023
        y = fourier_bandpass(x, lo, hi, kind=kind, order=n)
        np.testing.assert_allclose(np.asarray(y), g_lp(hi) * (1 - g_lp(lo)) * x, atol=3e-6)
        if kind == "ideal":
            assert g_lp(hi) * (1 - g_lp(lo)) == float(lo < f <= hi)


def test_fft_filter_array_phase_ramp_is_shift(img):
    fy, fx = frequency_grid((H, W), real=False)
    shift = jnp.exp(-2j * jnp.pi * (fx * 3 + fy * 1))  # translate by (1, 3) pixels
    y = jax.jit(fft_filter)(img, shift)
    np.testing.assert_allclose(np.asarray(y), np.roll(img, (1, 3), axis=(0, 1)), atol=2e-6)


def test_fft_filter_callable_batch_vmap(img):
    batch = np.stack([img, 2 * img])
    tf = lambda fy, fx: jnp.exp(-(fy**2 + fx**2) / (2 * 0.1**2))
    y = fft_filter(batch, tf)
    yv = jax.vmap(lambda x: fourier_lowpass(x, 0.1))(batch)
    np.testing.assert_allclose(np.asarray(y), np.asarray(yv), atol=2e-6)
    gray = fft_filter(img[..., 0], tf)
    np.testing.assert_allclose(np.asarray(gray), np.asarray(y[0, ..., 0]), atol=2e-6)


@pytest.mark.parametrize("kind", ["gaussian", "butterworth"])
def test_grad_wrt_cutoff_and_order(x64, kind):
    x = jnp.asarray(np.random.default_rng(6).random((12, 10)))
    check_grads_jit(lambda c, n, x: fourier_lowpass(x, c, kind=kind, order=n), (0.1, 2.0, x), 1)
    check_grads_jit(lambda lo, hi: fourier_bandpass(x, lo, hi, kind=kind), (0.05, 0.2), 1)


def test_grad_wrt_cutoff_closed_form(x64):
    # d/dc of exp(-f²/(2c²)) cos = (f²/c³) exp(-f²/(2c²)) cos
    f, c = np.hypot(3 / H, 4 / W), 0.1
    x = jnp.asarray(_cos(3, 4))
    g = jax.jit(jax.grad(lambda c: fourier_lowpass(x, c)[0, 0]))(c)
    np.testing.assert_allclose(float(g), f**2 / c**3 * np.exp(-(f**2) / (2 * c**2)), rtol=1e-10)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("cutoff", [1e-6, 1e6])
def test_extreme_cutoffs_finite(img, kind, cutoff):
    x = img[..., 0]
    y, g = jax.jit(jax.value_and_grad(lambda c: fourier_lowpass(x, c, kind=kind, order=4.0).sum()))(
        cutoff
    )
    assert np.isfinite(float(y)) and np.isfinite(float(g))
    out = fourier_lowpass(x, cutoff, kind=kind, order=4.0)
    # tiny cutoff keeps only the mean; huge cutoff is the identity
    ref = np.full_like(x, x.mean()) if cutoff < 1 else x
    np.testing.assert_allclose(np.asarray(out), ref, atol=2e-5)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda x: fourier_lowpass(x, 0.1, kind="box"), "kind"),
        (lambda x: fourier_lowpass(x, -0.1), "cutoff"),
        (lambda x: fourier_lowpass(x, 0.1, padding="zero"), "padding"),
        (lambda x: fourier_lowpass(x, 0.1, kind="butterworth", order=0), "order"),
        (lambda x: fourier_bandpass(x, 0.3, 0.1), "low"),
        (lambda x: fft_filter(x, jnp.ones((3, 3))), "transfer"),
        (lambda x: fourier_highpass(x[0, :, 0], 0.1), "image"),
    ],
)
def test_bad_input_raises(img, call, match):
    with pytest.raises(ValueError, match=match):
        call(img)


def test_fft_filter_new_callables_share_one_program(img):
    # a callable transfer is evaluated at the boundary, so a new lambda per call (different
    # width) reuses one compiled program; reference: scipy.ndimage.fourier_gaussian
    from jaxgfx.image.fourier import _filter_rfft

    x = img[..., 0]
    n0 = _filter_rfft._cache_size()
    for sigma in (1.0, 2.5):
        c = 1.0 / (2 * np.pi * sigma)  # frequency-domain sigma of a spatial blur sigma
        y = fft_filter(x, lambda fy, fx, c=c: jnp.exp(-(fy**2 + fx**2) / (2 * c * c)))
        ref = np.fft.ifft2(ndimage.fourier_gaussian(np.fft.fft2(x), sigma)).real
        np.testing.assert_allclose(np.asarray(y), ref, atol=2e-6)
    assert _filter_rfft._cache_size() - n0 <= 1
