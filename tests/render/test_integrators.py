"""Integrators against closed forms: white furnace, diffuse plane under a constant sky, point
light on a plane (inverse square + cosine), irradiance from a rectangular area light (Lambert's
polygon formula); Whitted/direct/path agreement; finite gradients through every integrator.

Tolerances: each check compares an image mean over ``n`` independent pixel estimates against the
closed form with a bound of 5 standard errors (sample std / sqrt(n)), plus a small absolute
floor for float32 rounding.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene

from ._scenes import camera, plane_scene, sphere, sphere_floor_scene

KEY = jax.random.key(7)


def _assert_mean(img, expected, *, n_sigma=5.0, floor=2e-3):
    x = np.asarray(img, np.float64).reshape(-1, img.shape[-1])
    mean = x.mean(0)
    se = x.std(0, ddof=1) / np.sqrt(x.shape[0])
    tol = n_sigma * se + floor * np.maximum(np.abs(expected), 1.0)
    assert np.all(np.abs(mean - expected) <= tol), (mean, expected, tol)


@pytest.mark.slow  # issue 9: ~10 s of a loaded 2-core run; out of make test
def test_white_furnace_sphere():
    desc = {
        "camera": camera([0, 0, 4], [0, 0, 0], fov=20, width=16, up=[0, 1, 0]),
        "shapes": [sphere([0, 0, 0], 1.0, "w")],
        "materials": {"w": {"type": "diffuse", "reflectance": 1.0}},
        "emitters": [{"type": "constant", "radiance": 1.0}],
    }
    scene = load_scene(desc)
    for integ, depth in (("path", 4), ("direct", 2)):
        img = render(scene, KEY, spp=16, integrator=integ, max_depth=depth)
        _assert_mean(img, np.ones(3))


# 4.1 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_diffuse_plane_under_constant_sky():
    scene = load_scene(plane_scene([{"type": "constant", "radiance": [1.0, 2.0, 0.5]}]))
    img = render(scene, KEY, spp=16, integrator="path", max_depth=2)
    _assert_mean(img, 0.5 * np.array([1.0, 2.0, 0.5]))


POINT_SPP = 4  # one spp for every direct render of the plane + point light: one program


@pytest.mark.slow  # issue 9: ~10 s of a loaded 2-core run; out of make test
def test_point_light_inverse_square_cosine():
    # light at height 2 above the plane centre, offset 0 -> E = I / r^2 ; L = rho / pi * E
    scene = load_scene(plane_scene([{"type": "point", "position": [0, 2, 0], "intensity": 10.0}]))
    img = np.asarray(render(scene, KEY, spp=POINT_SPP, integrator="direct"))
    assert np.isfinite(img).all()
    # exact per sample: the camera ray meets the plane y = 0 at p, E = I cos / r^2 with
    # cos = 2 / r; the pixel value is the mean over its POINT_SPP samples (box filter)
    from jaxgfx.render.film import pixel_samples

    px = pixel_samples(jax.random.split(KEY)[0], 16, 16, POINT_SPP, scene.rfilter)
    o, d = (np.asarray(a, np.float64) for a in scene.camera.generate_ray(px))
    t = -o[..., 1] / d[..., 1]
    assert np.all(t > 0)  # the plane fills the view
    p = o + t[..., None] * d
    r2 = (p[..., 0] ** 2 + p[..., 2] ** 2) + 4.0
    expected = (0.5 / math.pi * 10.0 * (2.0 / np.sqrt(r2)) / r2).mean(-1)
    np.testing.assert_allclose(img.mean(-1), expected, rtol=2e-2)


def _polygon_irradiance(x, n, verts):
    """Lambert's formula: irradiance at x (normal n) from a unit-radiance polygon."""
    e = 0.0
    k = len(verts)
    for i in range(k):
        a = verts[i] - x
        b = verts[(i + 1) % k] - x
        a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
        c = np.cross(a, b)
        theta = math.acos(np.clip(np.dot(a, b), -1, 1))
        e += theta * np.dot(n, c / np.linalg.norm(c))
    return abs(e) / 2.0


