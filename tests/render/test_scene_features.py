"""Textures and SDF shapes in scene descriptions.

References: Mitsuba 3's checkerboard convention (closed form), colour-science's sRGB decoding
for PNG textures, per-ray BSDFs against BSDFs built with constant parameters, finite differences
for texel / radius gradients, and an analytic sphere for the sphere-traced SDF sphere.
"""

import math
import os

import colour
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from PIL import Image

from jaxgfx.render.bsdf import Diffuse, RoughConductor
from jaxgfx.render.bsdf.texture import Texture
from jaxgfx.render.bsdf.textured import Checkerboard, Textured, texture_eval, texture_from_dict
from jaxgfx.render.geometry import Spheres, intersect
from jaxgfx.render.geometry.sdf import SDFSphere
from jaxgfx.render.geometry.sphere_tracing import SDFShape
from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import ad_fd_per_key, check_grads_fd

from ._scenes import camera, point_light, sphere, textured_plane_scene

KEY = jax.random.key(3)


# ------------------------------------------------------------------------------------------
# textures


def test_checkerboard_mitsuba_convention():
    tex = texture_from_dict({"type": "checkerboard", "color0": [1, 0, 0], "color1": 0.25})
    uv = jnp.array([[0.25, 0.25], [0.75, 0.25], [0.25, 0.75], [0.75, 0.75], [1.25, -0.25]])
    got = np.asarray(texture_eval(tex, uv))
    c0, c1 = [1, 0, 0], [0.25] * 3
    np.testing.assert_array_equal(got, [c0, c1, c1, c0, c1])
    # scale multiplies uv: with scale 2 the cell size is 1/4
    tex2 = texture_from_dict({"type": "checkerboard", "scale": 2})
    got2 = np.asarray(texture_eval(tex2, jnp.array([[0.1, 0.1], [0.3, 0.1]])))
    np.testing.assert_allclose(got2[:, 0], [0.4, 0.2], rtol=1e-6)


def test_bitmap_png_srgb_decoding(tmp_path):
    rng = np.random.default_rng(0)
    px = rng.integers(0, 256, (3, 4, 3), dtype=np.uint8)
    Image.fromarray(px).save(tmp_path / "t.png")
    tex = texture_from_dict({"type": "bitmap", "file": "t.png"}, base_dir=str(tmp_path))
    ref = colour.cctf_decoding(px / 255.0, function="sRGB")
    np.testing.assert_allclose(np.asarray(tex.image), ref, atol=2e-6)
    raw = texture_from_dict({"type": "bitmap", "file": str(tmp_path / "t.png"), "raw": True})
    np.testing.assert_allclose(np.asarray(raw.image), px / 255.0, atol=1e-6)


def test_bitmap_errors(tmp_path):
    with pytest.raises(ValueError, match=r"materials.m: reflectance.file"):
        load_scene(_plane_scene({"type": "bitmap", "file": str(tmp_path / "missing.png")}))
    with pytest.raises(ValueError, match="reflectance.type"):
        load_scene(_plane_scene({"type": "noise"}))
    with pytest.raises(ValueError, match="reflectance: unknown key"):
        load_scene(_plane_scene({"type": "bitmap", "image": [[0.5]], "gamma": 2}))
    bad = {"type": "roughconductor", "alpha": {"type": "bitmap", "image": [[0.1, 0.0]]}}
    with pytest.raises(ValueError, match="alpha: texture values must be positive"):
        load_scene(_plane_scene(None, material=bad))
    with pytest.raises(ValueError, match="reflectance.wrap"):
        load_scene(_plane_scene({"type": "bitmap", "image": [[0.5]], "wrap": "tile"}))


