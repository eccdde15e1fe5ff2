"""The virtual camera: scene radiance → exposure → white balance → sensor noise → clip →
colour matrix → tone curve → response → quantise, and back (:class:`Camera`).

One model of a camera for the whole library: :func:`jaxgfx.hdr.make_bracketed_stack` takes
photographs with it, and the inverse-rendering fit (``jaxgfx fit`` with a ``camera:`` section)
puts it between the rendered radiance and an 8- or 16-bit target. Every stage is a method, so a
caller can run the part it needs (the fit's loss compares in linear radiance through
:meth:`Camera.linearize`; a synthetic bracket runs the whole chain with :meth:`Camera.capture`).

Units. ``radiance`` is scene-referred linear RGB; the sensor sees ``x = exposure · gains ·
radiance`` in normalised units where ``x = 1`` is the clipping level (full well). The response
maps ``x`` to a normalised level ``z ∈ [0, 1]`` with ``x = 1 ↦ z = 1`` whatever the response's
own anchor; ``bits`` then quantises to integer codes ``round(z · (2^bits - 1))``.

A camera's picture style sits between the sensor and the response (both optional): a 3×3
camera → output ``color_matrix`` ``y = max(M x, 0)`` and a global :class:`ToneCurve` applied
to each channel, anchored like the response (the sensor's clip level ``y = 1`` maps to 1).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from .._checks import check_choice, is_concrete
from ..color.transfer import aces_narkowicz2015
from ._model import CameraResponse
from .noise import NoiseModel

__all__ = ["Camera", "CAMERA_BITS", "ToneCurve", "TONE_CURVES"]

CAMERA_BITS = (8, 16, None)
"""Quantisation choices: 8-bit (uint8), 16-bit (uint16) codes, or ``None`` (float levels)."""


TONE_CURVES = ("reinhard", "filmic")
"""Tone curves of a camera's picture style (:class:`ToneCurve`): the global operators of
:data:`jaxgfx.tonemap.TONEMAP_METHODS` whose luminance curve is a rational function
``(p₂u² + p₁u) / (q₂u² + q₁u + q₀)`` of a scaled signal ``u = s·y`` — monotone on ``u ≥ 0``
and inverted in closed form (one quadratic root), so a fit linearises a code through the
curve exactly and differentiably: ``"reinhard"`` (Reinhard et al. 2002 eq. 4, ``u = key·y``,
shoulder ``white``) and ``"filmic"`` (the ACES fit of Narkowicz 2015, ``u = 0.18 · 2^exposure
· y``)."""


def _tone_coefficients(op: str, params: dict, dtype):
    """``(s, (p₂, p₁), (q₂, q₁, q₀))`` of the rational curve ``op`` (module doc)."""
    if op == "reinhard":
        w = jnp.asarray(params["white"], dtype)
        one = jnp.ones((), dtype)
        return jnp.asarray(params["key"], dtype), (1.0 / (w * w), one), (0.0 * one, one, one)
    from ..color.transfer import ACES_NARKOWICZ2015

    a, b, c, d, e = (jnp.asarray(v, dtype) for v in ACES_NARKOWICZ2015)
    s = 0.18 * jnp.exp2(jnp.asarray(params["exposure"], dtype))
    return s, (a, b), (c, d, e)


class ToneCurve(eqx.Module):
    """A global tone curve ``T̃(y) = T(s·y) / T(s)`` applied to each channel of the
    output-linear signal ``y`` (1 = the sensor's clip level, mapped to 1: the camera's anchor).

    ``op``: one of :data:`TONE_CURVES` (static); ``params``: the operator's curve parameters
    (``reinhard``: ``key``, ``white``; ``filmic``: ``exposure`` in stops), scalar arrays
    (differentiable leaves). ``T`` is the operator's luminance curve of
    :mod:`jaxgfx.tonemap` with the adaptation luminance fixed at 1 (a camera does not adapt to
    the image): the tone mappers' ``reinhard`` / ``filmic`` curves. Per channel (as a
    camera's RGB tone curve; not the operators' luminance + recolouring), so a clipped
    channel bounds that channel only, and :meth:`inverse` is exact.

    Example: ``ToneCurve("filmic", {"exposure": 0.0})(jnp.ones(3))`` is 1 in each channel.
    """

    op: str = eqx.field(static=True)
    params: dict

    def __check_init__(self):
        check_choice(self.op, "op", TONE_CURVES)
        need = {"reinhard": {"key", "white"}, "filmic": {"exposure"}}[self.op]
        if set(self.params) != need:
            raise ValueError(
                f"params: the {self.op!r} tone curve takes {sorted(need)}, got "
                f"{sorted(self.params)}"
            )
        for k in ("key", "white"):
            v = self.params.get(k)
            if v is not None and is_concrete(v) and not bool(jnp.all(jnp.asarray(v) > 0)):
                raise ValueError(f"params.{k}: expected a value > 0, got {v}")

    def _raw(self, u, dtype):
        # the tone mappers' curves at adaptation 1 (jaxgfx.tonemap's reinhard_curve with
        # key 1, L_avg 1; aces_curve at exposure 0 on u / 0.18), written here because hdr sits
        # below tonemap: Reinhard et al. (2002) eq. 4 and Narkowicz's ACES fit
        if self.op == "reinhard":
            w = jnp.asarray(self.params["white"], dtype)
            return u * (1.0 + u / (w * w)) / (1.0 + u)
        return aces_narkowicz2015(u)

    def __call__(self, y):
        """``T̃(y)`` for ``y >= 0`` (any shape)."""
        y = jnp.asarray(y)
        s, _, _ = _tone_coefficients(self.op, self.params, y.dtype)
        return self._raw(s * y, y.dtype) / self._raw(s, y.dtype)

    def inverse(self, t):
        """``y`` with ``T̃(y) = t`` for ``t`` in ``[0, 1]`` (closed form: the non-negative root
        of ``(p₂ − τq₂)u² + (p₁ − τq₁)u − τq₀ = 0``, ``τ = t · T(s)``, written without
        cancellation; differentiable in ``t`` and the parameters)."""
        t = jnp.asarray(t)
        s, (p2, p1), (q2, q1, q0) = _tone_coefficients(self.op, self.params, t.dtype)
        tau = t * self._raw(s, t.dtype)
        a = p2 - tau * q2
        b = p1 - tau * q1
        c = tau * q0  # the root of a u² + b u − c = 0 with c >= 0
        disc = jnp.maximum(b * b + 4.0 * a * c, 0.0)
        u = 2.0 * c / jnp.maximum(b + jnp.sqrt(disc), jnp.finfo(t.dtype).tiny)
        return u / s


class Camera(eqx.Module):
    """A camera between linear radiance and recorded pixel levels.

    Fields (arrays are differentiable leaves; ``bits`` and ``clip`` are static):
      * ``response``: a :class:`CameraResponse` (any kind: analytic, gamma, table, polynomial).
      * ``exposure``: scalar (or broadcastable) relative exposure, > 0 (time × gain).
      * ``white_balance``: ``(C,)`` per-channel gains applied before the sensor clips
        (``None``: no gains).
      * ``noise``: a :class:`NoiseModel` (Poisson–Gaussian in normalised units) or ``None``.
      * ``bits``: 8, 16 or ``None`` (levels stay floats in ``[0, 1]``).
      * ``clip``: clip the sensor signal to ``[0, 1]`` before the response (a real sensor does).
      * ``color_matrix``: ``(3, 3)`` camera → output matrix applied to the clipped sensor signal,
        ``y = max(M x, 0)`` (``None``: none).
      * ``tone``: a :class:`ToneCurve` applied to each channel of ``y`` before the response
        (``None``: none).

    Example: a gamma-2 camera at exposure 0.5 records radiance 0.5 at level
    ``(0.25)^(1/2) = 0.5``, code 128 at 8 bits:

        >>> cam = Camera(CameraResponse.gamma(2.0), jnp.asarray(0.5), bits=8)
        >>> int(cam.capture(jnp.full((1, 1, 1), 0.5))[0, 0, 0])
        128
    """

    response: CameraResponse
    exposure: Array
    white_balance: Array | None = None
    noise: NoiseModel | None = None
    bits: int | None = eqx.field(static=True, default=None)
    clip: bool = eqx.field(static=True, default=True)
    color_matrix: Array | None = None
    tone: ToneCurve | None = None

    def __check_init__(self):
        if not isinstance(self.response, CameraResponse):
            raise TypeError(
                f"response: expected a CameraResponse, got {type(self.response).__name__}"
            )
        if self.bits not in CAMERA_BITS:
            raise ValueError(f"bits: expected one of {CAMERA_BITS}, got {self.bits!r}")
        if self.noise is not None and not isinstance(self.noise, NoiseModel):
            raise TypeError(
                f"noise: expected a NoiseModel or None, got {type(self.noise).__name__}"
            )
        if self.color_matrix is not None and jnp.shape(self.color_matrix) != (3, 3):
            raise ValueError(
                f"color_matrix: expected a (3, 3) matrix, got shape {jnp.shape(self.color_matrix)}"
            )
        if self.tone is not None and not isinstance(self.tone, ToneCurve):
            raise TypeError(f"tone: expected a ToneCurve or None, got {type(self.tone).__name__}")
        e = self.exposure
        if is_concrete(e) and not bool(jnp.all(jnp.asarray(e) > 0)):
            raise ValueError(f"exposure: expected values > 0, got {e}")

    # -- units ------------------------------------------------------------------------------
    @property
    def code_max(self) -> float:
        """Largest code: 255, 65535, or 1.0 for float levels."""
        return 1.0 if self.bits is None else float(2**self.bits - 1)

    def _gain(self, dtype):
        g = jnp.asarray(self.exposure, dtype)
        if self.white_balance is not None:
            g = g * jnp.asarray(self.white_balance, dtype)
        return g

    def _x1(self, dtype):
        """The response's relative exposure at level 1 (so that ``x = 1 ↦ z = 1``), ``(C,)``
        for the response's channels (broadcasts against the data's)."""
        return self.response.to_linear_normalized(jnp.ones((self.response.channels,), dtype))

    # -- forward: radiance → levels ---------------------------------------------------------
    def expose(self, radiance):
        """Sensor signal ``x = exposure · gains · radiance`` (normalised, 1 = clipping)."""
        radiance = jnp.asarray(radiance)
        return self._gain(radiance.dtype) * radiance

    def sense(self, key, x):
        """Add sensor noise to the clean signal ``x`` and clip (when ``clip``).

        Noise (Gaussian approximation of Poisson shot noise plus read noise):
        ``x + sqrt(gain · max(x, 0)) n₁ + sqrt(read_variance) n₂`` with ``n₁, n₂ ~ N(0, 1)``
        drawn from ``key``. Without a noise model (or without a key) only the clip applies.
        """
        x = jnp.asarray(x)
        if self.noise is not None and key is not None:
            k1, k2 = jax.random.split(key)
            n1 = jax.random.normal(k1, x.shape, x.dtype)
            n2 = jax.random.normal(k2, x.shape, x.dtype)
            gain = jnp.asarray(self.noise.gain, x.dtype)
            read_sigma = jnp.sqrt(jnp.asarray(self.noise.read_variance, x.dtype))
            x = x + jnp.sqrt(gain * jnp.maximum(x, 0.0)) * n1 + read_sigma * n2
        return jnp.clip(x, 0.0, 1.0) if self.clip else jnp.maximum(x, 0.0)

    def develop(self, x):
        """The picture style on sensor signal ``x`` ``(..., 3)``: ``y = max(M x, 0)`` (colour
        matrix), then the tone curve per channel; identity when the camera has neither."""
        x = jnp.asarray(x)
        if self.color_matrix is not None:
            x = jnp.maximum(x @ jnp.asarray(self.color_matrix, x.dtype).T, 0.0)
        if self.tone is not None:
            x = self.tone(x)
        return x

    def undevelop(self, t):
        """Inverse of :meth:`develop` (the tone curve's closed-form inverse, then ``M⁻¹``;
        exact where ``M x >= 0``)."""
        t = jnp.asarray(t)
        if self.tone is not None:
            t = self.tone.inverse(t)
        if self.color_matrix is not None:
            t = t @ jnp.linalg.inv(jnp.asarray(self.color_matrix, t.dtype)).T
        return t

    def encode(self, x):
        """Normalised level ``z = f(develop(x))`` of sensor signal ``x`` (``f(1) = 1``;
        continuous, not clipped or quantised: differentiable)."""
        x = self.develop(x)
        return self.response.from_linear_normalized(x * self._x1(x.dtype))

    def quantise(self, z):
        """Integer codes of normalised levels ``z`` (uint8 / uint16; floats in [0, 1] when
        ``bits`` is None). Not differentiable (rounding)."""
        z = jnp.clip(z, 0.0, 1.0)
        if self.bits is None:
            return z
        dtype = jnp.uint8 if self.bits == 8 else jnp.uint16
        return jnp.round(z * self.code_max).astype(dtype)

    def display(self, radiance):
        """Continuous level ``f(exposure · gains · radiance)`` without clip or quantisation
        (what an inverse-rendering fit differentiates)."""
        return self.encode(self.expose(radiance))

    def capture(self, radiance, key=None):
        """The whole chain: expose, :meth:`sense` (noise from ``key``, clip), :meth:`encode`,
        :meth:`quantise`. ``radiance`` ``(..., C)``; returns codes of the same shape."""
        return self.quantise(self.encode(self.sense(key, self.expose(radiance))))

    # -- inverse: levels → radiance ---------------------------------------------------------
    def linearize(self, z):
        """Radiance that records level ``z`` (input units: codes when ``bits`` is set, else
        normalised): ``develop⁻¹(f⁻¹(z / code_max)) / (exposure · gains)``. Inverse of
        :meth:`display` on ``[0, 1]``; differentiable in the response parameters, exposure,
        gains, matrix and tone parameters."""
        zn = jnp.clip(jnp.asarray(z) / self.code_max, 0.0, 1.0)
        x = self.response.to_linear_normalized(zn) / self._x1(zn.dtype)
        return self.undevelop(x) / self._gain(zn.dtype)
