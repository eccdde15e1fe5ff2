"""Fresnel reflectance: Schlick's approximation, exact dielectric and exact conductor.

Conventions follow Mitsuba 3 (``mitsuba/render/fresnel.h``): ``eta`` is the relative index of
refraction ``η_interior / η_exterior``; a negative ``cos_theta_i`` means the ray arrives from the
interior side, in which case the interface is evaluated with ``1/eta``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from jaxgfx._math import safe_div, safe_sqrt

__all__ = [
    "fresnel_schlick",
    "fresnel_dielectric",
    "fresnel_dielectric_polarized",
    "fresnel_conductor",
    "fresnel_diffuse_reflectance",
    "FresnelDielectric",
]


def fresnel_schlick(f0, cos_theta):
    """Schlick (1994): ``F = F0 + (1 - F0) (1 - cos θ)^5``.

    ``f0``: reflectance at normal incidence (scalar or RGB ``(..., 3)``); ``cos_theta`` (...)
    is clamped to ``[0, 1]``. Returns the broadcast of ``f0`` against ``cos_theta`` (RGB ``f0``
    broadcasts against ``cos_theta[..., None]`` when the caller adds the axis).

    Example: ``fresnel_schlick(0.04, 1.0) = 0.04``; ``fresnel_schlick(0.04, 0.0) = 1``.
    """
    c = jnp.clip(cos_theta, 0.0, 1.0)
    m = 1.0 - c
    m2 = m * m
    return f0 + (1.0 - f0) * (m2 * m2 * m)


class FresnelDielectric(NamedTuple):
    """Result of :func:`fresnel_dielectric`."""

    r: jnp.ndarray  # unpolarised reflectance in [0, 1]
    cos_theta_t: jnp.ndarray  # cosine of the refracted direction (sign opposite to cos_theta_i)
    eta_it: jnp.ndarray  # relative IOR seen by the ray (eta or 1/eta)
    eta_ti: jnp.ndarray  # its reciprocal


def _dielectric_terms(cos_theta_i, eta):
    cos_theta_i = jnp.asarray(cos_theta_i)
    eta = jnp.asarray(eta, dtype=jnp.result_type(cos_theta_i, 1.0))
    outside = cos_theta_i >= 0
    eta_it = jnp.where(outside, eta, 1.0 / eta)
    eta_ti = 1.0 / eta_it
    cos_i = jnp.abs(cos_theta_i)
    cos_t_sqr = 1.0 - eta_ti * eta_ti * (1.0 - cos_i * cos_i)
    cos_t = safe_sqrt(cos_t_sqr)
    a_s = safe_div(cos_i - eta_it * cos_t, cos_i + eta_it * cos_t, fill=1.0)
    a_p = safe_div(cos_t - eta_it * cos_i, cos_t + eta_it * cos_i, fill=-1.0)
    return outside, eta_it, eta_ti, cos_i, cos_t, a_s, a_p


def fresnel_dielectric(cos_theta_i, eta) -> FresnelDielectric:
    """Exact unpolarised Fresnel reflectance of a smooth dielectric interface.

    ``cos_theta_i`` (...) in ``[-1, 1]`` (negative: arriving from inside), ``eta > 0`` the
    relative IOR (interior / exterior). Total internal reflection gives ``r = 1`` and
    ``cos_theta_t = 0``. ``eta == 1`` gives ``r = 0``. Returns :class:`FresnelDielectric`
    with ``cos_theta_t`` signed opposite to ``cos_theta_i`` (Mitsuba convention).

    Reference: Born & Wolf, *Principles of Optics* §1.5; pbrt-v4 eq. (9.6).
    Example: ``fresnel_dielectric(1.0, 1.5).r = 0.04``.
    """
    outside, eta_it, eta_ti, cos_i, cos_t, a_s, a_p = _dielectric_terms(cos_theta_i, eta)
    r = 0.5 * (a_s * a_s + a_p * a_p)
    r = jnp.where(eta_it == 1.0, 0.0, r)
    cos_theta_t = jnp.where(outside, -cos_t, cos_t)
    return FresnelDielectric(r=r, cos_theta_t=cos_theta_t, eta_it=eta_it, eta_ti=eta_ti)


def fresnel_dielectric_polarized(cos_theta_i, eta):
    """``(R_s, R_p)``: s- and p-polarised reflectances of a dielectric interface (see above).

    ``R_p`` vanishes at Brewster's angle ``tan θ_B = eta``.
    """
    _, eta_it, _, _, _, a_s, a_p = _dielectric_terms(cos_theta_i, eta)
    matched = eta_it == 1.0
    return jnp.where(matched, 0.0, a_s * a_s), jnp.where(matched, 0.0, a_p * a_p)


def fresnel_conductor(cos_theta_i, eta, k):
    """Exact unpolarised Fresnel reflectance of a conductor with complex IOR ``eta + i k``.

    ``cos_theta_i`` (...) in ``[0, 1]``; ``eta``, ``k`` >= 0 broadcast against it (use
    ``cos_theta_i[..., None]`` with RGB ``(3,)`` constants). Formula of Mitsuba 3's
    ``fresnel_conductor`` (after Hecht / pbrt-v3 ``FrConductor``); ``k = 0`` reduces to the
    dielectric case.

    Example: ``fresnel_conductor(1.0, 1.5, 0.0) = 0.04``;
    normal incidence ``((η-1)² + k²)/((η+1)² + k²)``.
    """
    c = jnp.clip(jnp.asarray(cos_theta_i), 0.0, 1.0)
    c2 = c * c
    s2 = 1.0 - c2
    s4 = s2 * s2
    temp1 = eta * eta - k * k - s2
    a2pb2 = safe_sqrt(temp1 * temp1 + 4.0 * k * k * eta * eta)
    a = safe_sqrt(0.5 * (a2pb2 + temp1))
    term1 = a2pb2 + c2
    term2 = 2.0 * c * a
    r_s = safe_div(term1 - term2, term1 + term2, fill=1.0)
    term3 = a2pb2 * c2 + s4
    term4 = term2 * s2
    r_p = r_s * safe_div(term3 - term4, term3 + term4, fill=1.0)
    return 0.5 * (r_s + r_p)


_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)


def fresnel_diffuse_reflectance(eta):
    """Hemispherical (cosine-weighted) average of the dielectric Fresnel reflectance.

    ``F_dr(eta) = 2 ∫₀¹ F(μ, eta) μ dμ``: fraction of uniformly diffuse (Lambertian) light
    reflected by a smooth interface of relative IOR ``eta`` (light arriving from the ``eta = 1``
    side). For ``eta < 1`` the total-internal-reflection part ``μ < μ_c = sqrt(1 - eta²)`` is
    integrated analytically (``μ_c²``) and the rest in the variable ``t = cos θ_t``
    (``μ dμ = eta² t dt``, which removes the square-root kink at the critical angle); for
    ``eta >= 1`` directly in ``μ``. 64-point Gauss–Legendre, differentiable in ``eta``.
    Used for the internal-scattering term of rough plastic (d'Eon & Irving 2011 give a fit).

    Example: ``fresnel_diffuse_reflectance(1.5) ≈ 0.0918``; ``(1/1.5) ≈ 0.5963``.
    """
    eta = jnp.asarray(eta)
    if not jnp.issubdtype(eta.dtype, jnp.floating):
        eta = eta.astype(jnp.float32)
    x = 0.5 * (jnp.asarray(_GL_X, eta.dtype) + 1.0)  # nodes on [0, 1]
    w = 0.5 * jnp.asarray(_GL_W, eta.dtype)
    e = eta[..., None]
    # eta >= 1: 2 ∫ F(μ) μ dμ over [0, 1]
    above = 2.0 * jnp.sum(w * fresnel_dielectric(x, e).r * x, axis=-1)
    # eta < 1: μ_c² + 2 eta² ∫ F(μ(t)) t dt, μ(t) = sqrt(μ_c² + eta² t²)
    mu_c2 = jnp.maximum(1.0 - eta * eta, 0.0)
    mu_t = jnp.sqrt(mu_c2[..., None] + e * e * x * x)
    below = mu_c2 + 2.0 * eta * eta * jnp.sum(w * fresnel_dielectric(mu_t, e).r * x, axis=-1)
    return jnp.where(eta >= 1.0, above, below)