# issue 9: ~6 s of a loaded 2-core default run; the checkerboard and bitmap texture checks stay in
# the default run
@pytest.mark.slow
def test_textured_at_matches_per_ray_bsdfs(x64):
    """RGB reflectance and scalar GGX alpha per ray equal BSDFs built with those constants."""
    alpha_img = jnp.array([[0.05, 0.3], [0.6, 1.0]])
    refl_img = jnp.array([[[0.9, 0.5, 0.1], [0.2, 0.4, 0.8]], [[1.0, 1.0, 1.0], [0.3, 0.3, 0.3]]])
    texs = {
        "alpha": texture_from_dict({"type": "bitmap", "image": alpha_img, "filter": "nearest"}),
        "reflectance": texture_from_dict(
            {"type": "bitmap", "image": refl_img, "filter": "nearest"}
        ),
    }
    mat = Textured(RoughConductor(0.5), texs)
    uv = jnp.array([[0.25, 0.25], [0.75, 0.25], [0.25, 0.75], [0.75, 0.75]])
    wo = jnp.array([[0.3, 0.1, 0.95], [-0.5, 0.2, 0.84], [0.0, 0.7, 0.71], [0.1, -0.2, 0.97]])
    wo = wo / jnp.linalg.norm(wo, axis=-1, keepdims=True)
    wi = jnp.array([[-0.2, 0.3, 0.93], [0.4, 0.4, 0.82], [0.1, -0.6, 0.79], [0.6, 0.0, 0.8]])
    wi = wi / jnp.linalg.norm(wi, axis=-1, keepdims=True)
    u1 = jnp.full(4, 0.3)
    u2 = jnp.array([[0.2, 0.7], [0.5, 0.1], [0.9, 0.4], [0.3, 0.3]])

    @jax.jit
    def per_ray(mat):
        b = mat.at(uv)
        return b.eval(wo, wi), b.pdf(wo, wi), b.sample(wo, u1, u2)

    f, pdf, s = per_ray(mat)
    a_flat = np.asarray(alpha_img).reshape(-1)
    r_flat = np.asarray(refl_img).reshape(-1, 3)
    for i in range(4):
        ref = RoughConductor(float(a_flat[i]), reflectance=r_flat[i])
        np.testing.assert_allclose(f[i], ref.eval(wo[i], wi[i]), rtol=1e-10)
        np.testing.assert_allclose(pdf[i], ref.pdf(wo[i], wi[i]), rtol=1e-10)
        si = ref.sample(wo[i], u1[i], u2[i])
        np.testing.assert_allclose(s.wi[i], si.wi, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(s.weight[i], si.weight, rtol=1e-9)

    def loss(img):
        t = Textured(Diffuse(0.5), {"reflectance": Texture(img)})
        return jnp.sum(t.at(uv * 0.9 + 0.03).eval(wo, wi))

    check_grads(loss, (refl_img,), order=1, modes=["rev"])


def _plane_scene(tex, *, material=None, width=8):
    return textured_plane_scene(tex, material=material, width=width)


TEX_IMG = np.array([[[0.9, 0.5, 0.1], [0.2, 0.4, 0.8]], [[0.6, 0.6, 0.6], [0.3, 0.1, 0.7]]])


@eqx.filter_jit
def _img_and_grad(scene, path, value, w, key=KEY):
    """``direct`` image (4 spp) of ``scene`` with parameter ``path`` set to ``value``, and the
    gradient of ``sum_c w_c mean(image_c)`` w.r.t. ``value``, in ONE compiled program (the
    finite differences reuse it, so each scene structure compiles once)."""

    def f(v):
        img = render(scene.replace(path, v), key, spp=4, integrator="direct")
        return jnp.sum(jnp.mean(img, (0, 1)) * w), img

    (_, img), g = jax.value_and_grad(f, has_aux=True)(value)
    return img, g


def _direct_loss(value, key, scene, path, w):
    """``sum_c w_c mean(image_c)`` of the ``direct`` image (4 spp), ``path`` set to ``value``."""
    img = render(scene.replace(path, value), key, spp=4, integrator="direct")
    return jnp.sum(jnp.mean(img, (0, 1)) * w)


@pytest.mark.slow  # issue 9: ~15 s of a loaded 2-core run; out of make test
def test_constant_texture_renders_like_plain_material_and_texel_gradient():
    path = "materials.m.reflectance.image"
    w = jnp.linspace(0.5, 1.5, 3)
    scene = load_scene(_plane_scene({"type": "bitmap", "image": TEX_IMG}))
    const = jnp.full((2, 2, 3), 0.3, jnp.float32)
    a, _ = _img_and_grad(scene, path, const, w)
    b = render(load_scene(_plane_scene(0.3)), KEY, spp=4, integrator="direct")
    assert float(jnp.mean(b)) > 0.05
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=1e-6)

    # texel gradient: the image is linear in the texels (direct light, diffuse), so central
    # differences with the same key are exact up to float32 rounding (every texel)
    x0 = jnp.asarray(TEX_IMG, jnp.float32)
    ok, g, fd = check_grads_fd(
        lambda x: _direct_loss(x, KEY, scene, path, w), x0, eps=0.05, rtol=2e-3, atol=1e-5, jit=True
    )
    assert np.all(np.isfinite(g)) and float(np.max(np.abs(g))) > 1e-3
    np.testing.assert_allclose(g, fd, rtol=2e-3, atol=1e-5)
    assert ok
    assert scene.get(path).shape == (2, 2, 3)


