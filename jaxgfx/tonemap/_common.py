"""Shared pieces of the tone-mapping operators: input checks, luminance, image statistics,
colour reconstruction with a saturation exponent, and display encoding."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from .._checks import as_float_array, check_choice, check_finite, is_concrete
from .._math import safe_div, safe_log, safe_pow
from ..color.spaces import LUMINANCE_WEIGHTS
from ..color.transfer import linear_to_srgb

ENCODINGS = ("srgb", "linear")
"""Display encodings of the operators' output: sRGB transfer curve or linear, both in [0, 1]."""

#: relative offset inside the log-average, ``delta = LOG_DELTA * mean(L)`` (scale invariant)
LOG_DELTA = 1e-6


class AdaptationStats(NamedTuple):
    """Image statistics a global operator adapts to, one value per image ``(...,)``.

    ``log_average``: ``exp(mean(log(L + delta)))`` (Reinhard's key luminance); ``maximum``:
    ``max(L)``. :func:`jaxgfx.tonemap.smooth_adaptation` replaces the per-frame values by
    temporally smoothed ones.
    """

    log_average: jnp.ndarray
    maximum: jnp.ndarray


def check_hdr(hdr, name: str = "hdr"):
    """Validate a linear HDR image: float array, >= 2-d, non-empty, finite, >= 0."""
    x = as_float_array(hdr, name)
    if x.ndim < 2:
        raise ValueError(
            f"{name}: expected an image (..., H, W, 3), (..., H, W, 1) or (..., H, W), "
            f"got shape {x.shape}"
        )
    if x.size == 0:
        raise ValueError(f"{name}: expected a non-empty image, got shape {x.shape}")
    check_finite(x, name)
    if is_concrete(x):
        n_neg = int(np.sum(np.asarray(x) < 0))
        if n_neg:
            raise ValueError(
                f"{name}: expected linear radiance >= 0, found {n_neg} negative values "
                "(clip or offset the image first)"
            )
    return x


def check_weights(weights):
    return check_choice(weights, "weights", tuple(LUMINANCE_WEIGHTS))


def check_encode(encode):
    return check_choice(encode, "encode", ENCODINGS)


def check_scalar(value, name: str, *, lo=None, hi=None, lo_open=True, hi_open=True):
    """A scalar parameter; concrete values are range-checked (tracers pass)."""
    if isinstance(value, (str, bytes)) or value is None:
        raise TypeError(f"{name}: expected a number, got {type(value).__name__}")
    if jnp.ndim(value) != 0:
        raise ValueError(f"{name}: expected a scalar, got shape {jnp.shape(value)}")
    if is_concrete(value):
        v = float(value)
        bad = not np.isfinite(v)
        if lo is not None:
            bad |= v <= lo if lo_open else v < lo
        if hi is not None:
            bad |= v >= hi if hi_open else v > hi
        if bad:
            lo_s = "" if lo is None else f"{'>' if lo_open else '>='} {lo}"
            hi_s = "" if hi is None else f"{'<' if hi_open else '<='} {hi}"
            what = " and ".join(s for s in (lo_s, hi_s) if s) or "finite"
            raise ValueError(f"{name}: expected a finite value {what}, got {value!r}")
    return value


def split_luminance(x, weights: str = "rec709"):
    """``(L, kind)``: luminance ``(..., H, W)`` of an RGB ``(..., H, W, 3)``, single-channel
    ``(..., H, W, 1)`` or luminance ``(..., H, W)`` image, and the layout kind."""
    if x.ndim >= 3 and x.shape[-1] == 3:
        w = LUMINANCE_WEIGHTS[weights]
        return w[0] * x[..., 0] + w[1] * x[..., 1] + w[2] * x[..., 2], "rgb"
    if x.ndim >= 3 and x.shape[-1] == 1:
        return x[..., 0], "single"
    return x, "lum"


def recolor(x, L, Ld, saturation, kind: str):
    """Colour reconstruction of Schlick (1994) / Fattal et al. (2002):
    ``C_out = (C_in / L_in)^s * L_out`` per channel; grey where ``L_in = 0``."""
    if kind == "lum":
        return Ld
    if kind == "single":
        return Ld[..., None]
    ratio = safe_div(x, L[..., None], fill=1.0)
    if saturation is None:  # s = 1 given as a Python number: skip the power
        return ratio * Ld[..., None]
    return safe_pow(ratio, saturation) * Ld[..., None]


def static_saturation(saturation):
    """``None`` for a concrete Python ``1`` / ``1.0`` (the fast path of :func:`recolor`),
    else the (possibly traced) value."""
    if isinstance(saturation, (int, float)) and not isinstance(saturation, bool):
        if float(saturation) == 1.0:
            return None
    return saturation


def encode_display(y, encode: str):
    """Clip to [0, 1] and apply the display encoding."""
    y = jnp.clip(y, 0.0, 1.0)
    if encode == "srgb":
        return linear_to_srgb(y)
    return y


def image_mean(L):
    return jnp.mean(L, axis=(-2, -1), keepdims=True)


def log_delta(L):
    """The scale-invariant offset inside logs: ``LOG_DELTA * mean(L)`` (+ tiny for black)."""
    tiny = float(jnp.finfo(L.dtype).tiny) * 1e6
    return LOG_DELTA * image_mean(L) + tiny


def log_average(L):
    """``exp(mean(log(L + delta)))`` over the last two axes, keepdims. ``delta`` is
    ``1e-6 * mean(L)`` so that the statistic scales with the image (zeros are harmless)."""
    return jnp.exp(jnp.mean(safe_log(L + log_delta(L)), axis=(-2, -1), keepdims=True))


def image_stats(L) -> AdaptationStats:
    """Per-image :class:`AdaptationStats` of luminance ``(..., H, W)`` (shape ``(...,)``)."""
    return AdaptationStats(log_average(L)[..., 0, 0], jnp.max(L, axis=(-2, -1)))


def stats_or_default(L, adaptation):
    """Statistics broadcastable to ``L``: from ``adaptation`` when given, else from ``L``."""
    if adaptation is None:
        return log_average(L), jnp.max(L, axis=(-2, -1), keepdims=True)
    la = jnp.asarray(adaptation.log_average, L.dtype)[..., None, None]
    mx = jnp.asarray(adaptation.maximum, L.dtype)[..., None, None]
    return la, mx
