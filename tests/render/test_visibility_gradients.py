"""Boundary terms of shape derivatives: ``render(..., visibility="edge")`` (issue 10).

References (independent of the renderer):

* primary silhouette: a non-emitting sphere on the optical axis in front of a constant
  environment of radiance 1, emitters only (``max_depth = 1``): the expected image mean is
  ``1 - π R² / (W H)`` with ``R = f tan(asin(r / D))`` the radius in pixels of the projected disc
  (``f = (W/2) / tan(fov/2)``): closed-form derivatives w.r.t. the radius and the distance;
* shadow boundary: a floor point straight below a sphere under a constant environment of
  radiance L (direct lighting, Lambertian floor of reflectance ρ) has radiance
  ``ρ L (1 - sin² α)``, ``sin α = r / h`` (the sphere blocks a cap of the hemisphere centred on
  the zenith, whose cosine-weighted measure is ``π sin² α``); seen by a 2° camera below the sphere;
* a scene with both (sphere in front of an area light and its shadow on a floor): central finite
  differences of the same renderer with the same keys (slow).

Without the boundary term the first two gradients are exactly 0 (the integrand inside the
moving regions is constant), so the negative controls cannot pass by accident.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import Spheres, load_scene, render
from jaxgfx.render.visibility import project, tangent_circle

from ._scenes import camera, rectangle

W = 8
FOV = 30.0


def _primary_desc(center=(0.0, 0.0, 0.0), radius=0.5, **kw):
    return {
        "camera": {"origin": [0, 0, 4.0], "target": [0, 0, 0], "fov": FOV, "width": W, "height": W},
        "shapes": [
            {"type": "sphere", "center": list(center), "radius": radius, "material": "black"}
        ],
        "materials": {"black": {"type": "diffuse", "reflectance": 0.5}},
        "emitters": [{"type": "constant", "radiance": 1.0}],
        **kw,
    }


def _mean_closed_form(r, dist):
    f = (W / 2) / math.tan(math.radians(FOV / 2))
    big_r = f * math.tan(math.asin(r / dist))
    return 1.0 - math.pi * big_r**2 / (W * W)


def _derivative(fn, x, h=1e-5):
    return (fn(x + h) - fn(x - h)) / (2 * h)


@pytest.fixture(scope="module")
def primary():
    """One compiled value-and-gradient program (w.r.t. radius and centre) of the primary scene
    with edge sampling; every default test below calls it with other parameter values."""
    scene = load_scene(_primary_desc())

    def image(r, c, key, vis):
        sc = scene.replace("shapes.0.radii", r).replace("shapes.0.centers", c)
        return render(sc, key, spp=4, integrator="path", max_depth=1, visibility=vis)

    vg = jax.jit(jax.value_and_grad(lambda r, c, k: image(r, c, k, "edge").mean(), argnums=(0, 1)))
    fwd = jax.jit(lambda r, c, k: image(r, c, k, None))
    fwd_edge = jax.jit(lambda r, c, k: image(r, c, k, "edge"))
    return scene, vg, fwd, fwd_edge


def _run(vg, r, c, seed=0):
    v, (gr, gc) = vg(jnp.float32(r), jnp.asarray(c, jnp.float32), jax.random.key(seed))
    return float(v), float(gr), np.asarray(gc, np.float64)


# 7.4 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_primary_silhouette_matches_projected_disc(primary):
    _, vg, _, _ = primary
    _, gr, gc = _run(vg, 0.5, [0.0, 0.0, 0.0])
    want_r = _derivative(lambda r: _mean_closed_form(r, 4.0), 0.5)
    # moving the centre towards the camera (+z) shortens the distance
    want_z = -_derivative(lambda d: _mean_closed_form(0.5, d), 4.0)
    # ΔL = -1 exactly on the whole silhouette, and its 4 x 64 parameter samples are stratified:
    # the estimator's only error is the jitter of a smooth periodic integrand (measured 2e-6
    # relative); 1e-3 allows for float32 rounding of the 256 terms.
    assert gr == pytest.approx(want_r, rel=1e-3)
    assert gc[2] == pytest.approx(want_z, rel=1e-3)
    # sideways: 0 by symmetry; stratified jitter leaves ~1e-3 of |d/dr|
    assert np.all(np.abs(gc[:2]) < 5e-3 * abs(want_r))


def test_plain_ad_misses_the_silhouette_term():
    """Negative control: without the boundary term the same derivative is exactly 0 (the
    closed form is -0.706), so removing the method fails the test above by ~all of it."""
    scene = load_scene(_primary_desc())
    g = jax.jit(
        jax.grad(
            lambda r, k: render(
                scene.replace("shapes.0.radii", r), k, spp=4, integrator="path", max_depth=1
            ).mean()
        )
    )(jnp.float32(0.5), jax.random.key(0))
    want_r = _derivative(lambda r: _mean_closed_form(r, 4.0), 0.5)
    assert abs(float(g) - want_r) > 0.5 * abs(want_r)


# slow: ~6 s of the default run (2026-12-06, quiet: the two forward programs only it compiles);
# the value-and-gradient program's values stay checked by the default tests below
@pytest.mark.slow
def test_values_are_unchanged(primary):
    """The boundary term changes derivatives only: forward images are bit-identical, and the
    value of the value-and-gradient program equals the forward image's mean."""
    _, vg, fwd, fwd_edge = primary
    c = jnp.asarray([0.3, -0.2, 0.1], jnp.float32)
    for seed in (0, 1):
        k = jax.random.key(seed)
        a = np.asarray(fwd(jnp.float32(0.6), c, k))
        b = np.asarray(fwd_edge(jnp.float32(0.6), c, k))
        np.testing.assert_array_equal(a, b)
        v, _, _ = _run(vg, 0.6, c, seed)
        assert v == pytest.approx(float(a.mean()), rel=1e-6)


