"""Correlated colour temperature by Robertson (1968) against colour-science's implementation
of the same method and table; jit and finite-difference gradients."""

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.color import cct_to_xy, xy_to_cct

XY = np.array(
    [[0.3127, 0.329], [0.44758, 0.40745], [0.3457, 0.3585], [0.28, 0.29], [0.5, 0.41], [0.33, 0.36]]
)


def test_xy_to_cct_vs_colour(x64):
    ours = np.asarray(jax.jit(xy_to_cct)(jnp.asarray(XY)))
    uv = colour.UCS_to_uv(colour.XYZ_to_UCS(colour.xy_to_XYZ(XY)))
    ref = np.array([colour.temperature.uv_to_CCT_Robertson1968(p)[0] for p in uv])
    np.testing.assert_allclose(ours, ref, rtol=1e-9)
    assert abs(float(xy_to_cct(jnp.array([0.3127, 0.329]))) - 6504) < 1  # D65, float32


@pytest.mark.parametrize("cct", [1800.0, 2856.0, 4000.0, 5003.0, 6504.0, 10000.0, 20000.0])
def test_cct_to_xy_vs_colour(x64, cct):
    ours = np.asarray(jax.jit(cct_to_xy)(jnp.asarray(cct)))
    ref = colour.UCS_uv_to_xy(colour.temperature.CCT_to_uv_Robertson1968(np.array([cct, 0.0])))
    np.testing.assert_allclose(ours, ref, atol=1e-12)
    np.testing.assert_allclose(float(xy_to_cct(ours)), cct, rtol=1e-5)  # round trip (the
    # two directions interpolate along different lines: inverse to ~1e-6, not exactly)


def test_gradients_vs_finite_differences(x64):
    xy = jnp.array([0.36, 0.37])
    g = jax.grad(lambda p: xy_to_cct(p))(xy)
    h = 1e-7
    fd = [(xy_to_cct(xy + h * e) - xy_to_cct(xy - h * e)) / (2 * h) for e in jnp.eye(2)]
    np.testing.assert_allclose(np.asarray(g), np.asarray(fd), rtol=1e-5)
    t = jnp.array(4321.0)
    gt = jax.grad(lambda c: cct_to_xy(c)[0])(t)
    fdt = (cct_to_xy(t + 1e-3)[0] - cct_to_xy(t - 1e-3)[0]) / 2e-3
    np.testing.assert_allclose(float(gt), float(fdt), rtol=1e-5)


def test_bad_cct():
    with pytest.raises(ValueError, match="cct"):
        cct_to_xy(-5.0)
