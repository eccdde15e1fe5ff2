"""Tests for jaxgfx.hdr.align against closed forms, scikit-image, OpenCV and SciPy."""

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy import ndimage
from skimage.registration import phase_cross_correlation

from jaxgfx.hdr.align import align_stack, mtb_align, phase_correlation, shift_image

N, S = 128, 96  # band-limited periodic texture of N^2, crops of S^2
C0 = (N - S) // 2


def _texture(seed, bw=0.2):
    rng = np.random.default_rng(seed)
    f = np.fft.fft2(rng.standard_normal((N, N)))
    k2 = np.fft.fftfreq(N)[:, None] ** 2 + np.fft.fftfreq(N)[None, :] ** 2
    t = np.real(np.fft.ifft2(f * np.exp(-k2 / (2 * bw**2))))
    return 0.05 + 0.9 * ((t - t.min()) / (t.max() - t.min())) ** 2


def _fshift(img, dy, dx):
    """Exact band-limited periodic shift (NumPy FFT), content moves by (+dy, +dx)."""
    k = np.fft.fftfreq(img.shape[0])
    ph = np.exp(-2j * np.pi * (k[:, None] * dy + k[None, :] * dx))
    return np.real(np.fft.ifft2(np.fft.fft2(img) * ph))


def _pair(seed, dy, dx, gain, noise=0.01):
    base = _texture(seed)
    rng = np.random.default_rng(seed + 99)
    ref = base[C0 : C0 + S, C0 : C0 + S]
    img = gain * _fshift(base, dy, dx)[C0 : C0 + S, C0 : C0 + S]
    img = np.clip(img + noise * rng.standard_normal(img.shape), 0.0, 1.0)
    return ref.astype(np.float32), img.astype(np.float32)


_pc1 = jax.jit(lambda a, b: phase_correlation(a, b))
_pc20 = jax.jit(lambda a, b: phase_correlation(a, b, upsample=20))
_mtb = jax.jit(lambda a, b: mtb_align(a, b, levels=4))


@pytest.mark.parametrize(
    "seed,dy,dx,gain", [(0, 2.3, -1.7, 0.4), (1, -5.45, 3.2, 1.6), (2, 0.5, 6.8, 1.0)]
)
def test_phase_correlation_subpixel_across_exposures(seed, dy, dx, gain):
    ref, img = _pair(seed, dy, dx, gain)
    est = np.asarray(_pc20(ref, img))
    assert np.all(np.abs(est - [dy, dx]) < 0.1)
    assert np.all(np.abs(np.asarray(_pc1(ref, img)) - [dy, dx]) < 0.25)  # parabola only
    # scikit-image on the same Hann-windowed input returns the registration shift (-shift)
    win = cv2.createHanningWindow((S, S), cv2.CV_64F)
    sk = -phase_cross_correlation(ref * win, img * win, upsample_factor=20)[0]
    assert np.all(np.abs(est - sk) < 0.1)


def test_phase_correlation_integer_matches_opencv():
    ref, img = _pair(3, 4.0, -7.0, 0.7, noise=0.0)
    est = np.asarray(_pc1(ref, img))
    win = cv2.createHanningWindow((S, S), cv2.CV_64F)
    (cx, cy), _ = cv2.phaseCorrelate(ref.astype(np.float64), img.astype(np.float64), win)
    np.testing.assert_allclose(est, [4.0, -7.0], atol=0.05)
    np.testing.assert_allclose(est, [cy, cx], atol=0.1)
    # circular shift of a periodic image: exact
    base = _texture(4)[:64, :64].astype(np.float32)
    rolled = np.roll(base, (3, -5), axis=(0, 1))
    np.testing.assert_allclose(phase_correlation(base, rolled, upsample=4), [3, -5], atol=0.1)


# 6.2 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_mtb_integer_and_subpixel_with_nonlinear_response():
    ref, img = _pair(5, 6.0, -9.0, 0.5)
    img = img ** (1 / 2.2)  # a different (monotonic) response: medians still match
    np.testing.assert_array_equal(_mtb(ref, img), [6, -9])
    ref, img = _pair(6, -3.4, 2.6, 1.5)
    est = np.asarray(_mtb(ref, img))
    assert est.dtype == np.int32
    assert np.all(np.abs(est - [-3.4, 2.6]) <= 1.0)


