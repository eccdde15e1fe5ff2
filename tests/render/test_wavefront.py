"""Wavefront shading (``PathIntegrator(chunk=...)``): rays sorted by material, shaded in chunks.

References: NumPy's stable argsort for the counting sort; for the renderer, the plain layout
(``chunk=None``: every ray shaded with every material), which the Mitsuba 3 and closed-form
tests validate. The two are the same per-ray arithmetic in another order, so images and
gradients agree to float32 rounding.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.config import read_yaml
from jaxgfx.render.integrators import PathIntegrator
from jaxgfx.render.integrators import _common as C
from jaxgfx.render.integrators._wavefront import shade_sorted, sort_positions
from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene
from tests.render._scenes import EXAMPLE_YAML, area_light, camera, diffuse, rectangle, sphere


def test_sort_positions_match_a_stable_argsort():
    rng = np.random.default_rng(3)
    key = rng.integers(0, 5, size=1000).astype(np.int32)  # keys 0..3 live, 4 dead
    pos = np.asarray(jax.jit(sort_positions, static_argnums=1)(jnp.asarray(key), 4))
    order = np.argsort(key, kind="stable")
    expect = np.empty_like(order)
    expect[order] = np.arange(key.size)
    np.testing.assert_array_equal(pos, expect)


# 3.0 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_shade_sorted_equals_shading_every_ray():
    # fn depends on the key it is given: each live ray must see its own key and arguments
    rng = np.random.default_rng(0)
    h, w = 12, 8
    x = jnp.asarray(rng.normal(size=(h, w, 3)), jnp.float32)
    key = jnp.asarray(rng.integers(0, 4, size=(h, w)), jnp.int32)  # 3 = dead

    def fn(args, k):
        (v,) = args
        return v * (k[..., None] + 1.0), jnp.sum(v, -1) - k

    for chunk in (8, 40, 1000):  # one row, 5 rows (a partial last chunk), more than the image
        out = jax.jit(lambda v, k, c=chunk: shade_sorted(fn, (v,), k, 3, c))(x, key)
        ref = fn((x,), key)
        live = np.asarray(key) < 3
        for a, b in zip(out, ref, strict=True):
            np.testing.assert_allclose(np.asarray(a)[live], np.asarray(b)[live], rtol=1e-6)


# issue 13: ~3 s; the chunked render test of the default run goes through the lazy dispatch
@pytest.mark.slow
def test_lazy_dispatch_equals_the_select_chain():
    scene = load_scene(_example(8))
    n = len(scene.materials)
    mat = jnp.asarray(np.arange(64).reshape(8, 8) % n, jnp.int32)
    wo = jnp.broadcast_to(jnp.asarray([0.3, -0.2, 0.93]), (8, 8, 3))
    wi = jnp.broadcast_to(jnp.asarray([-0.5, 0.1, 0.86]), (8, 8, 3))

    def ev(lazy, m):
        return C.dispatch(scene, m, lambda b: b.eval(wo, wi), lazy=lazy)

    ref = ev(False, mat)
    np.testing.assert_allclose(jax.jit(lambda m: ev(True, m))(mat), ref, rtol=1e-6)
    # a batch of one material: the other materials are skipped, the values unchanged
    one = jnp.zeros_like(mat)
    np.testing.assert_allclose(ev(True, one), ev(False, one), rtol=1e-6)


def _example(res):
    desc = read_yaml(EXAMPLE_YAML)
    desc["camera"]["width"] = desc["camera"]["height"] = res
    return desc


@pytest.fixture(scope="module")
def example16():
    return load_scene(_example(16))


def _img(scene, key, chunk, depth=3):
    # 16² rays, chunks of 4 rows (64 rays): four chunks, three materials, dead rays
    return render(scene, key, spp=2, integrator=PathIntegrator(max_depth=depth, chunk=chunk))


# issue 9 budget: ~8-11 s (two path-tracer compiles); the default run keeps the jitted
# shade_sorted and sort tests, CI runs this with the slow suite
@pytest.mark.slow
def test_chunked_path_tracer_equals_the_plain_layout():
    # 8² rays in chunks of 2 rows (16 rays): four chunks; two materials (diffuse, cheap to
    # compile), an area light and rays that leave the scene. The slow tests below run the
    # example scene (conductor, glass, diffuse) at depth 3 with gradients.
    scene = load_scene(
        {
            "camera": camera([0, 1.5, 4], [0, 0.6, 0], fov=40, width=8),
            "shapes": [sphere([0, 0.7, 0], 0.7, "ball"), rectangle(size=(4, 4), material="floor")],
            "materials": {"ball": diffuse(0.8), "floor": diffuse(0.3)},
            "emitters": [area_light([0, 3, 0], [0, -1, 0], [1, 1], 8.0)],
        }
    )
    key = jax.random.key(5)
    plain = np.asarray(_img(scene, key, None, 2))
    chunked = np.asarray(jax.jit(_img, static_argnums=(2, 3))(scene, key, 16, 2))
    assert 0.01 < plain.mean() and (plain == 0).any()  # lit, and rays that leave
    np.testing.assert_allclose(chunked, plain, rtol=2e-5, atol=2e-6)


# issue 13: ~47 s (two reverse-mode compiles of the example scene); the default run keeps the
# image equality below on a two-material scene
@pytest.mark.slow
def test_chunked_gradients_equal_the_plain_layout(example16):
    def loss(alpha, refl, chunk):
        s = example16.replace("materials.metal.alpha", alpha)
        s = s.replace("materials.floor.reflectance", refl)
        return jnp.mean(_img(s, jax.random.key(2), chunk))

    a0, r0 = jnp.float32(0.3), jnp.full((3,), 0.5, jnp.float32)
    g_plain = jax.grad(loss, argnums=(0, 1))(a0, r0, None)
    g_chunk = jax.jit(jax.grad(loss, argnums=(0, 1)), static_argnums=2)(a0, r0, 64)
    assert abs(float(g_plain[0])) > 1e-3  # the metal sphere is in view
    for a, b in zip(g_chunk, g_plain, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6)


# issue 13: ~11 s (a vmapped compile of the example scene)
@pytest.mark.slow
def test_chunked_render_under_vmap_equals_separate_keys(example16):
    # under vmap the chunk conditionals become selects: all chunks run, same values
    keys = jax.random.split(jax.random.key(9), 2)
    both = jax.vmap(lambda k: _img(example16, k, 64))(keys)
    for i in range(2):
        np.testing.assert_allclose(both[i], _img(example16, keys[i], None), rtol=2e-5, atol=2e-6)


@pytest.mark.parametrize("bad", [0, -4, 2.5, "4096"])
def test_chunk_must_be_a_positive_int(bad):
    with pytest.raises(ValueError, match="chunk"):
        PathIntegrator(chunk=bad)
