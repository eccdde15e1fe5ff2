"""Smooth plastic: a Lambertian base under a smooth dielectric coating (Mitsuba ``plastic``)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from jaxgfx._checks import as_float_array
from jaxgfx._math import safe_div
from jaxgfx.render.bsdf._base import (
    INV_PI,
    BSDFSample,
    mask3,
    prep_dirs,
    sample_setup,
    to_rgb,
)
from jaxgfx.render.bsdf._roughplastic import PlasticBase
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric, fresnel_diffuse_reflectance
from jaxgfx.render.geometry.frame import reflect
from jaxgfx.render.sampling import square_to_cosine_hemisphere

__all__ = ["SmoothPlastic"]


class SmoothPlastic(PlasticBase):
    """Smooth plastic after Mitsuba 3's ``plastic`` (Weidlich & Wilkie 2007 layering).

    A delta specular reflection ``F(cos θ_o) ks`` in the mirror direction plus the base seen
    through the smooth coat:
    ``eval = kd / (1 - [kd] F_dr(1/η)) · (1 - F(cos θ_o)) (1 - F(cos θ_i)) cos θ_i / (π η²)``
    (``eval`` and ``pdf`` hold the diffuse part only). ``diffuse_reflectance`` kd (0.5),
    ``specular_reflectance`` ks (1), ``eta`` interior / exterior IOR (1.49 / 1.000277, as
    Mitsuba), ``nonlinear`` (static): ``1 / (1 - kd F_dr)`` accounts for the colour shift of
    internal scattering. ``F_dr`` is the exact hemispherical average
    (:func:`~jaxgfx.render.bsdf.fresnel.fresnel_diffuse_reflectance`; Mitsuba 3 uses a fit).
    With a white base the albedo is exactly ``F + (1 - F) = 1`` (the F_dr identity).

    Sampling (Mitsuba 3): the specular lobe with probability ``∝ F(cos θ_o) w_s``, else the
    cosine-weighted base with ``∝ (1 - F(cos θ_o))(1 - w_s)``,
    ``w_s = mean(ks) / (mean(kd) + mean(ks))``. One-sided (0 below the surface).

    Example: kd = 0, normal incidence, η = 1.5: a mirror sample of weight 0.04 / p_s.
    """

    diffuse_reflectance: jnp.ndarray
    specular_reflectance: jnp.ndarray
    eta: jnp.ndarray
    nonlinear: bool = eqx.field(static=True, default=False)

    has_delta = True

    def __init__(
        self,
        diffuse_reflectance=0.5,
        *,
        eta=1.49 / 1.000277,
        specular_reflectance=1.0,
        nonlinear=False,
    ):
        self.diffuse_reflectance = to_rgb(diffuse_reflectance, "diffuse_reflectance")
        self.specular_reflectance = to_rgb(specular_reflectance, "specular_reflectance")
        self.eta = as_float_array(eta, "eta")
        self.nonlinear = bool(nonlinear)

    def _prob_spec(self, f_o):
        ws = self._spec_weight()
        ps, pd = f_o * ws, (1.0 - f_o) * (1.0 - ws)
        return safe_div(ps, ps + pd, fill=0.5)

    def _diffuse(self, f_o, f_i, ci):
        kd = self.diffuse_reflectance
        fdr = fresnel_diffuse_reflectance(1.0 / self.eta)[..., None]
        base = kd / (1.0 - (kd * fdr if self.nonlinear else fdr))
        t = (1.0 - f_o) * (1.0 - f_i) * ci * INV_PI / (self.eta * self.eta)
        return base * t[..., None]

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        co, ci = wo[..., 2], wi[..., 2]
        valid = (co > 0) & (ci > 0)
        f_o = fresnel_dielectric(co, self.eta).r
        f_i = fresnel_dielectric(ci, self.eta).r
        return mask3(valid, self._diffuse(f_o, f_i, ci))

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        co, ci = wo[..., 2], wi[..., 2]
        valid = (co > 0) & (ci > 0)
        ps = self._prob_spec(fresnel_dielectric(co, self.eta).r)
        return jnp.where(valid, (1.0 - ps) * ci * INV_PI, 0.0)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        co = wo[..., 2]
        f_o = fresnel_dielectric(co, self.eta).r
        ps = self._prob_spec(f_o)
        spec = u1 < ps
        wi_d = square_to_cosine_hemisphere(u2)
        wi = jnp.where(spec[..., None], reflect(wo), wi_d)
        ci = wi[..., 2]
        f_i = fresnel_dielectric(ci, self.eta).r
        pdf_d = (1.0 - ps) * ci * INV_PI
        w_d = self._diffuse(f_o, f_i, ci) / jnp.where(pdf_d > 0, pdf_d, 1.0)[..., None]
        # specular weight F ks / p_s; times p_s / stop_gradient(p_s) (value 1): the lobe choice's
        # share of the derivative, so that E[d weight] = d(F ks) (as SmoothDielectric)
        w_s = safe_div(f_o, ps)[..., None] * self.specular_reflectance
        w_s = w_s * safe_div(ps, jax.lax.stop_gradient(ps), fill=1.0)[..., None]
        pdf = jnp.where(spec, ps, pdf_d)
        valid = (co > 0) & (ci > 0) & (pdf > 0)
        return BSDFSample(
            wi=wi,
            pdf=jnp.where(valid, pdf, 0.0),
            weight=mask3(valid, jnp.where(spec[..., None], w_s, w_d)),
            is_delta=spec & valid,
            eta=jnp.ones(shape, wo.dtype),
        )
