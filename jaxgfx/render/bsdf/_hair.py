"""Hair fibre scattering: Chiang, Bitterli, Tappan & Burley 2016 (Mitsuba 3 ``hair``).

Frame (Mitsuba 3's, which is pbrt-v3's with the fibre axis on ``y``): in the BSDF's local
coordinates the fibre tangent is ``+y`` and the normal ``+z``; a direction ``w`` has the
longitudinal angle ``θ`` with ``sin θ = w_y`` (measured from the fibre's normal plane) and the
azimuth ``φ = atan2(w_z, w_x)`` in that plane. The offset across the fibre is not a separate
input: it comes from the viewing direction ``wo`` (Mitsuba's ``si.wi``), ``γ_o = atan2(-wo_x,
wo_z)`` and ``h = sin γ_o = -wo_x / sqrt(wo_x² + wo_z²)``, exact for a cylinder (a ray that hits
a circular cross-section at offset ``h`` sees the normal at angle ``γ_o`` in that plane). In a
scene the frame's ``x`` is ``dp/du`` projected on the shading plane and ``y = n x x``
(:meth:`Hair.at`), so on Mitsuba's ``cylinder`` (u around, v along the axis) ``y`` is the axis.

``eval(wo, wi) = Σ_{p<3} M_p(θ_o^p, θ_i) 2π A_p N_p(Δφ) + M_3(θ_o, θ_i) A_3`` over the whole
sphere (no hemisphere test; the value already is Mitsuba's "f |cos|"):

* ``M_p``: d'Eon et al. 2011's energy-conserving longitudinal lobe with variance ``v_p``
  (``v_0 = (0.726 β_m + 0.812 β_m² + 3.7 β_m^20)²``, ``v_1 = v_0 / 4``, ``v_2 = v_3 = 4 v_0``,
  Chiang eq. 7) as a solid-angle density around the specular cone, evaluated with the exact
  scaled Bessel function ``i0e`` (Mitsuba / pbrt use a 10-term series and an asymptotic
  ``log I0``: relative differences up to ~1e-3 at small roughness);
* the cuticle tilt ``α`` (degrees) turns ``θ_o`` by ``-2α``, ``+α``, ``+4α`` for ``p = 0, 1, 2``;
* ``A_p``: Fresnel ``f`` at ``cos θ_o cos γ_o`` and the transmittance ``T = exp(-σ_a 2 cos γ_t /
  cos θ_t)``: ``A_0 = f``, ``A_1 = (1-f)² T``, ``A_2 = A_1 T f``, ``A_3 = A_2 T f / (1 - T f)``;
* ``N_p``: the logistic of scale ``s = sqrt(π/8) (0.265 β_n + 1.194 β_n² + 5.372 β_n^22)``
  trimmed to ``[-π, π]`` around ``Φ_p = 2p γ_t - 2γ_o + pπ`` (Chiang eq. 8-10).

Sampling (Chiang §4 / pbrt-v3): ``p`` by the luminance of ``A_p``, then ``M_p`` (d'Eon's exact
inversion), then ``N_p`` (the trimmed logistic's inverse CDF; uniform for ``p = 3``); ``pdf`` is
the sum over ``p`` with ``A_p`` replaced by those probabilities, ``weight = eval / pdf``.
"""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.special import i0e

from jaxgfx._checks import as_float_array, check_finite, check_nonnegative, is_concrete
from jaxgfx._math import safe_atan2, safe_div, safe_sqrt
from jaxgfx.render.bsdf._base import (
    BSDF,
    BSDFSample,
    check_rgb,
    mask3,
    prep_dirs,
    sample_setup,
    to_rgb,
)
from jaxgfx.render.bsdf._normalmap import PerturbedBSDF
from jaxgfx.render.bsdf._principled import _LUM
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric

__all__ = ["Hair", "EUMELANIN_SIGMA_A", "PHEOMELANIN_SIGMA_A", "HAIR_ETA"]

EUMELANIN_SIGMA_A = (0.419, 0.697, 1.37)
"""Absorption per unit eumelanin concentration (RGB, per fibre radius; d'Eon et al. 2011,
as Chiang et al. 2016 and Mitsuba 3 use them)."""
PHEOMELANIN_SIGMA_A = (0.187, 0.4, 1.05)
"""Absorption per unit pheomelanin concentration (same source)."""
HAIR_ETA = 1.55 / 1.000277
"""Mitsuba 3's default ``int_ior / ext_ior`` for ``hair`` (amber / air)."""

