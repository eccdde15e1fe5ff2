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
