"""Transfer functions vs colour-science, closed forms, round trips, gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from colour.models import (
    cctf_decoding_ProPhotoRGB,
    cctf_encoding_ProPhotoRGB,
    eotf_inverse_sRGB,
    eotf_sRGB,
    oetf_BT709,
    oetf_inverse_BT709,
)
from jax.test_util import check_grads

from jaxgfx.color import (
    ADOBE_RGB_GAMMA,
    TRANSFER_FUNCTIONS,
    adobe_rgb_to_linear,
    gamma_decode,
    gamma_encode,
    linear_to_adobe_rgb,
    linear_to_prophoto,
    linear_to_rec709,
    linear_to_srgb,
    prophoto_to_linear,
    rec709_to_linear,
    srgb_to_linear,
    transfer_decode,
    transfer_encode,
)

# (ours, colour-science reference) on non-negative inputs
PAIRS = [
    (linear_to_srgb, eotf_inverse_sRGB),
    (srgb_to_linear, eotf_sRGB),
    (linear_to_rec709, oetf_BT709),
    (rec709_to_linear, oetf_inverse_BT709),
    (linear_to_prophoto, cctf_encoding_ProPhotoRGB),
    (prophoto_to_linear, cctf_decoding_ProPhotoRGB),
    (linear_to_adobe_rgb, lambda x: np.power(x, 256.0 / 563.0)),
    (adobe_rgb_to_linear, lambda x: np.power(x, 563.0 / 256.0)),
]
ROUND_TRIPS = [(enc, dec) for name, (enc, dec) in TRANSFER_FUNCTIONS.items()]


def _samples(rng):
    # dense on [0, 1] plus HDR values and points just either side of every knee (exactly at a
    # knee, colour-science's eotf_sRGB switches at 0.0404482 instead of the standard's 0.04045)
    knees = np.array([0.0031308, 0.04045, 0.018, 0.081, 1 / 512, 1 / 32])
    near = np.concatenate([knees * (1 - 1e-4), knees * (1 + 1e-4)])
    return np.concatenate([rng.uniform(0, 1, 200), rng.uniform(0, 4, 20), near, [0.0, 1.0]])


def test_named_values(x64):
    assert float(linear_to_srgb(0.18)) == pytest.approx(0.46135612950044164, rel=1e-14)
    assert float(srgb_to_linear(0.46135612950044164)) == pytest.approx(0.18, rel=1e-14)
    # sRGB 8-bit mid grey 128/255 -> 0.21586050011389926 (IEC 61966-2-1 formula)
    assert float(srgb_to_linear(128 / 255)) == pytest.approx(0.21586050011389926, rel=1e-13)
    assert ADOBE_RGB_GAMMA == 2.19921875
    # ROMM: linear 1/512 encodes to exactly 1/32 from both branches
    assert float(linear_to_prophoto(1 / 512)) == pytest.approx(1 / 32, rel=1e-14)
    assert float(gamma_encode(0.25, 2.0)) == pytest.approx(0.5, rel=1e-15)


@jax.jit
def _all_ours(x):
    return [ours(x) for ours, _ in PAIRS]


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_vs_colour_science(dtype, rng, x64):
    """All curves, jitted, against colour-science (float64 to 1e-12, float32 to 2e-6)."""
    x = _samples(rng).astype(dtype)
    tol = dict(rtol=1e-12, atol=1e-15) if dtype == np.float64 else dict(rtol=2e-6, atol=1e-7)
    for (ours, ref), y in zip(PAIRS, _all_ours(x), strict=True):
        assert y.dtype == dtype, ours.__name__
        np.testing.assert_allclose(
            np.asarray(y), ref(x.astype(np.float64)), **tol, err_msg=ours.__name__
        )


@jax.jit
def _round_trips(x):
    return [(enc(x), dec(enc(x)), enc(-x)) for enc, dec in ROUND_TRIPS]


def test_round_trip_and_odd_extension(rng, x64):
    x = np.sort(np.concatenate([rng.uniform(-3, 3, 300), [0.0, -0.01, 0.01]]))
    for name, (y, back, yneg) in zip(TRANSFER_FUNCTIONS, _round_trips(x), strict=True):
        assert y.dtype == jnp.float64
        np.testing.assert_allclose(np.asarray(back), x, rtol=1e-12, atol=1e-15, err_msg=name)
        np.testing.assert_allclose(np.asarray(yneg), -np.asarray(y), rtol=0, atol=0)
        assert np.all(np.diff(np.asarray(y)) > 0), name  # strictly increasing


@jax.jit
def _grads_at(k):
    """Gradients at 0 and at the sRGB knee, in one compiled program."""
    g = jax.grad
    return jnp.stack(
        [
            g(linear_to_srgb)(0.0 * k),
            g(srgb_to_linear)(0.0 * k),
            g(linear_to_rec709)(0.0 * k),
            g(linear_to_prophoto)(0.0 * k),
            g(prophoto_to_linear)(0.0 * k),
            g(linear_to_srgb)(k),
            g(linear_to_srgb)(k + 1e-12),
            g(linear_to_adobe_rgb)(0.0 * k),
            g(adobe_rgb_to_linear)(0.0 * k),
            g(gamma_encode, argnums=1)(0.0 * k, 2.2),
            g(gamma_decode, argnums=1)(0.5 + 0.0 * k, 2.0),
        ]
    )


def test_gradient_at_zero_and_knees(x64):
    k = 0.0031308
    gr = np.asarray(_grads_at(k))
    np.testing.assert_allclose(gr[:5], [12.92, 1 / 12.92, 4.5, 16.0, 1 / 16], rtol=1e-14)
    # sRGB knee: one-sided slopes (closed form) are both finite and close
    below, above = gr[5], gr[6]
    assert below == pytest.approx(12.92)
    assert above == pytest.approx(1.055 / 2.4 * (k + 1e-12) ** (1 / 2.4 - 1), rel=1e-9)
    assert abs(above - below) / below < 0.02  # the standard's constants are not exactly C1
    # power laws at 0: finite (0) instead of inf/NaN
    np.testing.assert_array_equal(gr[7:10], 0.0)
    # d/dgamma x^gamma = x^gamma log x
    assert gr[10] == pytest.approx(0.25 * np.log(0.5), rel=1e-12)
    # IEC 61966-2-1: V <= 0.04045 is on the linear segment
    assert float(srgb_to_linear(0.04045)) == pytest.approx(0.04045 / 12.92, rel=1e-15)


def test_check_grads(x64):
    """Every curve and its inverse (and gamma w.r.t. both arguments) against finite
    differences, in one compiled program; points avoid the knees (the slope jumps there)."""
    x = jnp.array([0.05, 0.3, 0.9, 1.7, -0.4, 0.0005, -0.001])  # incl. linear toes

    @jax.jit
    def f(x, gamma):
        outs = []
        for enc, dec in ROUND_TRIPS[1:]:
            xs = x[:5] if enc is linear_to_adobe_rgb else x  # power law: skip 0's neighbourhood
            outs += [enc(xs), dec(xs)]
        outs += [gamma_encode(x[:5], gamma), gamma_decode(x[:5], gamma * 0.8)]
        return jnp.concatenate(outs)

    check_grads(f, (x, 2.2), order=1, modes=["rev"])


def test_vmap_and_nd_shapes(rng):
    x = rng.uniform(0, 1, (2, 5, 7, 3)).astype(np.float32)
    ref = eotf_sRGB(x.astype(np.float64))
    out = jax.jit(jax.vmap(srgb_to_linear))(x)
    assert out.shape == x.shape
    np.testing.assert_allclose(np.asarray(out), ref, rtol=2e-6, atol=1e-7)


def test_named_registry():
    x = jnp.array([0.2, 0.5])
    np.testing.assert_array_equal(
        np.asarray(transfer_encode(x, curve="srgb")), np.asarray(linear_to_srgb(x))
    )
    np.testing.assert_array_equal(
        np.asarray(transfer_decode(x, curve="prophoto")), np.asarray(prophoto_to_linear(x))
    )
    np.testing.assert_array_equal(np.asarray(transfer_encode(x, curve="linear")), np.asarray(x))


def test_bad_inputs():
    with pytest.raises(ValueError, match="curve"):
        transfer_encode(0.5, curve="srgb2")
    with pytest.raises(ValueError, match="^x: .*NaN"):
        linear_to_srgb(jnp.array([0.1, jnp.nan]))
    with pytest.raises(ValueError, match="^v: .*NaN"):
        srgb_to_linear(np.array([np.inf]))
    with pytest.raises(ValueError, match="gamma"):
        gamma_encode(0.5, 0.0)
    with pytest.raises(ValueError, match="gamma"):
        gamma_decode(0.5, -2.0)
    with pytest.raises(TypeError, match="x"):
        linear_to_srgb("0.5")
