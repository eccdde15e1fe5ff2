"""``render`` batched over keys (``jax.vmap`` under ``jax.jit``) against the same renders one key
at a time, values and gradients; and the structural property that kept the batch fast: the
renderer's fusion barriers (``lax.cond`` on a runtime predicate, ``jaxgfx._math.fusion_barrier``)
stay ``cond``s under ``vmap`` instead of becoming ``select``s (measured 7-31x slower per key before,
docs/performance.md "Batches of keys").
"""

import collections

import jax
import jax.extend
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene

from ._scenes import area_light, plane_scene, point_light

K = 3
SPP = 2
CAM = {"width": 4, "height": 4}


@pytest.fixture(scope="module")
def lit_plane():
    """4 x 4 diffuse plane under a point light, direct lighting: every fusion barrier of the
    renderer (ray pass, intersection, shading frame, light sample, BSDF eval and sample)."""
    scene = load_scene(plane_scene([point_light([0.3, 2.0, 0.2], 10.0)], cam=CAM))
    return scene, lambda scene, key: render(scene, key, spp=SPP, integrator="direct")


@pytest.mark.slow  # ~6.5 CPU s (two compiles of the direct integrator); out of make test
def test_vmap_over_keys_equals_per_key_renders(lit_plane):
    scene, image = lit_plane
    keys = jax.random.split(jax.random.key(11), K)
    one = jax.jit(image)
    ref = np.stack([np.asarray(one(scene, k)) for k in keys])
    out = jax.jit(jax.vmap(image, in_axes=(None, 0)))(scene, keys)
    assert out.shape == (K, 4, 4, 3)
    # the same operations on the same numbers: bit-identical (measured; before the fix of
    # fusion_barrier the batched program fused differently and differed by float32 rounding)
    np.testing.assert_array_equal(out, ref)
    assert np.all(ref.std(0).max(-1) > 0)  # the keys differ (else the check above is void)


# issue 9 budget: ~7 s on the quiet machine (a vmapped value_and_grad compile); the default run
# keeps the jaxpr check that the vmapped render keeps every barrier
@pytest.mark.slow
def test_gradient_of_vmap_over_keys_equals_per_key_gradients():
    """Reverse mode of the batched render against reverse mode per key, and against the closed
    form: the image of an emitter seen directly (max_depth 1) is linear in its radiance, so the
    derivative of the image mean w.r.t. a radiance scale, at 1, is the mean itself. The light
    (0.6 wide, facing the camera) covers part of the 4 x 4 image: edge pixels depend on the
    key's pixel samples."""
    light = area_light([0, 0.01, 0], [0, 1, 0], [0.6, 0.6], 5.0)
    scene = load_scene(plane_scene([light], cam=CAM))
    path = "emitters.area.0.radiance"
    base = scene.get(path)

    def mean(x, key):
        return jnp.mean(render(scene.replace(path, base * x), key, spp=SPP, max_depth=1))

    keys = jax.random.split(jax.random.key(12), K)
    vg = jax.value_and_grad(mean)
    one = jax.jit(vg)
    ref = [one(1.0, k) for k in keys]
    vals, grads = jax.jit(jax.vmap(vg, in_axes=(None, 0)))(1.0, keys)
    np.testing.assert_array_equal(vals, [v for v, _ in ref])
    np.testing.assert_allclose(grads, [g for _, g in ref], rtol=1e-6)
    np.testing.assert_allclose(grads, vals, rtol=1e-5)
    assert np.ptp(np.asarray(vals)) > 0  # the keys differ


def _count(jaxpr, counter=None):
    counter = collections.Counter() if counter is None else counter
    for eqn in jaxpr.eqns:
        counter[eqn.primitive.name] += 1
        for p in eqn.params.values():
            for sub in p if isinstance(p, (list, tuple)) else [p]:
                if isinstance(sub, jax.extend.core.ClosedJaxpr):
                    _count(sub.jaxpr, counter)
                elif isinstance(sub, jax.extend.core.Jaxpr):
                    _count(sub, counter)
    return counter


def test_fusion_barriers_survive_vmap_over_keys(lit_plane):
    """The batched program keeps every ``cond`` of the unbatched one (a batched predicate turns
    a cond into a select: XLA then fuses through the barrier and recomputes intersection tests,
    the 7-31x of docs/performance.md). Tracing only, no compilation (~1 CPU s)."""
    scene, render_one = lit_plane
    keys = jax.random.split(jax.random.key(13), K)
    path = "materials.m.reflectance"

    def image(x, key):
        return render_one(scene.replace(path, scene.get(path) * x), key)

    x = jnp.float32(1.0)
    one = _count(jax.make_jaxpr(image)(x, keys[0]).jaxpr)
    many = _count(jax.make_jaxpr(jax.vmap(image, in_axes=(None, 0)))(x, keys).jaxpr)
    assert one["cond"] >= 4  # render's pass barrier and intersect's two, at least
    assert many["cond"] == one["cond"]
    # (through reverse mode: tests/test_math.py::test_fusion_barrier_stays_a_cond_under_vmap)


