"""Smooth dielectric interface (glass, water): Fresnel-weighted specular reflection/refraction."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgfx._math import safe_div
from jaxgfx.render.bsdf._base import (
    BSDFSample,
    DeltaBSDF,
    check_rgb,
    check_scalar,
    float_field,
    mask3,
    rgb_field,
    sample_setup,
)
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric

__all__ = ["SmoothDielectric", "DeltaDielectric"]


class DeltaDielectric(DeltaBSDF):
    """What the delta dielectrics share (:class:`SmoothDielectric`, ``ThinDielectric``): the
    interior / exterior IOR ``eta`` (> 0), the specular reflectance and transmittance factors,
    zero ``eval`` / ``pdf`` of :class:`~jaxgfx.render.bsdf._base.DeltaBSDF` and a zero diffuse
    albedo; subclasses define ``sample``."""

    eta: jnp.ndarray = float_field(1.5046, "eta")
    specular_reflectance: jnp.ndarray = rgb_field(1.0, "specular_reflectance", kw_only=True)
    specular_transmittance: jnp.ndarray = rgb_field(1.0, "specular_transmittance", kw_only=True)

    EVAL_DTYPE_OF = "eta"
    is_transmissive = True

    def __check_init__(self):
        check_scalar(self.eta, "eta", positive=True)
        check_rgb(self.specular_reflectance, "specular_reflectance")
        check_rgb(self.specular_transmittance, "specular_transmittance")

    @property
    def albedo(self):
        return jnp.zeros_like(self.specular_reflectance)


class SmoothDielectric(DeltaDielectric):
    """Smooth dielectric boundary (Mitsuba ``dielectric``), both sides usable.

    ``eta`` = interior IOR / exterior IOR (> 0; e.g. 1.5 for glass in air). With the exact
    Fresnel reflectance ``R(cos θ_o)`` the sampler picks reflection with probability ``R``
    (``wi = (-wo_x, -wo_y, wo_z)``) else refraction (``wi = (-η_ti wo_x, -η_ti wo_y, cos θ_t)``,
    Snell's law); total internal reflection always reflects. ``pdf`` is the discrete lobe
    probability, ``weight = specular_reflectance`` for reflection and
    ``specular_transmittance / η_it²`` for refraction: radiance is scaled by ``1/η²`` when it
    enters a denser medium (radiance transport mode, as Mitsuba 3; Veach 1997 §5.2).
    ``eta`` in the sample is 1 (reflection) or ``η_it`` (refraction). ``eval``/``pdf`` are 0.

    Example: ``eta = 1.5``, normal incidence: reflection probability 0.04, refraction weight
    ``1/2.25 ≈ 0.444``.
    """

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        co = wo[..., 2]
        fr = fresnel_dielectric(co, self.eta)
        r = fr.r
        refl = u1 <= r
        wi_r = jnp.stack([-wo[..., 0], -wo[..., 1], co], axis=-1)
        wi_t = jnp.stack(
            [-fr.eta_ti * wo[..., 0], -fr.eta_ti * wo[..., 1], fr.cos_theta_t], axis=-1
        )
        wi = jnp.where(refl[..., None], wi_r, wi_t)
        pdf = jnp.where(refl, r, 1.0 - r)
        w_t = self.specular_transmittance * (fr.eta_ti * fr.eta_ti)[..., None]
        # the lobe is chosen with probability R: the weight's value is ks (kt/η²) but its
        # derivative is that of ks R / stop_gradient(R) (resp. T), the discrete choice's
        # contribution to d/dη (Mitsuba 3 dielectric.cpp does the same in AD variants)
        w_sel = safe_div(pdf, jax.lax.stop_gradient(pdf), fill=1.0)  # p / p = 1 exactly
        weight = jnp.where(refl[..., None], self.specular_reflectance, w_t) * w_sel[..., None]
        valid = (co != 0) & (pdf > 0)
        return BSDFSample(
            wi=wi,
            pdf=jnp.where(valid, pdf, 0.0),
            weight=mask3(valid, weight),
            is_delta=jnp.ones(shape, bool),
            eta=jnp.where(refl, 1.0, fr.eta_it),
        )
