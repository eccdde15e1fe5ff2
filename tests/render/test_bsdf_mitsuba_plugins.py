"""BSDF values and densities against Mitsuba 3 evaluated in the same run (``mitsuba`` marker;
skips without it): roughdielectric (GGX, both sides), plastic and roughplastic (the rough
coat's tables), principled (reflection lobes). Tolerances: Mitsuba's float32 arithmetic
(measured max relative differences in the comments); plastic also differs by Mitsuba's F_dr fit
(documented)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.bsdf import make_bsdf
from tests.render._mitsuba import local_si, mitsuba_fixture, unit_dirs

pytestmark = pytest.mark.mitsuba


mi = mitsuba_fixture()


def _mitsuba_values(mi, desc, wo, wi):
    b = mi.load_dict(desc)
    f, p = [], []
    for a, c in zip(wo, wi, strict=True):
        si = local_si(mi, a)
        f.append(np.array(b.eval(mi.BSDFContext(), si, mi.Vector3f(c))))
        p.append(b.pdf(mi.BSDFContext(), si, mi.Vector3f(c)))
    return np.array(f), np.array(p)


_ev = jax.jit(lambda b, wo, wi: (b.eval(wo, wi), b.pdf(wo, wi)))

CASES = [
    # (jaxgfx desc, mitsuba desc, upper hemisphere only, rtol); measured max rel. differences
    ({"type": "roughdielectric", "alpha": 0.3, "eta": 1.5},
     {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.3, "int_ior": 1.5,
      "ext_ior": 1.0}, False, 1e-3),  # 1.2e-4
    ({"type": "roughdielectric", "alpha": 0.05, "eta": 1 / 1.4},
     {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.05, "int_ior": 1.0,
      "ext_ior": 1.4}, False, 1e-3),  # 4e-6
    ({"type": "roughplastic", "alpha": 0.4, "eta": 1.5, "diffuse_reflectance": [0.02, 0.2, 0.9]},
     {"type": "roughplastic", "distribution": "ggx", "alpha": 0.4, "int_ior": 1.5,
      "ext_ior": 1.0, "diffuse_reflectance": {"type": "rgb", "value": [0.02, 0.2, 0.9]}},
     True, 2e-3),  # 4.7e-4 (eval), 3.9e-4 (pdf)
    ({"type": "roughplastic", "alpha": 1.0, "eta": 1.5, "nonlinear": True,
      "diffuse_reflectance": [0.02, 0.2, 0.9]},
     {"type": "roughplastic", "distribution": "ggx", "alpha": 1.0, "int_ior": 1.5,
      "ext_ior": 1.0, "nonlinear": True,
      "diffuse_reflectance": {"type": "rgb", "value": [0.02, 0.2, 0.9]}}, True, 2e-3),  # 1.9e-4
    ({"type": "plastic", "eta": 1.5, "diffuse_reflectance": [0.02, 0.2, 0.9]},
     {"type": "plastic", "int_ior": 1.5, "ext_ior": 1.0,
      "diffuse_reflectance": {"type": "rgb", "value": [0.02, 0.2, 0.9]}},
     True, 3e-3),  # 1.15e-3: Mitsuba's fitted F_dr(1/eta) vs the exact integral
    # principled: tolerances not yet measured (added without Mitsuba installed)
    ({"type": "principled", "base_color": [0.8, 0.45, 0.2], "roughness": 0.35, "metallic": 0.3,
      "specular": 0.6, "spec_tint": 0.4, "sheen": 0.7, "sheen_tint": 0.5, "flatness": 0.25,
      "clearcoat": 0.8, "clearcoat_gloss": 0.6},
     {"type": "principled", "base_color": {"type": "rgb", "value": [0.8, 0.45, 0.2]},
      "roughness": 0.35, "metallic": 0.3, "specular": 0.6, "spec_tint": 0.4, "sheen": 0.7,
      "sheen_tint": 0.5, "flatness": 0.25, "clearcoat": 0.8, "clearcoat_gloss": 0.6},
     True, 2e-3),
    ({"type": "principled", "base_color": [0.9, 0.6, 0.3], "roughness": 0.5, "metallic": 0.8,
      "anisotropic": 0.6, "eta": 1.33},
     {"type": "principled", "base_color": {"type": "rgb", "value": [0.9, 0.6, 0.3]},
      "roughness": 0.5, "metallic": 0.8, "anisotropic": 0.6, "eta": 1.33}, True, 2e-3),
]  # fmt: skip


@pytest.mark.parametrize("ours,theirs,upper,rtol", CASES, ids=lambda x: str(x)[:40])
def test_eval_and_pdf_equal_mitsuba(mi, ours, theirs, upper, rtol):
    wo, wi = unit_dirs(200, 0, upper=upper), unit_dirs(200, 1, upper=upper)
    fm, pm = _mitsuba_values(mi, theirs, wo, wi)
    f, p = _ev(make_bsdf(ours), jnp.asarray(wo, jnp.float32), jnp.asarray(wi, jnp.float32))
    f, p = np.asarray(f), np.asarray(p)
    live = fm[:, 0] > 1e-4
    assert live.sum() > 50
    np.testing.assert_allclose(f[live], fm[live], rtol=rtol)
    np.testing.assert_allclose(f[~live], fm[~live], atol=2e-5)
    big = pm > 1e-3
    np.testing.assert_allclose(p[big], pm[big], rtol=rtol)


_sample = jax.jit(lambda b, wo, u1, u2: b.sample(wo, u1, u2))


@pytest.mark.parametrize("nonlinear", [False, True])
def test_plastic_sample_equals_mitsuba(mi, nonlinear):
    """``plastic.sample`` for the same (wo, u1, u2): the same lobe (delta flag), direction,
    pdf (the specular lobe's probability) and weight. Measured max relative differences: delta
    weight and pdf 1e-6; diffuse weight 6.6e-4 (linear; Mitsuba's fitted F_dr(1/eta)) and 2.6e-4
    (nonlinear), direction 2e-6."""
    kd = [0.1, 0.3, 0.6]
    theirs = mi.load_dict({"type": "plastic", "int_ior": 1.6, "ext_ior": 1.0,
                           "nonlinear": nonlinear,
                           "diffuse_reflectance": {"type": "rgb", "value": kd}})  # fmt: skip
    ours = make_bsdf({"type": "plastic", "eta": 1.6, "nonlinear": nonlinear,
                      "diffuse_reflectance": kd})  # fmt: skip
    rng = np.random.default_rng(3)
    wo = unit_dirs(120, 2, upper=True)
    wo[:10, 2] = 0.02  # grazing: the specular lobe is likely
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    u1, u2 = rng.random(120), rng.random((120, 2))
    w_m, p_m, d_m, wi_m = [], [], [], []
    for a, b, c in zip(wo, u1, u2, strict=True):
        bs, w = theirs.sample(mi.BSDFContext(), local_si(mi, a), float(b), mi.Point2f(c))
        w_m.append(np.array(w))
        p_m.append(bs.pdf)
        d_m.append(mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta))
        wi_m.append(np.array(bs.wo))
    s = _sample(ours, *(jnp.asarray(x, jnp.float32) for x in (wo, u1, u2)))
    delta, d_m = np.asarray(s.is_delta), np.array(d_m)
    assert 20 < d_m.sum() < 100  # both lobes are exercised
    np.testing.assert_array_equal(delta, d_m)
    np.testing.assert_allclose(np.asarray(s.wi), np.array(wi_m), atol=2e-5)
    np.testing.assert_allclose(np.asarray(s.pdf), np.array(p_m), rtol=1e-4)
    w, w_m = np.asarray(s.weight), np.array(w_m)
    np.testing.assert_allclose(w[delta], w_m[delta], rtol=1e-5)
    np.testing.assert_allclose(w[~delta], w_m[~delta], rtol=2e-3)


@pytest.mark.slow  # ~5.4 s on the loaded 2-core box (two jaxgfx compiles + Mitsuba's scalar loop)
def test_roughdielectric_sample_visible_false_mitsuba_weight_is_not_eval_over_pdf(mi):
    """Documents a Mitsuba 3.9.1 deviation that jaxgfx does not copy.

    With ``sample_visible=false`` Mitsuba draws microfacet normals from alpha widened by
    ``1.2 - 0.2 sqrt|cos theta_i|`` (Walter et al. 2007's trick) but weights a sample with the
    unwidened Walter weight ``G |wi.m| / (|cos theta_i| cos theta_m)``, so its weight is not its
    own ``eval / pdf`` (off by ``D_widened(m) / D(m)``) and the albedo it renders is too high at
    grazing incidence (its heavy-tailed mean weight needs more samples than this test affords
    in Mitsuba's scalar variant: the per-sample ratio is the deterministic symptom). jaxgfx
    samples ``D cos theta_m`` unwidened with weight ``eval / pdf``: its albedo equals Mitsuba's
    visible-normal one. If this fails on a newer Mitsuba, the deviation was fixed there
    (update docs/render_mitsuba.md)."""
    desc = {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.15, "int_ior": 1.25,
            "ext_ior": 1.0}  # fmt: skip
    wo = np.array([math.sqrt(1 - 0.01), 0.0, 0.1])  # cos theta_o = 0.1
    rng = np.random.default_rng(5)
    means, ratio = {}, []
    for sv, n in ((True, 2000), (False, 300)):
        b = mi.load_dict({**desc, "sample_visible": sv})
        si = local_si(mi, wo)
        w = np.zeros(n)
        for k in range(n):
            bs, wk = b.sample(mi.BSDFContext(), si, float(rng.random()), mi.Point2f(rng.random(2)))
            w[k] = np.array(wk)[0]
            if not sv and w[k] > 0 and bs.pdf > 0:
                f = np.array(b.eval(mi.BSDFContext(), si, bs.wo))[0]
                ratio.append(w[k] / (f / b.pdf(mi.BSDFContext(), si, bs.wo)))
        means[sv] = (w.mean(), w.std() / math.sqrt(n))
    ratio = np.array(ratio)
    # jaxgfx, both samplers, many samples (cheap)
    ours = {}
    for sv in (True, False):
        b = make_bsdf({"type": "roughdielectric", "alpha": 0.15, "eta": 1.25, "sample_visible": sv})
        k1, k2 = jax.random.split(jax.random.key(0))
        m = 100_000
        s = _sample(b, jnp.tile(jnp.asarray(wo, jnp.float32), (m, 1)),
                    jax.random.uniform(k1, (m,)), jax.random.uniform(k2, (m, 2)))  # fmt: skip
        wj = np.asarray(s.weight, np.float64)[:, 0]
        ours[sv] = (wj.mean(), wj.std() / math.sqrt(m))

    def z(a, b):
        return (a[0] - b[0]) / math.hypot(a[1], b[1])

    # Mitsuba's sample_visible=false weight is not eval/pdf (measured ratio 0.77 .. 1.29)
    assert ratio.min() < 0.9 and ratio.max() > 1.1
    # jaxgfx: the two samplers agree with each other and with Mitsuba's visible-normal albedo
    # (measured: 0.6460 +- 0.0004 visible, 0.6500 +- 0.0025 full D cos; Mitsuba 0.6486 +- 0.003;
    # Mitsuba's own sample_visible=false mean, 3000 samples: 0.670 +- 0.019)
    assert abs(z(ours[False], ours[True])) < 4
    assert abs(z(ours[True], means[True])) < 4
