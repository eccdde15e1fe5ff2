"""Microfacet distributions (GGX / Trowbridge–Reitz and Beckmann), isotropic or anisotropic.

Conventions follow Mitsuba 3 (``mitsuba/render/microfacet.h``): ``alpha`` is the distribution's
roughness α (GGX: ``D(m) = 1 / (π α_u α_v ((m_x/α_u)² + (m_y/α_v)² + m_z²)²)``), not its square;
directions live in the local frame with the macro-normal ``+z``.

References: Walter, Marschner, Li, Torrance, "Microfacet Models for Refraction through Rough
Surfaces", EGSR 2007; Heitz, "Understanding the Masking-Shadowing Function in Microfacet-Based
BRDFs", JCGT 3(2), 2014; Heitz, "Sampling the GGX Distribution of Visible Normals", JCGT 7(4),
2018.
"""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.special import erfc

from jaxgfx._checks import as_float_array, check_choice, check_positive
from jaxgfx._math import fusion_barrier, safe_div, safe_normalize, safe_sqrt, sincos, sum_last

__all__ = ["MicrofacetDistribution", "MICROFACET_TYPES"]

MICROFACET_TYPES = ("ggx", "beckmann")
_INV_SQRT_PI = 1.0 / math.sqrt(math.pi)
ALPHA_MIN = 1e-4  # smallest roughness used (Mitsuba 3 clamps alpha the same way)


# parameter names of a BSDF that holds a ``distribution`` field (rough conductor, rough plastic)
DISTRIBUTION_ALIASES: dict[str, tuple[str, ...]] = {
    "alpha": ("distribution.alpha_u", "distribution.alpha_v"),
    "alpha_u": ("distribution.alpha_u",),
    "alpha_v": ("distribution.alpha_v",),
}


