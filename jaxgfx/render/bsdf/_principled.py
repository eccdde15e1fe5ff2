"""Principled BSDF (Burley 2012 / 2015) as Mitsuba 3's ``principled`` plugin evaluates it:
Burley diffuse with retro-reflection and optional fake subsurface, sheen, the GGX main
specular lobe with the metallic / specular-tint Fresnel blend, the GTR1 clearcoat, and (when
``spec_trans`` is given) the rough dielectric transmission lobe of Burley 2015 on both sides."""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_finite, check_nonnegative, is_concrete
from jaxgfx._math import safe_div, safe_normalize, safe_sqrt, sincos, vdot
from jaxgfx.render.bsdf._base import (
    BSDF,
    INV_PI,
    BSDFSample,
    check_rgb,
    glossy_sample,
    mask3,
    prep_dirs,
    sample_setup,
    to_rgb,
)
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric
from jaxgfx.render.bsdf.microfacet import MicrofacetDistribution, reflection_pdf
from jaxgfx.render.geometry.frame import reflect
from jaxgfx.render.sampling import square_to_cosine_hemisphere

__all__ = [
    "Principled",
    "schlick_weight",
    "gtr1_eval",
    "gtr1_sample",
    "principled_alphas",
    "specular_to_eta",
    "optional_weight",
]

# mitsuba::luminance of linear sRGB (Rec. 709 Y with Mitsuba's 6-digit constants)
_LUM = (0.212671, 0.715160, 0.072169)
# weights that Mitsuba documents as "between 0 and 1" and whose formulas need it
_UNIT = ("metallic", "spec_tint", "sheen_tint", "flatness", "anisotropic", "clearcoat_gloss")
_NONNEG = ("roughness", "sheen", "clearcoat")
SPECULAR_MAX = 12.5  # specular -> eta = 2 / (1 - sqrt(0.08 s)) - 1 is finite below 12.5


def schlick_weight(c):
    """``clip(1 - c, 0, 1)^5``: the Schlick Fresnel weight (Mitsuba ``schlick_weight``)."""
    m = jnp.clip(1.0 - c, 0.0, 1.0)
    m2 = m * m
    return m2 * m2 * m


def _schlick(r0, cos_theta, eta):
    """Mitsuba's ``calc_schlick(R0, cos, eta)``: ``R0 + (1 - R0) w`` with ``w`` the Schlick
    weight of ``|cos|`` when the relative IOR seen by the ray exceeds 1, else of the refracted
    cosine (1 under total internal reflection gives ``w = 1``). ``r0`` RGB (..., 3) or scalar;
    ``cos_theta``, ``eta`` (...)."""
    outside = cos_theta >= 0
    eta_it = jnp.where(outside, eta, 1.0 / eta)
    eta_ti = 1.0 / eta_it
    cos_t = safe_sqrt(1.0 - (1.0 - cos_theta * cos_theta) * eta_ti * eta_ti)
    w = jnp.where(eta_it > 1.0, schlick_weight(jnp.abs(cos_theta)), schlick_weight(cos_t))
    if jnp.ndim(r0) > 0 and jnp.shape(r0)[-1] == 3:
        w = w[..., None]
    return r0 + (1.0 - r0) * w


def specular_to_eta(specular):
    """Mitsuba's map of ``specular`` to the relative IOR: ``2 / (1 - sqrt(0.08 s)) - 1``
    (``F0 = ((η - 1)/(η + 1))² = 0.08 s``; ``s = 0.5 -> η = 1.5``). The derivative at ``s = 0``
    is taken as 0 (the square root's is infinite there)."""
    return 2.0 / (1.0 - safe_sqrt(0.08 * specular)) - 1.0


def principled_alphas(roughness, anisotropic):
    """GGX ``(α_u, α_v)`` of the main lobe (Burley 2012 §5.4, Mitsuba ``calc_dist_params``):
    ``aspect = sqrt(1 - 0.9 anisotropic)``, ``α_u = max(1e-3, r²/aspect)``,
    ``α_v = max(1e-3, r² aspect)``."""
    r2 = roughness * roughness
    aspect = safe_sqrt(1.0 - 0.9 * anisotropic)
    return jnp.maximum(1e-3, r2 / aspect), jnp.maximum(1e-3, r2 * aspect)


