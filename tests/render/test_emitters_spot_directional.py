"""Directional and spot emitters (issue 24): closed-form direct light on a diffuse plane through
the path integrator, Mitsuba's falloff curve, finite-difference gradients (cutoff, beam width,
direction, irradiance), hard cases (on the axis, at the cutoff, beam = cutoff, grazing light),
loader errors, and a pointwise comparison with Mitsuba 3's ``sample_direction`` (``mitsuba``
marker)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.emitters import DirectionalLight, SpotLight
from jaxgfx.render.integrators.path import path_radiance
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import check_grads_fd
from tests.render._scenes import camera, rectangle

RHO = 0.6
# camera rays from above straight down onto the plane y = 0 at these (x, z)
XZ = np.array([[0.0, 0.0], [0.3, 0.1], [0.55, -0.2], [0.8, 0.4], [1.4, 0.0]])


def _scene(emitter, dtype=None, extra=()):
    return load_scene(
        {
            "camera": camera([0, 3, 0.01], [0, 0, 0], fov=40, width=2),
            "shapes": [rectangle(size=(8, 8), material="m")],
            "materials": {"m": {"type": "diffuse", "reflectance": RHO}},
            "emitters": [emitter, *extra],
        },
        dtype=dtype,
    )


def _spot(cutoff=30.0, beam=10.0, height=2.0):
    return {
        "type": "spot",
        "position": [0, height, 0],
        "direction": [0, -1, 0],
        "intensity": [1.0, 2.0, 3.0],
        "cutoff_angle": cutoff,
        "beam_width": beam,
    }


def _rays(dtype, u_sel=0.5):
    o = np.stack([XZ[:, 0], np.full(len(XZ), 1.0), XZ[:, 1]], -1)
    d = np.tile([0.0, -1.0, 0.0], (len(XZ), 1))
    u = np.full((len(XZ), 2, 7), 0.5)
    u[:, 0, 0] = u_sel  # light selection at the first vertex
    return jnp.asarray(o, dtype), jnp.asarray(d, dtype), jnp.asarray(u, dtype)


@jax.jit
def _radiance(scene, o, d, u):
    # depth 2: emitted + direct light (delta lights: light sampling only)
    return path_radiance(scene, o, d, u, max_depth=2)


def _two_light_radiance(scene):
    # two lights, each picked with probability 1/2: the mean over both choices is exact
    r = [_radiance(scene, *_rays(jnp.float32, u_sel)) for u_sel in (0.25, 0.75)]
    return np.asarray(0.5 * (r[0] + r[1]))


def _spot_closed_form(cutoff, beam, height=2.0):
    r2 = XZ[:, 0] ** 2 + XZ[:, 1] ** 2 + height**2
    cos = height / np.sqrt(r2)
    theta = np.degrees(np.arccos(cos))
    fall = np.where(theta <= beam, 1.0, np.clip((cutoff - theta) / (cutoff - beam), 0, 1))
    fall = np.where(theta < cutoff, fall, 0.0)
    return RHO / math.pi * np.array([1.0, 2.0, 3.0]) * (fall * cos / r2)[:, None]


DARK_DIRECTIONAL = {"type": "directional", "direction": [0, -1, 0], "irradiance": 0.0}


def test_spot_direct_light_closed_form():
    # with a directional light of irradiance 0: the same program as the next test
    s = _scene(_spot(), extra=[DARK_DIRECTIONAL])
    L = _two_light_radiance(s)
    ref = _spot_closed_form(30.0, 10.0)
    # points on the axis, in the beam, in the transition and outside the cone
    assert ref[0, 0] > 0 and 0 < ref[2, 0] < ref[1, 0] and ref[-1, 0] == 0
    np.testing.assert_allclose(L, ref, rtol=2e-5, atol=1e-7)


def test_directional_direct_light_closed_form():
    e = {"type": "directional", "direction": [0.6, -0.8, 0.0], "irradiance": [2.0, 1.0, 0.5]}
    dark_spot = _spot() | {"intensity": 0.0}
    L = _two_light_radiance(_scene(dark_spot, extra=[e]))
    ref = RHO / math.pi * 0.8 * np.array([2.0, 1.0, 0.5])
    np.testing.assert_allclose(L, np.broadcast_to(ref, L.shape), rtol=2e-5)
    # light from below the plane: the camera's side (y > 0) is in the plane's shadow
    e_below = e | {"direction": [0.6, 0.8, 0.0]}
    L_below = _two_light_radiance(_scene(dark_spot, extra=[e_below]))
    np.testing.assert_array_equal(L_below, 0.0)


def test_spot_falloff_matches_mitsuba_curve():
    s = SpotLight.create([0, 0, 0], [0, 0, 1], 1.0, cutoff_angle=40.0, beam_width=25.0)
    th = np.linspace(0, 60, 121)
    f = np.asarray(s.falloff(jnp.cos(jnp.deg2rad(jnp.asarray(th)))))
    ref = np.where(th <= 25, 1.0, np.clip((40 - th) / 15, 0, 1)) * (th < 40)
    np.testing.assert_allclose(f, ref, atol=2e-5)
    # default beam width: 3/4 of the cutoff (Mitsuba)
    assert float(SpotLight.create([0, 0, 0], [0, 0, 1], 1.0, 20.0).beam_width) == 15.0


W = jnp.asarray([1.0, 0.5, 0.25])


def _spot_total(scene, c, b, h, o, d, u):
    s = scene.replace("emitters.spot.0.cutoff_angle", c)
    s = s.replace("emitters.spot.0.beam_width", b)
    s = s.replace("emitters.spot.0.position", jnp.stack([0.1, h, 0.0 * h]))
    return jnp.sum(_radiance(s, o, d, u) * W)


def _dir_total(scene, a, k, o, d, u):
    s = scene.replace("emitters.directional.0.direction", jnp.stack([a, -0.8, 0.0 * a]))
    s = s.replace("emitters.directional.0.irradiance", k)
    return jnp.sum(_radiance(s, o, d, u) * W)


def _check_fd(fn, x0, h=1e-5):
    """Gradient of ``fn(*x)`` against central differences in float64, jitted
    (:func:`jaxgfx.testing.check_grads_fd`); returns the gradient."""
    x0 = jnp.asarray(x0, jnp.float64)
    ok, g, fd = check_grads_fd(lambda x: fn(*x), x0, eps=h, rtol=1e-6, atol=1e-12, jit=True)
    assert np.all(np.isfinite(g))
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-12)
    assert ok
    return g


def test_spot_sample_gradients_vs_fd(x64):
    # the light's own sample (the shading term rho/pi Li cos): fast, one small compile
    pts = jnp.asarray(np.stack([XZ[:, 0], 0 * XZ[:, 0], XZ[:, 1]], -1), jnp.float64)

    s0 = SpotLight.create([0.1, 2.0, 0.0], [0, -1, 0], [1.0, 2.0, 3.0], 30.0, 10.0)

    def fn(c, b, h, s=s0):
        s = SpotLight(jnp.stack([0.1, h, 0.0 * h]), s.direction, s.intensity, c, b)
        wi, _, li = s.sample(pts)
        return jnp.sum(li * wi[..., 1:2] * W)

    g = _check_fd(fn, [30.0, 10.0, 2.0])
    assert float(g[0]) > 0 and float(g[1]) > 0  # a wider cone / beam: more light


@pytest.mark.slow  # measured 33 s (compile of value_and_grad through path_radiance, x2)
def test_render_gradients_vs_fd(x64):
    # end to end through the path integrator and Scene.replace; the transition region holds
    # XZ[2] (theta 15.5 deg), so d/dcutoff and d/dbeam are nonzero
    o, d, u = _rays(jnp.float64)
    spot = _scene(_spot(), dtype=jnp.float64)
    g = _check_fd(lambda c, b, h: _spot_total(spot, c, b, h, o, d, u), [30.0, 10.0, 2.0])
    assert float(g[0]) > 0 and float(g[1]) > 0
    e = {"type": "directional", "direction": [0.6, -0.8, 0.0], "irradiance": [2.0, 1.0, 0.5]}
    dirl = _scene(e, dtype=jnp.float64)
    g = _check_fd(lambda a, k: _dir_total(dirl, a, k, o, d, u), [0.6, 1.5])
    assert abs(float(g[0])) > 0


@jax.jit
def _hard_spot(scene, c, b, o, d, u):
    return jax.value_and_grad(lambda c, b: _spot_total(scene, c, b, 2.0, o, d, u), (0, 1))(c, b)


def test_spot_sample_hard_cases_finite(x64):
    # the axis itself (theta = 0), beam = cutoff, a point exactly at the cutoff, a tiny cone
    pts = jnp.asarray(np.stack([XZ[:, 0], 0 * XZ[:, 0], XZ[:, 1]], -1), jnp.float64)
    theta2 = float(np.degrees(np.arctan(np.hypot(*XZ[2]) / 2.0)))
    s0 = SpotLight.create([0.0, 2.0, 0.0], [0, -1, 0], 1.0, 30.0, 10.0)

    @jax.jit
    def vg(c, b):
        def f(c, b):
            s = SpotLight(s0.position, s0.direction, s0.intensity, c, b)
            return jnp.sum(s.sample(pts)[2])

        return jax.value_and_grad(f, (0, 1))(c, b)

    for cutoff, beam in [(30.0, 30.0), (theta2, 5.0), (theta2, theta2), (1e-3, 0.0)]:
        v, g = vg(jnp.float64(cutoff), jnp.float64(beam))
        assert np.isfinite(v) and np.isfinite(g).all()
        assert v > 0  # the axis point is lit in every case


@pytest.mark.slow  # measured 20 s (compile of value_and_grad through path_radiance, x2)
def test_hard_cases_finite(x64):
    # beam = cutoff (hard edge), the axis itself (theta = 0), a point exactly at the cutoff,
    # a tiny cone, and a directional light grazing the plane: values and gradients finite
    o, d, u = _rays(jnp.float64)
    theta2 = float(np.degrees(np.arctan(np.hypot(*XZ[2]) / 2.0)))
    base = _scene(_spot(), dtype=jnp.float64)
    for cutoff, beam in [(30.0, 30.0), (theta2, 5.0), (theta2, theta2), (1e-3, 0.0)]:
        v, g = _hard_spot(base, jnp.float64(cutoff), jnp.float64(beam), o, d, u)
        assert np.isfinite(v) and np.isfinite(g).all()
    e = {"type": "directional", "direction": [1.0, 0.0, 0.0], "irradiance": 1.0}
    base = _scene(e, dtype=jnp.float64)

    def fdir(a):
        s = base.replace("emitters.directional.0.direction", jnp.stack([1.0, a, 0.0 * a]))
        return jnp.sum(_radiance(s, o, d, u))

    v, g = jax.jit(jax.value_and_grad(fdir))(0.0)
    assert v == 0 and np.isfinite(g)


@pytest.mark.parametrize(
    "emitter, match",
    [
        (_spot(20.0, 25.0), r"emitters\[0\]\.beam_width"),
        (_spot(200.0, 25.0), r"emitters\[0\]\.cutoff_angle"),
        (_spot() | {"direction": [0, 0, 0]}, r"emitters\[0\]\.direction"),
        (_spot() | {"radius": 1}, r"emitters\[0\]: unknown key"),
        ({"type": "directional", "direction": [0, -1, 0]}, r"emitters\[0\]: missing key"),
        ({"type": "directional", "direction": [0, -1], "irradiance": 1}, r"\.direction"),
        ({"type": "directional", "direction": [0, -1, 0], "irradiance": -1}, r"\.irradiance"),
    ],
)
def test_bad_input_names_the_key(emitter, match):
    with pytest.raises(ValueError, match=match):
        _scene(emitter)


def test_parameters_and_replace_validation():
    s = _scene(_spot())
    paths = [p.path for p in s.parameters() if p.path.startswith("emitters")]
    assert paths == [
        f"emitters.spot.0.{k}"
        for k in ("position", "direction", "intensity", "cutoff_angle", "beam_width")
    ]
    with pytest.raises(ValueError, match="beam_width"):
        s.replace("emitters.spot.0.beam_width", 40.0)
    assert s.n_lights == 1 and isinstance(s.delta_lights[0], SpotLight)
    sd = _scene({"type": "directional", "direction": [0, -2, 0], "irradiance": 1})
    assert isinstance(sd.delta_lights[0], DirectionalLight)
    np.testing.assert_allclose(sd.get("emitters.directional.0.direction"), [0, -1, 0])


@pytest.mark.mitsuba
def test_sample_direction_matches_mitsuba():
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1.5, 1.5, size=(64, 3)) * [1, 1, 0.2]
    spot = mi.load_dict(
        {
            "type": "spot",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=[0.1, 0.2, 2], target=[0.3, 0, 0], up=[0, 1, 0]
            ),
            "intensity": {"type": "rgb", "value": [1.0, 2.0, 3.0]},
            "cutoff_angle": 35.0,
            "beam_width": 12.0,
        }
    )
    direc = mi.load_dict(
        {
            "type": "directional",
            "direction": [0.3, -0.4, -1.0],
            "irradiance": {"type": "rgb", "value": [2.0, 1.0, 0.5]},
        }
    )
    mi.load_dict({"type": "scene", "e": direc, "s": {"type": "sphere"}})  # sets the bounds
    ours_s = SpotLight.create([0.1, 0.2, 2], [0.2, -0.2, -2], [1.0, 2.0, 3.0], 35.0, 12.0)
    ours_d = DirectionalLight.create([2.0, 1.0, 0.5], [0.3, -0.4, -1.0])
    for ours, theirs in [(ours_s, spot), (ours_d, direc)]:
        wi, _, li = (np.asarray(x) for x in ours.sample(jnp.asarray(pts, jnp.float32)))
        for k, p in enumerate(pts):
            it = mi.Interaction3f()
            it.p = mi.Point3f(p)
            ds, w = theirs.sample_direction(it, mi.Point2f(0.5, 0.5))
            assert ds.pdf == 1.0  # a delta light in Mitsuba too
            np.testing.assert_allclose(wi[k], np.array(ds.d), atol=2e-6)
            np.testing.assert_allclose(li[k], np.array(w), rtol=2e-5, atol=1e-7)
