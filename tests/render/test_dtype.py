"""The renderer in float64: scenes carry one float dtype, renders and gradients follow it.

With ``jax_enable_x64`` on, ``load_scene`` builds float64 scenes by default (JAX's default
float) and ``load_scene(..., dtype=jnp.float32)`` float32 ones; before this, any render with x64
on failed in the sample loop (float32 samples, float64 scene values). References: the closed
form of a point light over a diffuse plane per camera sample (exact in float64 to 1e-12), and
central finite differences of the same float64 render for a parameter that moves no sample.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.film import pixel_samples
from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene

from ._scenes import area_light, camera, diffuse, plane_scene, point_light, rectangle, sphere

KEY = jax.random.key(3)


def _direct(scene):
    return render(scene, KEY, spp=4, integrator="direct")


_DIRECT = jax.jit(_direct)  # one program per dtype, shared by the tests below


def _point_plane():
    return plane_scene([point_light([0, 2, 0], 10.0)], cam={"width": 8, "height": 8})


# 12.6 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_point_light_plane_float64_matches_closed_form_per_pixel(x64):
    # light 2 above the plane centre: L = rho / pi * I cos / r^2, cos = 2 / r, at the point
    # each camera sample sees; float64 makes the whole chain exact to rounding
    scene = load_scene(_point_plane())
    assert scene.dtype == jnp.float64
    img = _DIRECT(scene)
    assert img.dtype == jnp.float64
    px = pixel_samples(jax.random.split(KEY)[0], 8, 8, 4, scene.rfilter, dtype=jnp.float64)
    o, d = (np.asarray(a) for a in scene.camera.generate_ray(px))
    t = -o[..., 1] / d[..., 1]
    p = o + t[..., None] * d
    r2 = p[..., 0] ** 2 + p[..., 2] ** 2 + 4.0
    expected = (0.5 / math.pi * 10.0 * (2.0 / np.sqrt(r2)) / r2).mean(-1)
    np.testing.assert_allclose(np.asarray(img), expected[..., None] * np.ones(3), rtol=1e-12)
    # a float32 scene with x64 on renders in float32 (it failed in the sample loop before);
    # its uniforms are the float64 ones rounded to 24 bits, so the images agree to ~1e-6
    s32 = load_scene(_point_plane(), dtype="float32")
    assert s32.dtype == jnp.float32
    i32 = _DIRECT(s32)
    assert i32.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(i32), np.asarray(img), rtol=1e-4)


def _glossy_desc():
    return {
        "camera": camera([0, 2, 3], [0, 0.3, 0], fov=40, width=6),
        "shapes": [sphere([0, 0.5, 0], 0.5, "metal"), rectangle(size=(6, 6), material="floor")],
        "materials": {
            "metal": {"type": "roughconductor", "alpha": 0.2, "reflectance": [0.9, 0.8, 0.5]},
            "floor": diffuse([0.6, 0.5, 0.4]),
        },
        "emitters": [area_light([0.5, 2.5, 0.5], [0, -1, 0], [1.0, 1.0], 8.0)],
    }


@pytest.mark.slow  # 15 s: two compiled float64 path renders
def test_float64_path_gradient_wrt_albedo_matches_finite_differences(x64):
    """Area light, glossy occluder, diffuse floor, depth 3 (below the roulette depth): the
    floor albedo moves no sample, so same-key central differences in float64 are exact to
    ~1e-8 and AD must match them that closely (float32 could only check to ~1e-3)."""
    scene = load_scene(_glossy_desc())
    path = "materials.floor.reflectance"

    def loss(v):
        img = render(scene.replace(path, v), KEY, spp=4, integrator="path", max_depth=3)
        return jnp.sum(img * jnp.array([1.0, 2.0, 3.0]))

    v0 = jnp.array([0.6, 0.5, 0.4])
    ad = np.asarray(jax.jit(jax.grad(loss))(v0))
    fl = jax.jit(loss)
    h = 1e-5
    fd = np.array(
        [(float(fl(v0.at[i].add(h))) - float(fl(v0.at[i].add(-h)))) / (2 * h) for i in range(3)]
    )
    assert np.all(np.abs(ad) > 1e-2)
    np.testing.assert_allclose(ad, fd, rtol=1e-7)
    # a float32 scene with x64 on: float32 image and gradient
    s32 = load_scene(_glossy_desc(), dtype=jnp.float32)
    g = eqx.filter_jit(eqx.filter_grad(lambda s: jnp.sum(_direct(s))))(s32)
    assert g.get(path).dtype == jnp.float32 and np.all(np.isfinite(np.asarray(g.get(path))))


def test_load_scene_dtype_errors():
    desc = plane_scene([point_light([0, 2, 0], 1.0)])
    with pytest.raises(ValueError, match="dtype: expected float32 or float64"):
        load_scene(desc, dtype=jnp.int32)
    if not jax.config.jax_enable_x64:
        with pytest.raises(ValueError, match="dtype: float64 needs"):
            load_scene(desc, dtype=jnp.float64)
    assert load_scene(desc).dtype == jnp.float32
