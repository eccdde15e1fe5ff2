"""Projector light and the spot light's projected texture (issue 24): closed-form irradiance
(a constant projected onto planes at several distances and tilts, a one-texel image lighting
exactly its footprint), the direct light through the path integrator under ``jit``, gradients
against finite differences in float64 (texels, ``scale``, ``fov``, position; spot intensity,
cutoff and texels), hard cases, loader errors, "model only what a scene needs", and pointwise
comparisons with Mitsuba 3's ``sample_direction`` plus a same-run render (``mitsuba`` marker)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.bsdf.texture import Texture
from jaxgfx.render.emitters import ProjectorLight, SpotLight
from jaxgfx.render.integrators.path import path_radiance
from jaxgfx.render.scene import load_scene
from tests.render._scenes import camera, rectangle, sphere

RHO = 0.6
H = 2.0  # the projector's height above the plane y = 0
# camera rays straight down onto the plane y = 0 at these (x, z)
XZ = np.array([[0.0, 0.0], [0.7, 0.3], [-1.2, 0.9], [1.9, -1.1], [2.6, 0.0], [0.0, -2.5]])


def _plane_desc(plane=False):
    """The diffuse plane y = 0 (``plane``; what the path-integrator test renders) or, for the
    tests that only load scenes or sample lights, a sphere below it (the rectangle's eager
    construction costs ~2.5 s of small XLA compilations here, the sphere's ~0.4 s)."""
    shape = rectangle(size=(12, 12), material="m") if plane else sphere((0, -3, 0), 1.0, "m")
    return {
        "camera": camera([0, 3, 0.01], [0, 0, 0], fov=40, width=2),
        "shapes": [shape],
        "materials": {"m": {"type": "diffuse", "reflectance": RHO}},
    }


def _plane_scene(emitter, dtype=None):
    return load_scene({**_plane_desc(), "emitters": [emitter]}, dtype=dtype)


def _projector(**kw):
    # looking straight down with up = +z: local x (left) = cross(up, dir) = -x, y = +z
    d = {"type": "projector", "position": [0, H, 0], "direction": [0, -1, 0], "up": [0, 0, 1]}
    return d | {"fov": 90.0, "irradiance": [1.0, 2.0, 3.0], "scale": 0.5} | kw


def _rays(dtype):
    o = np.stack([XZ[:, 0], np.full(len(XZ), 1.0), XZ[:, 1]], -1)
    d = np.tile([0.0, -1.0, 0.0], (len(XZ), 1))
    u = np.full((len(XZ), 2, 7), 0.5)
    return jnp.asarray(o, dtype), jnp.asarray(d, dtype), jnp.asarray(u, dtype)


@jax.jit
def _sample(light, p):
    return light.sample(p)


@jax.jit
def _radiance(scene, o, d, u):
    return path_radiance(scene, o, d, u, max_depth=2)  # emitted + direct light


def _two_lights_desc(plane=False):
    """A projector (red, green) and a textured spot (blue) at the same place above y = 0."""
    spot = {
        "type": "spot",
        "position": [0, H, 0],
        "direction": [0, -1, 0],
        "intensity": [0.0, 0.0, 2.0],
        "cutoff_angle": 40.0,
        "beam_width": 20.0,
        "up": [0, 0, 1],
        "texture": {"type": "bitmap", "image": np.full((2, 2, 3), 0.5)},
    }
    return {**_plane_desc(plane), "emitters": [_projector(irradiance=[1.0, 2.0, 0.0]), spot]}


def _two_lights_closed_form():
    """The diffuse plane's radiance ``rho / pi * irradiance`` at the points XZ from the
    projector (red, green: (N, 2)) and from the spot (blue: (N,)). Projector (Mitsuba's):
    irradiance pi * scale * E / z^2 on a plane facing it at distance z (the 1 / cos^3 of the
    frustum cancels the point light's cos^3 falloff), so rho * scale * E / H^2 inside the
    frustum (|x|, |z| < H tan 45) and 0 outside. Spot: a constant 0.5 texture, so the
    untextured spot's rho / pi * I * falloff * cos / r^2 times 0.5."""
    inside = (np.abs(XZ) < H).all(1)
    assert inside.tolist() == [True, True, True, True, False, False]
    pr = RHO * 0.5 * np.array([1.0, 2.0]) / H**2 * inside[:, None]
    r2 = XZ[:, 0] ** 2 + XZ[:, 1] ** 2 + H**2
    cos = H / np.sqrt(r2)
    theta = np.degrees(np.arccos(cos))
    fall = np.where(theta <= 20, 1.0, np.clip((40 - theta) / 20, 0, 1)) * (theta < 40)
    assert fall[0] == 1 and 0 < fall[2] < 1 and fall[-1] == 0  # on axis, falloff, outside
    return pr, RHO / math.pi * 2.0 * 0.5 * fall * cos / r2


@jax.jit
def _sample_light(scene, p, u_sel):
    from jaxgfx.render.integrators._common import sample_light

    return sample_light(scene, p, u_sel, jnp.full(p.shape[:-1] + (2,), 0.5, p.dtype))


def test_light_sampling_selects_projector_and_spot():
    """The integrators' light sampling (``sample_light``, under jit) with a projector and a
    textured spot: a uniform choice (pdf 1/2, delta), each light giving its closed form."""
    p = jnp.asarray(np.stack([XZ[:, 0], np.zeros(len(XZ)), XZ[:, 1]], -1), jnp.float32)
    scene = load_scene(_two_lights_desc())
    ref_pr, ref_spot = _two_lights_closed_form()
    r = np.sqrt(XZ[:, 0] ** 2 + XZ[:, 1] ** 2 + H**2)
    for u_sel in (0.25, 0.75):
        out = _sample_light(scene, p, jnp.full(len(XZ), u_sel, jnp.float32))
        wi, dist, li, pdf, delta = (np.asarray(v, np.float64) for v in out)
        assert np.all(delta) and np.allclose(pdf, 0.5)
        L = RHO / math.pi * li * wi[:, 1:2]  # the plane's normal is +y
        ref = np.zeros((len(XZ), 3))
        if u_sel < 0.5:
            ref[:, :2] = ref_pr
        else:
            ref[:, 2] = ref_spot
        np.testing.assert_allclose(L, ref, rtol=2e-5, atol=1e-7)
        np.testing.assert_allclose(dist, r, rtol=1e-6)


@pytest.mark.slow  # ~9-11 s measured (load 15, 2 cores): compiling the path integrator
def test_projector_and_textured_spot_through_the_path_integrator():
    """One scene, one compiled program (the path integrator's light sampling, under jit): a
    projector lighting the red and green channels and a textured spot the blue one; the
    diffuse plane's radiance against the closed forms."""
    # the integrator picks one of the two lights (weight 2): u = 0.25 everywhere selects the
    # first, 0.75 the second; their mean is the sum of both lights' direct light
    o, d, u = _rays(jnp.float32)
    o, d, u = jnp.concatenate([o, o]), jnp.concatenate([d, d]), jnp.concatenate([u, u])
    u = u.at[: len(XZ)].set(0.25).at[len(XZ) :].set(0.75)
    L2 = np.asarray(_radiance(load_scene(_two_lights_desc(True)), o, d, u)).reshape(2, len(XZ), 3)
    assert np.all(L2[0, :, 2] == 0) and np.all(L2[1, :, :2] == 0)  # one light per estimate
    L = L2.mean(0)
    ref_pr, ref_spot = _two_lights_closed_form()
    np.testing.assert_allclose(L[:, :2], ref_pr, rtol=2e-5, atol=1e-7)
    np.testing.assert_allclose(L[:, 2], ref_spot, rtol=2e-5, atol=1e-7)


@pytest.mark.parametrize("tilt", [0.0, 30.0, 70.0])
@pytest.mark.parametrize("dist", [0.5, 1.0, 3.0])
def test_irradiance_on_planes_closed_form(dist, tilt):
    """Irradiance ``Li cos(incidence)`` on a plane through (0, 0, dist) (projector at the
    origin looking along +z) tilted by ``tilt`` about the x axis: with the local depth z and
    the distance r, E = pi s E_tex r / z^3 * cos(incidence); on the untilted plane pi s / d^2."""
    pr = ProjectorLight.create([0, 0, 0], [0, 0, 1], 1.0, up=[0, 1, 0], fov=100.0, scale=2.0)
    t = math.radians(tilt)
    n = np.array([0.0, math.sin(t), -math.cos(t)])  # faces the projector
    a = np.linspace(-0.6, 0.6, 7) * dist
    # points of the plane: (0, 0, dist) + x e_x + y (cos t, sin t)-direction in the plane
    e2 = np.array([0.0, math.cos(t), math.sin(t)])
    pts = np.array([[x, 0, dist] + y * e2 for x in a for y in a])
    wi, r, li = (np.asarray(v, np.float64) for v in _sample(pr, jnp.asarray(pts, jnp.float32)))
    irr = li[:, 0] * (wi @ n)
    z = pts[:, 2]
    tan = math.tan(math.radians(50.0))
    inside = (np.abs(pts[:, 0]) <= z * tan) & (np.abs(pts[:, 1]) <= z * tan) & (z > 0)
    cos_inc = -(pts @ n) / np.linalg.norm(pts, axis=1)
    ref = np.where(inside, math.pi * 2.0 * np.linalg.norm(pts, axis=1) / z**3 * cos_inc, 0.0)
    np.testing.assert_allclose(irr, ref, rtol=2e-5, atol=1e-6)
    if tilt == 0.0:  # the facing plane: constant pi * scale / dist^2 where lit
        np.testing.assert_allclose(irr[inside], 2.0 * math.pi / dist**2, rtol=2e-5)


def _texel_footprint(pts, i, j, h, w, tan, aspect):
    """Whether points (local frame, z > 0) map into texel (i, j) of an h x w image."""
    u = 0.5 - 0.5 * pts[:, 0] / (pts[:, 2] * tan)
    v = 0.5 - 0.5 * aspect * pts[:, 1] / (pts[:, 2] * tan)
    return (u > j / w) & (u < (j + 1) / w) & (v > i / h) & (v < (i + 1) / h)


def test_one_lit_texel_lights_exactly_its_footprint():
    """A 3 x 5 image black but texel (row 0, column 3), nearest lookup: on the plane z = 1 the
    lit set is the rectangle u in [3/5, 4/5], v in [0, 1/3] (row 0 at the top: +y; column
    3 of 5 right of the centre: -x), irradiance pi * scale * E there, 0 elsewhere."""
    img = np.zeros((3, 5, 3), np.float32)
    img[0, 3] = [1.0, 0.5, 0.25]
    tex = Texture(img, filter="nearest", wrap="clamp")
    pr = ProjectorLight.create([0, 0, 0], [0, 0, 1], tex, up=[0, 1, 0], fov=60.0, scale=3.0)
    g = np.linspace(-0.7, 0.7, 57)
    pts = np.array([[x, y, 1.0] for x in g for y in g])
    wi, _, li = (np.asarray(v, np.float64) for v in _sample(pr, jnp.asarray(pts, jnp.float32)))
    irr = li * -wi[:, 2:3]
    tan = math.tan(math.radians(30.0))
    lit = _texel_footprint(pts, 0, 3, 3, 5, tan, 5 / 3)
    # away from the texel edges (float32 rounding decides the edge points)
    u = 0.5 - 0.5 * pts[:, 0] / tan
    v = 0.5 - 0.5 * (5 / 3) * pts[:, 1] / tan
    edge = (np.min(np.abs(u[:, None] * 5 - np.arange(6)), 1) < 1e-4) | (
        np.min(np.abs(v[:, None] * 3 - np.arange(4)), 1) < 1e-4
    )
    assert lit.sum() > 20 and (pts[lit, 0] < 0).all() and (pts[lit, 1] > 0).all()
    ref = np.where(lit[:, None], 3.0 * math.pi * img[0, 3], 0.0)
    np.testing.assert_allclose(irr[~edge], ref[~edge], rtol=2e-5, atol=1e-6)


def test_fov_axis_y_and_aspect():
    """fov along y over a 2 x 4 (W / H = 2) texture: tan(fov_x / 2) = 2 tan(fov_y / 2), so the
    frustum's edges lie at x = z tan(fov_x / 2), y = z tan(fov_y / 2)."""
    tex = Texture(np.ones((2, 4, 3), np.float32))
    pr = ProjectorLight.create([0, 0, 0], [0, 0, 1], tex, fov=40.0, fov_axis="y")
    ty = math.tan(math.radians(20.0))
    np.testing.assert_allclose(math.tan(math.radians(float(pr.fov) / 2)), 2 * ty, rtol=1e-6)
    pts = jnp.asarray([[2 * ty * 0.99, 0, 1], [2 * ty * 1.01, 0, 1], [0, ty * 0.99, 1],
                       [0, ty * 1.01, 1]], jnp.float32)  # fmt: skip
    li = np.asarray(_sample(pr, pts)[2])[:, 0]
    assert li[0] > 0 and li[1] == 0 and li[2] > 0 and li[3] == 0


@jax.jit
def _sample_and_uv(spot, p, d):
    return spot.sample(p), spot.texture_uv(d)


def test_spot_texture_uv_and_value():
    """Mitsuba's spot ``direction_to_uv``: uv = 0.5 + 0.5 (x, y) / (z tan(cutoff)) in the look_at
    frame (x = cross(up, axis)); with a one-texel image and nearest lookup the intensity is
    I * falloff * texel / r^2 in that texel's cone and 0 in the others."""
    img = np.zeros((4, 4, 3), np.float32)
    img[1, 2] = [2.0, 1.0, 0.5]
    tex = Texture(img, filter="nearest", wrap="clamp")
    s = SpotLight.create([0, 0, 0], [0, 0, 1], [1.0, 2.0, 3.0], 30.0, 25.0, texture=tex,
                         up=[0, 1, 0])  # fmt: skip
    t = math.tan(math.radians(30.0))
    g = np.linspace(-0.5, 0.5, 41) * t
    pts = np.array([[x, y, 1.0] for x in g for y in g])
    d = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    (wi, r, li), uv = _sample_and_uv(s, jnp.asarray(pts, jnp.float32), jnp.asarray(d, jnp.float32))
    wi, r, li = (np.asarray(v, np.float64) for v in (wi, r, li))
    # x = cross(up, z) = cross(+y, +z) = +x: u increases with +x, v with +y
    u = 0.5 + 0.5 * d[:, 0] / (d[:, 2] * t)
    v = 0.5 + 0.5 * d[:, 1] / (d[:, 2] * t)
    np.testing.assert_allclose(np.asarray(uv), np.stack([u, v], -1),
                               atol=1e-6)  # fmt: skip
    theta = np.degrees(np.arccos(d[:, 2]))
    fall = np.where(theta <= 25, 1.0, np.clip((30 - theta) / 5, 0, 1)) * (theta < 30)
    lit = (np.floor(u * 4) == 2) & (np.floor(v * 4) == 1)
    edge = (np.min(np.abs(u[:, None] * 4 - np.arange(5)), 1) < 1e-4) | (
        np.min(np.abs(v[:, None] * 4 - np.arange(5)), 1) < 1e-4
    )
    ref = np.array([1.0, 2.0, 3.0]) * img[1, 2] * (lit * fall / r**2)[:, None]
    assert lit.sum() > 10
    np.testing.assert_allclose(li[~edge], ref[~edge], rtol=2e-5, atol=1e-7)


W3 = jnp.asarray([1.0, 0.5, 0.25])
PTS = np.array([[0.1, 0.05, 1.0], [-0.3, 0.2, 1.3], [0.25, -0.35, 0.8], [0.02, 0.4, 1.1]])


def _grad_and_fd(fn, x0, h=1e-6):
    """``jax.grad(fn)`` and central differences ``(fn(x + h e_k) - fn(x - h e_k)) / 2h`` of every
    element in one compiled program (the differences vmapped), float64."""
    x0 = jnp.asarray(x0, jnp.float64)
    e = h * jnp.eye(x0.size, dtype=x0.dtype)

    @jax.jit
    def both(x):
        fd = (jax.vmap(fn)(x + e) - jax.vmap(fn)(x - e)) / (2 * h)
        return fn(x), jax.grad(fn)(x), fd

    f0, g, fd = (np.asarray(v) for v in both(x0))
    assert np.all(np.isfinite(g))
    # atol: the differences' rounding, ~ 2.2e-16 |f| / h (x 4: sums of terms inside fn)
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=4 * 2.2e-16 * abs(f0) / h)
    return g