def test_shift_image_against_numpy_and_scipy():
    img = _texture(7)[:32, :40].astype(np.float32)
    fft_int = shift_image(img, (3.0, -2.0), mode="fft")
    np.testing.assert_allclose(fft_int, np.roll(img, (3, -2), axis=(0, 1)), atol=1e-5)
    sub = (1.3, -2.6)
    k_y, k_x = np.fft.fftfreq(32), np.fft.fftfreq(40)
    ph = np.exp(-2j * np.pi * (k_y[:, None] * sub[0] + k_x[None, :] * sub[1]))
    ref = np.real(np.fft.ifft2(np.fft.fft2(img) * ph))
    f = jax.jit(lambda im, s: shift_image(im, s, mode="fft"))
    np.testing.assert_allclose(f(img, jnp.array(sub)), ref, atol=1e-5)
    bil = jax.jit(lambda im, s: shift_image(im, s))(img, jnp.array(sub))
    np.testing.assert_allclose(bil, ndimage.shift(img, sub, order=1, mode="nearest"), atol=1e-5)
    rgb = np.stack([img, 2 * img, img**2], axis=-1)
    np.testing.assert_allclose(shift_image(rgb, sub)[..., 1], 2 * np.asarray(bil), rtol=1e-5)


# 3.4 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
@pytest.mark.parametrize("mode", ["fft", "bilinear"])
def test_shift_image_gradients(mode, x64):
    img = jnp.asarray(_texture(8)[:8, :8])
    s = jnp.array([0.3, -1.4])
    check_grads(
        lambda im, s: jnp.sum(shift_image(im, s, mode=mode) ** 2 * jnp.arange(8.0)),
        (img, s),
        order=1,
        modes=["rev"],
    )


# issue 9: ~6 s of a loaded 2-core default run; whole-stack alignment; the phase and MTB shift
# tests stay in the default run
@pytest.mark.slow
def test_align_stack_phase_and_mtb():
    base = _texture(9)
    true = np.array([[2.6, -1.2], [0.0, 0.0], [-3.3, 4.5]])
    gains = [0.4, 1.0, 1.8]
    frames = np.stack(
        [
            np.clip(g * _fshift(base, *t)[C0 : C0 + S, C0 : C0 + S], 0, 1)
            for g, t in zip(gains, true, strict=True)
        ]
    ).astype(np.float32)
    aligned, shifts = jax.jit(lambda x: align_stack(x, method="phase"))(frames)
    assert np.all(np.abs(np.asarray(shifts) - true) < 0.1)
    # aligned frames match the reference (scaled by the gain) away from the borders
    inner = (slice(8, -8), slice(8, -8))
    ref = frames[1][inner]
    err = np.abs(np.asarray(aligned[0])[inner] / gains[0] - ref).mean()
    before = np.abs(frames[0][inner] / gains[0] - ref).mean()
    assert err < 0.25 * before  # what is left is bilinear interpolation blur
    a_fft, _ = align_stack(frames, mode="fft")  # band-limited shift: near exact inside
    assert np.abs(np.asarray(a_fft[0])[inner] / gains[0] - ref).max() < 0.03
    _, ms = align_stack(frames, method="mtb", levels=4, reference=1)
    assert np.all(np.abs(np.asarray(ms) - true) <= 1.0)


def test_bad_inputs():
    a = np.zeros((16, 16), np.float32)
    with pytest.raises(ValueError, match="img"):
        phase_correlation(a, a[:8])
    with pytest.raises(ValueError, match="upsample"):
        phase_correlation(a, a, upsample=0)
    with pytest.raises(ValueError, match="levels"):
        mtb_align(a, a, levels=6)
    with pytest.raises(ValueError, match="method"):
        align_stack(np.stack([a, a]), method="sift")
    with pytest.raises(ValueError, match="images"):
        align_stack(a[None])
    with pytest.raises(ValueError, match="reference"):
        align_stack(np.stack([a, a]), reference=2)
    with pytest.raises(ValueError, match="mode"):
        shift_image(a, (0.0, 1.0), mode="cubic")
    with pytest.raises(ValueError, match="shift"):
        shift_image(a, (0.0, 1.0, 2.0))
    with pytest.raises(ValueError, match="ref"):
        phase_correlation(np.full((16, 16), np.nan), a)


# 5.2 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_degenerate_inputs_are_finite():
    flat = np.ones((16, 16), np.float32)
    np.testing.assert_array_equal(phase_correlation(flat, flat), [0.0, 0.0])
    np.testing.assert_array_equal(phase_correlation(flat, 0 * flat, upsample=4), [0.0, 0.0])
    np.testing.assert_array_equal(mtb_align(flat, flat, levels=2), [0, 0])
    # a shift far outside the image: edge value (bilinear), finite gradient
    eye = jnp.eye(4)
    np.testing.assert_array_equal(shift_image(eye, (100.0, -100.0))[0], [0.0, 0, 0, 0])
    g = jax.grad(lambda s: jnp.sum(shift_image(eye, s)))(jnp.array([100.0, -100.0]))
    assert np.all(np.isfinite(g))
