"""BSDF models: chi², weight = eval/pdf, reciprocity, furnace vs quadrature, closed-form values."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.bsdf import (
    BSDF_TYPES,
    Diffuse,
    Mirror,
    Phong,
    RoughConductor,
    RoughPlastic,
    SmoothDielectric,
    make_bsdf,
)
from jaxgfx.testing import chi2_test, furnace


def _dir(cos, phi=0.7):
    s = math.sqrt(max(1 - cos * cos, 0.0))
    return jnp.array([s * math.cos(phi), s * math.sin(phi), cos])


@jax.jit
def _sample(b, wo, u1, u2):
    s = b.sample(wo, u1, u2)
    return jnp.where((s.pdf > 0)[:, None], s.wi, 0.0), s


_pdf = jax.jit(lambda b, wo, w: b.pdf(wo, w))
_sample_raw = jax.jit(lambda b, wo, u1, u2: b.sample(wo, u1, u2))
_eval = jax.jit(lambda b, wo, wi: b.eval(wo, wi))

CHI2_CASES = [
    ("diffuse", Diffuse(0.7), 0.8),
    ("ggx a=0.3", RoughConductor(0.3), 0.8),
    ("ggx a=0.3 grazing", RoughConductor(0.3), 0.05),
    ("ggx a=1 wo=n", RoughConductor(1.0), 1.0),
    ("ggx a=0.05", RoughConductor(0.05), 0.6),
    pytest.param("ggx aniso", RoughConductor(0.1, alpha_v=0.4), 0.7, marks=pytest.mark.slow),
    pytest.param(
        "ggx full-D", RoughConductor(0.3, sample_visible=False), 0.7, marks=pytest.mark.slow
    ),
    ("beckmann a=0.3", RoughConductor(0.3, distribution="beckmann"), 0.7),
    pytest.param(
        "beckmann a=1", RoughConductor(1.0, distribution="beckmann"), 0.3, marks=pytest.mark.slow
    ),
    ("phong", Phong(0.3, 0.5, 20.0), 0.7),
    ("roughplastic a=0.3", RoughPlastic(0.5, 0.3), 0.7),
    pytest.param(
        "roughplastic a=0.05 grazing", RoughPlastic(0.5, 0.05), 0.1, marks=pytest.mark.slow
    ),
]


def _cases(cases):
    return [c.values if hasattr(c, "marks") else c for c in cases]


# 18.1 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
@pytest.mark.parametrize("name,bsdf,cos_o", CHI2_CASES, ids=[c[0] for c in _cases(CHI2_CASES)])
def test_chi2_and_pdf_mass(name, bsdf, cos_o):
    """Chi² of the sampler against its pdf; pdf mass; and weight == eval / pdf on the samples."""
    wo = _dir(cos_o)
    n = 40_000
    store = {}

    def sample_fn(u1, u2):
        w, store["s"] = _sample(bsdf, wo, u1, u2)
        return w

    ok, p, det = chi2_test(
        sample_fn,
        lambda w: _pdf(bsdf, wo, w),
        key=jax.random.key(7),
        n_samples=n,
        res_theta=16,
        res_phi=32,
        ires=40 if "0.05" in name else 10,  # peaked lobes need finer quadrature
        test_count=len(CHI2_CASES),
    )
    assert ok, (p, det["message"])
    # the pdf integrates to the fraction of successful samples (1 for Diffuse)
    frac = float(det["observed"].sum()) / n
    tol = 4 * math.sqrt(max(frac * (1 - frac), 1e-4) / n) + 3e-3
    assert det["pdf_integral"] == pytest.approx(frac, abs=tol)
    if name == "diffuse":
        assert det["pdf_integral"] == pytest.approx(1.0, abs=1e-6)
    _check_weights(bsdf, wo, store["s"])


def _check_weights(bsdf, wo, s):
    valid = np.asarray(s.pdf) > 0
    assert valid.mean() > 0.3
    np.testing.assert_allclose(s.pdf[valid], _pdf(bsdf, wo, s.wi)[valid], rtol=2e-3)
    ev = np.asarray(_eval(bsdf, wo, s.wi))[valid]
    np.testing.assert_allclose(
        s.weight[valid], ev / np.asarray(s.pdf)[valid][:, None], rtol=2e-3, atol=1e-6
    )
    assert np.all(np.asarray(s.weight)[~valid] == 0)
    assert not np.any(s.is_delta)
    np.testing.assert_allclose(np.linalg.norm(s.wi, axis=-1), 1.0, atol=1e-5)


def test_weight_classic_phong():
    bsdf, wo = Phong(0.3, 0.5, 20.0, normalized=False), _dir(0.7)
    k1, k2 = jax.random.split(jax.random.key(1))
    _, s = _sample(bsdf, wo, jax.random.uniform(k1, (40_000,)), jax.random.uniform(k2, (40_000, 2)))
    _check_weights(bsdf, wo, s)


RECIPROCAL = [
    Diffuse(0.6),
    RoughConductor(0.3),
    RoughConductor(0.2, alpha_v=0.5, distribution="beckmann"),
    RoughConductor(0.4, eta=[0.2, 0.9, 1.1], k=[3.5, 2.4, 1.9]),
    Phong(0.3, 0.5, 10.0),
    RoughPlastic([0.2, 0.5, 0.8], 0.2),
]


# 3.8 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
@pytest.mark.parametrize("bsdf", RECIPROCAL, ids=lambda b: type(b).__name__)
def test_reciprocity(bsdf):
    k1, k2 = jax.random.split(jax.random.key(2))
    a = jax.random.normal(k1, (256, 3))
    b = jax.random.normal(k2, (256, 3))
    a = a.at[:, 2].set(jnp.abs(a[:, 2]))
    b = b.at[:, 2].set(jnp.abs(b[:, 2]))
    a = a / jnp.linalg.norm(a, axis=-1, keepdims=True)
    b = b / jnp.linalg.norm(b, axis=-1, keepdims=True)
    f_ab = np.asarray(_eval(bsdf, a, b)) / np.asarray(b[:, 2:])
    f_ba = np.asarray(_eval(bsdf, b, a)) / np.asarray(a[:, 2:])
    np.testing.assert_allclose(f_ab, f_ba, rtol=2e-4, atol=1e-7)


def test_classic_phong_is_not_reciprocal():
    bsdf = Phong(0.0, 1.0, 10.0, normalized=False)
    a, b = _dir(0.9, 0.0), _dir(0.4, math.pi)
    f_ab = float(_eval(bsdf, a, b)[0]) / float(b[2])
    f_ba = float(_eval(bsdf, b, a)[0]) / float(a[2])
    # ks cos^n α / cos θ_i: swapping only changes the divisor
    assert f_ab / f_ba == pytest.approx(float(a[2] / b[2]), rel=1e-5)


# ------------------------------------------------------------------ furnace


def np_ggx_albedo(alpha, cos_o, n_theta=512, n_phi=256):
    """Directional albedo of the GGX conductor with F = 1 by float64 quadrature (NumPy only)."""
    x, w = np.polynomial.legendre.leggauss(n_theta)
    th = 0.25 * np.pi * (x + 1)
    wt = 0.25 * np.pi * w * np.sin(th)
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    T, P = np.meshgrid(th, ph, indexing="ij")
    wi = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    wo = np.array([math.sqrt(1 - cos_o**2), 0.0, cos_o])
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    tan2_h = (h[..., 0] ** 2 + h[..., 1] ** 2) / h[..., 2] ** 2
    D = 1 / (np.pi * alpha**2 * h[..., 2] ** 4 * (1 + tan2_h / alpha**2) ** 2)

    def g1(v):
        tan2 = (1 - v[..., 2] ** 2) / v[..., 2] ** 2
        return 2 / (1 + np.sqrt(1 + alpha**2 * tan2))

    f = D * g1(wi) * g1(wo) / (4 * cos_o)  # f cos θ_i
    return float(np.sum(f * wt[:, None] * (2 * np.pi / n_phi)))


_furnace = jax.jit(furnace, static_argnames="n")


@pytest.mark.parametrize(
    "alpha,cos_o",
    [
        (1.0, 1.0),
        pytest.param(0.3, 0.5, marks=pytest.mark.slow),
        pytest.param(0.6, 0.2, marks=pytest.mark.slow),
    ],
)
def test_furnace_ggx_conductor(alpha, cos_o):
    ref = np_ggx_albedo(alpha, cos_o)
    mean, se = _furnace(RoughConductor(alpha), _dir(cos_o), key=jax.random.key(4), n=50_000)
    assert float(mean[0]) == pytest.approx(ref, abs=4 * float(se[0]) + 1e-4)
    assert float(mean[0]) <= 1.0
    assert 0.25 < ref < 1.0
    if alpha == 1.0 and cos_o == 1.0:
        # GGX α = 1 has D = 1/π: at normal incidence the albedo is 1 - ln 2 in closed form
        assert ref == pytest.approx(1 - math.log(2), abs=1e-9)


# 4.5 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_furnace_closed_forms():
    wo = _dir(0.7)
    m, se = _furnace(Diffuse(1.0), wo, key=jax.random.key(0), n=20_000)
    np.testing.assert_allclose(m, 1.0, rtol=1e-6)
    np.testing.assert_allclose(se, 0.0, atol=1e-7)
    # rough plastic, white base, nearly smooth coat (docs/render_bsdf.md): albedo
    # F(μ_o) + (1 - F(μ_o)) (1 - F_dr(1/η)) / (1 - R_int), R_int Mitsuba 3's 64-point mean of
    # F(μ, 1/η) μ (1.1 % below F_dr(1/η)), so not exactly 1; NumPy reference below
    m, se = _furnace(RoughPlastic(1.0, 0.02), wo, key=jax.random.key(0), n=20_000)
    eta = 1.49 / 1.000277
    mu = np.linspace(0.0, 1.0, 64)
    r_int = 2 * np.mean(_np_fresnel(mu, 1 / eta) * mu)
    x, w = np.polynomial.legendre.leggauss(400)  # F_dr(1/η): the TIR part analytic
    mu_c = math.sqrt(1 - 1 / eta**2)
    t = 0.5 * (1 - mu_c) * (x + 1) + mu_c
    fdr = mu_c**2 + np.sum(0.5 * (1 - mu_c) * w * 2 * _np_fresnel(t, 1 / eta) * t)
    f_o = float(_np_fresnel(np.array(0.7), eta))
    ref = f_o + (1 - f_o) * (1 - fdr) / (1 - r_int)
    assert 0.97 < ref < 0.985
    assert float(m[0]) == pytest.approx(ref, abs=4 * float(se[0]) + 2e-3)


def _np_fresnel(mu, eta):
    """Unpolarised dielectric Fresnel reflectance (NumPy, float64; 1 under TIR)."""
    s2 = (1 - mu**2) / eta**2
    ct = np.sqrt(np.maximum(1 - s2, 0.0))
    tir = (s2 >= 1) | (mu <= 0)
    mu, ct = np.where(tir, 1.0, mu), np.where(tir, 1.0, ct)
    rs = (mu - eta * ct) / (mu + eta * ct)
    rp = (ct - eta * mu) / (ct + eta * mu)
    return np.where(tir, 1.0, 0.5 * (rs**2 + rp**2))


# ------------------------------------------------------------------ closed-form values


# 4.3 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_known_values():
    z = jnp.array([0.0, 0.0, 1.0])
    # Lambert: ρ/π cos θ_i
    np.testing.assert_allclose(_eval(Diffuse(0.5), z, _dir(0.5)), 0.25 / math.pi, rtol=1e-6)
    # GGX α = 1, wo = wi = n: D = 1/π, G = 1, F = 1 -> f cos = 1/(4π)
    np.testing.assert_allclose(_eval(RoughConductor(1.0), z, z), 0.25 / math.pi, rtol=1e-6)
    # Beckmann at the pole: D = 1/(π α²), G = 1 -> 1/(4 π α²)
    np.testing.assert_allclose(
        _eval(RoughConductor(0.5, distribution="beckmann"), z, z), 1 / math.pi, rtol=1e-6
    )
    # Phong at the mirror direction
    np.testing.assert_allclose(
        _eval(Phong(0.2, 0.5, 10.0), z, z), 0.2 / math.pi + 0.5 * 12 / (2 * math.pi), rtol=1e-6
    )
    np.testing.assert_allclose(_eval(Phong(0.2, 0.5, 10.0, normalized=False), z, z), 0.7)
    # below the surface: zero
    below = jnp.array([0.0, 0.6, -0.8])
    for b in [Diffuse(0.5), RoughConductor(0.3), Phong(), RoughPlastic()]:
        np.testing.assert_array_equal(_eval(b, z, below), 0.0)
        np.testing.assert_array_equal(_eval(b, below, z), 0.0)
        assert float(_pdf(b, z, below)) == 0.0


def test_delta_bsdfs():
    wo = _dir(0.6)
    u = jnp.full((4,), 0.5), jnp.full((4, 2), 0.5)
    s = _sample_raw(Mirror(), wo, *u)
    np.testing.assert_allclose(s.wi, jnp.broadcast_to(jnp.array([-wo[0], -wo[1], wo[2]]), (4, 3)))
    np.testing.assert_allclose(s.weight, 1.0)
    assert bool(jnp.all(s.is_delta)) and Mirror.has_delta
    eta, k = jnp.array([0.2, 0.9, 1.1]), jnp.array([3.5, 2.4, 1.9])
    s = _sample_raw(Mirror(0.9, eta=eta, k=k), _dir(1.0), *u)
    r0 = ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)
    np.testing.assert_allclose(s.weight[0], 0.9 * r0, rtol=1e-5)
    np.testing.assert_array_equal(_eval(Mirror(), wo, wo), 0.0)

    # smooth dielectric: reflection frequency = Fresnel reflectance (binomial tolerance)
    glass = SmoothDielectric(1.5)
    assert glass.is_transmissive and glass.has_delta
    n = 20_000
    u1 = jax.random.uniform(jax.random.key(3), (n,))
    u2 = jnp.zeros((n, 2))
    cos_o = 0.3
    s = _sample_raw(glass, _dir(cos_o), u1, u2)
    refl = np.asarray(s.wi[:, 2]) > 0
    r = 0.5 * (
        (
            (cos_o - 1.5 * math.sqrt(1 - (1 - cos_o**2) / 2.25))
            / (cos_o + 1.5 * math.sqrt(1 - (1 - cos_o**2) / 2.25))
        )
        ** 2
        + (
            (math.sqrt(1 - (1 - cos_o**2) / 2.25) - 1.5 * cos_o)
            / (math.sqrt(1 - (1 - cos_o**2) / 2.25) + 1.5 * cos_o)
        )
        ** 2
    )
    assert refl.mean() == pytest.approx(r, abs=4 * math.sqrt(r * (1 - r) / n))
    np.testing.assert_allclose(np.asarray(s.pdf)[refl], r, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(s.pdf)[~refl], 1 - r, rtol=1e-5)
    # Snell: sin θ_t = sin θ_o / 1.5 ; azimuth flipped; radiance scaled by 1/η² entering
    wt = np.asarray(s.wi)[~refl][0]
    assert math.hypot(wt[0], wt[1]) == pytest.approx(math.sqrt(1 - cos_o**2) / 1.5, rel=1e-5)
    assert wt[2] < 0
    np.testing.assert_allclose(np.asarray(s.weight)[~refl], 1 / 2.25, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(s.weight)[refl], 1.0)
    np.testing.assert_allclose(np.asarray(s.eta)[~refl], 1.5)
    # from inside beyond the critical angle: total internal reflection, weight 1
    s = _sample_raw(glass, -_dir(0.3), jnp.array([0.99]), jnp.zeros((1, 2)))
    assert float(s.wi[0, 2]) < 0 and float(s.pdf[0]) == pytest.approx(1.0)
    np.testing.assert_allclose(s.weight, 1.0)
    # leaving the glass at normal incidence: weight η²
    s = _sample_raw(glass, jnp.array([0.0, 0.0, -1.0]), jnp.array([0.99]), jnp.zeros((1, 2)))
    np.testing.assert_allclose(s.weight, 2.25, rtol=1e-5)
    np.testing.assert_allclose(s.wi, [[0.0, 0.0, 1.0]], atol=1e-6)


def test_batched_parameters_and_vmap():
    alphas = jnp.array([0.1, 0.3, 0.7])
    wo = jnp.stack([_dir(0.9), _dir(0.5), _dir(0.3)])
    wi = jnp.stack([_dir(0.8, 2.0), _dir(0.6, 3.0), _dir(0.2, 4.0)])
    batched = _eval(RoughConductor(alphas), wo, wi)
    looped = jnp.stack(
        [_eval(RoughConductor(float(a)), o, i) for a, o, i in zip(alphas, wo, wi, strict=True)]
    )
    np.testing.assert_allclose(batched, looped, rtol=1e-5)
    vm = jax.jit(jax.vmap(lambda a, o, i: RoughConductor(a).eval(o, i)))(alphas, wo, wi)
    np.testing.assert_allclose(vm, looped, rtol=1e-5)
    assert batched.shape == (3, 3)


def test_make_bsdf_and_errors():
    for name, cls in BSDF_TYPES.items():
        if name == "blendbsdf":  # a blend of two BSDFs: nothing to default to
            with pytest.raises(ValueError, match="'blendbsdf' needs 'bsdf0', 'bsdf1'"):
                make_bsdf({"type": name})
            continue
        if name == "measured":  # the material is its file (or tables): nothing to default to
            with pytest.raises(ValueError, match="filename: give exactly one"):
                make_bsdf({"type": name})
            continue
        if name in ("normalmap", "bumpmap", "mask"):  # wrappers: the nested BSDF is theirs to name
            with pytest.raises(ValueError, match="bsdf: missing nested BSDF"):
                make_bsdf({"type": name})
            continue
        assert isinstance(make_bsdf({"type": name}), cls)
    b = make_bsdf({"type": "roughconductor", "alpha": 0.2, "distribution": "beckmann"})
    assert b.distribution.type == "beckmann"
    with pytest.raises(ValueError, match="roughness"):
        make_bsdf({"type": "roughconductor", "roughness": 0.2})
    with pytest.raises(ValueError, match="type"):
        make_bsdf({"type": "velvet"})
    with pytest.raises(ValueError, match="reflectance"):
        Diffuse(-0.1)
    with pytest.raises(ValueError, match="reflectance"):
        Diffuse([0.1, 0.2])
    with pytest.raises(ValueError, match="alpha"):
        RoughConductor(0.0)
    with pytest.raises(ValueError, match="eta"):
        SmoothDielectric(-1.5)
    with pytest.raises(ValueError, match="eta"):
        Mirror(fresnel="conductor")
    with pytest.raises(ValueError, match="wo"):
        Diffuse().eval(jnp.zeros((4, 2)), jnp.zeros((4, 3)))
    with pytest.raises(ValueError, match="u2"):
        Diffuse().sample(jnp.array([0.0, 0.0, 1.0]), 0.5, jnp.zeros((3,)))
    with pytest.raises(ValueError, match="fresnel"):
        RoughConductor(0.1, fresnel="exact")