@pytest.mark.slow  # ~11 s measured (load 15, 2 cores): grad + 2 x 94 vmapped FD, float64
def test_gradients_vs_fd(x64):
    """d/d(texels, scale, fov, position) of a projector's and d/d(intensity, cutoff_angle,
    beam_width, texels) of a textured spot's shading term sum(Li cos W) at points inside the
    frustum / cone (bilinear textures: Li is smooth in uv away from texel centres; the spot's
    cutoff moves both the falloff and the texture's uv), against central differences in one
    compiled program."""
    rng = np.random.default_rng(1)
    img = jnp.asarray(rng.uniform(0.2, 1.0, (3, 4, 3)))
    simg = jnp.asarray(rng.uniform(0.2, 1.0, (4, 4, 3)))
    pr0 = ProjectorLight.create([0, 0, 0], [0, 0, 1], Texture(img), up=[0, 1, 0], fov=70.0)
    s0 = SpotLight.create([0, 0, 0], [0, 0, 1], [1.0, 2.0, 3.0], 30.0, 10.0,
                          texture=Texture(simg), up=[0, 1, 0])  # fmt: skip
    pts = jnp.asarray(PTS)
    n_pr, k = img.size + 5, img.size

    def total(light):
        wi, _, li = light.sample(pts)
        return jnp.sum(li * -wi[..., 2:3] * W3)

    def f(x):  # [texels, scale, fov, position] of the projector, then the spot's
        xp, xs = x[:n_pr], x[n_pr:]
        pr = ProjectorLight(xp[k + 2 :], pr0.frame, Texture(xp[:k].reshape(img.shape)), xp[k],
                            xp[k + 1])  # fmt: skip
        sp = SpotLight(s0.position, s0.direction, xs[:3], xs[3], xs[4],
                       Texture(xs[5:].reshape(simg.shape)), s0.up)  # fmt: skip
        return total(pr) + 0.7 * total(sp)

    x0 = np.concatenate([np.asarray(img).ravel(), [1.3, 70.0, 0.05, -0.02, 0.1],
                         [1.0, 2.0, 3.0, 30.0, 10.0], np.asarray(simg).ravel()])  # fmt: skip
    g = _grad_and_fd(f, x0)
    gp, gs = g[:n_pr], g[n_pr:]
    assert np.count_nonzero(gp[: img.size]) > 8  # the texels around the four points
    assert gp[img.size] > 0 and np.all(gp[img.size :] != 0)  # scale, fov, position
    assert np.all(gs[:3] > 0) and gs[3] != 0 and gs[4] != 0  # intensity, cutoff, beam width
    assert np.count_nonzero(gs[5:]) > 8