def test_offscreen_sphere_has_zero_finite_gradient(primary):
    _, vg, _, _ = primary
    # far to the side: no pixel sees it, the closed-form derivative is 0
    v, gr, gc = _run(vg, 0.5, [6.0, 0.0, 0.0])
    assert v == 1.0
    assert gr == 0.0 and np.all(gc == 0.0)
    # behind the camera (tangent points at negative depth are dropped)
    v, gr, gc = _run(vg, 0.5, [0.0, 0.0, 6.0])
    assert gr == 0.0 and np.all(gc == 0.0)
    # camera inside the sphere: no silhouette, finite
    _, gr, gc = _run(vg, 5.0, [0.0, 0.0, 0.0])
    assert np.isfinite(gr) and np.all(np.isfinite(gc))


def test_silhouette_tangent_to_image_border(primary):
    """Projected disc touching the right border: the part of the silhouette inside the image
    still moves; the derivative is finite and, as x moves the sphere out, negative for the mean
    of a dark disc on a bright background only through the disc's leaving pixels (> 0)."""
    _, vg, _, _ = primary
    tan_half = math.tan(math.radians(FOV / 2))
    # centre x such that the projected disc's right edge is at the border (on-axis size approx)
    r, dist = 0.5, 4.0
    edge = math.tan(math.asin(r / dist))  # angular radius, as a tangent
    x = dist * (tan_half - edge)
    _, gr, gc = _run(vg, r, [x, 0.0, 0.0])
    assert np.isfinite(gr) and np.all(np.isfinite(gc))
    assert gc[0] > 0  # moving out of the image uncovers background (radiance 1)