def test_checkerboard_albedo_aov():
    """AOV albedo of a checkerboard plane is exactly one of the two colours, half each."""
    tex = {"type": "checkerboard", "color0": [0.8, 0.1, 0.1], "color1": [0.1, 0.1, 0.8], "scale": 2}
    img = np.asarray(render(load_scene(_plane_scene(tex, width=16)), KEY, spp=1, integrator="aov"))
    alb = img[..., :3].reshape(-1, 3)
    is0 = np.all(np.abs(alb - [0.8, 0.1, 0.1]) < 1e-6, -1)
    is1 = np.all(np.abs(alb - [0.1, 0.1, 0.8]) < 1e-6, -1)
    assert np.all(is0 | is1)
    assert 0.35 < is0.mean() < 0.65


# ------------------------------------------------------------------------------------------
# SDF shapes


@pytest.mark.slow  # issue 9: ~9 s of a loaded 2-core run; out of make test
def test_sdf_shape_closest_t_matches_analytic_sphere(rng):
    c, r = np.array([0.2, -0.1, 0.3]), 0.8
    shape = SDFShape(SDFSphere(c, r), max_steps=256, eps=1e-5)
    o = rng.normal(size=(256, 3)) * 3
    d = c + rng.normal(size=(256, 3)) * 0.6 - o  # about half of the rays hit
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    o, d = jnp.asarray(o, jnp.float32), jnp.asarray(d, jnp.float32)
    t, _ = jax.jit(lambda o, d: shape.closest_t(o, d, tmin=0.0, tmax=jnp.inf))(o, d)
    ref = intersect(Spheres(c, r), o, d)
    np.testing.assert_array_equal(np.isfinite(t), np.asarray(ref.valid))
    v = np.asarray(ref.valid)
    assert 40 < v.sum() < 216
    np.testing.assert_allclose(np.asarray(t)[v], np.asarray(ref.t)[v], atol=2e-3)  # grazing
    # hit record: point and normal
    h = shape.hit(jnp.zeros(256, jnp.int32), o, d, jnp.asarray(v))
    np.testing.assert_allclose(np.asarray(h.p)[v], np.asarray(ref.p)[v], atol=2e-3)
    np.testing.assert_allclose(np.asarray(h.ng)[v], np.asarray(ref.ng)[v], atol=3e-3)


@pytest.mark.slow  # issue 9: ~6 s of a loaded 2-core run; out of make test
def test_sdf_shape_from_inside_and_from_its_surface():
    shape = SDFShape(SDFSphere([0.0, 0.0, 0.0], 1.0))
    # camera inside: hits the far wall at t = 1
    t, _ = shape.closest_t(jnp.zeros((1, 3)), jnp.array([[0.0, 0.6, 0.8]]), tmin=0.0, tmax=jnp.inf)
    np.testing.assert_allclose(t, [1.0], atol=1e-3)
    # rays leaving the surface outward: no self-hit; inward: chord 2 cos(theta)
    p = jnp.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    d = jnp.array([[0.6, 0.0, 0.8], [0.6, 0.0, -0.8]])
    t, _ = shape.closest_t(p, d, tmin=0.0, tmax=jnp.inf)
    assert not np.isfinite(t[0])
    np.testing.assert_allclose(t[1], 1.6, atol=2e-3)


def _sphere_scene(kind, radius=1.0, *, origin=(0, 0, 4), fov=40):
    if kind == "sdf":
        shape = {"type": "sdf", "expr": {"op": "sphere", "center": [0, 0, 0], "radius": radius}}
    else:
        shape = sphere([0, 0, 0], radius)
    return load_scene(
        {
            "camera": camera(origin, [0, 0, 0], fov=fov, width=12),
            "shapes": [shape | {"material": "m"}],
            "materials": {"m": {"type": "diffuse", "reflectance": 0.7}},
            "emitters": [
                point_light([1.5, 2.0, 3.0], 30),
                {"type": "constant", "radiance": 0.2},
            ],
        }
    )


