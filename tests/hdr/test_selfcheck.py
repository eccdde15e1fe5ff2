"""Leave-one-out self-check: closed forms, jit, and jaxgfx vs OpenCV on JPEG-like stacks."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx import hdr

from ._stacks import JPEG_TIMES3, JPEG_TIMES5, jpeg_stack, opencv_loo

LIN = hdr.CameraResponse(jnp.ones((1,)), "gamma", "linear", 1.0, 1.0)  # x = z
SQ = hdr.CameraResponse(jnp.full((1,), 2.0), "gamma", "square", 1.0, 1.0)  # x = z^2


def test_loo_closed_form():
    """Linear data 0.2 @ t=1, 0.4 @ t=2. With the right (linear) response the prediction is
    exact; with x = z² it is sqrt(0.08) for both frames: errors (0.2828 - 0.4) * 255 and
    (0.2828 - 0.2) * 255."""
    imgs = jnp.asarray([[[0.2]], [[0.4]]])
    t = jnp.asarray([1.0, 2.0])
    ok = hdr.leave_one_out(imgs, t, LIN)
    assert float(ok.mean_abs_error) == pytest.approx(0.0, abs=1e-4)
    bad = hdr.leave_one_out(imgs, t, SQ)
    p = np.sqrt(0.08)
    d = np.array([p - 0.2, p - 0.4]) * 255
    np.testing.assert_allclose(np.asarray(bad.per_frame_bias), d, rtol=1e-5)
    assert float(bad.mean_abs_error) == pytest.approx(np.mean(np.abs(d)), rel=1e-5)
    # 51 falls in band [50, 100), 102 in [100, 150)
    np.testing.assert_array_equal(np.asarray(bad.per_band_count), [0, 1, 1, 0, 0])
    np.testing.assert_allclose(np.asarray(bad.per_band_bias)[1:3], d, rtol=1e-5)
    js = bad.to_dict()
    assert js["per_band"][0] is None and js["per_band_count"] == [0, 1, 1, 0, 0]


# 4.4 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_loo_noise_free_interior_frames_exact_and_jit():
    """Noise-free float stack with its true response: every interior frame is predicted to
    float precision (the end frames may need a clipped/black bound), also under jit."""
    st = hdr.make_bracketed_stack(
        jax.random.key(0),
        hdr.synthetic_radiance(jax.random.key(1), 24, 24, dynamic_range=1e3),
        jnp.asarray([1.0, 4.0, 16.0]),
        hdr.synthetic_response("camera"),
        bits=None,
        gain=0.0,
        read_sigma=0.0,
    )
    f = jax.jit(lambda im, t: hdr.leave_one_out(im, t, st.response))
    lo = f(st.images, st.exposure_times)
    assert float(lo.per_frame[1]) < 2e-3
    assert np.all(np.isfinite(np.asarray(lo.per_frame)))


def test_loo_bad_inputs():
    imgs = np.zeros((2, 4, 4, 3), np.uint8)
    with pytest.raises(ValueError, match="bands"):
        hdr.leave_one_out(imgs, [1.0, 2.0], LIN, bands=(10, 5))
    with pytest.raises(TypeError, match="response"):
        hdr.leave_one_out(imgs, [1.0, 2.0], "gamma")
    with pytest.raises(ValueError, match="exposure"):
        hdr.leave_one_out(imgs[:1], [1.0], LIN)


def test_jpeg_roundtrip_block_and_chroma():
    flat = np.full((1, 16, 16, 3), 128, np.uint8)
    assert np.abs(hdr.jpeg_roundtrip(flat).astype(int) - 128).max() <= 1
    # a 1-pixel red/blue checker: 4:2:0 averages the chroma of each 2x2 block, 4:4:4 keeps it
    chk = np.zeros((1, 16, 16, 3), np.uint8)
    m = (np.indices((16, 16)).sum(0) % 2).astype(bool)
    chk[0, m, 0] = 200
    chk[0, ~m, 2] = 200
    e420 = np.abs(hdr.jpeg_roundtrip(chk).astype(int) - chk).mean()
    e444 = np.abs(hdr.jpeg_roundtrip(chk, subsampling="4:4:4").astype(int) - chk).mean()
    assert e420 > 2 * e444
    with pytest.raises(TypeError, match="uint8"):
        hdr.jpeg_roundtrip(chk.astype(np.float32))


def _compare(name, times, max_shift=0.0):
    st = jpeg_stack(name, times=times, max_shift=max_shift)
    resp = hdr.recover_response(st.images, st.exposure_times)
    ours = hdr.leave_one_out(st.images, st.exposure_times, resp)
    _, cv = opencv_loo(st.images, st.exposure_times)
    a, b = float(ours.mean_abs_error), float(cv.mean_abs_error)
    return a, b, resp


@pytest.mark.slow  # issue 9: ~15 s of a loaded 2-core run; out of make test
def test_jpeg_like_loo_at_or_below_opencv():
    """The issue-16 setting: three JPEG frames 3 stops apart, toe/shoulder response. Measured
    (96 px): jaxgfx 6.13 vs OpenCV 6.62 levels; before the fix jaxgfx was ~2x OpenCV."""
    a, b, resp = _compare("camera", JPEG_TIMES3)
    assert a <= b, (a, b)
    # the curve's toe and shoulder are near the truth (0.0086 and 6.44), not 0.021 / 3.5
    z = jnp.asarray([[2 / 255] * 3, [128 / 255] * 3, [250 / 255] * 3])
    x = np.asarray(resp.to_linear_normalized(z)).mean(axis=1)
    assert 0.004 < x[0] / x[1] < 0.012 and 5.0 < x[2] / x[1] < 8.5, x / x[1]


@pytest.mark.slow
@pytest.mark.parametrize(
    "name,times,shift",
    [
        ("camera-offset", JPEG_TIMES3, 0.0),
        ("camera", JPEG_TIMES5, 0.0),
        ("srgb", JPEG_TIMES5, 0.0),
        ("filmic", JPEG_TIMES5, 0.0),
        ("log", JPEG_TIMES5, 0.0),
        ("camera", JPEG_TIMES5, 0.7),
    ],
)
def test_jpeg_like_loo_vs_opencv_suite(name, times, shift):
    a, b, _ = _compare(name, times, shift)
    assert a <= b, (name, a, b)