def test_tangent_circle_and_projection(primary):
    """T is on the sphere and rays from o graze it there; project inverts generate_ray."""
    c = jnp.asarray([0.3, -0.2, 0.5])
    r = jnp.asarray(0.7)
    o = jnp.asarray([1.0, 2.0, 4.0])
    phi = jnp.linspace(0.0, 2 * math.pi, 13)
    t, u, rho, ok = jax.jit(tangent_circle)(c, r, o, phi)
    # the checks in NumPy: as jnp operations, op by op, they made ~40 small compiles
    t, u, rho, c, o = (np.asarray(a, np.float64) for a in (t, u, rho, c, o))
    assert bool(np.all(np.asarray(ok)))
    np.testing.assert_allclose(np.linalg.norm(t - c, axis=-1), 0.7, rtol=1e-6)
    np.testing.assert_allclose(np.sum((t - o) * (t - c), -1), 0.0, atol=1e-5)
    d2 = float(np.sum((c - o) ** 2))
    np.testing.assert_allclose(rho, 0.7 * math.sqrt(d2 - 0.49) / math.sqrt(d2), rtol=1e-6)
    # u points away from the axis (outside the cone of hitting rays)
    axis = (c - o) / np.linalg.norm(c - o)
    np.testing.assert_allclose(np.sum(u * axis, -1), 0.0, atol=1e-6)
    scene = primary[0]
    px = jnp.asarray([[0.3, 7.1], [4.0, 4.0], [7.9, 0.2]])
    oo, dd = jax.jit(lambda cam, px: cam.generate_ray(px))(scene.camera, px)
    back, z = jax.jit(project)(scene.camera, oo + 2.5 * dd)
    np.testing.assert_allclose(back, px, atol=1e-5)
    assert bool(jnp.all(z > 0))


def test_bad_options():
    scene = load_scene(_primary_desc())
    k = jax.random.key(0)
    with pytest.raises(ValueError, match="visibility"):
        render(scene, k, spp=1, visibility="reparam")
    with pytest.raises(ValueError, match="visibility"):
        render(scene, k, spp=1, integrator="whitted", visibility="edge")
    gauss = load_scene(_primary_desc(film={"filter": "gaussian"}))
    with pytest.raises(ValueError, match="box filter"):
        render(gauss, k, spp=1, visibility="edge")


# ------------------------------------------------------------------------ shadows (slow)

_RHO, _L, _R, _H = 0.5, 1.0, 0.5, 2.0


def _down_camera():
    """0.5 above the floor point, looking straight down, 2° field of view, 2 x 2 pixels."""
    return camera([0, 0.5, 0], [0, 0, 0], up=[0, 0, -1], fov=2, width=2)


def _shadow_scene():
    """Camera 0.5 above the floor looking straight down (2° field of view) under a sphere of
    radius 0.5 centred 2 above the floor point; constant environment 1; a small area light above
    the sphere that the sphere hides completely from the floor point (hard case)."""
    return load_scene(
        {
            "camera": _down_camera(),
            "shapes": [
                {"type": "sphere", "center": [0, _H, 0], "radius": _R, "material": "white"},
                rectangle(size=(4, 4), material="floor"),
            ],
            "materials": {
                "white": {"type": "diffuse", "reflectance": 0.5},
                "floor": {"type": "diffuse", "reflectance": _RHO},
            },
            "emitters": [
                {
                    "type": "area",
                    "shape": {
                        "type": "rectangle",
                        "center": [0, 3.0, 0],
                        "normal": [0, -1, 0],
                        "size": [0.2, 0.2],
                    },
                    "radiance": 10.0,
                },
                {"type": "constant", "radiance": _L},
            ],
        }
    )


