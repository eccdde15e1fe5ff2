"""Transfer functions (colour component transfer functions, CCTFs).

Each encoding maps *linear* light to a non-linear code value and each decoding is its exact
inverse. All functions are elementwise (any shape), jittable, vmappable and differentiable, and
keep the input's floating dtype.

**Negative inputs** use the *odd extension* ``f(-x) = -f(x)`` (as in scRGB / extended sRGB), so
out-of-gamut values survive a round trip and the maps stay strictly monotonic. Inputs above 1
follow the same analytic curve (no clamping). Near zero every curve with a linear toe (sRGB,
Rec.709, ProPhoto) has a finite, exact gradient; the pure power laws (Adobe RGB, ``gamma_*``)
have an infinite true slope at 0 for exponents < 1, where the gradient returned is 0.

Each public function validates its input eagerly and then calls one jitted core (``_*``), so
an eager call runs one compiled program instead of one dispatch per primitive.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._checks import check_choice, check_positive
from .._math import safe_pow
from ._common import as_values

__all__ = [
    "srgb_to_linear",
    "linear_to_srgb",
    "linear_to_rec709",
    "rec709_to_linear",
    "linear_to_adobe_rgb",
    "adobe_rgb_to_linear",
    "linear_to_prophoto",
    "prophoto_to_linear",
    "gamma_encode",
    "gamma_decode",
    "transfer_encode",
    "transfer_decode",
    "TRANSFER_FUNCTIONS",
    "ADOBE_RGB_GAMMA",
    "ACES_NARKOWICZ2015",
    "aces_narkowicz2015",
]

#: Adobe RGB (1998) exponent, 2 + 51/256 (Adobe RGB (1998) Color Image Encoding, 2005, §4.3.1.2).
ADOBE_RGB_GAMMA = 563.0 / 256.0


def _piecewise_odd(x, knee, lin_slope, curve):
    """``x * lin_slope`` for ``|x| <= knee``, else ``sign(x) * curve(|x|)``; NaN-free gradients."""
    a = jnp.abs(x)
    lin = a <= knee
    a_safe = jnp.where(lin, jnp.asarray(2.0 * knee + 1.0, a.dtype), a)
    s = jnp.where(x < 0, -1.0, 1.0).astype(a.dtype)
    return jnp.where(lin, x * lin_slope, s * curve(a_safe))


def _power_odd(x, p):
    s = jnp.where(x < 0, -1.0, 1.0).astype(jnp.result_type(x))
    return s * safe_pow(jnp.abs(x), p)


# --- sRGB (IEC 61966-2-1:1999) -----------------------------------------------------------------


@jax.jit
def _srgb_to_linear(v):
    return _piecewise_odd(v, 0.04045, 1.0 / 12.92, lambda a: ((a + 0.055) / 1.055) ** 2.4)


def srgb_to_linear(v):
    """sRGB EOTF: non-linear sRGB code value -> linear light (IEC 61966-2-1:1999).

    ``L = V / 12.92`` for ``V <= 0.04045``, else ``((V + 0.055) / 1.055) ** 2.4``; odd extension
    for ``V < 0``.

    Args:
      v: code values, any shape, nominal range [0, 1].

    Returns:
      Linear values, same shape and dtype.

    Example:
      >>> float(srgb_to_linear(0.5))  # doctest: +ELLIPSIS
      0.21404...
    """
    return _srgb_to_linear(as_values(v, "v"))


@jax.jit
def _linear_to_srgb(x):
    return _piecewise_odd(x, 0.0031308, 12.92, lambda a: 1.055 * a ** (1.0 / 2.4) - 0.055)


def linear_to_srgb(x):
    """Inverse sRGB EOTF: linear light -> sRGB code value (IEC 61966-2-1:1999).

    ``V = 12.92 L`` for ``L <= 0.0031308``, else ``1.055 L ** (1/2.4) - 0.055``; odd extension
    for ``L < 0``. The gradient is finite everywhere (12.92 at 0).

    Example:
      >>> float(linear_to_srgb(0.18))  # doctest: +ELLIPSIS
      0.46135...
    """
    return _linear_to_srgb(as_values(x, "x"))


# --- Rec. ITU-R BT.709-6 -------------------------------------------------------------------------

_REC709_KNEE_CODE = 1.099 * 0.018**0.45 - 0.099  # the OETF's value just above its knee


@jax.jit
def _linear_to_rec709(x):
    a = jnp.abs(x)
    lin = a < 0.018
    a_safe = jnp.where(lin, 1.0, a)
    s = jnp.where(x < 0, -1.0, 1.0).astype(a.dtype)
    return jnp.where(lin, 4.5 * x, s * (1.099 * a_safe**0.45 - 0.099))


def linear_to_rec709(x):
    """Rec. ITU-R BT.709-6 OETF: scene linear light -> video code value.

    ``V = 4.5 L`` for ``L < 0.018``, else ``1.099 L ** 0.45 - 0.099``; odd extension below 0.

    Example:
      >>> float(linear_to_rec709(0.18))  # doctest: +ELLIPSIS
      0.40900...
    """
    return _linear_to_rec709(as_values(x, "x"))


@jax.jit
def _rec709_to_linear(v):
    a = jnp.abs(v)
    lin = a < _REC709_KNEE_CODE
    a_safe = jnp.where(lin, 1.0, a)
    s = jnp.where(v < 0, -1.0, 1.0).astype(a.dtype)
    return jnp.where(lin, v / 4.5, s * ((a_safe + 0.099) / 1.099) ** (1.0 / 0.45))


def rec709_to_linear(v):
    """Inverse Rec.709 OETF: video code value -> scene linear light.

    ``L = V / 4.5`` below the OETF's value at its knee (0.0812...), else
    ``((V + 0.099) / 1.099) ** (1 / 0.45)``; odd extension below 0.
    """
    return _rec709_to_linear(as_values(v, "v"))


# --- Adobe RGB (1998) -----------------------------------------------------------------------------


@jax.jit
def _linear_to_adobe_rgb(x):
    return _power_odd(x, 1.0 / ADOBE_RGB_GAMMA)


def linear_to_adobe_rgb(x):
    """Adobe RGB (1998) encoding: ``V = L ** (256/563)`` (pure power law, odd extension).

    Reference: Adobe RGB (1998) Color Image Encoding, version 2005-05, §4.3.1.2.

    Example:
      >>> float(linear_to_adobe_rgb(0.18))  # doctest: +ELLIPSIS
      0.45852...
    """
    return _linear_to_adobe_rgb(as_values(x, "x"))


@jax.jit
def _adobe_rgb_to_linear(v):
    return _power_odd(v, ADOBE_RGB_GAMMA)


def adobe_rgb_to_linear(v):
    """Adobe RGB (1998) decoding: ``L = V ** (563/256)`` (odd extension)."""
    return _adobe_rgb_to_linear(as_values(v, "v"))


# --- ProPhoto RGB / ROMM RGB (ISO 22028-2:2013) ---------------------------------------------------

_ROMM_ET = 16.0 ** (1.8 / (1.0 - 1.8))  # = 1/512, where 16 x meets x ** (1/1.8)


@jax.jit
def _linear_to_prophoto(x):
    return _piecewise_odd(x, _ROMM_ET, 16.0, lambda a: a ** (1.0 / 1.8))


def linear_to_prophoto(x):
    """ProPhoto (ROMM) RGB encoding, ISO 22028-2:2013 (float code values).

    ``V = 16 L`` for ``L < 1/512``, else ``L ** (1/1.8)``; odd extension below 0.

    Example:
      >>> float(linear_to_prophoto(0.18))  # doctest: +ELLIPSIS
      0.38571...
    """
    return _linear_to_prophoto(as_values(x, "x"))


@jax.jit
def _prophoto_to_linear(v):
    return _piecewise_odd(v, 16.0 * _ROMM_ET, 1.0 / 16.0, lambda a: a**1.8)


def prophoto_to_linear(v):
    """ProPhoto (ROMM) RGB decoding: ``L = V / 16`` for ``V < 1/32``, else ``V ** 1.8``."""
    return _prophoto_to_linear(as_values(v, "v"))


# --- pure gamma -----------------------------------------------------------------------------------


@jax.jit
def _gamma_encode(x, gamma):
    # gamma is traced (a new value does not recompile) and cast to the image's dtype
    return _power_odd(x, 1.0 / jnp.asarray(gamma, dtype=x.dtype))


@jax.jit
def _gamma_decode(v, gamma):
    return _power_odd(v, jnp.asarray(gamma, dtype=v.dtype))


def gamma_encode(x, gamma=2.2):
    """Pure power-law encoding ``V = sign(L) |L| ** (1 / gamma)``.

    Differentiable in both ``x`` and ``gamma`` (``gamma > 0``). The gradient w.r.t. ``x`` at
    exactly 0 is returned as 0 (the true slope is infinite for ``gamma > 1``).

    Example:
      >>> float(gamma_encode(0.25, 2.0))
      0.5
    """
    x = as_values(x, "x")
    check_positive(gamma, "gamma")
    return _gamma_encode(x, gamma)


def gamma_decode(v, gamma=2.2):
    """Pure power-law decoding ``L = sign(V) |V| ** gamma`` (``gamma > 0``), inverse of
    :func:`gamma_encode`.

    Example:
      >>> float(gamma_decode(0.5, 2.0))
      0.25
    """
    v = as_values(v, "v")
    check_positive(gamma, "gamma")
    return _gamma_decode(v, gamma)


def _identity(x):
    return as_values(x, "x")


#: name -> (encode: linear -> code value, decode: code value -> linear).
TRANSFER_FUNCTIONS = {
    "linear": (_identity, _identity),
    "srgb": (linear_to_srgb, srgb_to_linear),
    "rec709": (linear_to_rec709, rec709_to_linear),
    "adobe_rgb": (linear_to_adobe_rgb, adobe_rgb_to_linear),
    "prophoto": (linear_to_prophoto, prophoto_to_linear),
}


def transfer_encode(x, *, curve="srgb"):
    """Encode linear light with the transfer function named ``curve`` (see
    :data:`TRANSFER_FUNCTIONS`: ``"linear"``, ``"srgb"``, ``"rec709"``, ``"adobe_rgb"``,
    ``"prophoto"``)."""
    check_choice(curve, "curve", TRANSFER_FUNCTIONS)
    return TRANSFER_FUNCTIONS[curve][0](x)


def transfer_decode(v, *, curve="srgb"):
    """Decode code values to linear light with the transfer function named ``curve``."""
    check_choice(curve, "curve", TRANSFER_FUNCTIONS)
    return TRANSFER_FUNCTIONS[curve][1](v)


# --- ACES filmic fit (Narkowicz 2015) --------------------------------------------------------

ACES_NARKOWICZ2015 = (2.51, 0.03, 2.43, 0.59, 0.14)
"""Coefficients ``(a, b, c, d, e)`` of :func:`aces_narkowicz2015`."""


def aces_narkowicz2015(x):
    """Narkowicz's (2015) rational fit of the ACES reference rendering + output transform:
    ``f(x) = x (a x + b) / (x (c x + d) + e)`` with ``(a, b, c, d, e) = (2.51, 0.03, 2.43, 0.59,
    0.14)`` (:data:`ACES_NARKOWICZ2015`), for scene-linear ``x >= 0``; ``f(0) = 0``, ``f → 1.03``
    as ``x → ∞``. The one definition: the ``"filmic"`` tone mapper and the ``"filmic"`` camera
    response (``f(4 x) / f(4)``) are built on it. Traceable, differentiable.

    Example: ``aces_narkowicz2015(1.0)`` → ``2.54 / 3.16 = 0.8037…``.
    """
    a, b, c, d, e = ACES_NARKOWICZ2015
    return x * (a * x + b) / (x * (c * x + d) + e)