def _gtr1_alpha(clearcoat_gloss):
    # Mitsuba: lerp(0.1, 0.001, gloss)
    return 0.1 + (0.001 - 0.1) * clearcoat_gloss


def gtr1_eval(m, alpha):
    """GTR1 ("Berry") normal distribution ``D(m) = (α² - 1) / (π ln α² (1 + (α² - 1) cos²θ_m))``
    (Burley 2012 eq. 4), 0 below the horizon; ``∫ D cos θ_m dω_m = 1``."""
    c = m[..., 2]
    a2 = alpha * alpha
    d = (a2 - 1.0) / (math.pi * jnp.log(a2) * (1.0 + (a2 - 1.0) * c * c))
    return jnp.where(d * c > 1e-20, d, 0.0)


def gtr1_sample(u, alpha):
    """Sample ``D(m) cos θ_m`` of GTR1: ``φ = 2π u_0``,
    ``cos²θ = (1 - α^(2(1 - u_1))) / (1 - α²)`` (Burley 2012 eq. 5; Mitsuba's order of u)."""
    a2 = alpha * alpha
    sp, cp = sincos(2.0 * math.pi * u[..., 0])
    c2 = (1.0 - jnp.power(a2, 1.0 - u[..., 1])) / (1.0 - a2)
    st = safe_sqrt(1.0 - c2)
    ct = safe_sqrt(c2)
    return jnp.stack([cp * st, sp * st, ct], axis=-1)


def _smith_ggx1(v, m, alpha):
    """Separable Smith G1 of isotropic GGX (Mitsuba ``smith_ggx1``, the clearcoat's α = 0.25):
    ``2 / (1 + sqrt(1 + α² tan²θ))``, written ``2c / (c + sqrt(c² + α²(1 - c²)))``; 0 where
    ``v·m`` and ``cos θ_v`` disagree in sign."""
    c = jnp.abs(v[..., 2])
    g = safe_div(2.0 * c, c + safe_sqrt(c * c + alpha * alpha * (1.0 - c * c)))
    return jnp.where(vdot(v, m) * v[..., 2] > 0, g, 0.0)


def _luminance(rgb):
    return rgb[..., 0] * _LUM[0] + rgb[..., 1] * _LUM[1] + rgb[..., 2] * _LUM[2]


