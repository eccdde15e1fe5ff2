"""Bijections for bounded parameters: round trips, closed-form derivatives, bounds, hard cases."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.optim import Interval, from_unconstrained, to_unconstrained
from jaxgfx.optim._transforms import check_bounds


def _sigmoid(u):
    return 1.0 / (1.0 + np.exp(-u))


@pytest.mark.parametrize(
    ("lo", "hi", "closed_form", "dclosed"),
    [
        (0.5, 3.0, lambda u: 0.5 + 2.5 * _sigmoid(u), lambda u: 2.5 * _sigmoid(u) * _sigmoid(-u)),
        (1.0, None, lambda u: 1.0 + np.log1p(np.exp(u)), _sigmoid),
        (None, 2.0, lambda u: 2.0 - np.log1p(np.exp(u)), lambda u: -_sigmoid(u)),
        (None, None, lambda u: u, lambda u: np.ones_like(u)),
    ],
)
# 3.1 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_forward_and_derivative_closed_form(x64, lo, hi, closed_form, dclosed):
    b = Interval(lo, hi)
    u = np.linspace(-8.0, 8.0, 17)
    x = np.asarray(jax.jit(b.forward)(jnp.asarray(u)))
    np.testing.assert_allclose(x, closed_form(u), rtol=1e-12, atol=1e-12)
    dx = np.asarray(jax.vmap(jax.grad(b.forward))(jnp.asarray(u)))
    np.testing.assert_allclose(dx, dclosed(u), rtol=1e-10, atol=1e-14)
    # round trip (the interior, away from the 1e-3 margin: |u| < 6.9) and the inverse's
    # derivative 1 / f'(u)
    u, x = u[2:-2], x[2:-2]
    np.testing.assert_allclose(
        np.asarray(jax.jit(b.inverse)(jnp.asarray(x))), u, rtol=1e-8, atol=1e-8
    )
    dinv = np.asarray(jax.vmap(jax.grad(b.inverse))(jnp.asarray(x)))
    np.testing.assert_allclose(dinv, 1.0 / dclosed(u), rtol=1e-7)


def test_values_never_leave_the_open_interval_float32():
    b = Interval(1e-3, 1.0)
    x = b.forward(jnp.asarray([-1e4, -100.0, 0.0, 100.0, 1e4], jnp.float32))
    assert np.all(np.asarray(x) >= 1e-3) and np.all(np.asarray(x) <= 1.0)
    g = jax.vmap(jax.grad(b.forward))(jnp.asarray([-1e4, 1e4], jnp.float32))
    assert np.all(np.isfinite(np.asarray(g)))
    p = Interval(0.0, None).forward(jnp.asarray([-200.0], jnp.float32))
    assert float(p[0]) >= 0.0 and np.isfinite(float(p[0]))


def test_init_on_a_bound_moves_inside_by_the_margin(x64):
    b = Interval(0.001, 1.0)
    for x, expect in ((0.001, 0.001 + 0.999e-3), (1.0, 1.0 - 0.999e-3)):
        u = b.inverse(x)
        assert np.isfinite(float(u))
        np.testing.assert_allclose(float(b.forward(u)), expect, rtol=1e-12)
        assert float(jax.grad(b.forward)(u)) > 0  # the optimiser can move away from the bound
    lower = Interval(0.0, None)
    np.testing.assert_allclose(float(lower.forward(lower.inverse(0.0))), 1e-3, rtol=1e-10)


def test_pytree_prefix_bounds_and_per_element_arrays(x64):
    params = {"alpha": jnp.asarray(0.3), "rgb": jnp.asarray([0.2, 0.5, 0.9]), "free": -4.0}
    bounds = {"alpha": (1e-3, 1.0), "rgb": (np.zeros(3), np.array([1.0, 1.0, 2.0])), "free": None}
    u = to_unconstrained(params, bounds)
    t = (0.3 - 1e-3) / (1.0 - 1e-3)
    np.testing.assert_allclose(float(u["alpha"]), np.log(t / (1 - t)), rtol=1e-12)
    np.testing.assert_allclose(float(u["free"]), -4.0)
    back = from_unconstrained(u, bounds)
    for k in params:
        np.testing.assert_allclose(np.asarray(back[k]), np.asarray(params[k]), rtol=1e-12)
    # logit for the third channel uses its own (0, 2) interval
    np.testing.assert_allclose(float(u["rgb"][2]), np.log(0.45 / 0.55), rtol=1e-10)


def test_bad_bounds_raise():
    with pytest.raises(ValueError, match="lo < hi"):
        Interval(1.0, 0.5)
    with pytest.raises(ValueError, match="finite"):
        Interval(0.0, np.inf)
    with pytest.raises(ValueError, match=r"params\['a'\].*outside"):
        check_bounds({"a": jnp.asarray(1.5)}, {"a": (0.0, 1.0)})
    with pytest.raises(ValueError, match=r"params\['a'\]"):
        check_bounds({"a": jnp.asarray(np.nan)}, None)
    with pytest.raises(ValueError, match="prefix"):
        to_unconstrained({"a": 1.0}, {"b": (0.0, 2.0)})
    with pytest.raises(TypeError, match="bounds"):
        to_unconstrained({"a": 1.0}, {"a": 3.0})
    check_bounds({"a": jnp.asarray(1.0)}, {"a": (0.0, 1.0)})  # on the bound: accepted