W3 = jnp.full(3, 1.0 / 3.0, jnp.float32)


def _radius(kind):
    return "shapes.0.sdf.radius" if kind == "sdf" else "shapes.0.radii"


@pytest.mark.slow  # issue 9: ~23 s of a loaded 2-core run; out of make test
def test_sdf_sphere_renders_like_analytic_sphere():
    a, _ = _img_and_grad(_sphere_scene("sdf"), _radius("sdf"), jnp.float32(1.0), W3)
    b = render(_sphere_scene("analytic"), KEY, spp=4, integrator="direct")
    assert float(jnp.mean(b)) > 0.05
    np.testing.assert_allclose(float(jnp.mean(a)), float(jnp.mean(b)), rtol=5e-3)
    close = np.abs(np.asarray(a) - np.asarray(b)) < 2e-3
    assert close.mean() > 0.95


def _radius_grad_fd(kind, keys, h=0.01):
    """Per key: AD and central-difference d(weighted image mean)/d radius at radius 1."""
    # zoomed in: every pixel sees the sphere, so there is no silhouette (whose motion AD of a
    # path tracer without edge sampling does not see) and d mean / d radius is smooth
    s = _sphere_scene(kind, origin=(0, 0, 2.2), fov=20)
    _, g, fd = ad_fd_per_key(_direct_loss, jnp.float32(1.0), keys, h, args=(s, _radius(kind), W3))
    return g, fd


# issue 9: ~10 s of a loaded 2-core default run; the SDF hit gradients stay in the default run
# (test_sdf_hit_gradients_float64, test_sdf.py)
@pytest.mark.slow
def test_sdf_radius_gradient_matches_finite_differences():
    """Implicit differentiation of the sphere-traced hit vs central differences, 8 keys.

    A statistical check, not a per-key identity: BSDF-sampled directions are detached in world
    space (Mitsuba 3 prb; docs/render_gradients.md), so AD differentiates a realisation whose
    directions stay fixed as the radius turns the normal, while same-key FD re-renders with
    directions that turn with it. Both estimate the derivative of the expected image; per key
    they differ by Monte Carlo noise (1.96 % at this key and 4 spp). Tolerance: 4 standard
    errors of the paired difference over the keys plus 0.5 % of |FD| for the central
    difference's O(h^2) error (measured 0.3 % at h = 0.01 when AD and FD shared directions).
    Measured: AD 0.06240, FD 0.06274, difference -0.00034 +- 0.00060 (0.6 se)."""
    g, fd = _radius_grad_fd("sdf", jnp.stack([jax.random.key(100 + i) for i in range(8)]))
    assert np.all(np.isfinite(g)) and abs(g.mean()) > 1e-2
    d = g - fd
    se = d.std(ddof=1) / np.sqrt(len(d))
    assert 4 * se < 0.05 * abs(fd.mean()), (se, fd.mean())  # the check resolves a 5 % error
    assert abs(d.mean()) < 4 * se + 0.005 * abs(fd.mean()), (d.mean(), se, fd.mean())


@pytest.mark.slow
def test_sdf_radius_gradient_matches_analytic_sphere():
    g_sdf, _ = _radius_grad_fd("sdf", jnp.stack([KEY]))
    g_ana, fd_ana = _radius_grad_fd("analytic", jnp.stack([KEY]))
    np.testing.assert_allclose(g_ana, fd_ana, rtol=0.05)
    np.testing.assert_allclose(g_sdf, g_ana, rtol=0.05)


def test_sdf_scene_errors():
    sdf = {"type": "sdf", "expr": {"op": "sphere", "center": [0, 0, 0], "radius": 1}}
    base = {
        "camera": {"origin": [0, 0, 4], "target": [0, 0, 0], "fov": 40, "width": 4, "height": 4}
    }
    with pytest.raises(ValueError, match="SDF shapes cannot be area lights"):
        load_scene(
            base | {"shapes": [sdf], "emitters": [{"type": "area", "shape": sdf, "radiance": 1}]}
        )
    with pytest.raises(ValueError, match=r"shapes\[0\].max_steps"):
        load_scene(base | {"shapes": [sdf | {"max_steps": 0}]})
    with pytest.raises(ValueError, match=r"shapes\[0\].expr.op: expected one of"):
        load_scene(base | {"shapes": [{"type": "sdf", "expr": {"op": "blob"}}]})
    with pytest.raises(ValueError, match=r"shapes\[0\]: unknown key"):
        load_scene(base | {"shapes": [sdf | {"steps": 3}]})
    assert math.isclose(float(load_scene(base | {"shapes": [sdf]}).get("shapes.0.sdf.radius")), 1.0)