@jax.jit
def _values_and_grads(lights, points):
    """Per light: ``Li`` at its points, and the value and gradient (all leaves) of the sum of
    ``Li``, ``wi`` and the finite distances (one compiled program for all lights)."""

    def f(light, pts):
        wi, dist, li = light.sample(pts)
        return jnp.sum(li) + jnp.sum(wi) + jnp.sum(jnp.where(jnp.isfinite(dist), dist, 0.0))

    pairs = zip(lights, points, strict=True)
    return [(lt.sample(p)[2],) + jax.value_and_grad(f)(lt, p) for lt, p in pairs]


@pytest.mark.slow  # ~13 s measured (load 15, 2 cores): value + gradient of both lights, float64
def test_hard_cases_finite(x64):
    """At the projector itself, behind it, at its frustum's edges and corners, at z = 0 (the
    pinhole's plane), 1e-6 in front of it, grazing: values and gradients (all leaves) finite;
    0 outside. (Li grows as 1 / r^2 towards the pinhole, as a point light's: at r = 1e-30 its
    derivative, ~1e90, overflows float64 products; at r = 0 the light gives 0.) A textured
    spot on and off its axis, at its cutoff, at itself, behind it: finite."""
    pr = ProjectorLight.create([0, 0, 0], [0, 0, 1], Texture(np.ones((2, 3, 3))), fov=90.0)
    t = 0.999  # just inside tan 45 (the edge itself is decided by rounding)
    a = 0.999 / 1.5  # the vertical half-extent at z = 1 (aspect 3 / 2)
    pts = jnp.asarray([[0, 0, 0], [0, 0, -1], [t, 0, 1], [-t, a, 1], [t, -a, 1], [1, 0, 0],
                       [1e-12, 0, 1e-12], [0, 0, 1e-6], [5, 0, 1e-3]], jnp.float64)  # fmt: skip
    s = SpotLight.create([0, 0, 0], [0, 0, 1], 1.0, 30.0, 30.0, texture=Texture(np.ones((2, 2))))
    tc = math.tan(math.radians(30.0))
    sp = jnp.asarray([[0, 0, 1], [tc, 0, 1], [0, 0, -1], [0, 0, 0], [1, 0, 0]], jnp.float64)
    out = _values_and_grads([pr, s], [pts, sp])
    for _, v, g in out:
        leaves = jax.tree_util.tree_leaves(g)
        assert np.isfinite(v) and all(np.isfinite(np.asarray(x)).all() for x in leaves)
    li = np.asarray(out[0][0])[:, 0]
    assert li[1] == 0 and li[5] == 0 and li[8] == 0  # behind, in the pinhole's plane, outside
    assert li[2] > 0 and li[3] > 0  # the frustum's edges are lit (u, v in [0, 1])
    li = np.asarray(out[1][0])[:, 0]
    assert li[0] > 0 and li[2] == 0 and li[4] == 0  # on the axis; behind; 90 degrees off