P_MAX = 3
_TWO_PI = 2.0 * math.pi


def _sin_theta(w):
    s = jnp.clip(w[..., 1], -1.0, 1.0)
    return s, safe_sqrt(1.0 - s * s)


def _gamma(w):
    """``γ`` of a direction in the normal plane (0 along the fibre axis, as Mitsuba)."""
    return safe_atan2(-w[..., 0], w[..., 2])


def _log_longitudinal(sin_a, cos_a, sin_b, cos_b, v):
    """``log M_p``: d'Eon et al.'s lobe as a solid-angle density (1/(2π) of the θ density per
    cos θ), ``κ/(2π) · exp(-κ sin_a sin_b) I0(κ cos_a cos_b) / (2 sinh κ)``, ``κ = 1/v``, in log
    form (``log I0`` from ``i0e``) so that small ``v`` neither overflows nor underflows."""
    k = 1.0 / v
    c = k * cos_a * cos_b
    s = k * sin_a * sin_b
    return jnp.log(k / _TWO_PI) + _log_i0(c) - s - k - jnp.log(-jnp.expm1(-2.0 * k))


def _longitudinal(sin_a, cos_a, sin_b, cos_b, v):
    """``M_p`` (:func:`_log_longitudinal`)."""
    return jnp.exp(_log_longitudinal(sin_a, cos_a, sin_b, cos_b, v))


def _log_i0(x):
    """``log I0(x)`` for ``x >= 0``, exact (``x + log i0e(x)``)."""
    return x + jnp.log(i0e(x))


def _log_trimmed_logistic(x, s):
    """``log`` of the logistic of scale ``s`` restricted to ``[-π, π]``:
    ``e^(-|x|/s) / (s (1 + e^(-|x|/s))²)`` over its mass there, ``tanh(π / 2s)``
    (= ``cdf(π) - cdf(-π)``, finite with its derivative for small ``s``)."""
    t = jnp.abs(x) / s
    return -t - jnp.log(s) - 2.0 * jnp.log1p(jnp.exp(-t)) - jnp.log(jnp.tanh(0.5 * jnp.pi / s))


def _trimmed_logistic_sample(u, s):
    """Inverse CDF of :func:`_trimmed_logistic`: ``x = s logit(q)``, ``q = cdf(-π) + u (cdf(π)
    - cdf(-π))``, ``cdf = sigmoid(· / s)``. With ``a = π / s``, ``q = sigmoid(-a) (1 + u (e^a -
    1))``, evaluated in log space (``logaddexp``) on the half ``u <= 1/2`` and mirrored, so that
    ``u = 0`` and ``1`` give ``∓π`` even where ``e^a`` overflows (``β_n`` = 0.01: a ≈ 1900)."""
    a = jnp.pi / s
    v = jnp.minimum(u, 1.0 - u)
    tiny = jnp.finfo(jnp.result_type(v, a)).tiny
    log_q = -jax.nn.softplus(a) + jnp.logaddexp(jnp.log1p(-v), jnp.log(jnp.maximum(v, tiny)) + a)
    log_q = jnp.minimum(log_q, math.log(0.5))
    x = s * (log_q - jnp.log1p(-jnp.exp(log_q)))
    return jnp.clip(jnp.where(u > 0.5, -x, x), -jnp.pi, jnp.pi)


def _wrap(phi):
    """``phi`` mapped to ``[-π, π]``."""
    return phi - _TWO_PI * jnp.round(phi / _TWO_PI)


class _Geometry(eqx.Module):
    """Per-``wo`` quantities shared by ``eval``, ``pdf`` and ``sample``."""

    sin_o: jnp.ndarray
    cos_o: jnp.ndarray
    phi_o: jnp.ndarray
    gamma_o: jnp.ndarray
    gamma_t: jnp.ndarray
    a_p: list  # P_MAX + 1 arrays (..., 3)
    a_pdf: list  # P_MAX + 1 arrays (...)


