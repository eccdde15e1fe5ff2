"""Thin principled BSDF (Burley 2015 §5 "thin-surface" model) as Mitsuba 3's
``principledthin``: a two-sided sheet with Burley diffuse reflection, sheen, Lambertian diffuse
transmission (``diff_trans``) and a GGX specular pair — reflection, and a transmission that
leaves unbent (the mirrored reflection direction) through a roughness scaled by the IOR."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from jaxgfx._checks import as_float_array, check_finite, check_nonnegative, is_concrete
from jaxgfx._math import safe_div, safe_normalize, vdot
from jaxgfx.render.bsdf._base import (
    BSDF,
    INV_PI,
    BSDFSample,
    check_rgb,
    mask3,
    prep_dirs,
    sample_setup,
    to_rgb,
)
from jaxgfx.render.bsdf._principled import (
    _check_unit,
    _luminance,
    _schlick,
    _sign,
    optional_weight,
    principled_alphas,
    sampling_rate,
    schlick_weight,
)
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric
from jaxgfx.render.bsdf.microfacet import MicrofacetDistribution
from jaxgfx.render.geometry.frame import reflect
from jaxgfx.render.sampling import square_to_cosine_hemisphere

__all__ = ["PrincipledThin"]

_UNIT = ("spec_tint", "sheen_tint", "flatness", "anisotropic")
_RATES = (
    "diffuse_reflectance_sampling_rate",
    "specular_reflectance_sampling_rate",
    "specular_transmittance_sampling_rate",
    "diffuse_transmittance_sampling_rate",
)


class PrincipledThin(BSDF):
    """Burley's thin-surface principled BSDF as Mitsuba 3's ``principledthin``.

    Parameters (Mitsuba's names and defaults; scalars or batch-shaped ``(...)``, ``base_color``
    RGB): ``base_color`` 0.5, ``roughness`` 0.5, ``eta`` 1.5 (the sheet's relative IOR, > 0),
    ``spec_tint`` 0, ``anisotropic`` 0, ``sheen`` 0, ``sheen_tint`` 0, ``flatness`` 0 (all in
    [0, 1] but ``sheen`` >= 0), ``spec_trans`` in [0, 1] and ``diff_trans`` in [0, 2]: each
    absent or a plain number 0 -> its lobes are not traced (``None``; an array keeps them, as
    Mitsuba's ``get_flag``); static sampling rates ``diffuse_reflectance_sampling_rate``,
    ``specular_reflectance_sampling_rate``, ``specular_transmittance_sampling_rate``,
    ``diffuse_transmittance_sampling_rate`` (all 1).

    The sheet is symmetric: ``wo`` and ``wi`` are mirrored to ``wo.z > 0``; ``wi`` then lies
    above (reflection) or below (transmission). With ``s = spec_trans``, ``t = diff_trans/2``,
    ``wi'`` = ``wi`` mirrored to the upper side, ``h = normalize(wo + wi')``, ``c_o, c_i`` the
    absolute cosines, ``eval = f c_i`` with ``f`` the sum of

    * specular reflection ``s F_thin D G / (4 c_o c_i)``, GGX ``α`` of ``roughness`` (aspect
      ``sqrt(1 - 0.9 anisotropic)``), ``F_thin = lerp(F_diel(wo·h, η), S(c_tint R0(η)),
      spec_tint)``;
    * specular transmission ``s base (1 - F_diel) D' G' / (4 c_o c_i)`` with ``D', G'`` of
      the roughness ``(0.65 η - 0.35) roughness`` (Burley 2015 fig. 15) — the transmitted ray
      is not bent: ``wi`` is the reflection of ``wo`` about ``h`` mirrored through the sheet;
    * diffuse ``(1 - s)(1 - t) base/π lerp(f_d + f_r, f_ss, flatness)`` and sheen
      ``(1 - s)(1 - t) sheen w(c_d) lerp(1, c_tint, sheen_tint)`` as in :class:`Principled`
      (reflection);
    * diffuse transmission ``(1 - s) t base/π`` (Lambertian, below).

    Sampling (Mitsuba 3): probabilities ∝ ``s r_sr/2`` (visible normals of ``D``, reflected),
    ``s r_st/2`` (visible normals of ``D'``, reflected and mirrored), ``(1 - s)(1 - t) r_dr``
    (cosine, above), ``(1 - s) t r_dt`` (cosine, below); ``pdf`` the mixture, ``weight = eval /
    pdf``; ``eta`` of a sample is 1 (no interface is crossed). Mitsuba's side tests of the
    specular transmission use the unmirrored ``wi`` against ``h`` (``-wi·h > 0``); jaxgfx keeps
    them, so both agree.

    Example: ``PrincipledThin(0.8, diff_trans=2.0)`` is a Lambertian transmitter: ``eval(+z,
    -z) = 0.8/π``.
    """

    base_color: jnp.ndarray
    roughness: jnp.ndarray
    eta: jnp.ndarray
    spec_tint: jnp.ndarray
    anisotropic: jnp.ndarray
    sheen: jnp.ndarray
    sheen_tint: jnp.ndarray
    flatness: jnp.ndarray
    spec_trans: jnp.ndarray | None
    diff_trans: jnp.ndarray | None
    diffuse_reflectance_sampling_rate: float = eqx.field(static=True, default=1.0)
    specular_reflectance_sampling_rate: float = eqx.field(static=True, default=1.0)
    specular_transmittance_sampling_rate: float = eqx.field(static=True, default=1.0)
    diffuse_transmittance_sampling_rate: float = eqx.field(static=True, default=1.0)

    def __init__(
        self,
        base_color=0.5,
        roughness=0.5,
        *,
        eta=1.5,
        spec_tint=0.0,
        anisotropic=0.0,
        sheen=0.0,
        sheen_tint=0.0,
        flatness=0.0,
        spec_trans=0.0,
        diff_trans=0.0,
        diffuse_reflectance_sampling_rate=1.0,
        specular_reflectance_sampling_rate=1.0,
        specular_transmittance_sampling_rate=1.0,
        diffuse_transmittance_sampling_rate=1.0,
    ):
        self.base_color = to_rgb(base_color, "base_color")
        self.roughness = as_float_array(roughness, "roughness")
        self.eta = as_float_array(eta, "eta")
        self.spec_tint = as_float_array(spec_tint, "spec_tint")
        self.anisotropic = as_float_array(anisotropic, "anisotropic")
        self.sheen = as_float_array(sheen, "sheen")
        self.sheen_tint = as_float_array(sheen_tint, "sheen_tint")
        self.flatness = as_float_array(flatness, "flatness")
        self.spec_trans = optional_weight(spec_trans, "spec_trans")
        self.diff_trans = optional_weight(diff_trans, "diff_trans")
        vals = (
            diffuse_reflectance_sampling_rate,
            specular_reflectance_sampling_rate,
            specular_transmittance_sampling_rate,
            diffuse_transmittance_sampling_rate,
        )
        for k, v in zip(_RATES, vals, strict=True):
            setattr(self, k, sampling_rate(v, k))

    def __check_init__(self):
        check_rgb(self.base_color, "base_color")
        for name in _UNIT:
            _check_unit(getattr(self, name), name)
        if self.spec_trans is not None:
            _check_unit(self.spec_trans, "spec_trans")
        for name in ("roughness", "sheen"):
            check_nonnegative(getattr(self, name), name)
        check_finite(self.eta, "eta")
        if is_concrete(self.eta) and not bool(jnp.all(self.eta > 0)):
            raise ValueError(f"eta: expected a finite value > 0, got {self.eta!r}")
        if self.diff_trans is not None:
            check_nonnegative(self.diff_trans, "diff_trans")
            if is_concrete(self.diff_trans) and not bool(jnp.all(self.diff_trans <= 2)):
                raise ValueError(f"diff_trans: expected values in [0, 2], got {self.diff_trans!r}")

    @property
    def albedo(self):
        return self.base_color

    @property
    def is_transmissive(self):
        return self.spec_trans is not None or self.diff_trans is not None

    # ------------------------------------------------------------------ pieces
    def _dists(self):
        """GGX of the specular reflection and of the (IOR-scaled) specular transmission."""
        au, av = principled_alphas(self.roughness, self.anisotropic)
        r_t = (0.65 * self.eta - 0.35) * self.roughness
        tu, tv = principled_alphas(r_t, self.anisotropic)
        return MicrofacetDistribution("ggx", au, av), MicrofacetDistribution("ggx", tu, tv)

    def _weights(self):
        s = 0.0 if self.spec_trans is None else self.spec_trans
        t = 0.0 if self.diff_trans is None else 0.5 * self.diff_trans
        return s, t

    def _probs(self):
        """Normalised ``(p_spec_reflect, p_spec_trans, p_diffuse_reflect, p_diffuse_trans)``."""
        s, t = self._weights()
        p_sr = 0.5 * s * self.specular_reflectance_sampling_rate
        p_st = 0.5 * s * self.specular_transmittance_sampling_rate
        p_dr = self.diffuse_reflectance_sampling_rate * (1.0 - s) * (1.0 - t)
        p_dt = self.diffuse_transmittance_sampling_rate * (1.0 - s) * t
        tot = p_sr + p_st + p_dr + p_dt
        return tuple(safe_div(p, tot) for p in (p_sr, p_st, p_dr, p_dt))

    @staticmethod
    def _frame(wo, wi):
        """``wo``, ``wi`` mirrored so that ``wo.z >= 0``; the half vector of ``wo`` and ``wi``
        mirrored to the upper side; the side tests of both specular lobes."""
        s = _sign(wo[..., 2])[..., None]
        wo_f, wi_t = wo * s, wi * s
        ci = wi_t[..., 2]
        wi_r = jnp.concatenate([wi_t[..., :2], jnp.abs(wi_t[..., 2:])], axis=-1)
        h = safe_normalize(wo_f + wi_r)
        dot_oh, dot_ih = vdot(wo_f, h), vdot(wi_t, h)
        live = (wo[..., 2] != 0) & (dot_oh > 0)
        mac_r = live & (ci > 0) & (dot_ih > 0)
        mac_t = live & (ci < 0) & (dot_ih < 0)
        return wo_f, wi_t, wi_r, h, mac_r, mac_t

    # ------------------------------------------------------------------ interface
    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        wo_f, wi_t, _, h, mac_r, mac_t = self._frame(wo, wi)
        co, ci = wo_f[..., 2], wi_t[..., 2]
        aci = jnp.abs(ci)
        base = self.base_color
        s, t = self._weights()
        refl, refr = (ci > 0) & (co > 0), (ci < 0) & (co > 0)
        lum = _luminance(base)
        c_tint = jnp.where((lum > 0)[..., None], base / jnp.where(lum > 0, lum, 1.0)[..., None],
                           1.0)  # fmt: skip
        # diffuse with retro-reflection and fake subsurface, sheen (reflection)
        fo, fi = schlick_weight(aci), schlick_weight(co)
        f_d = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo)
        cos_d = vdot(h, wi_t)
        rr = 2.0 * self.roughness * cos_d * cos_d
        f_r = rr * (fo + fi + fo * fi * (rr - 1.0))
        fss = (1.0 + (0.5 * rr - 1.0) * fo) * (1.0 + (0.5 * rr - 1.0) * fi)
        f_ss = 1.25 * (fss * (safe_div(1.0, co + aci) - 0.5) + 0.5)
        w_d = (1.0 - s) * (1.0 - t)
        diff = w_d * aci * INV_PI * (f_d + f_r + self.flatness * (f_ss - f_d - f_r))
        c_sheen = 1.0 + self.sheen_tint[..., None] * (c_tint - 1.0)
        sh = w_d * self.sheen * schlick_weight(jnp.abs(cos_d)) * aci
        val = mask3(refl, diff[..., None] * base + sh[..., None] * c_sheen)
        if self.diff_trans is not None:
            dt = (1.0 - s) * t * aci * INV_PI
            val = val + mask3(refr, dt[..., None] * base)
        if self.spec_trans is not None:
            d_r, d_t = self._dists()
            cos_oh = vdot(wo_f, h)
            F = fresnel_dielectric(cos_oh, self.eta).r
            r0 = ((self.eta - 1.0) / (self.eta + 1.0)) ** 2
            f_s = _schlick(c_tint * r0[..., None], cos_oh, self.eta)
            F_thin = F[..., None] + self.spec_tint[..., None] * (f_s - F[..., None])
            spec_r = safe_div(s * d_r.eval(h) * d_r.G(wo_f, wi_t, h), 4.0 * co)
            spec_t = safe_div(s * (1.0 - F) * d_t.eval(h) * d_t.G(wo_f, wi_t, h), 4.0 * co)
            val = val + mask3(mac_r, spec_r[..., None] * F_thin)
            val = val + mask3(mac_t, spec_t[..., None] * base)
        return val

    def _pdf(self, wo, wi):
        wo_f, wi_t, wi_r, h, mac_r, mac_t = self._frame(wo, wi)
        ci = wi_t[..., 2]
        p_sr, p_st, p_dr, p_dt = self._probs()
        live = wo[..., 2] != 0
        p = p_dr * jnp.maximum(ci, 0.0) * INV_PI
        if self.diff_trans is not None:
            p = p + p_dt * jnp.maximum(-ci, 0.0) * INV_PI
        if self.spec_trans is not None:
            d_r, d_t = self._dists()
            jac = safe_div(1.0, 4.0 * jnp.abs(vdot(wi_r, h)))
            p = p + jnp.where(mac_r, p_sr * d_r.pdf(wo_f, h) * jac, 0.0)
            p = p + jnp.where(mac_t, p_st * d_t.pdf(wo_f, h) * jac, 0.0)
        return jnp.where(live, p, 0.0)

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        return self._pdf(wo, wi)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        co = wo[..., 2]
        s = _sign(co)[..., None]
        wo_f = jnp.where((co != 0)[..., None], wo * s, jnp.array([0.0, 0.0, 1.0], wo.dtype))
        p_sr, p_st, p_dr, _ = self._probs()
        wi = square_to_cosine_hemisphere(u2)
        ok = co != 0
        pick_dt = u1 >= p_sr + p_st + p_dr
        if self.diff_trans is not None:
            wi = jnp.where(pick_dt[..., None], wi * jnp.array([1.0, 1.0, -1.0]), wi)
        if self.spec_trans is not None:
            d_r, d_t = self._dists()
            pick_sr = u1 < p_sr
            pick_st = ~pick_sr & (u1 < p_sr + p_st)
            m_r, _ = d_r.sample(wo_f, u2)
            m_t, _ = d_t.sample(wo_f, u2)
            m = jnp.where(pick_st[..., None], m_t, m_r)
            wi_m = reflect(wo_f, m)
            wi_m = jnp.where(pick_st[..., None], wi_m * jnp.array([1.0, 1.0, -1.0]), wi_m)
            ok_m = (vdot(wo_f, m) > 0) & jnp.where(pick_st, (wi_m[..., 2] < 0) & (
                vdot(wi_m, m) < 0), (wi_m[..., 2] > 0) & (vdot(wi_m, m) > 0))  # fmt: skip
            spec = pick_sr | pick_st
            wi = jnp.where(spec[..., None], wi_m, wi)
            ok = ok & (~spec | ok_m)
        wi = wi * s
        pdf = self._pdf(wo, wi)
        ok = ok & (pdf > 0)
        weight = self.eval(wo, wi) / jnp.where(ok, pdf, 1.0)[..., None]
        return BSDFSample(
            wi=wi,
            pdf=jnp.where(ok, pdf, 0.0),
            weight=mask3(ok, weight),
            is_delta=jnp.zeros(shape, bool),
            eta=jnp.ones(shape, wo.dtype),
        )