@pytest.mark.parametrize(
    "emitter, match",
    [
        (_projector(fov=180.0), r"emitters\[0\]\.fov"),
        (_projector(up=[0, 2, 0]), r"emitters\[0\]\.up"),
        (_projector(scale=-1.0), r"emitters\[0\]\.scale"),
        (_projector(irradiance=-1.0), r"emitters\[0\]\.irradiance"),
        (_projector(irradiance={"type": "checkerboard"}), r"emitters\[0\]\.irradiance\.type"),
        (_projector(fov_axis="diagonal"), r"emitters\[0\]\.fov_axis"),
        (_projector(radius=1.0), r"emitters\[0\]: unknown key"),
        ({"type": "projector", "position": [0, 1, 0], "direction": [0, -1, 0]},
         r"emitters\[0\]: missing key"),
        ({"type": "spot", "position": [0, 1, 0], "direction": [0, -1, 0], "intensity": 1,
          "up": [0, 0, 1]}, r"emitters\[0\]\.up"),
        ({"type": "spot", "position": [0, 1, 0], "direction": [0, -1, 0], "intensity": 1,
          "texture": {"type": "bitmap", "image": np.ones((2, 2))}, "up": [0, 1, 0]},
         r"emitters\[0\]\.up"),
    ],
)  # fmt: skip
def test_bad_input_names_the_key(emitter, match):
    with pytest.raises((ValueError, TypeError), match=match):
        _plane_scene(emitter)


