"""Image losses against NumPy / colour-science formulas; gradients vs FD; hard cases; jit."""

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxgfx.optim import censored_l2_loss, image_loss, l1_loss, l2_loss, relative_l2_loss


@pytest.fixture(scope="module")
def pair():
    rng = np.random.default_rng(0)
    x = rng.uniform(0.0, 2.0, size=(2, 5, 4, 3))
    y = rng.uniform(0.0, 2.0, size=(2, 5, 4, 3))
    mask = (rng.uniform(size=(2, 5, 4)) > 0.4).astype(np.float64)
    return x, y, mask


def test_linear_and_log_losses_match_numpy(x64, pair):
    x, y, mask = pair
    m3 = np.broadcast_to(mask[..., None], x.shape)
    jl2 = jax.jit(lambda a, b: l2_loss(a, b))
    np.testing.assert_allclose(float(jl2(x, y)), np.mean((x - y) ** 2), rtol=1e-12)
    np.testing.assert_allclose(
        float(l1_loss(x, y, mask=mask)), np.sum(m3 * np.abs(x - y)) / np.sum(m3), rtol=1e-12
    )
    lx, ly = np.log(x + 0.05), np.log(y + 0.05)
    got = jax.jit(lambda a, b, m: l2_loss(a, b, space="log", mask=m, offset=0.05))(x, y, mask)
    np.testing.assert_allclose(float(got), np.sum(m3 * (lx - ly) ** 2) / np.sum(m3), rtol=1e-12)
    rel = relative_l2_loss(x, y, eps=1e-2)
    np.testing.assert_allclose(float(rel), np.mean((x - y) ** 2 / (x**2 + 1e-2)), rtol=1e-12)
    np.testing.assert_allclose(
        float(image_loss(x, y, kind="l1")), np.mean(np.abs(x - y)), rtol=1e-12
    )


def test_lab_loss_is_mean_squared_delta_e_1976(x64, pair):
    x, y, _ = pair
    x, y = x / 2.0, y / 2.0
    lab = lambda v: colour.XYZ_to_Lab(colour.RGB_to_XYZ(v, "sRGB", apply_cctf_decoding=False))
    de = colour.delta_E(lab(x), lab(y), method="CIE 1976")
    got = jax.jit(lambda a, b: l2_loss(a, b, space="lab"))(x, y)
    np.testing.assert_allclose(float(got), np.mean(de**2) / 3.0, rtol=2e-4)


def test_relative_l2_gradient_has_the_detached_denominator(x64):
    x = jnp.asarray([0.0, 0.5, 3.0])
    y = jnp.asarray([0.2, 0.1, 1.0])
    g = jax.grad(lambda a: relative_l2_loss(a, y, eps=0.01))(x)
    ref = 2.0 * (np.asarray(x) - np.asarray(y)) / (np.asarray(x) ** 2 + 0.01) / 3.0
    np.testing.assert_allclose(np.asarray(g), ref, rtol=1e-12)


@pytest.mark.parametrize("space", ["linear", "log", "lab"])
def test_gradients_match_finite_differences(x64, pair, space):
    x, y, mask = pair
    # (relative L2 is excluded on purpose: its detached denominator makes AD differ from FD;
    # its gradient is checked against the closed form above)
    x, y, mask = x[0, :2], y[0, :2], mask[0, :2]
    check_grads(
        jax.jit(lambda a: l2_loss(a, y, space=space, mask=mask)),
        (x,),
        order=1,
        modes=("rev",),
        atol=1e-6,
        rtol=1e-5,
        eps=1e-6,
    )
    check_grads(
        jax.jit(lambda a: l1_loss(a, y, space=space)),
        (x,),
        order=1,
        modes=("fwd",),
        atol=1e-6,
        rtol=1e-5,
        eps=1e-6,
    )


def test_hard_cases_zeros_negatives_and_empty_mask():
    x = jnp.asarray([[[0.0, 0.0, 0.0], [-0.1, 1e-8, 50.0]]])
    y = jnp.zeros_like(x)
    combos = [
        (f, s) for s in ("linear", "log", "lab") for f in (l2_loss, relative_l2_loss, l1_loss)
    ]

    # the gradient of the sum is finite only if every loss's gradient is (a NaN propagates)
    v, g = jax.jit(
        jax.value_and_grad(lambda a: jnp.stack([f(a, y, space=s) for f, s in combos]).sum())
    )(x)
    assert np.all(np.isfinite(np.asarray(v))) and np.all(np.isfinite(np.asarray(g)))
    assert float(l2_loss(x, y + 1.0, mask=jnp.zeros((1, 2)))) == 0.0
    g = jax.grad(lambda a: l1_loss(a, a))(x)  # |x - x|: gradient 0, not NaN
    assert np.all(np.asarray(g) == 0.0)


def test_censored_l2_values_and_gradients(x64):
    v = jnp.asarray([1.3, 0.99, 0.5, -0.2, 0.01])
    q = jnp.asarray([255.0, 255.0, 102.0, 0.0, 0.0])
    hi, lo = 254.5 / 255, 0.5 / 255
    e = np.array([0.0, hi - 0.99, 0.5 - 0.4, 0.0, 0.01 - lo])
    np.testing.assert_allclose(float(jax.jit(censored_l2_loss)(v, q)), np.mean(e**2), rtol=1e-12)
    g = np.asarray(jax.grad(censored_l2_loss)(v, q))
    np.testing.assert_allclose(
        g, 2 * np.array([0, -e[1], e[2], 0, e[4]]) / 5, rtol=1e-12, atol=1e-15
    )


def test_bad_inputs():
    with pytest.raises(ValueError, match="y: expected the shape"):
        l2_loss(jnp.ones((2, 2, 3)), jnp.ones((2, 3, 3)))
    with pytest.raises(ValueError, match="space"):
        l2_loss(jnp.ones(3), jnp.ones(3), space="gamma")
    with pytest.raises(ValueError, match="mask"):
        l2_loss(jnp.ones((2, 2, 3)), jnp.ones((2, 2, 3)), mask=jnp.ones((3, 3)))
    with pytest.raises(ValueError, match="lab"):
        l2_loss(jnp.ones((2, 2, 1)), jnp.ones((2, 2, 1)), space="lab")
    with pytest.raises(ValueError, match="kind"):
        image_loss(jnp.ones(3), jnp.ones(3), kind="huber")