def test_checkerboard_module_example():
    t = Textured(Diffuse(0.5), {"reflectance": Checkerboard(jnp.ones(3), jnp.zeros(3))})
    np.testing.assert_array_equal(t.at(jnp.array([0.25, 0.25])).reflectance, [1, 1, 1])
    np.testing.assert_array_equal(t.at(jnp.array([0.75, 0.25])).reflectance, [0, 0, 0])
    with pytest.raises(ValueError, match="uv: a textured material needs the hit uv"):
        t.at(None)
    with pytest.raises(ValueError, match="not a texturable parameter"):
        Textured(Diffuse(0.5), {"roughness": Checkerboard(jnp.ones(1), jnp.zeros(1))})


def test_example_yamls_load():
    root = os.path.join(os.path.dirname(__file__), "..", "..", "configs", "scenes")
    tex = load_scene(os.path.join(root, "textured.yaml"))
    assert [type(m).__name__ for m in tex.materials][:3] == ["Textured"] * 3
    alpha = tex.get("materials.brushed.alpha.image")
    assert alpha.shape == (2, 4, 1) and float(alpha.min()) == pytest.approx(0.05)
    sdf = load_scene(os.path.join(root, "sdf.yaml"))
    assert sum(isinstance(s, SDFShape) for s in sdf.shapes) == 2


# 3.6 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_sdf_hit_gradients_float64(x64):
    """Implicit differentiation of the SDF hit: ``t`` w.r.t. radius and centre against finite
    differences (check_grads) and the closed form ``dt/dr = -1`` for rays through the centre."""
    o = jnp.array([[0.0, 0.0, -3.0], [0.3, 0.2, -3.0], [2.5, 0.1, 0.2]])
    d = jnp.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
    valid = jnp.ones(3, bool)

    @jax.jit
    def t_of(r, c):
        shape = SDFShape(SDFSphere(c, r), max_steps=400, eps=1e-11)
        return shape.hit(jnp.zeros(3, jnp.int32), o, d, valid).t

    r0, c0 = jnp.float64(1.0), jnp.array([0.0, 0.0, 0.05])
    check_grads(t_of, (r0, c0), order=1, modes=["rev"], eps=1e-5, rtol=1e-4, atol=1e-6)
    g = jax.jacrev(t_of)(r0, c0)
    np.testing.assert_allclose(g[0], -1.0, rtol=1e-8)


def test_mesh_scale_transforms_vertex_normals_by_inverse_transpose(tmp_path):
    # a tilted plane z = x with vertex normals (-1, 0, 1)/sqrt2; scaling x by 2 gives z = x/2,
    # whose normal is (-1, 0, 2)/sqrt5 = normalize(n / s)
    obj = tmp_path / "tilted.obj"
    obj.write_text("v 0 0 0\nv 1 0 1\nv 0 1 0\nvn -0.7071068 0 0.7071068\nf 1//1 2//1 3//1\n")
    desc = {
        "camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 30, "width": 4, "height": 4},
        "shapes": [{"type": "mesh", "file": str(obj), "scale": [2.0, 1.0, 1.0]}],
        "emitters": [{"type": "constant", "radiance": 1.0}],
    }
    from jaxgfx.render.scene import load_scene

    mesh = load_scene(desc).shapes[0]
    mesh = getattr(mesh, "mesh", mesh)
    expected = np.array([-1.0, 0, 2]) / np.sqrt(5)
    np.testing.assert_allclose(mesh.normals, np.tile(expected, (3, 1)), rtol=1e-6, atol=1e-7)
    v = np.asarray(mesh.vertices)
    ng = np.cross(v[1] - v[0], v[2] - v[0])
    np.testing.assert_allclose(np.abs(ng / np.linalg.norm(ng)), np.abs(expected), atol=1e-6)