# --- several sample passes per scan step (issue 22) -------------------------------------------
# estimator.render_partial traces passes_per_step(R W, spp, rays_per_step) passes per lax.scan
# step as one (k R, W) batch. Every sample keeps its camera sample and uniform numbers and the
# passes are summed in the same order, so the image may differ from one pass per step only by
# the rounding of differently compiled code. Reference: the one-pass-per-step render (the
# layout before issue 22). Tolerance per pixel 8 spp u |b| + u max|b| (u = 2^-24), that of
# test_distributed; a sample drawn from another stream would move a pixel by its Monte Carlo
# noise (the sphere-and-floor scene at 5 spp: tens of percent), ~10^5 times more.


def _grouped_renders(scene, integ, spp, steps):
    from jaxgfx.render.estimator import render_partial

    def make(rps):
        return jax.jit(lambda sc, k: render_partial(sc, k, integ, spp=spp, rays_per_step=rps))

    return {rps: make(rps) for rps in steps}


def test_passes_per_step_layout():
    from jaxgfx.render.estimator import passes_per_step

    # fewest padded passes for the step count: 16 passes of 6 912 rays -> 2 steps of 8
    assert passes_per_step(96 * 72, 16) == 8
    assert passes_per_step(384 * 288, 16) == 1  # a large image: one pass per step
    assert passes_per_step(100, 5, 250) == 2  # 3 steps of 2: one weight-0 padding pass
    assert passes_per_step(100, 7, 350) == 3  # 3 steps of 3, 2 padding passes
    assert passes_per_step(100, 7, 400) == 4  # 2 steps of 4 (not 4 + 3)
    assert passes_per_step(10, 1) == passes_per_step(10, 16, None) == 1


# ~11 CPU s, 47 s wall at load 11 (two compiles of a 10 x 6 path render, depth 2); the default
# run keeps it: it is the only check that the grouped layout keeps every sample's numbers
# 9.5 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_several_passes_per_step_keep_every_sample():
    from jaxgfx.render.integrators import PathIntegrator

    # diffuse plane under an area light (light and BSDF sampling, MIS, a shadow ray, a bounce)
    light = area_light([1.5, 1.5, 0.0], [-0.7071, -0.7071, 0.0], [1.0, 1.0], 5.0)
    scene = load_scene(plane_scene([light], cam={"width": 10, "height": 6, "fov": 60}))
    spp = 3
    integ = PathIntegrator(max_depth=2)
    # None: 1 pass per step (the reference); 120 rays: 2 passes per step, 2 steps, 1 weight-0
    # padding pass
    fns = _grouped_renders(scene, integ, spp, (None, 120))
    key = jax.random.key(11)
    ref = np.asarray(fns[None](scene, key), np.float64)
    assert ref.std() > 0.05 * ref.mean() > 0  # not a blank frame
    tol = 8 * spp * 2.0**-24 * np.abs(ref) + 2.0**-24 * np.abs(ref).max()
    img = np.asarray(fns[120](scene, key), np.float64)
    err = np.abs(img - ref)
    assert np.all(err <= tol), (err.max(), (err / tol).max())
    # another key moves the pixels by their noise: the check can fail
    other = np.asarray(fns[120](scene, jax.random.key(12)), np.float64)
    assert np.mean(np.abs(other - ref) > tol) > 0.5


# ~45 CPU s (two reverse-mode compiles of a path render, depth 3), 166 s wall at load 8; out of
# make test
@pytest.mark.slow
def test_several_passes_per_step_same_gradient():
    from jaxgfx.render.estimator import render_partial
    from jaxgfx.render.integrators import PathIntegrator

    from ._scenes import sphere_floor_scene

    scene = load_scene(sphere_floor_scene())
    integ = PathIntegrator(max_depth=3)
    key = jax.random.key(5)

    def grad(rps):
        def f(a):
            sc = scene.replace("materials.metal.alpha", a)
            return render_partial(sc, key, integ, spp=4, rays_per_step=rps).mean()

        return np.asarray(jax.jit(jax.value_and_grad(f))(jnp.float32(0.3)), np.float64)

    g1, g4 = grad(None), grad(1 << 16)
    assert abs(g1[1]) > 1e-3  # a real derivative
    # the H W 3 spp cotangent terms reduced in another order: ~ulps, rtol 1e-5 (~170 ulps)
    np.testing.assert_allclose(g4, g1, rtol=1e-5)