def _lamp_over_plane(center, size, radiance, res):
    """A rectangular lamp facing down over the albedo-0.5 plane, seen by a narrow camera looking
    straight down at the origin; returns the scene and the closed-form pixel value
    (rho / pi * L * E_unit, Lambert's polygon formula at the origin)."""
    lamp = {"type": "rectangle", "center": center, "normal": [0, -1, 0], "size": size}
    desc = plane_scene([{"type": "area", "radiance": radiance, "shape": lamp}])
    desc["camera"] = camera([0, 0.5, 0.0001], [0, 0, 0], fov=1.0, width=res, up=[0, 0, 1])
    scene = load_scene(desc)
    rect = scene.emitter_shapes[0]
    c, eu, ev = (np.asarray(a[0], np.float64) for a in (rect.centers, rect.edge_u, rect.edge_v))
    verts = [c - eu / 2 - ev / 2, c + eu / 2 - ev / 2, c + eu / 2 + ev / 2, c - eu / 2 + ev / 2]
    e = _polygon_irradiance(np.zeros(3), np.array([0, 1.0, 0]), verts)
    return scene, np.full(3, 0.5 / math.pi * radiance * e)


@pytest.mark.slow  # issue 9: ~6 s of a loaded 2-core run; out of make test
def test_rectangular_area_light_irradiance():
    # 8 x 8 pixels x 64 spp (as the strategy test below: the same compiled program)
    scene, expected = _lamp_over_plane([0.3, 1.0, 0.2], [1.0, 0.6], 3.0, 8)
    img = render(scene, KEY, spp=64, integrator="direct")
    _assert_mean(img, expected)


@pytest.mark.slow  # issue 9: ~6 s of a loaded 2-core run; out of make test
def test_light_bsdf_and_mis_strategies_agree_with_polygon_formula():
    """All three direct-light strategies are unbiased; BSDF sampling is the noisiest for a
    small light and MIS is close to the better single strategy (Veach 1997)."""
    scene, expected = _lamp_over_plane([0.2, 1.0, -0.1], [0.4, 0.3], 20.0, 8)
    var = {}
    for strategy in ("mis", "light", "bsdf"):
        img = render(scene, KEY, spp=64, integrator="direct", strategy=strategy)
        _assert_mean(img, expected)
        var[strategy] = float(np.var(np.asarray(img)[..., 0]))
    assert var["bsdf"] > 3 * var["light"]
    assert var["mis"] < 1.5 * min(var["light"], var["bsdf"])
    with pytest.raises(ValueError, match="strategy"):
        render(scene, KEY, spp=1, strategy="bidir")


@pytest.mark.slow  # issue 9: ~8 s of a loaded 2-core run; out of make test
def test_whitted_direct_path_agree_on_direct_light():
    # a noise-consistency test (the integrators against each other); each integrator's
    # independent closed forms are in this file and in test_integrator_references.py
    desc = plane_scene([{"type": "point", "position": [0.3, 1.5, -0.2], "intensity": 5.0}])
    scene = load_scene(desc)
    a = np.asarray(render(scene, KEY, spp=POINT_SPP, integrator="whitted", max_depth=1))
    b = np.asarray(render(scene, KEY, spp=POINT_SPP, integrator="direct"))
    c = np.asarray(render(scene, KEY, spp=POINT_SPP, integrator="path", max_depth=5))
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(b, c, rtol=1e-5, atol=1e-7)  # convex scene: no indirect light