@pytest.mark.slow  # issue 10: ~55 s (load 2) to 180 s (load 5) on 2 cores: direct + edges compile
def test_shadow_boundary_matches_occluded_cap():
    scene = _shadow_scene()
    si = next(i for i, s in enumerate(scene.shapes) if isinstance(s, Spheres))

    def mean(r, c, key, vis):
        sc = scene.replace(f"shapes.{si}.radii", r).replace(f"shapes.{si}.centers", c)
        return render(sc, key, spp=16, integrator="direct", visibility=vis).mean()

    vg = jax.jit(jax.value_and_grad(lambda r, c, k: mean(r, c, k, "edge"), argnums=(0, 1)))
    rows = []
    for s in range(8):
        v, (gr, gc) = vg(jnp.float32(_R), jnp.asarray([0, _H, 0], jnp.float32), jax.random.key(s))
        rows.append([float(v), float(gr), *np.asarray(gc, np.float64)])
    a = np.asarray(rows)
    m, se = a.mean(0), a.std(0, ddof=1) / np.sqrt(len(a))
    assert np.all(np.isfinite(a))
    sin2 = (_R / _H) ** 2
    assert m[0] == pytest.approx(_RHO * _L * (1 - sin2), abs=4 * se[0] + 1e-3)
    want_r = -2 * _RHO * _L * _R / _H**2  # -0.125
    want_h = 2 * _RHO * _L * _R**2 / _H**3  # 0.03125
    # tolerance: 4 standard errors over the keys, plus 1e-3 relative for the camera footprint
    # (the 2° pixel sees floor points up to 0.009 off the axis) and the rays' 1e-3 offsets
    assert m[1] == pytest.approx(want_r, abs=4 * se[1] + 1e-3 * abs(want_r))
    assert m[3] == pytest.approx(want_h, abs=4 * se[3] + 1e-3 * abs(want_h))
    for j in (2, 4):  # sideways: 0 by symmetry
        assert abs(m[j]) <= 4 * se[j] + 1e-3 * abs(want_r)
    # negative control: plain AD is exactly 0 here (the light is hidden; visibility is boolean)
    g = jax.jit(jax.grad(lambda r, k: mean(r, jnp.asarray([0, _H, 0], jnp.float32), k, None)))
    assert float(g(jnp.float32(_R), jax.random.key(0))) == 0.0


def _front_desc(size):
    from jaxgfx.testing.problems import visibility_scene_desc

    return visibility_scene_desc(size)


@pytest.mark.slow  # issue 10: ~60 s on the shared 2-core machine (two gradient programs)
def test_edge_gradient_matches_finite_differences():
    """Sphere moving in front of an area light over a lit floor (silhouette over the light and
    the floor, shadow edge on the floor), direct lighting, 8², fixed-weight image sum."""
    from jaxgfx.testing.problems import measure_visibility_bias

    res = measure_visibility_bias(8, keys=16, spp=16, h=0.05, integrator="direct")
    d, p = res["edge_minus_fd"], res["plain_minus_fd"]
    # AD with edges vs same-key FD: within 4 standard errors of the paired difference (FD's
    # O(h²) bias is below its noise at h = 0.05: measured at h = 0.03 and 0.05 alike)
    assert abs(d["mean"]) <= 4 * d["stderr"]
    # without the boundary term the same comparison is off by more than 4 standard errors
    assert abs(p["mean"]) > 4 * p["stderr"]


# ------------------------------------------------------------------- rectangles (slow)


@pytest.mark.slow  # issue 10: ~5-7 s (a second primary program; over the default budget)
def test_primary_square_matches_projected_square():
    """A black square of side 1 facing the camera at distance 4 before a constant environment:
    its image is a square of side f s / D pixels, so d mean / d(scale of both edges) =
    -2 (f s/D)² / (W H) and d mean / dz = -2 (f s)² / (D³ W H)."""
    desc = _primary_desc()
    desc["shapes"] = [
        {
            "type": "rectangle",
            "center": [0, 0, 0],
            "normal": [0, 0, 1],
            "size": [1.0, 1.0],
            "material": "black",
        }
    ]
    scene = load_scene(desc)
    eu, ev, c0 = (scene.get(f"shapes.0.{n}") for n in ("edge_u", "edge_v", "centers"))
    ez = jnp.asarray([0.0, 0.0, 1.0])

    def mean(x, dz, key, vis):
        sc = scene.replace("shapes.0.edge_u", eu * x).replace("shapes.0.edge_v", ev * x)
        sc = sc.replace("shapes.0.centers", c0 + ez * dz)
        return render(sc, key, spp=4, integrator="path", max_depth=1, visibility=vis).mean()

    vg = jax.jit(jax.grad(lambda x, dz, k: mean(x, dz, k, "edge"), argnums=(0, 1)))
    gx, gz = vg(jnp.float32(1.0), jnp.float32(0.0), jax.random.key(0))
    f = (W / 2) / math.tan(math.radians(FOV / 2))
    # ΔL = -1 on the whole outline and the positions along the 4 edges are stratified over
    # 4 x 64 samples: float32 rounding only (measured 1e-7 relative)
    assert float(gx) == pytest.approx(-2 * (f / 4) ** 2 / W**2, rel=1e-3)
    assert float(gz) == pytest.approx(-2 * f**2 / 4**3 / W**2, rel=1e-3)


