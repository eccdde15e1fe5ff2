"""Opacity mask (Mitsuba ``mask``, issue 23): its lobes in closed form, chi² of the nested lobe,
furnace, the choice's derivative, d radiance / d opacity through the path integrator against
the closed form and central differences of the estimator's expectation, opacity 0 and 1, the
description / XML / writer round trips, and values against Mitsuba 3's plugin (``mitsuba``)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.bsdf import Diffuse, Mask, RoughConductor, make_bsdf
from jaxgfx.render.integrators.path import path_radiance
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.load import material_from_desc
from jaxgfx.testing import chi2_test, furnace
from tests.render._scenes import area_light, camera, point_light, rectangle

RHO = np.array([0.2, 0.5, 0.8])


def _dir(cos, phi=0.7):
    s = math.sqrt(max(1 - cos * cos, 0.0))
    return jnp.array([s * math.cos(phi), s * math.sin(phi), cos])


@jax.jit
def _sample(b, wo, u1, u2):
    return b.sample(wo, u1, u2)


_eval = jax.jit(lambda b, wo, wi: b.eval(wo, wi))
_pdf = jax.jit(lambda b, wo, wi: b.pdf(wo, wi))


@pytest.mark.parametrize("a", [0.3, 0.0, 1.0])
def test_lobes_closed_form(a):
    m = Mask(Diffuse(RHO), a)
    wo = _dir(0.6)
    # u1 below a: the nested diffuse lobe (u1 / a reused); above: the pass-through
    u1 = jnp.array([0.5 * a, a + 0.5 * (1 - a), 0.999])
    s = _sample(m, wo, u1, jnp.full((3, 2), 0.3))
    for i in range(3):
        if u1[i] < a:
            cos = float(s.wi[i, 2])
            assert cos > 0 and not s.is_delta[i]
            np.testing.assert_allclose(s.pdf[i], a * cos / math.pi, rtol=1e-5)
            np.testing.assert_allclose(s.weight[i], RHO, rtol=1e-5)
        else:
            np.testing.assert_allclose(s.wi[i], -wo, atol=1e-7)
            assert bool(s.is_delta[i]) and float(s.eta[i]) == 1.0
            np.testing.assert_allclose(s.pdf[i], 1 - a, rtol=1e-6)
            np.testing.assert_allclose(s.weight[i], [1.0] * 3 if a < 1 else [0.0] * 3)
    wi = _dir(0.8, 2.0)
    np.testing.assert_allclose(_eval(m, wo, wi), a * RHO * 0.8 / math.pi, rtol=1e-5)
    np.testing.assert_allclose(_pdf(m, wo, wi), a * 0.8 / math.pi, rtol=1e-5)
    assert m.has_delta and not m.is_transmissive
    np.testing.assert_allclose(m.albedo, RHO)


@pytest.mark.slow  # slow: 4-9 s measured here (20k samples; compile of sample and pdf)
def test_nested_lobe_chi2_and_furnace():
    m = Mask(RoughConductor(0.3), 0.4)
    wo = _dir(0.5)
    n = 20_000

    def sample_fn(u1, u2):
        s = m.sample(jnp.broadcast_to(wo, (u1.shape[0], 3)), u1, u2)
        # pass-through samples are the delta lobe: dropped (missing mass 1 - a), as are the
        # nested lobe's reflections below the horizon (pdf 0)
        return jnp.where((s.is_delta | (s.pdf == 0))[..., None], 0.0, s.wi)

    ok, p, det = chi2_test(jax.jit(sample_fn), jax.jit(lambda w: m.pdf(wo, w)),
                           key=jax.random.key(3), n_samples=n)  # fmt: skip
    assert ok, p
    # the pdf's integral over the hemisphere is the probability that sample() returns a valid
    # nested direction: a times the nested lobe's share above the horizon (0.91 here, not 1),
    # against that fraction of independent samples (binomial standard error, plus 1e-3 for the
    # quadrature). Measured: integral 0.3645, fraction 0.3617 (standard error 0.0034)
    k1, k2 = jax.random.split(jax.random.key(4))
    wi = jax.jit(sample_fn)(jax.random.uniform(k1, (n,)), jax.random.uniform(k2, (n, 2)))
    frac = float(jnp.mean(jnp.any(wi != 0, -1)))
    assert abs(det["pdf_integral"] - frac) < 4 * math.sqrt(frac * (1 - frac) / n) + 1e-3, (
        det["pdf_integral"], frac)  # fmt: skip
    assert 0.3 < frac < 0.4
    # albedo = (1 - a) + a albedo_nested, each from its own estimate (standard errors)
    mean, se = furnace(m, wo, key=jax.random.key(1), n=40_000)
    mn, sen = furnace(RoughConductor(0.3), wo, key=jax.random.key(2), n=40_000)
    ref = 0.6 + 0.4 * mn
    assert np.all(np.abs(mean - ref) < 4 * np.sqrt(se**2 + (0.4 * sen) ** 2)), (mean, ref)


def test_furnace_diffuse_closed_form():
    # albedo (1 - a) + a rho; the only variance is the lobe choice's (one compiled estimate)
    run = jax.jit(lambda m, k: furnace(m, _dir(0.4), key=k, n=8192))
    mean, se = run(Mask(Diffuse(RHO), 0.3), jax.random.key(0))
    ref = 0.7 + 0.3 * RHO
    assert np.all(np.abs(mean - ref) < 4 * se), (mean, ref, se)


def test_choice_gradient_and_hard_cases(x64):
    wo = _dir(0.6)

    def w(a, u1):
        return Mask(Diffuse(0.5), a).sample(wo, u1, jnp.full((2,), 0.3)).weight[0]

    # d/da of the choice: a / sg(a) for the nested lobe, (1 - a) / sg(1 - a) for the null one;
    # opacity 0 and 1: finite values and gradients, either draw (one compiled function)
    a = jnp.asarray([0.4, 0.4] + [0.0] * 3 + [1.0] * 3)
    u1 = jnp.asarray([0.1, 0.9] + [0.0, 0.5, 0.999] * 2)
    v, g = jax.jit(jax.vmap(jax.value_and_grad(w)))(a, u1)
    np.testing.assert_allclose(g[:2], [0.5 / 0.4, -1 / 0.6], rtol=1e-12)
    assert np.all(np.isfinite(v)) and np.all(np.isfinite(g)), (v, g)
    # eval / pdf are linear in a: d/da against central differences; out-of-range opacity is
    # clipped to [0, 1] (Mitsuba's eval_opacity)
    wi = _dir(0.3, 1.0)
    f = jax.jit(jax.vmap(jax.value_and_grad(
        lambda a: Mask(RoughConductor(0.2), a).eval(wo, wi)[0])))  # fmt: skip
    (fp, fm, f1, f17), (g5, _, _, _) = f(jnp.asarray([0.5 + 1e-6, 0.5 - 1e-6, 1.0, 1.7]))
    np.testing.assert_allclose(g5, (fp - fm) / 2e-6, rtol=1e-8)
    assert f17 == f1 > 0


# -------------------------------------------------------------------- through the integrator

LE = np.array([2.0, 1.0, 0.5])  # the emitter behind the mask
INTENSITY = 3.0  # point light 1 above the mask
XZ = np.array([[0.0, 0.0], [0.3, 0.1], [0.55, -0.2]])


def _mask_scene(a):
    return load_scene(
        {
            "camera": camera([0, 3, 0.01], [0, 0, 0], fov=40, width=2),
            "shapes": [rectangle(size=(8, 8), material="m")],
            "materials": {
                "m": {
                    "type": "mask",
                    "opacity": a,
                    "bsdf": {"type": "diffuse", "reflectance": RHO.tolist()},
                }
            },
            "emitters": [
                point_light([0, 1, 0], INTENSITY),
                area_light([0, -1, 0], [0, 1, 0], (8, 8), LE.tolist()),
            ],
        },  # fmt: skip
        dtype=jnp.float64,
    )


_CHOICES = [(u_sel, nested) for u_sel in (0.25, 0.75) for nested in (True, False)]


@jax.jit
def _expected(scene, a):
    """The estimator's expectation over both discrete choices at the first vertex (light:
    1/2 each; lobe: nested with probability a, pass-through 1 - a) for camera rays straight
    down at XZ (max_depth 2), per ray: its derivative is ``E[dL/da]`` (the probabilities are
    detached), its central differences those of ``E[L]`` (they are not)."""
    sg = jax.lax.stop_gradient
    s = scene.replace("materials.m.opacity", a)
    n, k = len(XZ), len(_CHOICES)
    o = jnp.asarray(np.tile(np.stack([XZ[:, 0], np.ones(n), XZ[:, 1]], -1), (k, 1)))
    d = jnp.asarray(np.tile([0.0, -1.0, 0.0], (k * n, 1)))
    u_sel = jnp.repeat(jnp.asarray([c[0] for c in _CHOICES]), n)
    nested = jnp.repeat(jnp.asarray([c[1] for c in _CHOICES]), n)
    u1 = sg(jnp.where(nested, 0.5 * a, a + 0.5 * (1 - a)))
    u = jnp.full((k * n, 2, 7), 0.5).at[:, 0, 0].set(u_sel).at[:, 0, 3].set(u1)
    L = path_radiance(s, o, d, u, max_depth=2).reshape(k, n, 3)
    p = jnp.where(nested, a, 1 - a).reshape(k, n)[..., None]
    return jnp.sum(0.5 * sg(p) * L, 0)


def _fd(scene, a, h=1e-6):
    """Central differences of E[L]: the values of :func:`_expected` (the probabilities and the
    lobe choices moving with a; only derivatives are detached)."""
    e = [np.asarray(_expected(scene, jnp.float64(x))) for x in (a + h, a - h)]
    return (e[0] - e[1]) / (2 * h)


def _closed_form(a):
    cos_d2 = (
        1.0 / np.linalg.norm(np.stack([XZ[:, 0], -np.ones(len(XZ)), XZ[:, 1]], -1), axis=1) ** 3
    )
    nee = a * RHO[None] / math.pi * INTENSITY * cos_d2[:, None]  # cos / d^2 = 1 / d^3
    return nee + (1 - a) * LE[None], RHO[None] / math.pi * INTENSITY * cos_d2[:, None] - LE[None]


@pytest.mark.slow  # slow: 15-20 s on the loaded 2-core box (compile of path_radiance and its jvp)
def test_radiance_and_opacity_gradient_through_the_path_integrator(x64):
    scene = _mask_scene(0.5)
    grad = jax.jit(jax.jacfwd(_expected, argnums=1))
    for a in (0.3, 0.7):
        val, dval = _closed_form(a)
        np.testing.assert_allclose(_expected(scene, jnp.float64(a)), val, rtol=1e-9)
        g = grad(scene, jnp.float64(a))
        np.testing.assert_allclose(g, dval, rtol=1e-9)
        # central differences of the expectation (the choice probabilities move with a)
        fd = _fd(scene, a)
        np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)
    for a in (0.0, 1.0):  # opacity 0 and 1: values and derivatives finite
        assert np.all(np.isfinite(_expected(scene, jnp.float64(a))))
        assert np.all(np.isfinite(grad(scene, jnp.float64(a))))
    # opacity 0: everything passes through (the NEE term is a x ...): exactly Le
    np.testing.assert_allclose(_expected(scene, jnp.float64(0.0)), np.tile(LE, (3, 1)), rtol=1e-9)


# -------------------------------------------------------------------- descriptions and files


def test_descriptions_textures_and_errors():
    m = material_from_desc({"type": "mask", "opacity": {"type": "checkerboard", "color0": 0.2,
                                                        "color1": 0.9},
                            "bsdf": {"type": "diffuse", "reflectance": 0.4}})  # fmt: skip
    at = m.at(jnp.array([[0.25, 0.25], [0.75, 0.25]]))
    np.testing.assert_allclose(at.opacity, [0.2, 0.9])
    assert isinstance(at, Mask) and at.has_delta
    assert isinstance(make_bsdf({"type": "mask", "bsdf": {"type": "diffuse"}}).bsdf, Diffuse)
    assert float(make_bsdf({"type": "mask", "bsdf": {"type": "diffuse"}}).opacity) == 0.5
    with pytest.raises(ValueError, match="bsdf: missing nested BSDF"):
        make_bsdf({"type": "mask"})
    with pytest.raises(ValueError, match="opacity"):
        make_bsdf({"type": "mask", "opacity": float("nan"), "bsdf": {"type": "diffuse"}})
    with pytest.raises(ValueError, match=r"opacity: texture values must be non-negative"):
        material_from_desc({"type": "mask", "bsdf": {"type": "diffuse"},
                            "opacity": {"type": "bitmap", "image": [[-1.0]]}})  # fmt: skip


MASK_XML = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film>
  </sensor>
  <shape type="sphere"><point name="center" x="0" y="0" z="5"/>
    <bsdf type="mask">{body}</bsdf>
  </shape>
</scene>
"""


