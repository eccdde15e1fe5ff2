"""Safe math: values match NumPy away from singularities; values and gradients finite at them."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxgfx import _math
from jaxgfx._checks import (
    check_choice,
    check_image,
    check_odd_int,
    check_positive,
    check_positive_int,
)


@pytest.mark.parametrize(
    "fn, ref, xs",
    [
        (_math.safe_sqrt, np.sqrt, [0.25, 2.0, 9.0]),
        (_math.safe_log, np.log, [0.5, 1.0, 7.0]),
        (lambda x: _math.safe_pow(x, 2.2), lambda x: x**2.2, [0.1, 0.5, 3.0]),
        (_math.safe_arccos, np.arccos, [-0.9, 0.0, 0.7]),
    ],
)
# 7.7 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_matches_numpy_and_grads(x64, fn, ref, xs):
    x = jnp.asarray(xs, jnp.float64)
    np.testing.assert_allclose(fn(x), ref(np.asarray(xs)), rtol=1e-12)
    np.testing.assert_allclose(jax.jit(fn)(x), ref(np.asarray(xs)), rtol=1e-12)
    check_grads(fn, (x,), order=2, modes=["fwd", "rev"])


_LOG_TINY32 = float(np.log(np.finfo(np.float32).tiny))  # -87.33654...


@pytest.mark.parametrize(
    "fn, x, value, grad",
    [
        # (function, singular point, documented value there, documented gradient there)
        (_math.safe_sqrt, 0.0, 0.0, 0.0),
        (_math.safe_sqrt, -1.0, 0.0, 0.0),
        (_math.safe_log, 0.0, _LOG_TINY32, 0.0),  # log(floor), floor = smallest normal
        (lambda x: _math.safe_pow(x, 0.5), 0.0, 0.0, 0.0),
        (_math.safe_arccos, 1.0, 0.0, 0.0),
        (_math.safe_arccos, -1.0, np.pi, 0.0),
        (lambda x: _math.safe_div(1.0, x), 0.0, 0.0, 0.0),  # the fill value
        (lambda x: _math.safe_div(1.0, x, fill=-1.0), 0.0, -1.0, 0.0),
        (lambda x: _math.safe_atan2(x, x), 0.0, 0.0, 0.0),
        (lambda x: _math.safe_norm(jnp.stack([x, x, x])), 0.0, 0.0, 0.0),
        (lambda x: _math.safe_normalize(jnp.stack([x, x, x])).sum(), 0.0, 0.0, 0.0),
    ],
)
def test_singular_points_values_and_grads(fn, x, value, grad):
    x = jnp.float32(x)
    v, g = jax.jit(jax.value_and_grad(fn))(x)
    np.testing.assert_allclose(float(v), value, rtol=1e-6, atol=0)
    assert float(g) == grad


def test_safe_functions_next_to_their_singular_points(x64):
    # just inside the safe region the ordinary formula holds (values and derivatives)
    for x in (1e-300, 1e-8):
        np.testing.assert_allclose(float(_math.safe_sqrt(x)), np.sqrt(x), rtol=1e-15)
        np.testing.assert_allclose(
            float(jax.grad(_math.safe_sqrt)(x)), 0.5 / np.sqrt(x), rtol=1e-15
        )
        np.testing.assert_allclose(float(jax.grad(_math.safe_log)(x)), 1.0 / x, rtol=1e-15)
    c = 1.0 - 1e-6
    np.testing.assert_allclose(float(_math.safe_arccos(c)), np.arccos(c), rtol=1e-9)
    np.testing.assert_allclose(
        float(jax.grad(_math.safe_arccos)(c)), -1.0 / np.sqrt(1.0 - c * c), rtol=1e-9
    )


def test_safe_normalize_and_atan2_values():
    v = jnp.array([3.0, 4.0, 0.0])
    np.testing.assert_allclose(_math.safe_normalize(v), [0.6, 0.8, 0.0], rtol=1e-6)
    np.testing.assert_allclose(_math.safe_atan2(1.0, -1.0), 3 * np.pi / 4, rtol=1e-6)
    assert _math.safe_div(1.0, 0.0, fill=-1.0) == -1.0


def test_checks_raise_with_names():
    with pytest.raises(ValueError, match="img"):
        check_image(np.zeros(5), "img")
    with pytest.raises(ValueError, match="img.*NaN"):
        check_image(np.full((2, 2), np.nan), "img")
    with pytest.raises(ValueError, match="C in"):
        check_image(np.zeros((4, 4, 2)), "img", channels=3)
    with pytest.raises(TypeError, match="img"):
        check_image("foo", "img")
    with pytest.raises(ValueError, match="padding"):
        check_choice("mirror", "padding", ("zero", "reflect"))
    with pytest.raises(ValueError, match="sigma"):
        check_positive(-1.0, "sigma")
    with pytest.raises(ValueError, match="size"):
        check_odd_int(4, "size")
    with pytest.raises(TypeError, match="size"):
        check_odd_int(3.0, "size")
    for bad in (0, -2, True, 2.0, "3"):
        with pytest.raises(ValueError, match="spp: expected a positive integer"):
            check_positive_int(bad, "spp")
    assert check_positive_int(3, "spp") == 3
    # tracers are let through
    jax.jit(lambda s: check_positive(s, "sigma") * 2)(1.0)
    assert check_image(np.ones((3, 3), np.uint8)).dtype == jnp.float32


# ---------------------------------------------------------------- fusion-friendly helpers


def test_sincos_matches_numpy_f32():
    x = np.linspace(-1e4, 1e4, 200001).astype(np.float32)
    s, c = jax.jit(_math.sincos)(x)
    xs = x.astype(np.float64)
    # 2 ulp of 1.0 in float32
    assert np.abs(np.asarray(s, np.float64) - np.sin(xs)).max() < 2.4e-7
    assert np.abs(np.asarray(c, np.float64) - np.cos(xs)).max() < 2.4e-7
    s, c = _math.sincos(jnp.float32(np.pi / 6))
    np.testing.assert_allclose([s, c], [0.5, np.sqrt(3) / 2], rtol=2e-7)


def test_sincos_range_reduction_is_exact_without_fma():
    """Every pi/2 part but the last times any reduction index k (|k| < 2^13 for |x| <= 1e4 in
    float32, |k| < 2^20 for |x| <= 1e6 in float64) is exact in the working precision, so the
    result does not depend on whether the compiler fuses x - k * part into an FMA. Reference:
    the product in exact rational arithmetic."""
    from fractions import Fraction

    for dtype, kmax in ((np.float32, 2**13), (np.float64, 2**20)):
        parts = _math._PIO2[np.dtype(dtype).name]
        pi_half = Fraction("1.570796326794896619231321691639751442098584699687552910487")
        assert abs(float(sum(Fraction(p) for p in parts) - pi_half)) < 1e-14
        ks = np.concatenate([np.arange(1, 4097), kmax - np.arange(1, 4097)]).astype(dtype)
        for part in parts[:-1]:
            assert Fraction(float(dtype(part))) == Fraction(part)  # representable
            prod = ks * dtype(part)
            exact = [Fraction(int(k)) * Fraction(part) for k in ks]
            assert all(Fraction(float(a)) == b for a, b in zip(prod, exact, strict=True))


# 3.1 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_sincos_matches_numpy_f64_and_grads(x64):
    x = np.linspace(-1e6, 1e6, 200001)
    s, c = jax.jit(_math.sincos)(jnp.asarray(x))
    assert np.abs(np.asarray(s) - np.sin(x)).max() < 4.5e-16
    assert np.abs(np.asarray(c) - np.cos(x)).max() < 4.5e-16
    xs = jnp.asarray([-7.0, -0.3, 0.0, 0.785398, 2.5, 100.0])
    check_grads(lambda t: _math.sincos(t)[0] + 2 * _math.sincos(t)[1], (xs,), order=2)


def test_sum_max_last_and_vdot():
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 4, 7):
        x = rng.normal(size=(5, 6, n)).astype(np.float32)
        np.testing.assert_allclose(_math.sum_last(x), x.sum(-1), rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(_math.max_last(x), x.max(-1))
        np.testing.assert_allclose(
            _math.sum_last(x, keepdims=True), x.sum(-1, keepdims=True), rtol=1e-6, atol=1e-6
        )
        np.testing.assert_allclose(
            jax.jit(_math.vdot)(x, x[::-1]), (x * x[::-1]).sum(-1), rtol=1e-5, atol=1e-6
        )


def test_sum_last_equals_left_to_right_adds_bitwise():
    # the unrolled sum keeps the order x0 + x1 + x2 (+ x3): the renders do not change
    x = jnp.asarray(np.random.default_rng(1).normal(size=(64, 3)), jnp.float32) * 1e3
    ref = (x[:, 0] + x[:, 1]) + x[:, 2]
    np.testing.assert_array_equal(jax.jit(_math.sum_last)(x), ref)
    x4 = jnp.concatenate([x, x[:, :1] * 1e-3], -1)
    np.testing.assert_array_equal(_math.max_last(x4), np.max(np.asarray(x4), -1))


def test_cross_matches_numpy_jnp_and_grads(x64):
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(4, 5, 3)), rng.normal(size=(5, 3))  # broadcasting as jnp.cross
    np.testing.assert_allclose(jax.jit(_math.cross)(a, b), np.cross(a, b), rtol=1e-14)
    a32, b32 = jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32)
    # the same products; only float32 rounding differs (whether a multiply-add is fused)
    bound = 2 * np.finfo(np.float32).eps * np.abs(a[..., [1, 2, 0]] * b[..., [2, 0, 1]]).max()
    np.testing.assert_allclose(_math.cross(a32, b32), jnp.cross(a32, b32), rtol=0, atol=bound)
    check_grads(_math.cross, (jnp.asarray(a[0]), jnp.asarray(b)), order=1, modes=["rev"])
    with pytest.raises(ValueError, match="cross: expected vectors of length 3"):
        _math.cross(np.ones(2), np.ones(3))


# 3.4 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_fusion_barrier_is_identity_with_gradients(x64):
    x = jnp.asarray([0.5, -2.0, 3.0])
    tree = {"a": x, "b": x > 0}
    out = jax.jit(_math.fusion_barrier)(tree)
    np.testing.assert_array_equal(out["a"], x)
    np.testing.assert_array_equal(out["b"], [True, False, True])
    # a value whose bit pattern equals the sentinel still passes through (both branches agree)
    sentinel = jax.lax.bitcast_convert_type(jnp.int32(0x7FBADBAD), jnp.float32)
    np.testing.assert_array_equal(
        jnp.isnan(_math.fusion_barrier(jnp.stack([sentinel, 1.0]))), [True, False]
    )
    check_grads(lambda v: (_math.fusion_barrier(v * v) ** 2).sum(), (x,), order=2)
    g = jax.vmap(lambda v: _math.fusion_barrier(v).sum())(jnp.ones((4, 3)))
    np.testing.assert_array_equal(g, [3.0] * 4)
    # the sentinel in the first leaf runs the other branch: booleans must come out unchanged
    flags = jnp.asarray([True, False])
    out = jax.jit(_math.fusion_barrier)((jnp.stack([sentinel, 1.0]), flags))
    np.testing.assert_array_equal(out[1], [True, False])


def test_fusion_barrier_keeps_boolean_leaves_materialised():
    # Were both branches the identity on a boolean leaf, XLA would forward it past the
    # conditional (the barrier vanished for booleans before): the compiled program of a
    # boolean-only barrier must still hold the conditional.
    def f(x):
        return _math.fusion_barrier(x > 0.5) & (x < 2.0)

    hlo = jax.jit(f).lower(jnp.ones(8)).compile().as_text()
    assert "conditional(" in hlo
    np.testing.assert_array_equal(jax.jit(f)(jnp.asarray([0.0, 1.0, 3.0])), [False, True, False])


# 3.8 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_fusion_barrier_stays_a_cond_under_vmap(x64):
    """A batched predicate would turn the cond into a select (no barrier: render vmapped over
    keys was 7-31x slower per key, docs/performance.md); the predicate is read from one element
    of the batch instead. Values and derivatives through vmap, nested vmap, grad and jacfwd
    against the closed form of f(v) = sum(barrier(v * v)^2) = sum(v^4): df/dv = 4 v^3."""

    def f(v):
        return (_math.fusion_barrier({"a": v * v, "b": v > 0})["a"] ** 2).sum()

    def prims(fn, *args):
        return [e.primitive.name for e in jax.make_jaxpr(fn)(*args).jaxpr.eqns]

    x = jnp.asarray(np.random.default_rng(0).normal(size=(2, 4, 3)))
    assert "cond" in prims(jax.vmap(f), x[0])
    assert "cond" in prims(jax.vmap(jax.vmap(f)), x)
    assert "cond" in prims(jax.vmap(jax.grad(f)), x[0])
    assert "select_n" not in prims(jax.vmap(jax.vmap(f)), x)
    np.testing.assert_allclose(jax.jit(jax.vmap(jax.vmap(f)))(x), (x**4).sum(-1), rtol=1e-12)
    np.testing.assert_allclose(jax.jit(jax.vmap(jax.vmap(jax.grad(f))))(x), 4 * x**3, rtol=1e-12)
    np.testing.assert_allclose(
        jax.grad(lambda x: jax.vmap(jax.vmap(f))(x).sum())(x), 4 * x**3, rtol=1e-12
    )
    np.testing.assert_allclose(jax.vmap(jax.jacfwd(f))(x[0]), 4 * x[0] ** 3, rtol=1e-12)
    # the barrier's sentinel inside a batch: still the identity on every element
    sentinel = jax.lax.bitcast_convert_type(jnp.int32(0x7FBADBAD), jnp.float32)
    batch = jnp.stack([jnp.stack([sentinel, 1.0]), jnp.ones(2, jnp.float32)])
    out = jax.vmap(_math.fusion_barrier)(batch)
    np.testing.assert_array_equal(jnp.isnan(out), [[True, False], [False, False]])
