"""Next-event estimation from a shading point on an emitter's own surface (a NaN regression).

A BSDF-sampled bounce that lands on a planar area light, then samples that same light, sees
every light sample in the light's own plane: the cosine at the light is zero up to rounding.
A rectangle rotated by 90 degrees (Mitsuba ``<rotate angle="90"/>``) has a normal component of
``cos(pi/2) = 6.1e-17``, so that cosine came out as e.g. ``3.7e-20`` instead of 0: a float32
solid-angle density ``pdf_area * dist² / |cos|`` of 2e19, whose square in the power heuristic
overflowed, ``inf / inf`` = NaN (value); the density's derivative ``1 / cos²`` overflowed too
(NaN gradients w.r.t. every shape even with the weight fixed). Measured before the fix: 2
NaN samples in 1,048,576 (32² x 64 spp x 16 keys) of the scene of
:func:`test_rotated_light_scene_finite_and_matches_mitsuba`, 5 in 65,536 rays of
:func:`test_rays_onto_light_see_exactly_its_radiance`.

The fix (``jaxgfx.render.integrators._common``): :func:`area_to_solid_angle` gives density 0
to a light point seen at a cosine below the dtype's epsilon (it subtends no solid angle;
pbrt-v4 drops a light sample with infinite density), used by light sampling and by the MIS
density of a BSDF-sampled hit alike; :func:`mis_power` is computed from the ratio of the two
densities, finite for any pair in ``[0, inf]``.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.emitters import PointLights, SpotLight
from jaxgfx.render.integrators import _common as C
from jaxgfx.render.integrators.path import path_radiance
from jaxgfx.render.scene import load_scene

C90 = 6.123234e-17  # cos(pi / 2) in float64, as a 90-degree rotation leaves it in a normal
RADIANCE = 3.0


def _use(dtype, request):
    """float64 tests turn x64 on for their duration (tests/conftest.py)."""
    if dtype == jnp.float64:
        request.getfixturevalue("x64")


# --- the power heuristic and the area -> solid-angle conversion --------------------------


_mis = jax.jit(C.mis_power)
_mis_grad = jax.jit(jax.vmap(jax.grad(C.mis_power, argnums=(0, 1))))


def test_mis_power_is_the_power_heuristic_with_its_derivatives(x64):
    """float64: ``a² / (a² + b²)`` and its partials ``2ab² / s²``, ``-2a²b / s²`` (closed form),
    and a central finite difference of the jitted function."""
    rng = np.random.default_rng(0)
    a = jnp.asarray(10.0 ** rng.uniform(-6, 6, 200))
    b = jnp.asarray(10.0 ** rng.uniform(-6, 6, 200))
    s = a * a + b * b
    np.testing.assert_allclose(_mis(a, b), a * a / s, rtol=1e-13)
    ga, gb = _mis_grad(a, b)
    np.testing.assert_allclose(ga, 2 * a * b * b / s**2, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(gb, -2 * a * a * b / s**2, rtol=1e-12, atol=1e-300)
    # central difference where it is well conditioned (densities within 100x of each other)
    m = np.abs(np.log10(a / b)) < 2
    assert m.sum() > 20
    h = 1e-6 * a[m]
    fd = (_mis(a[m] + h, b[m]) - _mis(a[m] - h, b[m])) / (2 * h)
    np.testing.assert_allclose(ga[m], fd, rtol=1e-6)
    # the two strategies' weights sum to 1
    np.testing.assert_allclose(_mis(a, b) + _mis(b, a), 1.0, rtol=1e-14)


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_mis_power_finite_at_overflowing_zero_and_infinite_densities(dtype, request):
    _use(dtype, request)
    big = 2.1e19 if dtype == jnp.float32 else 1e200  # its square overflows
    inf = float("inf")
    a = jnp.asarray([big, 0.0, inf, 1.0, inf, 0.0, big, 3.0], dtype)
    b = jnp.asarray([0.0, big, 1.0, inf, inf, 0.0, big, 3.0], dtype)
    want = [1.0, 0.0, 1.0, 0.0, 0.5, 0.0, 0.5, 0.5]
    np.testing.assert_array_equal(_mis(a, b), np.asarray(want, dtype))
    ga, gb = _mis_grad(a, b)
    assert np.isfinite(ga).all() and np.isfinite(gb).all()


def _to_sa(*a):
    return jax.jit(C.area_to_solid_angle)(*a)


def _to_sa_grad(*a):
    return jax.jit(jax.vmap(jax.grad(C.area_to_solid_angle, argnums=(0, 1, 2))))(*a)


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_area_to_solid_angle_closed_form_and_zero_edge_on(dtype, request):
    _use(dtype, request)
    eps = float(jnp.finfo(dtype).eps)
    pa = jnp.asarray([0.25, 0.25, 0.25, 0.25, 0.25, 2.0], dtype)
    d2 = jnp.asarray([4.0, 4.0, 3.1, 3.1, 0.0, 1e-12], dtype)
    c = jnp.asarray([0.5, -0.5, 3.7e-20, -eps, 0.3, 1e-3], dtype)
    want = np.asarray([2.0, 2.0, 0.0, 0.0, 0.0, 2e-9], dtype)
    np.testing.assert_allclose(_to_sa(pa, d2, c), want, rtol=1e-6)
    gp, gd, gc = _to_sa_grad(pa, d2, c)
    for g in (gp, gd, gc):
        assert np.isfinite(g).all()
    # d/dcos of pa d2 / |c| = -sign(c) pa d2 / c² where kept, 0 where dropped
    np.testing.assert_allclose(gc[:2], [-4.0, 4.0], rtol=1e-6)
    np.testing.assert_array_equal(gc[2:5], 0.0)
    np.testing.assert_allclose(gd[0], 0.5, rtol=1e-6)


# --- light sampling from a point on the light ---------------------------------------------


def _light_scene(dtype, **light):
    """A rectangular area light 6 x 6 at ``y = 3`` facing down, its ``edge_v`` tilted by
    ``cos(pi/2)`` as a 90-degree rotation leaves it, over an 8 x 8 diffuse floor."""
    shape = {"type": "rectangle", "center": [0, 3, 0], "edge_u": [6, 0, 0]}
    shape["edge_v"] = [0, -6 * C90, 6]
    desc = {
        "camera": {
            "origin": [0, 1, 0.1],
            "target": [0, 3, 0],
            "up": [0, 0, 1],
            "fov": 60,
            "width": 8,
            "height": 8,
        },  # fmt: skip
        "shapes": [
            {
                "type": "rectangle",
                "center": [0, 0, 0],
                "normal": [0, 1, 0],
                "size": [8, 8],
                "material": "floor",
            }
        ],  # fmt: skip
        "materials": {"floor": {"type": "diffuse", "reflectance": 0.5}},
        "emitters": [{"type": "area", "radiance": RADIANCE, "shape": shape | light}],
    }
    return load_scene(desc, dtype=dtype)


# float64: slow: ~2.3 s quiet, ~8 s loaded (a second compile; the overflow was float32's)
@pytest.mark.parametrize("dtype", [jnp.float32, pytest.param(jnp.float64, marks=pytest.mark.slow)])
def test_sample_light_from_a_point_on_the_light_has_no_density(dtype, request):
    """From a point of the light's surface every sample lies in its plane: density 0 and no
    radiance (the NEE contribution is 0, not NaN), values and derivatives finite. The grid of
    light samples includes ones nearly along ``edge_u`` (|wi_z| ~ 1e-4: a rounding-level
    cosine of ~1e-20 before the fix)."""
    _use(dtype, request)
    scene = _light_scene(dtype)
    s = np.linspace(0.01, 0.99, 17)
    t = np.concatenate([np.linspace(0.01, 0.99, 9), 0.5 + np.asarray([1e-5, -1e-5, 1e-4, 3e-4])])
    u2 = jnp.asarray(np.stack(np.meshgrid(s, t), -1).reshape(-1, 2), dtype)
    p = jnp.broadcast_to(jnp.asarray([-0.4, 3.0, 0.3], dtype), u2.shape[:-1] + (3,))

    @jax.jit
    def nee(radiance, edge_v):
        """Light sampling from the light's own surface, where a ray from below hits it."""

        def f(radiance, edge_v):
            sc = scene.replace("emitters.area.0.radiance", radiance)
            sc = sc.replace("shapes.1.edge_v", edge_v)
            up = jnp.asarray([0, 1.0, 0], dtype)
            hit = C.intersect(sc, p - up, up)
            _, _, li, pdf, _ = C.sample_light(sc, hit.p, jnp.full(p.shape[:-1], 0.5, dtype), u2)
            return jnp.sum(li) + jnp.sum(pdf), (hit, li, pdf)

        return jax.value_and_grad(f, (0, 1), has_aux=True)(radiance, edge_v)

    (_, (hit, li, pdf)), grads = nee(
        scene.get("emitters.area.0.radiance"), scene.get("shapes.1.edge_v")
    )
    assert bool(jnp.all(hit.shape_id == 1)) and float(jnp.max(jnp.abs(hit.p - p))) < 1e-6
    np.testing.assert_array_equal(pdf, 0.0)
    np.testing.assert_array_equal(li, 0.0)
    for g in grads:
        assert np.isfinite(g).all()