def _xml(tmp_path, body):
    from jaxgfx.render.scene.mitsuba_xml import read_xml

    p = tmp_path / "s.xml"
    p.write_text(MASK_XML.replace("{body}", body))
    return read_xml(str(p)).desc["materials"]


def test_xml_mask_and_writers(tmp_path):
    from jaxgfx.render.scene.mitsuba import _bsdf_desc, _material

    mats = _xml(tmp_path, '<float name="opacity" value="0.3"/><bsdf type="twosided">'
                          '<bsdf type="diffuse"><rgb name="reflectance" value="0.1 0.8 0.1"/>'
                          "</bsdf></bsdf>")  # fmt: skip
    (m,) = mats.values()
    assert m == {"type": "mask", "opacity": 0.3,
                 "bsdf": {"type": "diffuse", "reflectance": [0.1, 0.8, 0.1]}}  # fmt: skip
    m = _xml(tmp_path, '<bsdf type="diffuse"/>')
    assert next(iter(m.values()))["opacity"] == 0.5  # Mitsuba's default
    tex = _xml(tmp_path, '<texture name="opacity" type="checkerboard"/><bsdf type="diffuse"/>')
    assert next(iter(tex.values()))["opacity"]["type"] == "checkerboard"
    for body, msg in (
        ("", "expected exactly one nested <bsdf>, got 0"),
        ('<bsdf type="diffuse"/><bsdf type="diffuse"/>', "exactly one nested <bsdf>, got 2"),
        ('<texture type="checkerboard"/><bsdf type="diffuse"/>', 'needs name="opacity"'),
        ('<bsdf type="mask"><bsdf type="diffuse"/></bsdf>', "a mask nested in a"),
        ('<bsdf type="diffuse"><texture name="reflectance" type="checkerboard"/></bsdf>',
         "textures are not supported in a BSDF nested in a blendbsdf or mask"),
    ):  # fmt: skip
        with pytest.raises(ValueError, match=msg):
            _xml(tmp_path, body)
    # writers: Mitsuba dict (nested one-sided BSDF in twosided) and the description
    desc = {"type": "mask", "opacity": 0.3, "bsdf": {"type": "diffuse", "reflectance": 0.4}}
    out = _material(desc, "m")
    assert out["type"] == "mask" and out["opacity"] == pytest.approx(0.3)
    assert out["bsdf"]["type"] == "twosided" and out["bsdf"]["bsdf"]["type"] == "diffuse"
    back = _bsdf_desc(make_bsdf(desc), "m")
    rt = make_bsdf(back)
    assert back["type"] == "mask" and float(rt.opacity) == pytest.approx(0.3)
    np.testing.assert_allclose(rt.bsdf.reflectance, 0.4)


