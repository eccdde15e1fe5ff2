"""Rough plastic: Lambertian base under a rough GGX/Beckmann dielectric coating."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from jaxgfx._checks import as_float_array
from jaxgfx._math import safe_div, safe_normalize, vdot
from jaxgfx.render.bsdf._base import (
    BSDF,
    INV_PI,
    check_rgb,
    check_scalar,
    glossy_sample,
    mask3,
    prep_dirs,
    sample_setup,
    to_rgb,
)
from jaxgfx.render.bsdf._coating import CoatingTerms
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric
from jaxgfx.render.bsdf.microfacet import (
    DISTRIBUTION_ALIASES,
    MicrofacetDistribution,
    reflection_pdf,
)
from jaxgfx.render.geometry.frame import reflect
from jaxgfx.render.sampling import square_to_cosine_hemisphere

__all__ = ["RoughPlastic", "PlasticBase"]


class PlasticBase(BSDF):
    """What the plastics share (:class:`RoughPlastic`, ``SmoothPlastic``): the checks of
    ``diffuse_reflectance``, ``specular_reflectance`` and ``eta``, the diffuse albedo, and the
    specular lobe's selection weight from the mean reflectances (no fields of its own)."""

    def __check_init__(self):
        check_rgb(self.diffuse_reflectance, "diffuse_reflectance")
        check_rgb(self.specular_reflectance, "specular_reflectance")
        check_scalar(self.eta, "eta", positive=True)

    @property
    def albedo(self):
        return self.diffuse_reflectance

    def _spec_weight(self):
        md = jnp.mean(self.diffuse_reflectance, axis=-1)
        ms = jnp.mean(self.specular_reflectance, axis=-1)
        return safe_div(ms, md + ms, fill=0.5)


class RoughPlastic(PlasticBase):
    """Rough plastic after Mitsuba 3's ``roughplastic`` (Weidlich & Wilkie 2007 layering).

    ``eval = F(wo·h) D G / (4 cos θ_o) · ks
    + kd / (1 - [kd] R_int) · T(cos θ_o) T(cos θ_i) cos θ_i / (π η²)``

    * specular term: microfacet dielectric reflection of the coat (``alpha``, ``distribution``
      static ``"ggx"``/``"beckmann"``, ``eta`` = interior/exterior IOR, default 1.49 / 1.000277
      as Mitsuba), times ``specular_reflectance`` ks;
    * diffuse term: the base ``diffuse_reflectance`` kd, entering and leaving through the
      *rough* coat with its directional transmittance ``T(μ)`` (albedo of the interface's
      transmission lobe) and bouncing inside with the rough interface's internal diffuse
      reflectance ``R_int`` (``nonlinear=True``: ``1 / (1 - kd R_int)``), both tabulated as
      Mitsuba 3 does (:mod:`jaxgfx.render.bsdf._coating`), as functions of ``alpha`` and
      ``eta`` (differentiable). As ``alpha → 0``: ``T → 1 - F``,
      ``R_int → 2 mean_i F(μ_i, 1/η) μ_i`` (Mitsuba's 64-point rule, μ_i = i/63; 1.1 % below
      ``F_dr(1/η)`` at η = 1.49).

    Sampling (Mitsuba 3): specular lobe with probability ``∝ (1 - T(cos θ_o)) w_s``, diffuse
    (cosine) with ``∝ T(cos θ_o)(1 - w_s)``, ``w_s = mean(ks) / (mean(kd) + mean(ks))``.
    """

    distribution: MicrofacetDistribution
    diffuse_reflectance: jnp.ndarray
    specular_reflectance: jnp.ndarray
    eta: jnp.ndarray
    nonlinear: bool = eqx.field(static=True, default=False)

    PARAMETER_ALIASES: ClassVar[dict[str, tuple[str, ...]]] = DISTRIBUTION_ALIASES

    def __init__(
        self,
        diffuse_reflectance=0.5,
        alpha=0.1,
        *,
        eta=1.49 / 1.000277,
        specular_reflectance=1.0,
        distribution="ggx",
        nonlinear=False,
        sample_visible=True,
    ):
        self.distribution = MicrofacetDistribution(
            distribution, alpha, sample_visible=sample_visible
        )
        self.diffuse_reflectance = to_rgb(diffuse_reflectance, "diffuse_reflectance")
        self.specular_reflectance = to_rgb(specular_reflectance, "specular_reflectance")
        self.eta = as_float_array(eta, "eta")
        self.nonlinear = bool(nonlinear)

    def _coating(self):
        return CoatingTerms(self.distribution, self.eta)

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        return self._eval(wo, wi, self._coating())

    def _eval(self, wo, wi, coat):
        co, ci = wo[..., 2], wi[..., 2]
        valid = (co > 0) & (ci > 0)
        h = safe_normalize(wo + wi)
        d = self.distribution
        F = fresnel_dielectric(vdot(wo, h), self.eta).r
        spec = safe_div(F * d.eval(h) * d.G(wo, wi, h), 4.0 * co)
        kd = self.diffuse_reflectance
        r_int = coat.r_int[..., None]
        diff = kd / (1.0 - (kd * r_int if self.nonlinear else r_int))
        t = coat.T(co) * coat.T(ci) * ci * INV_PI / (self.eta * self.eta)
        val = spec[..., None] * self.specular_reflectance + diff * t[..., None]
        return mask3(valid, val)

    def _probs(self, co, coat=None):
        ws = self._spec_weight()
        t = (coat or self._coating()).T(co)
        ps = (1.0 - t) * ws
        pd = t * (1.0 - ws)
        return safe_div(ps, ps + pd, fill=0.5)

    def _pdf_spec(self, wo, m):
        return reflection_pdf(self.distribution, wo, m)

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        return self._pdf(wo, wi, self._coating())

    def _pdf(self, wo, wi, coat):
        co, ci = wo[..., 2], wi[..., 2]
        valid = (co > 0) & (ci > 0)
        h = safe_normalize(wo + wi)
        ps = self._probs(co, coat)
        p = ps * self._pdf_spec(wo, h) + (1.0 - ps) * ci * INV_PI
        return jnp.where(valid, p, 0.0)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        co = wo[..., 2]
        wo_up = jnp.where((co > 0)[..., None], wo, jnp.array([0.0, 0.0, 1.0], wo.dtype))
        m, _ = self.distribution.sample(wo_up, u2)
        spec_dir = reflect(wo, m)
        diff_dir = square_to_cosine_hemisphere(u2)
        coat = self._coating()
        wi = jnp.where((u1 < self._probs(co, coat))[..., None], spec_dir, diff_dir)
        pdf = self._pdf(wo, wi, coat)
        valid = (co > 0) & (wi[..., 2] > 0) & (pdf > 0)
        weight = self._eval(wo, wi, coat) / jnp.where(valid, pdf, 1.0)[..., None]
        return glossy_sample(wi, pdf, weight, valid, shape, wo.dtype)