def test_parameters_and_ids():
    tex = {"type": "bitmap", "image": np.ones((2, 3, 3))}
    s = _plane_scene(_projector(id="beamer", irradiance=tex))
    paths = [p.path for p in s.parameters() if p.path.startswith("emitters")]
    assert paths == [f"emitters.beamer.{k}" for k in ("position", "frame", "irradiance.image",
                                                       "scale", "fov")]  # fmt: skip
    assert s.get("emitters.projector.0.scale") == 0.5
    s2 = s.replace("emitters.beamer.scale", 2.0)
    assert float(s2.delta_lights[0].scale) == 2.0
    with pytest.raises(ValueError, match="scale"):
        s.replace("emitters.projector.0.scale", -1.0)
    b = [p.bounds for p in s.parameters() if p.path.endswith("irradiance.image")][0]
    assert b == (0.0, float("inf"))


def test_scenes_without_projector_or_texture_trace_none_of_it(monkeypatch):
    """Model only what a scene needs: an untextured spot's program never traces a texture
    lookup, and only a projector scene traces the projector."""
    from jaxgfx.render.emitters import SpotLight as S

    calls = []
    orig_tex, orig_pr = S.texture_value, ProjectorLight.sample
    monkeypatch.setattr(S, "texture_value", lambda *a: calls.append("tex") or orig_tex(*a))
    monkeypatch.setattr(ProjectorLight, "sample", lambda *a: calls.append("pr") or orig_pr(*a))
    spot = {"type": "spot", "position": [0, H, 0], "direction": [0, -1, 0], "intensity": 1.0}
    o, d, u = _rays(jnp.float32)
    jax.make_jaxpr(lambda s: path_radiance(s, o, d, u, max_depth=2))(_plane_scene(spot))
    assert calls == []
    jax.make_jaxpr(lambda s: path_radiance(s, o, d, u, max_depth=2))(_plane_scene(_projector()))
    assert calls == ["pr"]