def _rays_onto_light(n, dtype):
    k1, k2 = jax.random.split(jax.random.key(0))
    xz = jax.random.uniform(k1, (n, 2), dtype, -2.5, 2.5)
    o = jnp.stack([xz[:, 0], jnp.ones(n, dtype), xz[:, 1]], -1)
    d = jnp.broadcast_to(jnp.asarray([0.0, 1.0, 0.0], dtype), (n, 3))
    return o, d, jax.random.uniform(k2, (n, 3, 7), dtype)


@jax.jit
def _radiance_and_grads(radiance, refl, edge_v, scene, o, d, u):
    def mean(radiance, refl, edge_v):
        sc = scene.replace("emitters.area.0.radiance", radiance)
        sc = sc.replace("materials.floor.reflectance", refl).replace("shapes.1.edge_v", edge_v)
        L = path_radiance(sc, o, d, u, max_depth=3)
        return jnp.mean(L), L

    return jax.value_and_grad(mean, (0, 1, 2), has_aux=True)(radiance, refl, edge_v)


# slow: ~3.6 s of the default run (2026-12-06, quiet: a depth-3 path program); NEE on the light
# stays in the default run (test_sample_light_from_a_point_on_the_light_has_no_density)
@pytest.mark.slow
def test_rays_onto_light_see_exactly_its_radiance():
    """float32, path of depth 3: rays from below onto the light see its radiance, and nothing
    else: light sampling from the light's own surface adds 0, and the bounce off its black
    back material carries 0 weight, so every ray's radiance is exactly ``RADIANCE``. Before
    the fix: 5 of these 65,536 rays were NaN."""
    scene = _light_scene(jnp.float32)
    o, d, u = _rays_onto_light(65536, jnp.float32)
    L = jax.jit(path_radiance, static_argnames="max_depth")(scene, o, d, u, max_depth=3)
    np.testing.assert_array_equal(L, RADIANCE)