def test_save_scene_round_trip(tmp_path, x64):
    from jaxgfx.render.scene.mitsuba import scene_to_desc
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    scene = _mask_scene(0.35)
    p = str(tmp_path / "mask.xml")
    save_scene(scene, p)
    desc = read_xml(p).desc
    (m,) = [v for v in desc["materials"].values() if v["type"] == "mask"]
    assert m["opacity"] == pytest.approx(0.35) and m["bsdf"]["type"] == "diffuse"
    (m2,) = [v for v in scene_to_desc(scene)["materials"].values() if v["type"] == "mask"]
    np.testing.assert_allclose(m2["opacity"], 0.35)


@pytest.mark.mitsuba
def test_values_match_mitsuba():
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(5)
    nested = {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2}
    ref = mi.load_dict({"type": "mask", "opacity": 0.35, "b": nested})
    ours = Mask(RoughConductor(0.2), 0.35)
    for _ in range(32):
        a, c = rng.normal(size=(2, 3))
        a[2], c[2] = abs(a[2]), abs(c[2])
        a, c = a / np.linalg.norm(a), c / np.linalg.norm(c)
        u1, u2 = rng.uniform(size=3)[0], rng.uniform(size=2)
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(a)
        si.sh_frame = mi.Frame3f(mi.Normal3f(0, 0, 1))
        ctx = mi.BSDFContext()
        wo, wi = jnp.asarray(a, jnp.float32), jnp.asarray(c, jnp.float32)
        np.testing.assert_allclose(_eval(ours, wo, wi), np.array(ref.eval(ctx, si, mi.Vector3f(c))),
                                   rtol=2e-3, atol=1e-6)  # fmt: skip
        np.testing.assert_allclose(_pdf(ours, wo, wi), ref.pdf(ctx, si, mi.Vector3f(c)),
                                   rtol=2e-3, atol=1e-6)  # fmt: skip
        bs, w = ref.sample(ctx, si, float(u1), mi.Point2f(*u2))
        s = _sample(ours, wo, jnp.asarray(u1, jnp.float32), jnp.asarray(u2, jnp.float32))
        # the same lobe choice for the same u1 (the nested lobes map u2 to directions by
        # different VNDF warps, so the nested direction itself is not compared: its pdf and
        # weight are, against Mitsuba's mask at jaxgfx's direction)
        assert bool(s.is_delta) == mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
        assert bool(s.is_delta) == (u1 >= 0.35)
        if bool(s.is_delta):
            np.testing.assert_allclose(s.wi, -a, atol=1e-6)
            np.testing.assert_allclose(np.array(bs.wo), -a, atol=1e-6)
            np.testing.assert_allclose([s.pdf, bs.pdf], 0.65, rtol=1e-5)
            np.testing.assert_allclose(s.weight, np.array(w), rtol=1e-5)
        elif s.pdf > 0 and s.wi[2] > 0:
            wi_s = mi.Vector3f(np.asarray(s.wi, np.float64))
            pdf_mi = ref.pdf(ctx, si, wi_s)
            np.testing.assert_allclose(s.pdf, pdf_mi, rtol=2e-3)
            np.testing.assert_allclose(s.weight, np.array(ref.eval(ctx, si, wi_s)) / pdf_mi,
                                       rtol=2e-3, atol=1e-6)  # fmt: skip