# ------------------------------------------------------------------------------------------
# Mitsuba 3


def _mitsuba_pair(mi, tmp_path):
    from jaxgfx.io import write_exr

    rng = np.random.default_rng(0)
    img = rng.uniform(0.1, 2.0, (5, 7, 3)).astype(np.float32)
    path = str(tmp_path / "tex.exr")
    write_exr(path, img)
    o, t, up = np.array([0.1, 0.2, 2.0]), np.array([0.3, 0.0, 0.0]), np.array([0.2, 1.0, 0.0])
    tw = mi.ScalarTransform4f().look_at(origin=o.tolist(), target=t.tolist(), up=up.tolist())
    bm = {"type": "bitmap", "filename": path, "raw": True}
    theirs = [
        mi.load_dict({"type": "projector", "to_world": tw, "irradiance": bm, "scale": 1.7,
                      "fov": 50.0}),
        mi.load_dict({"type": "projector", "to_world": tw, "fov": 40.0, "fov_axis": "y",
                      "irradiance": {"type": "rgb", "value": [0.5, 1.0, 2.0]}}),
        mi.load_dict({"type": "spot", "to_world": tw, "texture": bm, "cutoff_angle": 35.0,
                      "beam_width": 12.0, "intensity": {"type": "rgb", "value": [1, 2, 3]}}),
    ]  # fmt: skip
    tex = Texture(img)
    ours = [
        ProjectorLight.create(o, t - o, tex, up=up, scale=1.7, fov=50.0),
        ProjectorLight.create(o, t - o, [0.5, 1.0, 2.0], up=up, fov=40.0, fov_axis="y"),
        SpotLight.create(o, t - o, [1, 2, 3], 35.0, 12.0, texture=tex, up=up),
    ]
    return ours, theirs