@pytest.mark.slow  # slow: ~7 s quiet, ~21 s loaded (reverse mode, 65,536 paths of depth 3)
def test_rays_onto_light_gradients_closed_form():
    """The same rays: the mean's derivative is 1/3 per channel w.r.t. the radiance, and exactly
    0 w.r.t. the floor's reflectance and the light's edge (NaN before the fix)."""
    scene = _light_scene(jnp.float32)
    o, d, u = _rays_onto_light(65536, jnp.float32)
    args = (
        scene.get("emitters.area.0.radiance"),
        scene.get("materials.floor.reflectance"),
        scene.get("shapes.1.edge_v"),
    )
    (_, L), (g_rad, g_refl, g_edge) = _radiance_and_grads(*args, scene, o, d, u)
    np.testing.assert_array_equal(L, RADIANCE)
    np.testing.assert_allclose(g_rad, 1.0 / 3.0, rtol=1e-6)
    np.testing.assert_array_equal(g_refl, 0.0)
    np.testing.assert_array_equal(g_edge, 0.0)


# --- the failing configuration of the report ----------------------------------------------

SCENE_XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <sensor type="thinlens"><float name="fov" value="40"/>
    <float name="aperture_radius" value="0.15"/><float name="focus_distance" value="4"/>
    <transform name="to_world"><lookat origin="0, 1, 5" target="0, 0.4, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/>
      <rfilter type="box"/></film></sensor>
  <bsdf type="diffuse" id="checks"><texture type="checkerboard" name="reflectance">
      <rgb name="color0" value="0.8, 0.7, 0.5"/><rgb name="color1" value="0.1, 0.2, 0.3"/>
      <transform name="to_uv"><scale x="6" y="6"/></transform></texture></bsdf>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/>
      <scale value="4"/></transform><ref id="checks"/></shape>
  <shape type="sphere"><point name="center" value="-1.0, 0.4, 2.5"/>
    <float name="radius" value="0.4"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.2, 0.2"/></bsdf></shape>
  <shape type="sphere"><point name="center" value="0.3, 0.4, 1"/>
    <float name="radius" value="0.4"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.8, 0.2"/></bsdf></shape>
  <shape type="sphere"><point name="center" value="1.2, 0.5, -2"/>
    <float name="radius" value="0.5"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.3, 0.9"/></bsdf></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="90"/>
      <translate y="3"/></transform>
    <emitter type="area"><rgb name="radiance" value="10, 10, 10"/></emitter></shape>
