"""Gradients of every continuous parameter of every operator against central finite
differences in float64 (jax.test_util.check_grads), and finite gradients on hard images."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxgfx import tonemap as tm
from tests.tonemap._refs import synthetic_hdr

STATIC = {
    "contrast_inversion": {"radius": 6},
    "durand": {"range_bins": 40, "sigma_spatial": 2.0},
}
# finite differences (float64) need a converged solve: the implicit derivative is that of the
# exact solution, the finite difference that of the iterate
FD_STATIC = {"mantiuk": {"tol": 1e-12, "iterations": 4000}}
POINT = {  # evaluation points away from clipping kinks
    "exposure": {"exposure": -3.0, "gamma": 1.3, "saturation": 0.9},
    "contrast_inversion": {"k": 3.0, "sigma": 1.5, "saturation": 0.9},
    "reinhard_local": {"key": 0.1, "saturation": 0.9},
    "reinhard_devlin": {"intensity": 0.3, "light_adapt": 0.6, "color_adapt": 0.4},
}


def _loss_fn(method, img, fd=False):
    specs = tm.TONEMAP_PARAMETERS[method]
    names = tuple(specs)
    point = {n: specs[n].initial for n in names}
    point.update(POINT.get(method, {}))
    if method == "reinhard_devlin":
        point["light_adapt"], point["color_adapt"] = 0.6, 0.4
    w = jnp.asarray(np.random.default_rng(5).random(img.shape), img.dtype)
    op = tm.TONEMAP_METHODS[method]
    extra = {**STATIC.get(method, {}), **(FD_STATIC.get(method, {}) if fd else {})}

    def f(p):
        y = op(img, encode="linear", **extra, **dict(zip(names, p, strict=True)))
        return jnp.sum(w * y)

    return f, jnp.asarray([point[n] for n in names], img.dtype)


# default suite: the most used global operators; the others (slow compiles) run with -m slow
DEFAULT = ("drago", "exposure", "filmic", "reinhard")
FD_CASES = [
    m if m in DEFAULT else pytest.param(m, marks=pytest.mark.slow)
    for m in sorted(tm.TONEMAP_METHODS)
]


# 4.7 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
@pytest.mark.parametrize("method", FD_CASES)
def test_parameter_gradients_match_finite_differences(method, x64):
    img = jnp.asarray(synthetic_hdr(8, 8, dynamic_range=30.0), jnp.float64) * 0.02
    f, p0 = _loss_fn(method, img, fd=True)
    g = jax.grad(f)(p0)
    assert np.all(np.isfinite(g))
    if method not in ("reinhard_local",):
        assert np.all(np.abs(g) > 0), (method, g)  # every parameter acts on the image
    check_grads(f, (p0,), order=1, modes=("rev",), eps=1e-5, atol=1e-5, rtol=1e-4)


HARD_CASES = [
    m if m in ("drago", "exposure") else pytest.param(m, marks=pytest.mark.slow)
    for m in sorted(tm.TONEMAP_METHODS)
]


# 3.7 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
@pytest.mark.parametrize("method", HARD_CASES)
def test_gradients_finite_on_zeros_and_spike(method):
    img = synthetic_hdr(8, 8, zeros=True)
    img[2, 3] = 1e6
    names = tuple(tm.TONEMAP_PARAMETERS[method])
    _, p0 = _loss_fn(method, jnp.asarray(img))
    op = tm.TONEMAP_METHODS[method]
    extra = STATIC.get(method, {})

    def f(p, im):
        return jnp.sum(op(im, **extra, **dict(zip(names, p, strict=True))))

    gp, gi = jax.grad(f, argnums=(0, 1))(p0, jnp.asarray(img))
    assert np.all(np.isfinite(gp)) and np.all(np.isfinite(gi)), method


# issue 27: zero backgrounds with a 1e6 sun; compiling the gradient of the local operators takes
# 10-20 s each on a loaded 2-core run (measured), so only the global ones run by default
@pytest.mark.parametrize("method", HARD_CASES)
def test_gradients_finite_on_black_background_scenes(method):
    from tests.tonemap._refs import hard_scenes

    names = tuple(tm.TONEMAP_PARAMETERS[method])
    op = tm.TONEMAP_METHODS[method]
    extra = STATIC.get(method, {})
    scenes = hard_scenes(32, 8)
    _, p0 = _loss_fn(method, jnp.asarray(scenes["stars"]))

    def f(p, im):
        return jnp.sum(op(im, **extra, **dict(zip(names, p, strict=True))))

    grad = jax.jit(jax.grad(f, argnums=(0, 1)))
    for name, img in scenes.items():
        gp, gi = grad(p0, jnp.asarray(img))
        assert np.all(np.isfinite(gp)) and np.all(np.isfinite(gi)), (method, name)
