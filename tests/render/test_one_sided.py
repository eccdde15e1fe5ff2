"""One-sided materials (``one_sided: true``; Mitsuba 3's ``diffuse``, ``conductor``, ... without
``twosided``): black from behind, unchanged from the front. Closed forms (a diffuse rectangle
under a directional light: ``L = rho E / pi`` exactly, no Monte Carlo noise), the BSDFs' back
side, the loader's errors, the XML reader and writer (round trip)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.bsdf import TangentSpace, make_bsdf
from jaxgfx.render.bsdf.texture import Texture
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import ad_fd_per_key

RHO, E = 0.6, 2.0


def _desc(cam_z, light_dz, one_sided, *, material=None, integrator_light=None):
    """A 4x4 rectangle in z = 0 (normal +z) seen from ``(0, 0, cam_z)``; a directional light
    travelling along ``(0, 0, light_dz)`` (or ``integrator_light``)."""
    mat = material or {"type": "diffuse", "reflectance": RHO}
    if one_sided is not None:
        mat = {**mat, "one_sided": one_sided}
    light = integrator_light or {"type": "directional", "direction": [0, 0, light_dz],
                                 "irradiance": E}  # fmt: skip
    return {
        "camera": {
            "origin": [0, 0, cam_z],
            "target": [0, 0, 0],
            "up": [0, 1, 0],
            "fov": 20,
            "width": 4,
            "height": 4,
        },  # fmt: skip
        "shapes": [
            {
                "type": "rectangle",
                "center": [0, 0, 0],
                "normal": [0, 0, 1],
                "size": [4, 4],
                "material": "m",
            }
        ],  # fmt: skip
        "materials": {"m": mat},
        "emitters": [light],
    }


@jax.jit
def _render(scene, key):
    return render(scene, key, spp=2, integrator="path", max_depth=4)


@pytest.mark.parametrize("one_sided", [None, False, True])
def test_diffuse_rectangle_front_and_back_closed_form(x64, one_sided):
    """Front (camera and light on +z): ``rho E / pi`` for every flag. Back (both on -z): the
    same for a two-sided material (the default and ``false``), exactly 0 for a one-sided one."""
    expect = RHO * E / math.pi
    front = load_scene(_desc(3.0, -1.0, one_sided))
    back = load_scene(_desc(-3.0, 1.0, one_sided))
    assert front.one_sided == ((True,) if one_sided else ())
    key = jax.random.key(0)
    np.testing.assert_allclose(np.asarray(_render(front, key)), expect, rtol=1e-12)
    img = np.asarray(_render(back, key))
    if one_sided:
        assert np.all(img == 0.0)
    else:
        np.testing.assert_allclose(img, expect, rtol=1e-12)


def _loss(x, key, scene):
    s = scene.replace("materials.m.reflectance", x)
    return jnp.mean(_render(s, key))


@pytest.mark.parametrize(
    "cam_z",
    [pytest.param(3.0, marks=pytest.mark.slow), -3.0],  # slow: ~12 s under load
)
def test_one_sided_reflectance_gradient(x64, cam_z):
    """d/d reflectance of the one-sided rectangle: ``E / pi`` per channel / 3 from the front,
    exactly 0 from behind; reverse mode under jit equals central differences."""
    scene = load_scene(_desc(cam_z, -math.copysign(1.0, cam_z), True))
    x = jnp.full((3,), RHO)
    keys = jax.random.split(jax.random.key(1), 2)
    _, ad, fd = ad_fd_per_key(_loss, x, keys, 1e-4, args=(scene,))
    expect = E / math.pi / 3 if cam_z > 0 else 0.0
    np.testing.assert_allclose(ad, expect, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(fd, expect, rtol=1e-6, atol=1e-12)


@pytest.mark.slow  # slow: ~11 s on 2 cores under load (three scenes compiled, one gradient)
def test_area_light_behind_one_sided_adds_nothing(x64):
    """An area light on the back side (facing the rectangle's back, out of view): NEE and
    BSDF-sampled hits (MIS) add exactly 0 to a one-sided rectangle seen from behind, with
    finite gradients; the two-sided rectangle there equals the mirrored front-side scene."""
    area = {"type": "area", "radiance": [3.0, 3.0, 3.0],
            "shape": {"type": "rectangle", "center": [2.5, 0, -2.0], "normal": [-1, 0, 1],
                      "size": [1, 1]}}  # fmt: skip
    mirrored = {**area, "shape": {**area["shape"], "center": [-2.5, 0, 2.0],
                                  "normal": [1, 0, -1]}}  # fmt: skip
    key = jax.random.key(3)
    one = load_scene(_desc(-3.0, 0, True, integrator_light=area))
    assert np.all(np.asarray(_render(one, key)) == 0.0)
    g = jax.grad(_loss)(jnp.full((3,), RHO), key, one)
    assert np.all(g == 0.0)
    two = np.asarray(_render(load_scene(_desc(-3.0, 0, False, integrator_light=area)), key))
    # the front view of the mirrored scene (rotated by pi about y): same image, flipped in x
    ref = np.asarray(_render(load_scene(_desc(3.0, 0, True, integrator_light=mirrored)), key))
    assert ref.mean() > 1e-3
    np.testing.assert_allclose(two.mean(), ref.mean(), rtol=0.3)  # independent MC paths
    np.testing.assert_allclose(two.sum((0, 1)), two[..., ::-1, :].sum((0, 1)))


_TS = TangentSpace(s=jnp.array([1.0, 0.0, 0.0]), t=jnp.array([0.0, 1.0, 0.0]),
                   du=jnp.array([1.0, 0.0]), dv=jnp.array([0.0, 1.0]))  # fmt: skip
_ONE_SIDED_BSDFS = {
    "diffuse": {"type": "diffuse", "reflectance": 0.5},
    "conductor": {"type": "conductor"},
    "roughconductor": {"type": "roughconductor", "alpha": 0.3},
    "plastic": {"type": "plastic"},
    "roughplastic": {"type": "roughplastic", "alpha": 0.3},
    "principled": {"type": "principled", "roughness": 0.4, "clearcoat": 0.5, "sheen": 0.3},
    "blendbsdf": {
        "type": "blendbsdf",
        "weight": 0.3,
        "bsdf0": {"type": "diffuse"},
        "bsdf1": {"type": "roughconductor", "alpha": 0.2},
    },  # fmt: skip
}


def _resolved(name):
    if name == "normalmap":
        nm = make_bsdf({"type": "normalmap", "bsdf": make_bsdf({"type": "diffuse"}),
                        "normalmap": jnp.array([0.6, 0.4, 0.9])})  # fmt: skip
        return nm.at(jnp.array([0.3, 0.6]), _TS)
    if name == "bumpmap":
        tex = Texture(jnp.linspace(0.0, 1.0, 16).reshape(4, 4, 1))
        return make_bsdf({"type": "bumpmap", "bsdf": make_bsdf({"type": "roughplastic"}),
                          "height": tex, "scale": 0.5}).at(jnp.array([0.3, 0.6]), _TS)  # fmt: skip
    return make_bsdf(_ONE_SIDED_BSDFS[name])


# slow: 3.5-8.5 s each on 2 cores under load (the principled / microfacet samplers' compile)
_SLOW = ("plastic", "roughplastic", "principled", "blendbsdf", "bumpmap")


@pytest.mark.parametrize(
    "name",
    [pytest.param(n, marks=pytest.mark.slow) if n in _SLOW else n
     for n in (*_ONE_SIDED_BSDFS, "normalmap", "bumpmap")],
)  # fmt: skip
def test_reflection_bsdfs_are_black_below(x64, rng, name):
    """Below the surface (``wo.z < 0``, what a one-sided material sees from behind) every
    reflection-only BSDF gives 0 eval, 0 pdf and a zero-weight sample, under jit, with finite
    gradients w.r.t. the directions (grazing included)."""
    m = _resolved(name)
    w = rng.normal(size=(256, 3))
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    wo = jnp.asarray(w).at[:, 2].set(-np.abs(w[:, 2]))
    wo = wo.at[0].set(jnp.array([1.0, 0.0, -1e-12]))  # grazing
    wi = jnp.asarray(rng.normal(size=(256, 3)))
    wi = wi / jnp.linalg.norm(wi, axis=-1, keepdims=True)
    u1 = jnp.asarray(rng.uniform(size=256))
    u2 = jnp.asarray(rng.uniform(size=(256, 2)))

    @jax.jit
    def run(a):
        s = m.sample(a, u1, u2)
        g = jax.grad(lambda a: jnp.sum(m.eval(a, wi)) + jnp.sum(m.sample(a, u1, u2).weight))(a)
        return m.eval(a, wi), m.pdf(a, wi), s.weight, s.pdf, g

    f, p, weight, spdf, g = (np.asarray(v) for v in run(wo))
    assert np.all(f == 0.0) and np.all(p == 0.0)
    assert np.all(weight == 0.0) and np.all(np.isfinite(spdf))
    assert np.all(np.isfinite(g))


@pytest.mark.parametrize(
    ("material", "why"),
    [
        ({"type": "dielectric"}, "SmoothDielectric (transmissive)"),
        ({"type": "principled", "spec_trans": 0.5}, "Principled (transmissive)"),
        ({"type": "mask", "opacity": 0.5, "bsdf": {"type": "diffuse"}}, "a mask"),
    ],
)
def test_one_sided_refused_on_two_sided_scatterers(material, why):
    with pytest.raises(ValueError, match=r"materials\.m\.one_sided: only reflection-only") as e:
        load_scene(_desc(3.0, -1.0, True, material=material))
    assert why in str(e.value)


def test_one_sided_must_be_a_bool():
    with pytest.raises(ValueError, match=r"materials\.m\.one_sided: expected true or false"):
        load_scene(_desc(3.0, -1.0, "yes"))


def test_one_sided_loads_textured_and_mapped(tmp_path):
    """The flag sits beside the material's own keys: paths are unchanged."""
    d = _desc(3.0, -1.0, True, material={"type": "diffuse", "reflectance": {
        "type": "checkerboard", "color0": 0.2, "color1": 0.8}})  # fmt: skip
    s = load_scene(d)
    assert s.one_sided == (True,)
    assert [p.path for p in s.parameters() if p.path.startswith("materials")] == [
        "materials.m.reflectance.color0", "materials.m.reflectance.color1"]  # fmt: skip
