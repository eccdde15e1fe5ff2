"""Host data (lists, tuples, NumPy arrays) becomes a JAX array without a compiled program:
``as_float_array``, ``to_rgb`` and a scene's rectangles (the description's constants)."""

import jax
import jax.monitoring
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx._checks import as_float_array
from jaxgfx.render.bsdf._base import to_rgb
from jaxgfx.render.geometry.frame import frame_from_normal
from jaxgfx.render.scene.schema import rectangle_from_desc

_COMPILES = [0]  # XLA programs compiled in this worker (a jax.monitoring event each)


def _count(name, secs, **kw):
    if name.endswith("backend_compile_duration"):
        _COMPILES[0] += 1


jax.monitoring.register_event_duration_secs_listener(_count)


def _compiles(fn):
    """``fn()`` and the number of XLA programs it compiled."""
    n0 = _COMPILES[0]
    out = fn()
    jax.block_until_ready(out)
    return out, _COMPILES[0] - n0


# fresh shapes: no program compiled by another test can serve them
@pytest.mark.parametrize(
    "x, dtype",
    [
        ([[1, 2, 3, 4, 5, 6, 7]], np.float32),  # integers become float32
        ((0.5, 0.25, 0.125, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0), np.float32),
        (np.arange(11, dtype=np.float64), np.float32),  # float64 without x64: float32
        (np.arange(13, dtype=np.float16), np.float16),
    ],
)
def test_host_data_converts_without_compiling_and_as_jax_would(x, dtype):
    out, n = _compiles(lambda: as_float_array(x, "x"))
    assert n == 0
    ref = jnp.asarray(x)  # what it was before: JAX's conversion, then a float cast
    ref = ref if jnp.issubdtype(ref.dtype, jnp.floating) else ref.astype(jnp.float32)
    assert out.dtype == ref.dtype == dtype and out.shape == ref.shape
    np.testing.assert_array_equal(np.asarray(out), np.asarray(ref))


def test_python_numbers_keep_jaxs_weak_type():
    assert as_float_array(0.5, "x").weak_type
    assert as_float_array(3, "x").dtype == jnp.float32


@pytest.mark.parametrize(
    "x, match",
    [(["a", "b"], "x: expected an array of numbers"), ([True, False], "x: expected a numeric"),
     ([[1, 2], [3]], "x: expected an array of numbers"), (None, "x: expected an array")],
)  # fmt: skip
def test_bad_host_data_gets_one_clear_error(x, match):
    with pytest.raises(TypeError, match=match):
        as_float_array(x, "x")


def test_a_list_of_tracers_is_stacked_under_jit_and_differentiable():
    f = jax.jit(jax.grad(lambda r: jnp.sum(to_rgb([r, 2 * r, 3 * r], "albedo") ** 2)))
    assert float(f(1.0)) == pytest.approx(2 * (1 + 4 + 9))  # d/dr of 14 r^2 at 1


def test_to_rgb_broadcasts_host_data_without_compiling():
    out, n = _compiles(lambda: to_rgb(np.full((5, 1), 0.25), "albedo"))
    assert n == 0 and out.shape == (5, 3)
    np.testing.assert_array_equal(np.asarray(out), 0.25)
    with pytest.raises(ValueError, match=r"albedo: expected a scalar or an RGB array"):
        to_rgb([1.0, 2.0], "albedo")


def test_rectangle_from_a_description_compiles_nothing_and_matches_the_jax_frame():
    d = {"center": [0, 1, 0], "normal": [0.3, -2.0, 0.5], "size": [1.5, 0.75]}
    rect, n = _compiles(lambda: rectangle_from_desc(d, "shapes[0]"))
    assert n == 0
    nrm = jnp.asarray([0.3, -2.0, 0.5]) / jnp.linalg.norm(jnp.asarray([0.3, -2.0, 0.5]))
    fr = frame_from_normal(nrm)  # the traced construction it replaces
    np.testing.assert_allclose(np.asarray(rect.edge_u[0]), np.asarray(fr.s) * 1.5, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(rect.edge_v[0]), np.asarray(fr.t) * 0.75, rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(rect.centers), [[0.0, 1.0, 0.0]])
    for bad, match in [({"normal": [0, 0, 0]}, "normal: expected a non-zero vector"),
                       ({"size": [1.0, -1.0]}, "size: expected two positive numbers")]:  # fmt: skip
        with pytest.raises(ValueError, match=match):
            rectangle_from_desc({**d, **bad}, "shapes[0]")