class Hair(BSDF):
    """Chiang et al. 2016 hair / fur fibre BSDF (Mitsuba 3 ``hair``; module docstring for the
    frame, the ``h`` convention and the formulae).

    ``eumelanin``, ``pheomelanin`` (>= 0; defaults 1.3 and 0.2, brown) give
    ``σ_a = eumelanin (0.419, 0.697, 1.37) + pheomelanin (0.187, 0.4, 1.05)``; or ``sigma_a``
    (RGB >= 0, per fibre radius) times ``scale`` directly (not both, as Mitsuba).
    ``longitudinal_roughness`` β_m and ``azimuthal_roughness`` β_n in ``(0, 1]`` (0.3);
    ``scale_tilt`` α in degrees (2); ``eta`` > 1 the fibre's relative IOR (amber / air).

    Example: ``Hair(sigma_a=0.0)`` conserves energy: ``∫ eval(wo, wi) dω_i = 1`` for every
    ``wo`` (tests/render/test_bsdf_hair.py, the furnace).
    """

    longitudinal_roughness: jnp.ndarray
    azimuthal_roughness: jnp.ndarray
    scale_tilt: jnp.ndarray
    eta: jnp.ndarray
    eumelanin: jnp.ndarray | None
    pheomelanin: jnp.ndarray | None
    sigma_a: jnp.ndarray | None
    scale: jnp.ndarray | None

    is_transmissive: ClassVar[bool] = True
    needs_tangents: ClassVar[bool] = True

    def __init__(
        self,
        *,
        eumelanin=None,
        pheomelanin=None,
        sigma_a=None,
        scale=1.0,
        longitudinal_roughness=0.3,
        azimuthal_roughness=0.3,
        scale_tilt=2.0,
        eta=HAIR_ETA,
    ):
        if sigma_a is not None and (eumelanin is not None or pheomelanin is not None):
            raise ValueError(
                "sigma_a: give either sigma_a or eumelanin / pheomelanin, not both (as Mitsuba)"
            )
        self.longitudinal_roughness = as_float_array(
            longitudinal_roughness, "longitudinal_roughness"
        )
        self.azimuthal_roughness = as_float_array(azimuthal_roughness, "azimuthal_roughness")
        self.scale_tilt = as_float_array(scale_tilt, "scale_tilt")
        self.eta = as_float_array(eta, "eta")
        if sigma_a is None:
            self.eumelanin = as_float_array(1.3 if eumelanin is None else eumelanin, "eumelanin")
            self.pheomelanin = as_float_array(
                0.2 if pheomelanin is None else pheomelanin, "pheomelanin"
            )
            self.sigma_a = self.scale = None
        else:
            self.eumelanin = self.pheomelanin = None
            self.sigma_a = to_rgb(sigma_a, "sigma_a")
            self.scale = as_float_array(scale, "scale")

    def __check_init__(self):
        for name in ("longitudinal_roughness", "azimuthal_roughness"):
            x = getattr(self, name)
            check_finite(x, name)
            if is_concrete(x) and not bool(jnp.all((x > 0) & (x <= 1))):
                raise ValueError(f"{name}: expected a value in (0, 1], got {x!r}")
        check_finite(self.scale_tilt, "scale_tilt")
        check_finite(self.eta, "eta")
        if is_concrete(self.eta) and not bool(jnp.all(self.eta > 1)):
            raise ValueError(
                f"eta: expected a relative IOR > 1 (fibre / outside), got {self.eta!r}"
            )
        if self.sigma_a is None:
            check_nonnegative(self.eumelanin, "eumelanin")
            check_nonnegative(self.pheomelanin, "pheomelanin")
        else:
            check_rgb(self.sigma_a, "sigma_a")
            check_nonnegative(self.scale, "scale")

    # ------------------------------------------------------------------ parameters

    @property
    def absorption(self):
        """``σ_a`` (..., 3): from the melanin concentrations or ``scale · sigma_a``."""
        if self.sigma_a is not None:
            return self.scale[..., None] * self.sigma_a
        eu = jnp.asarray(EUMELANIN_SIGMA_A, self.eumelanin.dtype)
        ph = jnp.asarray(PHEOMELANIN_SIGMA_A, self.pheomelanin.dtype)
        return self.eumelanin[..., None] * eu + self.pheomelanin[..., None] * ph

    @property
    def albedo(self):
        """A colour for AOVs: the transmittance ``exp(-2 σ_a)`` across the fibre's diameter at
        normal incidence (no Fresnel)."""
        return jnp.exp(-2.0 * self.absorption)

    def _v(self):
        b = self.longitudinal_roughness
        v0 = (0.726 * b + 0.812 * b * b + 3.7 * b**20) ** 2
        return [v0, 0.25 * v0, 4.0 * v0, 4.0 * v0]

    def _s(self):
        b = self.azimuthal_roughness
        return math.sqrt(math.pi / 8.0) * (0.265 * b + 1.194 * b * b + 5.372 * b**22)

    def _tilted(self, sin_o, cos_o):
        """``(sin, |cos|)`` of ``θ_o - 2α``, ``θ_o + α``, ``θ_o + 4α`` (p = 0, 1, 2)."""
        a = jnp.deg2rad(self.scale_tilt)
        out = []
        for k in (-2.0, 1.0, 4.0):
            sa, ca = jnp.sin(k * a), jnp.cos(k * a)
            out.append((sin_o * ca + cos_o * sa, jnp.abs(cos_o * ca - sin_o * sa)))
        return out

    # ------------------------------------------------------------------ model

    def _geometry(self, wo):
        sin_o, cos_o = _sin_theta(wo)
        phi_o = safe_atan2(wo[..., 2], wo[..., 0])
        gamma_o = _gamma(wo)
        h = jnp.sin(gamma_o)
        eta = self.eta
        # transmission angles: longitudinal θ_t and azimuthal γ_t (Bravais' modified index)
        sin_t = sin_o / eta
        cos_t = safe_sqrt(1.0 - sin_t * sin_t)
        # sin γ_t = h / η' with η' = sqrt(η² - sin² θ_o) / cos θ_o (no division by cos θ_o:
        # finite along the fibre axis; the root is >= sqrt(η² - 1) > 0)
        sin_gt = jnp.clip(h * cos_o / jnp.sqrt(eta * eta - sin_o * sin_o), -1.0, 1.0)
        cos_gt = safe_sqrt(1.0 - sin_gt * sin_gt)
        gamma_t = jnp.arcsin(sin_gt)
        length = safe_div(2.0 * cos_gt, cos_t)
        T = jnp.exp(-self.absorption * length[..., None])
        cos_go = safe_sqrt(1.0 - h * h)
        f = fresnel_dielectric(cos_o * cos_go, eta).r[..., None]
        a0 = jnp.broadcast_to(f, T.shape)
        a1 = (1.0 - f) ** 2 * T
        a2 = a1 * T * f
        tf = T * f
        a3 = a2 * safe_div(tf, 1.0 - tf)
        a_p = [a0, a1, a2, a3]
        lum = [x @ jnp.asarray(_LUM, x.dtype) for x in a_p]
        total = lum[0] + lum[1] + lum[2] + lum[3]
        a_pdf = [safe_div(x, total) for x in lum]
        return _Geometry(sin_o, cos_o, phi_o, gamma_o, gamma_t, a_p, a_pdf)

    def _log_lobes(self, g, wi):
        """Per ``p < 3``: ``log(2π M_p N_p)``; and ``log M_3`` (the residual lobe, uniform in
        φ)."""
        sin_i, cos_i = _sin_theta(wi)
        dphi = safe_atan2(wi[..., 2], wi[..., 0]) - g.phi_o
        v, s = self._v(), self._s()
        tilted = self._tilted(g.sin_o, g.cos_o)
        out = []
        for p in range(P_MAX):
            sp, cp = tilted[p]
            m = _log_longitudinal(sp, cp, sin_i, cos_i, v[p])
            phi = _wrap(dphi - (2.0 * p * g.gamma_t - 2.0 * g.gamma_o + p * jnp.pi))
            out.append(math.log(_TWO_PI) + m + _log_trimmed_logistic(phi, s))
        out.append(_log_longitudinal(g.sin_o, g.cos_o, sin_i, cos_i, v[P_MAX]))
        return out

    @staticmethod
    def _finite(x):
        return jnp.where(jnp.isfinite(x), x, 0.0)

    @staticmethod
    def _sum(log_lobes, coef):
        """``Σ_p exp(log_lobes[p]) coef[p]`` (``coef`` (..., 3) or (...))."""
        if coef[0].ndim > log_lobes[0].ndim:
            return sum(jnp.exp(lg)[..., None] * c for lg, c in zip(log_lobes, coef, strict=True))
        return sum(jnp.exp(lg) * c for lg, c in zip(log_lobes, coef, strict=True))

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        g = self._geometry(wo)
        return self._finite(self._sum(self._log_lobes(g, wi), g.a_p))

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        g = self._geometry(wo)
        return self._finite(self._sum(self._log_lobes(g, wi), g.a_pdf))

    def sample(self, wo, u1, u2) -> BSDFSample:
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        g = self._geometry(wo)
        # lobe p by the A_p probabilities; u1 rescaled within the chosen interval
        c0 = g.a_pdf[0]
        c1 = c0 + g.a_pdf[1]
        c2 = c1 + g.a_pdf[2]
        p = (u1 >= c0).astype(jnp.int32) + (u1 >= c1) + (u1 >= c2)
        lo = jnp.select([p == 1, p == 2, p == 3], [c0, c1, c2], 0.0)
        width = jnp.select([p == 0, p == 1, p == 2], [g.a_pdf[0], g.a_pdf[1], g.a_pdf[2]],
                           g.a_pdf[3])  # fmt: skip
        ur = jnp.clip(safe_div(u1 - lo, width), 0.0, 1.0)
        # longitudinal: d'Eon's inversion around the (tilted) cone
        v = self._v()
        tilted = self._tilted(g.sin_o, g.cos_o) + [(g.sin_o, g.cos_o)]
        sin_op = jnp.select([p == k for k in range(P_MAX)], [t[0] for t in tilted[:P_MAX]],
                            tilted[P_MAX][0])  # fmt: skip
        cos_op = jnp.select([p == k for k in range(P_MAX)], [t[1] for t in tilted[:P_MAX]],
                            tilted[P_MAX][1])  # fmt: skip
        vp = jnp.select([p == k for k in range(P_MAX)], v[:P_MAX], v[P_MAX])
        ua = u2[..., 0]
        # cos = 1 + v log(u + (1 - u) e^(-2/v)) (d'Eon et al.), in log space: u = 0 gives -1
        tiny = jnp.finfo(jnp.result_type(ua, vp)).tiny
        cos_th = 1.0 + vp * jnp.logaddexp(jnp.log(jnp.maximum(ua, tiny)),
                                          jnp.log1p(-ua) - 2.0 / vp)  # fmt: skip
        cos_th = jnp.clip(cos_th, -1.0, 1.0)
        sin_th = safe_sqrt(1.0 - cos_th * cos_th)
        cos_phi = jnp.cos(_TWO_PI * u2[..., 1])
        sin_i = jnp.clip(-cos_th * sin_op + sin_th * cos_phi * cos_op, -1.0, 1.0)
        cos_i = safe_sqrt(1.0 - sin_i * sin_i)
        # azimuthal: trimmed logistic around Φ_p (p < 3), uniform for the residual
        pf = p.astype(cos_i.dtype)
        phi_p = 2.0 * pf * g.gamma_t - 2.0 * g.gamma_o + pf * jnp.pi
        dphi = jnp.where(p < P_MAX, phi_p + _trimmed_logistic_sample(ur, self._s()), _TWO_PI * ur)
        phi_i = g.phi_o + dphi
        wi = jnp.stack([cos_i * jnp.cos(phi_i), sin_i, cos_i * jnp.sin(phi_i)], axis=-1)
        lg = self._log_lobes(g, wi)
        pdf = self._finite(self._sum(lg, g.a_pdf))
        # weight = eval / pdf from the lobes relative to the largest term of the pdf (finite
        # derivatives in the far tails, where both densities underflow together)
        tiny = jnp.finfo(pdf.dtype).tiny
        terms = [x + jnp.log(jnp.maximum(a, tiny)) for x, a in zip(lg, g.a_pdf, strict=True)]
        top = jnp.maximum(jnp.maximum(terms[0], terms[1]), jnp.maximum(terms[2], terms[3]))
        top = jax.lax.stop_gradient(jnp.where(jnp.isfinite(top), top, 0.0))
        rel = [x - top for x in lg]
        num, den = self._sum(rel, g.a_p), self._sum(rel, g.a_pdf)
        valid = (pdf > 0) & (den > 0)
        weight = mask3(valid, self._finite(safe_div(num, den[..., None])))
        return BSDFSample(
            wi=wi,
            pdf=jnp.where(valid, pdf, 0.0),
            weight=weight,
            is_delta=jnp.zeros(shape, bool),
            eta=jnp.ones(shape, pdf.dtype),
        )

    # ------------------------------------------------------------------ scenes

    def at(self, uv, tangents=None):
        """This BSDF in Mitsuba's frame at the hits: ``x`` = the tangent space's ``s``
        (``dp/du`` projected), ``y = n x s`` the fibre axis, ``z`` the normal (an identity
        :class:`~jaxgfx.render.bsdf.PerturbedBSDF`). Without ``tangents`` (albedo AOV) the
        BSDF itself."""
        if tangents is None:
            return self
        s = tangents.s
        n = jnp.broadcast_to(jnp.asarray([0.0, 0.0, 1.0], s.dtype), s.shape)
        return PerturbedBSDF(self, n, s, False, False)
