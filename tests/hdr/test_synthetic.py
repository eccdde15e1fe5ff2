"""Synthetic scenes, response shapes (colour-science as the sRGB oracle), sensor model, metrics."""

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx import hdr

from ._stacks import radiance


def test_radiance_range_and_determinism():
    a = np.asarray(radiance(64, 1e4))
    b = np.asarray(hdr.synthetic_radiance(jax.random.key(1), 64, 64, dynamic_range=1e4))
    np.testing.assert_array_equal(a, b)
    assert a.shape == (64, 64, 3)
    np.testing.assert_allclose([a.min(), a.max()], [1e-4, 1.0], rtol=1e-5)
    assert (a >= 0.999).mean() > 0.005  # the sun disc


# 6.4 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
@pytest.mark.parametrize("name", hdr.SYNTHETIC_RESPONSES)
def test_responses_round_trip_and_anchor(x64, name):
    r = hdr.synthetic_response(name, channels=1)
    x = jnp.geomspace(1e-4, 1.0, 50, dtype=jnp.float64)[:, None]
    x1 = r.to_linear_normalized(jnp.ones((1,), jnp.float64))
    z = r.from_linear_normalized(x * x1)
    np.testing.assert_allclose(np.asarray(z[-1]), 1.0, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(r.to_linear_normalized(z) / x1), np.asarray(x), rtol=1e-8)
    assert np.all(np.diff(np.asarray(z[:, 0])) > 0)
    np.testing.assert_allclose(np.asarray(r.to_linear(jnp.full((1,), 0.5))), 1.0, rtol=1e-12)


def test_srgb_matches_colour_science(x64):
    r = hdr.synthetic_response("srgb", channels=1)
    x = np.linspace(0.0, 1.0, 101)
    ours = np.asarray(
        r.from_linear_normalized(jnp.asarray(x)[:, None] * r.to_linear_normalized(jnp.ones((1,))))
    )[:, 0]
    np.testing.assert_allclose(ours, colour.models.eotf_inverse_sRGB(x), atol=1e-9)


def test_sensor_noise_statistics():
    rad = jnp.full((64, 64, 1), 0.25)
    resp = hdr.CameraResponse(jnp.ones((1,)), "gamma", "linear", 1.0, 1.0)
    st = hdr.make_bracketed_stack(
        jax.random.key(0), rad, jnp.asarray([1.0]), resp, bits=None, gain=1e-3, read_sigma=1e-2
    )
    v = float(np.var(np.asarray(st.images)))
    expected = 1e-3 * 0.25 + 1e-4
    # 4096 samples: relative sd of a sample variance = sqrt(2/4095) = 2.2 %
    assert abs(v / expected - 1) < 0.08
    q = hdr.make_bracketed_stack(
        jax.random.key(0), rad, jnp.asarray([1.0, 2.0]), resp, bits=8, gain=0.0, read_sigma=0.0
    )
    assert q.images.dtype == jnp.uint8
    np.testing.assert_array_equal(np.asarray(q.images[:, 0, 0, 0]), [64, 128])


def test_metrics_known_values():
    g2 = hdr.CameraResponse(jnp.asarray([2.0]), "gamma", "g", 1.0, 0.5)
    g22 = hdr.CameraResponse(jnp.asarray([2.2]), "gamma", "g", 1.0, 0.5)
    assert float(hdr.response_curve_error(g2, g2)) == 0.0
    z = np.arange(10, 246) / 255.0
    d = 0.2 * np.log(z)
    expected = np.sqrt(np.mean((d - d.mean()) ** 2))
    np.testing.assert_allclose(float(hdr.response_curve_error(g2, g22)), expected, rtol=1e-5)
    e = jnp.asarray([1.0, 2.0, 4.0, 8.0])
    assert float(hdr.radiance_error(3.0 * e, e)) == pytest.approx(0.0, abs=1e-6)
    e2 = e * jnp.exp(jnp.asarray([0.0, 0.1, 0.1, 0.3]))
    # log ratios 0, .1, .1, .3: median .1; |d - .1| = .1, 0, 0, .2 → median .05
    assert float(hdr.radiance_error(e2, e)) == pytest.approx(0.05, abs=1e-6)


def test_synthetic_bad_inputs():
    with pytest.raises(ValueError, match="name"):
        hdr.synthetic_response("linearish")
    with pytest.raises(ValueError, match="bits"):
        hdr.make_bracketed_stack(
            jax.random.key(0),
            jnp.ones((8, 8)),
            jnp.ones(2),
            hdr.synthetic_response("srgb", channels=1),
            bits=12,
        )
    with pytest.raises(ValueError, match="dynamic_range"):
        hdr.synthetic_radiance(jax.random.key(0), 16, 16, dynamic_range=0.5)
