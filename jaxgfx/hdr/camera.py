"""The virtual camera: scene radiance → exposure → white balance → sensor noise → clip →
response → quantise, and back (:class:`Camera`).

One model of a camera for the whole library: :func:`jaxgfx.hdr.make_bracketed_stack` takes
photographs with it, and the inverse-rendering fit (``jaxgfx fit`` with a ``camera:`` section)
puts it between the rendered radiance and an 8- or 16-bit target. Every stage is a method, so a
caller can run the part it needs (the fit's loss compares in linear radiance through
:meth:`Camera.linearize`; a synthetic bracket runs the whole chain with :meth:`Camera.capture`).

Units. ``radiance`` is scene-referred linear RGB; the sensor sees ``x = exposure · gains ·
radiance`` in normalised units where ``x = 1`` is the clipping level (full well). The response
maps ``x`` to a normalised level ``z ∈ [0, 1]`` with ``x = 1 ↦ z = 1`` whatever the response's
own anchor; ``bits`` then quantises to integer codes ``round(z · (2^bits - 1))``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from .._checks import is_concrete
from ._model import CameraResponse
from .noise import NoiseModel

__all__ = ["Camera", "CAMERA_BITS"]

CAMERA_BITS = (8, 16, None)
"""Quantisation choices: 8-bit (uint8), 16-bit (uint16) codes, or ``None`` (float levels)."""


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

    def encode(self, x):
        """Normalised level ``z = f(x)`` of sensor signal ``x`` (``f(1) = 1``; continuous, not
        clipped or quantised: differentiable)."""
        x = jnp.asarray(x)
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
        normalised): ``f⁻¹(z / code_max) / (exposure · gains)``. Inverse of :meth:`display`
        on ``[0, 1]``; differentiable in the response parameters, exposure and gains."""
        zn = jnp.clip(jnp.asarray(z) / self.code_max, 0.0, 1.0)
        x = self.response.to_linear_normalized(zn) / self._x1(zn.dtype)
        return x / self._gain(zn.dtype)