def _square_form_factor(s, c):
    """Cosine-weighted fraction of the hemisphere a centred parallel square (side s, height c)
    covers: 4 x the corner formula (Howell's catalogue, configuration B-3)."""
    x = y = (s / 2) / c
    ax, ay = math.sqrt(1 + x * x), math.sqrt(1 + y * y)
    f = (x / ax * math.atan(y / ax) + y / ay * math.atan(x / ay)) / (2 * math.pi)
    return 4 * f


@pytest.mark.slow  # issue 10: ~25 s at load 2 (compile of direct + edges, 16 keys)
def test_shadow_of_a_square_matches_form_factor():
    """Floor point below a square occluder (side 1, height 2) under a constant environment:
    radiance ρ L (1 - F(s, h)); derivatives of the closed form w.r.t. s and h."""
    desc = {
        "camera": _down_camera(),
        "shapes": [
            {
                "type": "rectangle",
                "center": [0, _H, 0],
                "normal": [0, 1, 0],
                "size": [1.0, 1.0],
                "material": "white",
            },
            rectangle(size=(4, 4), material="floor"),
        ],
        "materials": {
            "white": {"type": "diffuse", "reflectance": 0.5},
            "floor": {"type": "diffuse", "reflectance": _RHO},
        },
        "emitters": [{"type": "constant", "radiance": _L}],
    }
    scene = load_scene(desc)
    eu, ev, c = (scene.get(f"shapes.0.{n}") for n in ("edge_u", "edge_v", "centers"))
    # the loader concatenates both rectangles into one shape: move only the occluder (row 0)
    sel = jnp.asarray([[1.0], [0.0]])
    ey = jnp.asarray([0.0, 1.0, 0.0])

    def mean(x, dh, key):
        k = 1 + sel * (x - 1)
        sc = scene.replace("shapes.0.edge_u", eu * k).replace("shapes.0.edge_v", ev * k)
        sc = sc.replace("shapes.0.centers", c + sel * ey * dh)
        return render(sc, key, spp=16, integrator="direct", visibility="edge").mean()

    vg = jax.jit(jax.value_and_grad(mean, argnums=(0, 1)))
    rows = []
    for s in range(16):
        v, (gx, gh) = vg(jnp.float32(1.0), jnp.float32(0.0), jax.random.key(s))
        rows.append([float(v), float(gx), float(gh)])
    a = np.asarray(rows)
    m, se = a.mean(0), a.std(0, ddof=1) / np.sqrt(len(a))
    assert np.all(np.isfinite(a))
    ff = _square_form_factor
    want_v = _RHO * _L * (1 - ff(1.0, _H))
    want_s = -_RHO * _L * _derivative(lambda s: ff(s, _H), 1.0)  # d/d(scale) at side 1
    want_h = -_RHO * _L * _derivative(lambda h: ff(1.0, h), _H)
    assert m[0] == pytest.approx(want_v, abs=4 * se[0] + 1e-3)
    # 4 standard errors over the keys plus 1e-3 relative (pixel footprint, ray offsets)
    assert m[1] == pytest.approx(want_s, abs=4 * se[1] + 1e-3 * abs(want_s))
    assert m[2] == pytest.approx(want_h, abs=4 * se[2] + 1e-3 * abs(want_h))


# ---------------------------------------------------------------------- meshes