</scene>
"""
"""The reported thin-lens scene (checkered floor, three diffuse spheres) with a 2 x 2 area
light at ``y = 3`` facing down, placed by a 90-degree rotation, instead of its constant sky."""

# Two float32 samples of that scene whose path (depth 3) was NaN before the fix: ray origin,
# direction, then the (3, 7) uniform numbers. Found by rendering 16 keys of 64 spp
# (``jax.random.split(jax.random.key(100 + i), 4)``, i < 4; key 0 pass 24 pixel (19, 12), key 1
# pass 44 pixel (14, 17)). Both bounce off the floor / the green sphere onto the light, and
# sample the light from there.
FAILING = [
    [-0.009514957666397095, 1.0036425590515137, 4.999562740325928, -0.08764176070690155,
     -0.19530963897705078, -0.976817786693573, 0.7273521423339844, 0.6329751014709473,
     0.2805578112602234, 0.3124242424964905, 0.7080448269844055, 0.6240610480308533,
     0.9403861165046692, 0.9616796374320984, 5.40614128112793e-05, 0.17961573600769043,
     0.809989333152771, 0.06576383113861084, 0.3233373165130615, 0.7641544342041016,
     0.7746676802635193, 0.6299777626991272, 0.7136498093605042, 0.5831559896469116,
     0.7151839137077332, 0.7741024494171143, 0.49265944957733154],
    [-0.14203473925590515, 0.988690197467804, 5.001357078552246, 0.07050655782222748,
     -0.08658367395401001, -0.9937464594841003, 0.9488057494163513, 0.7843358516693115,
     0.5367817878723145, 0.21785855293273926, 0.257682740688324, 0.9556217193603516,
     0.43461841344833374, 0.921502947807312, 0.48012715578079224, 0.47417378425598145,
     0.6975759267807007, 0.8632327318191528, 0.31953638792037964, 0.3553133010864258,
     0.7133311629295349, 0.556338369846344, 0.04544156789779663, 0.8833126425743103,
     0.3708200454711914, 0.33188772201538086, 0.32372432947158813],
]  # fmt: skip


def _xml_scene(tmp_path):
    from jaxgfx.render.scene.mitsuba_xml import read_xml

    path = tmp_path / "scene.xml"
    path.write_text(SCENE_XML)
    return load_scene(read_xml(str(path)).desc, dtype=jnp.float32), str(path)


def _failing():
    rows = jnp.asarray(FAILING, jnp.float32)
    return rows[:, :3], rows[:, 3:6], rows[:, 6:].reshape(-1, 3, 7)


@pytest.mark.slow  # slow: ~10 s quiet, ~30 s loaded, per mode (reverse mode, 15 leaves)
@pytest.mark.parametrize("sampling", ["detached", "attached"])
def test_failing_samples_finite_and_light_adds_nothing_from_itself(tmp_path, sampling):
    """The two samples, float32: the third vertex lies on the light, whose material is black
    and whose own light samples lie in its plane, so depth 3 adds exactly nothing to depth 2
    (it was NaN); the gradients of their radiance w.r.t. every material, emitter and shape
    parameter are finite (NaN for 10 of the 15 leaves before the fix, in both modes)."""
    scene, _ = _xml_scene(tmp_path)
    o, d, u = _failing()
    names = [p.path for p in scene.parameters() if not p.path.startswith("camera")]

    @jax.jit
    def value_and_grads(vals):
        def loss(vals):
            sc = scene
            for n, v in zip(names, vals, strict=True):
                sc = sc.replace(n, v)
            L = path_radiance(sc, o, d, u, max_depth=3, sampling=sampling)
            return jnp.sum(L), L

        (_, l3), g = jax.value_and_grad(loss, has_aux=True)(vals)
        return l3, path_radiance(scene, o, d, u[:, :2], max_depth=2, sampling=sampling), g

    l3, l2, g = value_and_grads([scene.get(n) for n in names])
    assert np.isfinite(l3).all()
    np.testing.assert_array_equal(l3, l2)
    assert float(jnp.min(l2)) > 0  # the vertices before do see light
    bad = [n for n, x in zip(names, g, strict=True) if not np.isfinite(x).all()]
    assert not bad, bad


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_point_and_spot_light_at_distance_zero(dtype, request):
    """A shading point exactly at a point / spot light: no direction, no radiance (0, not
    ``I / 0``), finite derivatives w.r.t. the position, the intensity and the point."""
    _use(dtype, request)
    pos = jnp.asarray([[0.2, 1.0, -0.3]], dtype)
    inten = jnp.full((1, 3), 5.0, dtype)

    def point(pos, inten, p):
        wi, dist, li = PointLights(pos, inten).sample(jnp.zeros((1,), jnp.int32), p)
        return wi, dist, li

    spot = SpotLight.create([0.2, 1.0, -0.3], [0, -1, 0], 5.0)

    def spot_fn(pos, inten, p):
        sl = SpotLight(pos[0], spot.direction.astype(dtype), inten[0], spot.cutoff_angle,
                       spot.beam_width)  # fmt: skip
        return sl.sample(p)

    for fn in (point, spot_fn):
        out = jax.jit(fn)(pos, inten, pos)
        for x in out:
            np.testing.assert_array_equal(x, 0.0)
        g = jax.jit(jax.grad(lambda *a, fn=fn: sum(jnp.sum(x) for x in fn(*a)), (0, 1, 2)))(
            pos, inten, pos
        )
        for x in g:
            assert np.isfinite(x).all()


# --- render level: the scene over a million samples, and Mitsuba 3 -------------------------


@pytest.mark.slow  # slow: ~7 s quiet, ~27 s loaded (1M samples of jaxgfx, 1M of Mitsuba 3)
@pytest.mark.mitsuba
def test_rotated_light_scene_finite_and_matches_mitsuba(tmp_path):
    """The scene of the report, path of depth 3, 16 keys x 64 spp at 32²: every pixel finite
    (before the fix: 2 NaN samples among these 1,048,576), and the mean per channel agrees with
    Mitsuba 3 (``scalar_rgb``, 16 seeds) within 4 standard errors of the difference."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from jaxgfx.render.render import render

    scene, path = _xml_scene(tmp_path)
    keys = jnp.concatenate([jax.random.split(jax.random.key(100 + i), 4) for i in range(4)])
    f = jax.jit(jax.vmap(lambda k: render(scene, k, spp=64, integrator="path", max_depth=3)))
    a = np.asarray(f(keys), np.float64)
    assert np.isfinite(a).all()
    ms = mi.load_file(path)
    b = np.stack([np.array(mi.render(ms, spp=64, seed=i))[..., :3] for i in range(16)])
    b = b.astype(np.float64)
    ma, mb = a.mean((1, 2)), b.mean((1, 2))  # (16, 3) per-key image means
    se = np.sqrt(ma.var(0, ddof=1) / len(ma) + mb.var(0, ddof=1) / len(mb))
    z = (ma.mean(0) - mb.mean(0)) / se
    assert np.all(np.abs(z) < 4), (ma.mean(0), mb.mean(0), z)
    assert math.isfinite(float(se.max())) and float(se.max()) < 0.01 * float(mb.mean())