@pytest.mark.mitsuba
def test_sample_direction_matches_mitsuba(tmp_path):
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    ours, theirs = _mitsuba_pair(mi, tmp_path)
    pts = np.random.default_rng(3).uniform(-1.5, 1.5, size=(200, 3)) * [1, 1, 0.2]
    for a, b in zip(ours, theirs, strict=True):
        wi, _, li = (np.asarray(x, np.float64) for x in _sample(a, jnp.asarray(pts, jnp.float32)))
        lit = 0
        for k, p in enumerate(pts):
            it = mi.Interaction3f()
            it.p = mi.Point3f(p)
            ds, w = b.sample_direction(it, mi.Point2f(0.5, 0.5))
            w = np.array(w)
            lit += bool(w.max() > 0)
            np.testing.assert_allclose(li[k], w, rtol=5e-5, atol=1e-6)
            if ds.pdf > 0:  # a delta light (pdf 1) where lit
                assert ds.pdf == 1.0 and ds.delta
                np.testing.assert_allclose(wi[k], np.array(ds.d), atol=2e-6)
                np.testing.assert_allclose(np.array(b.eval_direction(it, ds)), w, rtol=1e-6)
        assert 30 < lit < len(pts)  # both lit and unlit points were compared


def test_save_scene_round_trips_projector_and_textured_spot(tmp_path):
    """save_scene (Mitsuba XML) -> read_xml -> load_scene gives the same light leaves."""
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    tex = {"type": "bitmap", "image": np.linspace(0, 1, 18).reshape(2, 3, 3)}
    spot = {"type": "spot", "position": [0.3, H, 0], "direction": [0.1, -1, 0], "intensity": 2.0,
            "cutoff_angle": 30.0, "beam_width": 10.0, "up": [0, 0, 1], "texture": tex}  # fmt: skip
    s = load_scene({**_plane_desc(), "emitters": [_projector(irradiance=tex), spot]})
    s2 = load_scene(read_xml(save_scene(s, str(tmp_path / "s.xml"))).desc)
    for a, b in zip(s.delta_lights, s2.delta_lights, strict=True):
        assert type(a) is type(b)
        for u, v in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
            np.testing.assert_allclose(np.asarray(u), np.asarray(v), atol=1e-6)