class MicrofacetDistribution(eqx.Module):
    """Microfacet normal distribution ``D``, Smith masking ``G1``/``G``, and a sampler.

    Fields: ``alpha_u``, ``alpha_v`` (roughness along local x / y, > 0; arrays broadcasting
    against the batch shape ``(...)`` of the directions), ``type`` (static, ``"ggx"`` or
    ``"beckmann"``), ``sample_visible`` (static; GGX only: sample the distribution of visible
    normals of Heitz 2018 — Beckmann always samples ``D(m) cos θ_m`` exactly through Gaussian
    slopes, documented deviation from Mitsuba's Beckmann VNDF sampler).

    Construct with ``MicrofacetDistribution("ggx", alpha)`` (isotropic) or
    ``MicrofacetDistribution("ggx", alpha_u, alpha_v)``.

    Example: GGX with α = 1 has ``D(+z) = 1/π``.
    """

    alpha_u: jnp.ndarray
    alpha_v: jnp.ndarray
    type: str = eqx.field(static=True, default="ggx")
    sample_visible: bool = eqx.field(static=True, default=True)

    PARAMETER_ALIASES: ClassVar[dict[str, tuple[str, ...]]] = {"alpha": ("alpha_u", "alpha_v")}

    def __init__(self, type="ggx", alpha=0.1, alpha_v=None, *, sample_visible=True):
        check_choice(type, "type", MICROFACET_TYPES)
        self.type = type
        self.sample_visible = bool(sample_visible)
        self.alpha_u = as_float_array(alpha, "alpha")
        self.alpha_v = self.alpha_u if alpha_v is None else as_float_array(alpha_v, "alpha_v")

    def __check_init__(self):
        check_choice(self.type, "type", MICROFACET_TYPES)
        check_positive(self.alpha_u, "alpha")
        check_positive(self.alpha_v, "alpha_v")

    # The roughness used is max(alpha, ALPHA_MIN), as Mitsuba 3 (microfacet.h ``configure``):
    # below 1e-4 the lobe is a mirror at any image resolution, and the derivative of the image
    # w.r.t. alpha there is 0 (finite differences agree) instead of growing like 1/alpha.
    @property
    def _au(self):
        return jnp.where(self.alpha_u >= ALPHA_MIN, self.alpha_u, ALPHA_MIN)

    @property
    def _av(self):
        return jnp.where(self.alpha_v >= ALPHA_MIN, self.alpha_v, ALPHA_MIN)

    # ------------------------------------------------------------------ D
    def eval(self, m):
        """Normal distribution ``D(m)`` (sr⁻¹), normalised so that ``∫ D(m) cos θ_m dω_m = 1``."""
        au, av = self._au, self._av
        cz = m[..., 2]
        up = cz > 0
        cz_s = jnp.where(up, cz, 1.0)
        if self.type == "ggx":
            t = (m[..., 0] / au) ** 2 + (m[..., 1] / av) ** 2 + cz_s * cz_s
            d = 1.0 / (math.pi * au * av * t * t)
        else:
            # decide where D underflows on gradient-free values, then evaluate on safe inputs
            # only (double-where: no inf partials reach the zero cotangents)
            ng = jax.lax.stop_gradient
            expo_ng = ((ng(m[..., 0]) / ng(au)) ** 2 + (ng(m[..., 1]) / ng(av)) ** 2) / ng(
                cz_s * cz_s
            )
            ok = up & (expo_ng < 80.0)
            mx = jnp.where(ok, m[..., 0], 0.0)
            my = jnp.where(ok, m[..., 1], 0.0)
            cz2 = jnp.where(ok, cz_s * cz_s, 1.0)
            expo = ((mx / au) ** 2 + (my / av) ** 2) / cz2
            d = jnp.where(ok, jnp.exp(-expo) / (math.pi * au * av * cz2 * cz2), 0.0)
        return jnp.where(up, d, 0.0)

    # ------------------------------------------------------------------ masking
    def smith_lambda(self, v):
        """Smith's auxiliary function ``Λ(v)`` (Heitz 2014, eqs. 72 and 86); 0 at the pole."""
        xy = (self._au * v[..., 0]) ** 2 + (self._av * v[..., 1]) ** 2
        cz2 = v[..., 2] * v[..., 2]
        # tan²θ_α = xy / cos²θ  (α-scaled tangent); infinite at grazing -> guard
        if self.type == "ggx":
            # Λ = (sqrt(1 + tan²) - 1)/2 = tan² / (2 (sqrt(1 + tan²) + 1)), written without tan
            # for cz -> 0: Λ = (sqrt(cz² + xy) - |cz|) / (2 |cz|)
            cz = jnp.abs(v[..., 2])
            num = xy / (safe_sqrt(cz2 + xy) + cz + (xy == 0))  # = sqrt(cz²+xy) - cz
            return safe_div(num, 2.0 * cz, fill=jnp.inf)
        # Beckmann: a = 1/(α tan θ) = |cz| / sqrt(xy)
        cz = jnp.abs(v[..., 2])
        pole = xy <= 0
        sq = safe_sqrt(jnp.where(pole, 1.0, xy))
        a = cz / sq
        big = a > 8.0
        a_s = jnp.where(big | (a <= 0), 1.0, a)
        lam = 0.5 * (jnp.exp(-a_s * a_s) * _INV_SQRT_PI / a_s - erfc(a_s))
        lam = jnp.where(big | pole, 0.0, lam)
        return jnp.where((a <= 0) & ~pole, jnp.inf, lam)

    def smith_g1(self, v, m):
        """Smith masking ``G1(v, m) = χ⁺(v·m / v·n) / (1 + Λ(v))`` in ``[0, 1]``."""
        lam = self.smith_lambda(v)
        g = jnp.where(jnp.isinf(lam), 0.0, 1.0 / (1.0 + jnp.where(jnp.isinf(lam), 0.0, lam)))
        ok = sum_last(v * m) * v[..., 2] > 0
        return jnp.where(ok, g, 0.0)

    def G(self, wo, wi, m, *, height_correlated=False):
        """Shadowing–masking ``G(wo, wi, m)``: separable ``G1 G1`` (Mitsuba's default) or the
        height-correlated ``1 / (1 + Λ(wo) + Λ(wi))`` (Heitz 2014 eq. 99)."""
        if not height_correlated:
            return self.smith_g1(wo, m) * self.smith_g1(wi, m)
        lo, li = self.smith_lambda(wo), self.smith_lambda(wi)
        inf = jnp.isinf(lo) | jnp.isinf(li)
        g = 1.0 / (1.0 + jnp.where(inf, 0.0, lo + li))
        ok = (sum_last(wo * m) * wo[..., 2] > 0) & (sum_last(wi * m) * wi[..., 2] > 0)
        return jnp.where(ok & ~inf, g, 0.0)

    # ------------------------------------------------------------------ sampling
    def sample(self, wi, u):
        """Sample a microfacet normal ``m`` for the direction ``wi`` (local, ``wi_z > 0``).

        ``u`` (..., 2) uniform numbers. Returns ``(m (..., 3), pdf (...))`` with ``pdf`` the
        solid-angle density of ``m``: GGX visible normals ``G1(wi) max(0, wi·m) D(m) / wi_z``
        (Heitz 2018), otherwise ``D(m) cos θ_m``.
        """
        if self.type == "ggx" and self.sample_visible:
            m = self._sample_ggx_vndf(wi, u)
        elif self.type == "ggx":
            m = self._sample_ggx_full(u)
        else:
            m = self._sample_beckmann_full(u)
        # materialise m: its consumers (reflection, pdf, G1, Fresnel) are separate kernels that
        # each recomputed the whole sampling routine (measured: GGX sampling in 5 kernels)
        m = fusion_barrier(m)
        return m, self.pdf(wi, m)

    def pdf(self, wi, m):
        """Solid-angle density of :meth:`sample` (for ``wi`` with ``wi_z > 0``)."""
        d = self.eval(m)
        if self.type == "ggx" and self.sample_visible:
            cz = wi[..., 2]
            dot = jnp.maximum(sum_last(wi * m), 0.0)
            return safe_div(self.smith_g1(wi, m) * dot * d, cz)
        return d * jnp.maximum(m[..., 2], 0.0)

    def _sample_ggx_vndf(self, wi, u):
        # Heitz 2018, written per component: XLA fuses it into one loop (the vector form with
        # stack/cross was split into several kernels that each recomputed the shared terms).
        au, av = self._au, self._av
        hx, hy, hz = au * wi[..., 0], av * wi[..., 1], wi[..., 2]
        n = safe_sqrt(hx * hx + hy * hy + hz * hz)
        inv_n = safe_div(1.0, n)
        hx, hy, hz = hx * inv_n, hy * inv_n, hz * inv_n
        lensq = hx * hx + hy * hy
        has = lensq > 0
        inv = jnp.where(has, 1.0 / safe_sqrt(jnp.where(has, lensq, 1.0)), 0.0)
        t1x = jnp.where(has, -hy * inv, 1.0)
        t1y = jnp.where(has, hx * inv, 0.0)
        r = safe_sqrt(u[..., 0])
        phi = 2.0 * math.pi * u[..., 1]
        sp, cp = sincos(phi)
        p1 = r * cp
        p2 = r * sp
        s = 0.5 * (1.0 + hz)
        p2 = (1.0 - s) * safe_sqrt(1.0 - p1 * p1) + s * p2
        p3 = safe_sqrt(1.0 - p1 * p1 - p2 * p2)
        # materialised: XLA split what follows into kernels that each recomputed the above
        hx, hy, hz, t1x, t1y, p1, p2, p3 = fusion_barrier((hx, hy, hz, t1x, t1y, p1, p2, p3))
        # t2 = vh x t1 with t1z = 0
        t2x, t2y, t2z = -hz * t1y, hz * t1x, hx * t1y - hy * t1x
        nx = p1 * t1x + p2 * t2x + p3 * hx
        ny = p1 * t1y + p2 * t2y + p3 * hy
        nz = p2 * t2z + p3 * hz
        ex, ey, ez = au * nx, av * ny, jnp.maximum(nz, 0.0)
        ln = safe_sqrt(ex * ex + ey * ey + ez * ez)
        il = safe_div(1.0, ln)
        return jnp.stack([ex * il, ey * il, ez * il], axis=-1)

    def _sample_ggx_full(self, u):
        # slopes of GGX: radial tan²θ = α² u/(1-u) along the anisotropic ellipse
        phi = 2.0 * math.pi * u[..., 1]
        t = safe_sqrt(u[..., 0] / jnp.maximum(1.0 - u[..., 0], 1e-12))
        sp, cp = sincos(phi)
        sx = self._au * t * cp
        sy = self._av * t * sp
        return safe_normalize(jnp.stack([-sx, -sy, jnp.ones_like(sx)], axis=-1))

    def _sample_beckmann_full(self, u):
        # Beckmann slopes are Gaussian with variance α²/2 per axis (Box–Muller)
        phi = 2.0 * math.pi * u[..., 1]
        t = safe_sqrt(-jnp.log(jnp.maximum(1.0 - u[..., 0], 1e-30)))
        sp, cp = sincos(phi)
        sx = self._au * t * cp
        sy = self._av * t * sp
        return safe_normalize(jnp.stack([-sx, -sy, jnp.ones_like(sx)], axis=-1))


def reflection_pdf(distribution: MicrofacetDistribution, wo, m):
    """Solid-angle density of ``wi = reflect(wo, m)`` when ``m`` is drawn by
    ``distribution.sample(wo, u)``: ``pdf_m / (4 |wo . m|)`` (Walter et al. 2007, eq. 14),
    written for the visible-normal (``G1 D / (4 cos_o)``) and full (``D cos_m / (4 wo.m)``) cases.
    """
    dm = distribution.eval(m)
    if distribution.type == "ggx" and distribution.sample_visible:
        return safe_div(distribution.smith_g1(wo, m) * dm, 4.0 * wo[..., 2])
    return safe_div(dm * m[..., 2], 4.0 * sum_last(wo * m))