@pytest.mark.slow  # issue 9: ~9 s of a loaded 2-core run; out of make test
def test_mirror_sphere_reflects_sky():
    desc = {
        "camera": camera([0, 0, 4], [0, 0, 0], fov=10, width=8, up=[0, 1, 0]),
        "shapes": [sphere([0, 0, 0], 1.0, "m")],
        "materials": {"m": {"type": "mirror"}},
        "emitters": [{"type": "constant", "radiance": 2.0}],
    }
    scene = load_scene(desc)
    for integ in ("path", "whitted"):
        img = np.asarray(render(scene, KEY, spp=1, integrator=integ, max_depth=3))
        np.testing.assert_allclose(img, 2.0, rtol=1e-4)


@pytest.mark.parametrize(
    "integrator",
    [
        # 40-140 s of XLA compilation each on 2 cores: run with `make test-slow`. The default
        # suite checks path gradients against the integrating sphere's closed form
        # (test_integrator_references.py) and direct-light gradients at hard cases
        # (test_hard_cases.py)
        pytest.param("path", marks=pytest.mark.slow),
        pytest.param("direct", marks=pytest.mark.slow),
        pytest.param("whitted", marks=pytest.mark.slow),
    ],
)
def test_gradients_finite_wrt_roughness_and_albedo(integrator):
    desc = sphere_floor_scene()
    scene = load_scene(desc)

    def loss(alpha, rho):
        s = scene.replace("materials.metal.alpha", alpha).replace(
            "materials.floor.reflectance", rho
        )
        return jnp.mean(render(s, KEY, spp=2, integrator=integrator, max_depth=3))

    vg = jax.jit(jax.value_and_grad(loss, argnums=(0, 1)))  # one compile for all three calls
    rho = jnp.full(3, 0.5, jnp.float32)
    _, (ga, gr) = vg(jnp.float32(0.3), rho)
    assert np.isfinite(ga) and np.all(np.isfinite(gr))
    assert np.any(np.asarray(gr) > 0)  # brighter floor -> brighter image
    # values: at depth 3 every path meets the (flat) floor at most once, so the image is affine
    # in its albedo and a central difference with the same key is exact up to rounding (same
    # compiled program). d/d alpha is not checked against the same-key difference: AD detaches
    # the sampled directions (f / detach(pdf)), a different estimator of the same derivative.
    h = 0.1
    fd = (float(vg(jnp.float32(0.3), rho + h)[0]) - float(vg(jnp.float32(0.3), rho - h)[0])) / (
        2 * h
    )
    np.testing.assert_allclose(float(jnp.sum(gr)), fd, rtol=2e-3, atol=1e-5)


@pytest.mark.parametrize(
    "patch, match",
    [
        (
            {"shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1, "material": "nope"}]},
            "material",
        ),
        ({"shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": -1}]}, "radius"),
        ({"shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1, "colour": 1}]}, "colour"),
        ({"shapes": [{"type": "cone"}]}, "type"),
        (
            {"emitters": [{"type": "point", "position": [0, float("nan"), 0], "intensity": 1}]},
            "position",
        ),
        ({"materials": {"m": {"type": "velvet"}}}, "materials.m"),
        ({"camrea": {}}, "camrea"),
    ],
)
def test_scene_errors_name_the_field(patch, match):
    desc = {
        "camera": {"origin": [0, 0, 4], "target": [0, 0, 0], "fov": 30, "width": 4, "height": 4},
        "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1}],
    }
    desc.update(patch)
    with pytest.raises(ValueError, match=match):
        load_scene(desc)


def test_replace_and_get():
    desc = plane_scene([{"type": "point", "position": [0, 2, 0], "intensity": 10.0}])
    scene = load_scene(desc)
    s2 = scene.replace("materials.m.reflectance", 0.25)
    np.testing.assert_allclose(s2.get("materials.m.reflectance"), 0.25)
    np.testing.assert_allclose(scene.get("materials.m.reflectance"), 0.5)
    with pytest.raises(ValueError, match="unknown material"):
        scene.replace("materials.x.alpha", 0.1)
    with pytest.raises(ValueError, match="no parameter"):
        scene.replace("materials.m.roughness", 0.1)