def sampling_rate(v, name) -> float:
    """A lobe's sampling rate: a plain number >= 0 (static), as a float."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0:
        raise ValueError(f"{name}: expected a number >= 0, got {v!r}")
    return float(v)


def optional_weight(x, name):
    """A lobe weight that Mitsuba switches off when it is absent or a plain number equal to 0
    (its ``get_flag``): ``None`` then (the lobe is not traced at all), else a float array
    (an array, even of zeros, keeps the lobe, e.g. to differentiate at 0)."""
    if x is None or (isinstance(x, (int, float)) and not isinstance(x, bool) and x == 0):
        return None
    return as_float_array(x, name)


def _sign(x):
    """+1 where ``x >= 0``, else -1 (drjit's ``mulsign`` convention)."""
    return jnp.where(x >= 0, 1.0, -1.0).astype(x.dtype)


def _check_unit(x, name):
    if is_concrete(x):
        a = np.asarray(x)
        if not np.all(np.isfinite(a)) or not np.all((a >= 0) & (a <= 1)):
            raise ValueError(f"{name}: expected values in [0, 1], got {x!r}")


class Principled(BSDF):
    """Burley's principled ("Disney") BSDF as Mitsuba 3's ``principled``.

    Parameters (Mitsuba's names and defaults; scalars or batch-shaped ``(...)``, ``base_color``
    RGB): ``base_color`` 0.5, ``roughness`` 0.5, ``metallic`` 0, ``specular`` 0.5 (or ``eta``,
    not both: ``specular = ((η-1)/(η+1))² / 0.08``), ``spec_tint`` 0, ``anisotropic`` 0,
    ``sheen`` 0, ``sheen_tint`` 0, ``flatness`` 0, ``clearcoat`` 0, ``clearcoat_gloss`` 0; static
    sampling rates ``diffuse_reflectance_sampling_rate``, ``main_specular_sampling_rate``,
    ``clearcoat_sampling_rate`` (all 1, Mitsuba's code defaults); ``spec_trans`` (in [0, 1]):
    absent or a plain number 0 -> no transmission lobe (``None``: nothing of it is traced, the
    BSDF is reflection-only and ``is_transmissive`` is False); an array, even of zeros, keeps
    the lobe (Mitsuba's ``get_flag``).

    With ``h = normalize(wo + wi)``, ``c_o, c_i`` the cosines, ``c_d = h·wi``, ``F_o = w(c_i)``,
    ``F_i = w(c_o)`` (``w(c) = (1 - c)^5``), ``eval = f c_i`` with ``f`` the sum of

    * diffuse ``(1 - metallic) base/π · lerp(f_d + f_r, f_ss, flatness)``,
      ``f_d = (1 - F_i/2)(1 - F_o/2)``, ``R_r = 2 roughness c_d²``,
      ``f_r = R_r (F_o + F_i + F_o F_i (R_r - 1))`` (Burley 2015 eqs. 4-5),
      ``f_ss = 1.25 (F_ss (1/(c_o + c_i) - 1/2) + 1/2)``, ``F_ss = lerp(1, R_r/2, F_o) lerp(1,
      R_r/2, F_i)`` (Hanrahan–Krueger-like);
    * sheen ``sheen (1 - metallic) w(c_d) lerp(1, base/lum(base), sheen_tint)`` (no 1/π, as
      Burley's code and Mitsuba);
    * main specular ``F D G / (4 c_o c_i)``, GGX with ``α = max(1e-3, roughness²)`` (aspect
      ``sqrt(1 - 0.9 anisotropic)``), separable Smith G, and
      ``F = (1 - metallic)(1 - spec_tint) F_diel(wo·h, η) + metallic S(base)
      + (1 - metallic) spec_tint S(base/lum(base) R0(η))`` with ``S`` Schlick's approximation
      and ``F_diel`` the exact dielectric Fresnel (0 at ``η = 1``, where Mitsuba drops the lobe);
    * clearcoat ``clearcoat/4 · S_0.04(wo·h) D_GTR1(h) G1_0.25(wo) G1_0.25(wi)`` with
      ``α_cc = lerp(0.1, 0.001, clearcoat_gloss)`` — Mitsuba's form, which lacks the
      ``1/(4 c_o c_i)`` of Burley's ``smithG_GGX`` (so the lobe is weaker than Burley's).

    Sampling (Mitsuba 3): lobe probabilities ∝ ``(1 - metallic) r_d`` (cosine),
    ``clearcoat/4 · r_cc`` (GTR1 ``D cos θ_m``, reflected) and ``r_s`` (GGX visible normals,
    reflected); ``pdf`` is the mixture, ``weight = eval / pdf``. Without ``spec_trans`` only
    the front side (``cos θ_o > 0``) reflects; jaxgfx shades reflection-only BSDFs two-sided.

    Transmission (``spec_trans`` given; Burley 2015 §4, Mitsuba's form): with
    ``b = (1 - metallic) spec_trans`` the diffuse lobe's weight becomes
    ``(1 - metallic)(1 - spec_trans)`` and, with ``η' = η`` seen from outside (``1/η`` from
    inside), the generalised half vector ``h = ±normalize(wo + η' wi)`` (``+z`` side) and
    ``F = F_diel(wo·h, η)``,

    * refraction (both sides): ``sqrt(base) b (1 - F) D G |wo·h||wi·h| / (|c_o| (wo·h +
      η' wi·h)²)`` (Walter et al. 2007 with the radiance scaling ``1/η'²``);
    * back side (``c_o < 0``) reflection: ``b F D G / (4 |c_o|)`` (no tint, metal, diffuse,
      sheen or clearcoat inside);
    * front side: the reflection lobes above unchanged.

    Sampling probabilities: front ``p_d, p_cc`` as above, main specular ``r_s`` split into
    reflection ``r_s (1 - b (1 - F))`` and refraction ``r_s b (1 - F)``; back side reflection
    ``F``, refraction ``1 - F`` (``F`` at the sampled microfacet). With ``spec_trans``, an
    ``eta`` of exactly 1 is read as 1.001 and a ``specular`` of exactly 0 as 1e-3, as Mitsuba
    (an index-matched rough interface has no finite lobe).

    Example: base 1, roughness 0.5, specular 0 at ``wo = wi = +z``: ``f_d = 1``,
    ``R_r = 1``, ``f_r = 0`` -> ``eval = 1/π``.
    """

    base_color: jnp.ndarray
    roughness: jnp.ndarray
    metallic: jnp.ndarray
    specular: jnp.ndarray | None
    eta: jnp.ndarray | None
    spec_tint: jnp.ndarray
    anisotropic: jnp.ndarray
    sheen: jnp.ndarray
    sheen_tint: jnp.ndarray
    flatness: jnp.ndarray
    clearcoat: jnp.ndarray
    clearcoat_gloss: jnp.ndarray
    spec_trans: jnp.ndarray | None
    diffuse_reflectance_sampling_rate: float = eqx.field(static=True, default=1.0)
    main_specular_sampling_rate: float = eqx.field(static=True, default=1.0)
    clearcoat_sampling_rate: float = eqx.field(static=True, default=1.0)

    def __init__(
        self,
        base_color=0.5,
        roughness=0.5,
        *,
        metallic=0.0,
        specular=None,
        eta=None,
        spec_tint=0.0,
        anisotropic=0.0,
        sheen=0.0,
        sheen_tint=0.0,
        flatness=0.0,
        clearcoat=0.0,
        clearcoat_gloss=0.0,
        spec_trans=0.0,
        diffuse_reflectance_sampling_rate=1.0,
        main_specular_sampling_rate=1.0,
        clearcoat_sampling_rate=1.0,
    ):
        if specular is not None and eta is not None:
            raise ValueError("specular: give either 'specular' or 'eta', not both (Mitsuba)")
        self.base_color = to_rgb(base_color, "base_color")
        self.roughness = as_float_array(roughness, "roughness")
        self.metallic = as_float_array(metallic, "metallic")
        self.eta = None if eta is None else as_float_array(eta, "eta")
        self.specular = (
            as_float_array(0.5 if specular is None else specular, "specular") if eta is None
            else None
        )  # fmt: skip
        self.spec_tint = as_float_array(spec_tint, "spec_tint")
        self.anisotropic = as_float_array(anisotropic, "anisotropic")
        self.sheen = as_float_array(sheen, "sheen")
        self.sheen_tint = as_float_array(sheen_tint, "sheen_tint")
        self.flatness = as_float_array(flatness, "flatness")
        self.clearcoat = as_float_array(clearcoat, "clearcoat")
        self.clearcoat_gloss = as_float_array(clearcoat_gloss, "clearcoat_gloss")
        self.spec_trans = optional_weight(spec_trans, "spec_trans")
        rates = {
            "diffuse_reflectance_sampling_rate": diffuse_reflectance_sampling_rate,
            "main_specular_sampling_rate": main_specular_sampling_rate,
            "clearcoat_sampling_rate": clearcoat_sampling_rate,
        }
        rates = {k: sampling_rate(v, k) for k, v in rates.items()}
        if rates["main_specular_sampling_rate"] <= 0:
            raise ValueError("main_specular_sampling_rate: expected > 0 (the specular lobe is "
                             "always present)")  # fmt: skip
        for k, v in rates.items():
            setattr(self, k, v)

    def __check_init__(self):
        check_rgb(self.base_color, "base_color")
        for name in _UNIT:
            _check_unit(getattr(self, name), name)
        if self.spec_trans is not None:
            _check_unit(self.spec_trans, "spec_trans")
        for name in _NONNEG:
            check_nonnegative(getattr(self, name), name)
        if self.eta is not None:
            check_finite(self.eta, "eta")
            if is_concrete(self.eta) and not np.all(np.asarray(self.eta) > 0):
                raise ValueError(f"eta: expected a finite value > 0, got {self.eta!r}")
        if self.specular is not None:
            check_nonnegative(self.specular, "specular")
            if is_concrete(self.specular) and not np.all(np.asarray(self.specular) < SPECULAR_MAX):
                raise ValueError(
                    f"specular: expected a value in [0, {SPECULAR_MAX}) (finite eta), "
                    f"got {self.specular!r}"
                )

    @property
    def albedo(self):
        return self.base_color

    @property
    def is_transmissive(self):
        return self.spec_trans is not None

    # ------------------------------------------------------------------ pieces
    def _eta(self):
        if self.spec_trans is None:
            return self.eta if self.eta is not None else specular_to_eta(self.specular)
        # Mitsuba: an index-matched interface is not plausible for transmission
        if self.eta is not None:
            return jnp.where(self.eta == 1.0, 1.001, self.eta)
        return specular_to_eta(jnp.where(self.specular == 0.0, 1e-3, self.specular))

    def _distribution(self):
        au, av = principled_alphas(self.roughness, self.anisotropic)
        return MicrofacetDistribution("ggx", au, av)

    def _probs(self):
        """Normalised lobe probabilities ``(p_diffuse, p_clearcoat, p_specular)`` (front side)."""
        pd = self._brdf_weight() * self.diffuse_reflectance_sampling_rate
        pc = 0.25 * self.clearcoat * self.clearcoat_sampling_rate
        ps = self.main_specular_sampling_rate
        tot = pd + pc + ps
        return pd / tot, pc / tot, ps / tot

    def _brdf_weight(self):
        """Weight of the diffuse lobe: ``(1 - metallic)(1 - spec_trans)``."""
        if self.spec_trans is None:
            return 1.0 - self.metallic
        return (1.0 - self.metallic) * (1.0 - self.spec_trans)

    def _eval(self, wo, wi, dist, eta):
        co, ci = wo[..., 2], wi[..., 2]
        valid = (co > 0) & (ci > 0)
        h = safe_normalize(wo + wi)
        cos_oh = vdot(wo, h)
        cos_d = vdot(wi, h)
        base = self.base_color
        m = self.metallic
        # main specular lobe with the metallic / tinted-dielectric Fresnel blend
        f_diel = fresnel_dielectric(cos_oh, eta).r
        lum = _luminance(base)
        c_tint = jnp.where((lum > 0)[..., None], base / jnp.where(lum > 0, lum, 1.0)[..., None],
                           1.0)  # fmt: skip
        eta_it = jnp.where(cos_oh >= 0, eta, 1.0 / eta)
        r0 = ((eta_it - 1.0) / (eta_it + 1.0)) ** 2
        st = self.spec_tint
        F = (
            ((1.0 - m) * (1.0 - st) * f_diel)[..., None]
            + m[..., None] * _schlick(base, cos_oh, eta)
            + ((1.0 - m) * st)[..., None] * _schlick(c_tint * r0[..., None], cos_oh, eta)
        )
        spec = safe_div(dist.eval(h) * dist.G(wo, wi, h), 4.0 * co)
        spec = jnp.where(f_diel > 0, spec, 0.0)
        val = spec[..., None] * F
        # clearcoat (Mitsuba's form: no 1/(4 cos_o cos_i))
        a_cc = _gtr1_alpha(self.clearcoat_gloss)
        g_cc = _smith_ggx1(wo, h, 0.25) * _smith_ggx1(wi, h, 0.25)
        f_cc = _schlick(jnp.asarray(0.04, co.dtype), cos_oh, eta)
        cc = 0.25 * self.clearcoat * f_cc * gtr1_eval(h, a_cc) * g_cc * ci
        # diffuse with retro-reflection (and the fake subsurface through flatness)
        fo, fi = schlick_weight(ci), schlick_weight(co)
        f_d = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo)
        rr = 2.0 * self.roughness * cos_d * cos_d
        f_r = rr * (fo + fi + fo * fi * (rr - 1.0))
        fss90 = 0.5 * rr
        fss = (1.0 + (fss90 - 1.0) * fo) * (1.0 + (fss90 - 1.0) * fi)
        f_ss = 1.25 * (fss * (safe_div(1.0, co + ci) - 0.5) + 0.5)
        diff = self._brdf_weight() * ci * INV_PI * (f_d + f_r + self.flatness * (f_ss - f_d - f_r))
        # sheen (no 1/pi)
        c_sheen = 1.0 + self.sheen_tint[..., None] * (c_tint - 1.0)
        sh = self.sheen * (1.0 - m) * schlick_weight(cos_d) * ci
        val = val + cc[..., None] + diff[..., None] * base + sh[..., None] * c_sheen
        return mask3(valid, val)

    def _pdf(self, wo, wi, dist):
        co, ci = wo[..., 2], wi[..., 2]
        valid = (co > 0) & (ci > 0)
        h = safe_normalize(wo + wi)
        pd, pc, ps = self._probs()
        p_spec = reflection_pdf(dist, wo, h)
        p_cc = safe_div(
            gtr1_eval(h, _gtr1_alpha(self.clearcoat_gloss)) * h[..., 2], 4.0 * vdot(wi, h)
        )
        p = ps * p_spec + pd * ci * INV_PI + pc * p_cc
        return jnp.where(valid, p, 0.0)

    # ------------------------------------------------------------------ transmission
    def _half_st(self, wo, wi, eta):
        """Generalised half vector (``+z`` side) of the pair and what the lobes test:
        ``(h, refl, eta_path, dot_oh, dot_ih, mac_r, mac_t)`` with ``mac_*`` Mitsuba's
        macro/micro-surface side checks for reflection and refraction."""
        co, ci = wo[..., 2], wi[..., 2]
        refl = co * ci > 0
        eta_path = jnp.where(co > 0, eta, 1.0 / eta)
        h = safe_normalize(wo + wi * jnp.where(refl, 1.0, eta_path)[..., None])
        h = h * _sign(h[..., 2])[..., None]
        dot_oh, dot_ih = vdot(wo, h), vdot(wi, h)
        s = _sign(co)
        side_o = (co != 0) & (dot_oh * s > 0)
        mac_r = side_o & refl & (dot_ih * s > 0)
        mac_t = side_o & (co * ci < 0) & (dot_ih * s < 0)
        return h, refl, eta_path, dot_oh, dot_ih, mac_r, mac_t

    def _eval_st(self, wo, wi, dist, eta):
        """``eval`` with the transmission lobe (both sides)."""
        co = wo[..., 2]
        val = self._eval(wo, wi, dist, eta)  # front side reflection lobes
        h, _, eta_path, dot_oh, dot_ih, mac_r, mac_t = self._half_st(wo, wi, eta)
        b = (1.0 - self.metallic) * self.spec_trans
        F = fresnel_dielectric(dot_oh, eta).r
        dg = dist.eval(h) * dist.G(wo, wi, h)
        aco = jnp.abs(co)
        back = mac_r & (co < 0) & (F > 0)
        f_r = safe_div(b * F * dg, 4.0 * aco)
        denom = dot_oh + eta_path * dot_ih
        trans = mac_t & (F < 1) & (b > 0)
        f_t = safe_div(b * (1.0 - F) * dg * jnp.abs(dot_oh * dot_ih), aco * denom * denom)
        val = val + mask3(back, f_r[..., None]) + mask3(trans, f_t[..., None] * safe_sqrt(
            self.base_color))  # fmt: skip
        return val

    def _pdf_st(self, wo, wi, dist, eta):
        co, ci = wo[..., 2], wi[..., 2]
        front = co > 0
        h, refl, eta_path, dot_oh, dot_ih, mac_r, mac_t = self._half_st(wo, wi, eta)
        pd, pc, ps = self._probs()
        b = (1.0 - self.metallic) * self.spec_trans
        F = fresnel_dielectric(dot_oh, eta).r
        p_r = jnp.where(front, ps * (1.0 - b * (1.0 - F)), F)
        p_t = jnp.where(front, ps * b * (1.0 - F), 1.0 - F)
        wo_up = wo * _sign(co)[..., None]
        p_m = dist.pdf(wo_up, h)
        denom = dot_oh + eta_path * dot_ih
        jac = jnp.where(refl, safe_div(1.0, 4.0 * jnp.abs(dot_ih)),
                        safe_div(eta_path * eta_path * jnp.abs(dot_ih), denom * denom))  # fmt: skip
        p_cc = gtr1_eval(h, _gtr1_alpha(self.clearcoat_gloss)) * h[..., 2] * jac
        p_front = pd * jnp.maximum(ci, 0.0) * INV_PI + jnp.where(mac_r, pc * p_cc, 0.0)
        p = jnp.where(mac_r, p_r * p_m * jac, 0.0) + jnp.where(mac_t, p_t * p_m * jac, 0.0)
        p = p + jnp.where(front & refl, p_front, 0.0)
        return jnp.where(co != 0, p, 0.0)

    def _sample_st(self, wo, u1, u2, shape):
        co = wo[..., 2]
        front = co > 0
        s = _sign(co)
        dist, eta = self._distribution(), self._eta()
        wo_up = jnp.where((co != 0)[..., None], wo * s[..., None],
                          jnp.array([0.0, 0.0, 1.0], wo.dtype))  # fmt: skip
        m_spec, _ = dist.sample(wo_up, u2)
        fr = fresnel_dielectric(vdot(wo, m_spec), eta)
        m_cc = gtr1_sample(u2, _gtr1_alpha(self.clearcoat_gloss))
        pd, pc, ps = self._probs()
        b = (1.0 - self.metallic) * self.spec_trans
        pd, pc = jnp.where(front, pd, 0.0), jnp.where(front, pc, 0.0)
        p_t = jnp.where(front, ps * b * (1.0 - fr.r), 1.0 - fr.r)
        pick_d = u1 < pd
        pick_c = ~pick_d & (u1 < pd + pc)
        pick_t = ~pick_d & ~pick_c & (u1 < pd + pc + p_t)
        m = jnp.where(pick_c[..., None], m_cc, m_spec)
        wi_r = reflect(wo, m)
        dot_om = vdot(wo, m)
        wi_t = m * (dot_om * fr.eta_ti + fr.cos_theta_t)[..., None] - wo * fr.eta_ti[..., None]
        wi = jnp.where(pick_t[..., None], wi_t, wi_r)
        wi = jnp.where(pick_d[..., None], square_to_cosine_hemisphere(u2), wi)
        ci = wi[..., 2]
        ms = m * s[..., None]
        ok_m = (vdot(wo, ms) > 0) & jnp.where(pick_t, vdot(wi, ms) < 0, vdot(wi, ms) > 0)
        ok = (co != 0) & jnp.where(pick_t, co * ci < 0, co * ci > 0) & (pick_d | ok_m)
        ok = ok & (front | (b > 0))  # inside, only the transmission lobe scatters
        pdf = self._pdf_st(wo, wi, dist, eta)
        ok = ok & (pdf > 0)
        weight = self._eval_st(wo, wi, dist, eta) / jnp.where(ok, pdf, 1.0)[..., None]
        return BSDFSample(
            wi=wi,
            pdf=jnp.where(ok, pdf, 0.0),
            weight=mask3(ok, weight),
            is_delta=jnp.zeros(shape, bool),
            eta=jnp.where(ok & pick_t, fr.eta_it, 1.0),
        )

    # ------------------------------------------------------------------ interface
    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        if self.spec_trans is not None:
            return self._eval_st(wo, wi, self._distribution(), self._eta())
        return self._eval(wo, wi, self._distribution(), self._eta())

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        if self.spec_trans is not None:
            return self._pdf_st(wo, wi, self._distribution(), self._eta())
        return self._pdf(wo, wi, self._distribution())

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        if self.spec_trans is not None:
            return self._sample_st(wo, u1, u2, shape)
        co = wo[..., 2]
        dist = self._distribution()
        wo_up = jnp.where((co > 0)[..., None], wo, jnp.array([0.0, 0.0, 1.0], wo.dtype))
        m_spec, _ = dist.sample(wo_up, u2)
        m_cc = gtr1_sample(u2, _gtr1_alpha(self.clearcoat_gloss))
        pd, pc, _ = self._probs()
        pick_d = u1 < pd
        pick_c = ~pick_d & (u1 < pd + pc)
        m = jnp.where(pick_c[..., None], m_cc, m_spec)
        wi = jnp.where(pick_d[..., None], square_to_cosine_hemisphere(u2), reflect(wo, m))
        pdf = self._pdf(wo, wi, dist)
        valid = (co > 0) & (wi[..., 2] > 0) & (pdf > 0)
        weight = self._eval(wo, wi, dist, self._eta()) / jnp.where(valid, pdf, 1.0)[..., None]
        return glossy_sample(wi, pdf, weight, valid, shape, wo.dtype)