def test_edge_multiplicity_weights():
    """Each undirected edge counts once: a closed tetrahedron's 6 edges are each shared by two
    faces (12 half-edges of weight 1/2); two triangles forming a square share the diagonal."""
    from jaxgfx.render.visibility import edge_multiplicity_weights

    tet = jnp.asarray([[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]])
    np.testing.assert_array_equal(jax.jit(edge_multiplicity_weights)(tet), np.full(12, 0.5))
    quad = jnp.asarray([[0, 1, 2], [0, 2, 3]])
    w = np.asarray(jax.jit(edge_multiplicity_weights)(quad))
    # half-edges (0,1) (1,2) (2,0) | (0,2) (2,3) (3,0): the diagonal 0-2 appears twice
    np.testing.assert_array_equal(w, [1, 1, 0.5, 0.5, 1, 1])


@pytest.mark.parametrize("m, e", [(64, 36), (64, 4), (10, 36)])
def test_deal_is_unbiased_per_edge(m, e):
    """Every edge's weights sum to 1 (m >= e: stratified t in [k/n, (k+1)/n)) or, for m < e,
    to 1 on average over the random offset."""
    from jaxgfx.render.visibility import _deal

    deal = jax.jit(_deal, static_argnums=(0, 1))
    tot = np.zeros(e)
    offs = (np.arange(e) + 0.5) / e  # every offset once: the average is exact
    for uo in offs:
        edge, t, wt = (np.asarray(x) for x in deal(m, e, jnp.float32(uo), jnp.full((m,), 0.5)))
        assert np.all((t > 0) & (t < 1))
        np.add.at(tot, edge, wt)
        if m >= e:
            for k in range(e):
                tk = np.sort(t[edge == k])
                np.testing.assert_allclose(tk, (np.arange(len(tk)) + 0.5) / len(tk), rtol=1e-6)
    np.testing.assert_allclose(tot / len(offs), 1.0, rtol=1e-6)


_CUBE_V = [[x, y, z] for z in (-0.5, 0.5) for y in (-0.5, 0.5) for x in (-0.5, 0.5)]
_CUBE_F = [
    [0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6],  # z = -0.5, z = +0.5
    [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7],  # y = -0.5, y = +0.5
    [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5],  # x = -0.5, x = +0.5
]  # fmt: skip


@pytest.mark.slow  # issue 10: ~5 s (a third primary program; over the default budget)
def test_primary_cube_mesh_matches_projected_front_face():
    """A black unit cube (12 triangles, every edge shared by two faces) on the axis, front face
    at distance 3.5: its image is the front face's square of side f s / (4 - s/2) pixels.
    d mean / d(scale of the vertices about the centre) from that closed form."""
    desc = _primary_desc()
    desc["shapes"] = [{"type": "mesh", "vertices": _CUBE_V, "faces": _CUBE_F, "material": "black"}]
    scene = load_scene(desc)
    idx = next(i for i, s in enumerate(scene.shapes) if hasattr(s, "faces") or hasattr(s, "mesh"))
    v0 = scene.get(f"shapes.{idx}.vertices")

    def mean(x, key):
        sc = scene.replace(f"shapes.{idx}.vertices", v0 * x)
        return render(sc, key, spp=4, integrator="path", max_depth=1, visibility="edge").mean()

    g = float(jax.jit(jax.grad(mean))(jnp.float32(1.0), jax.random.key(0)))
    f = (W / 2) / math.tan(math.radians(FOV / 2))
    want = _derivative(lambda x: 1 - (f * x / (4 - x / 2)) ** 2 / W**2, 1.0)
    # 36 half-edges: the 8 on the front face's outline carry ΔL = -1 along their whole length
    # (the rest are hidden: ΔL = 0); samples are dealt to every edge and stratified along it,
    # so the estimate is exact up to float32 rounding (measured on 16 keys: spread 3e-8).
    # With offsets of 1e-3 px instead of 1e-4, hidden edges ending on the outline straddled it
    # in 2 of 12 keys (+6 % each): this test would catch that.
    assert g == pytest.approx(want, rel=1e-3)
