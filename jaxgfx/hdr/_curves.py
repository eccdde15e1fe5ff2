"""Curve families behind :class:`CameraResponse` (normalised units: z, x in [0, 1], x(1) = 1).

Each kind maps normalised pixel level ``z`` to *un-anchored* linear exposure ``base(z)`` and
back. ``params`` has a kind-specific leading shape and a trailing channel axis ``C``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._math import safe_pow, safe_sqrt
from ..color.transfer import (
    ACES_NARKOWICZ2015,
    aces_narkowicz2015,
    linear_to_srgb,
    srgb_to_linear,
)

__all__ = [
    "base_to_linear",
    "base_from_linear",
    "interp_channels",
    "ANALYTIC_KINDS",
    "ANALYTIC_RESPONSES",
]

_TINY = 1e-30


def interp_channels(x, xp, fp):
    """Per-channel ``jnp.interp``: ``x`` ``(..., C)``, ``xp``/``fp`` ``(L, C)`` → ``(..., C)``."""
    c = xp.shape[-1]
    x = jnp.broadcast_to(x, x.shape[:-1] + (c,)) if x.ndim else jnp.broadcast_to(x, (c,))
    flat = x.reshape(-1, c)
    out = jax.vmap(jnp.interp, in_axes=(1, 1, 1), out_axes=1)(flat, xp, fp)
    return out.reshape(x.shape)


def table_lookup(z, table):
    """Piecewise-linear interpolation of ``table`` ``(L, C)`` on uniform knots over [0, 1]."""
    n = table.shape[0]
    u = jnp.clip(z, 0.0, 1.0) * (n - 1)
    i0 = jnp.clip(jnp.floor(u), 0, n - 2).astype(jnp.int32)
    frac = u - i0
    ch = jnp.arange(table.shape[1])
    lo = table[i0, ch]
    hi = table[i0 + 1, ch]
    return lo + frac * (hi - lo)


# --- analytic ground-truth curves (all with base(1) = 1) -------------------------------------
_SK, _SS = 0.3, 1.6  # s-curve knee and slope
_SC = 1.0 + _SK**_SS
_LOG_A = 100.0


_aces = aces_narkowicz2015  # the ACES fit (jaxgfx.color), as the "filmic" response's shoulder
_A, _B, _C, _D, _E = ACES_NARKOWICZ2015
_ACES4 = 4.0 * (_A * 4.0 + _B) / (4.0 * (_C * 4.0 + _D) + _E)  # _aces(4), a Python float


def _srgb_fwd(x):
    return linear_to_srgb(x)  # the sRGB OETF of jaxgfx.color


def _srgb_inv(z):
    return srgb_to_linear(z)


def _scurve_fwd(x):
    p = safe_pow(x, _SS)
    return _SC * p / (p + _SK**_SS)


def _scurve_inv(z):
    u = jnp.clip(z / _SC, 0.0, 1.0 / _SC)
    return _SK * safe_pow(u / (1.0 - u), 1.0 / _SS)


def _filmic_fwd(x):
    x = jnp.maximum(x, 0.0)
    return _aces(4.0 * x) / _ACES4


def _filmic_inv(z):
    y = jnp.clip(z, 0.0, 1.0) * _ACES4
    a = _A - _C * y  # the quadratic x (a x + b) = y (x (c x + d) + e) solved for x
    b = _B - _D * y
    c = -_E * y
    return (-b + safe_sqrt(b * b - 4.0 * a * c)) / (2.0 * a) / 4.0


def _log_fwd(x):
    return jnp.log1p(_LOG_A * jnp.maximum(x, 0.0)) / jnp.log1p(_LOG_A)


def _log_inv(z):
    return jnp.expm1(z * jnp.log1p(_LOG_A)) / _LOG_A


# "camera": a JPEG-like in-camera curve: a toe (x^2 (1+c) / (x + c), shadows compressed), a
# Reinhard-style shoulder (x (1+k) / (x + k), highlights rolled off), then the sRGB encoding;
# "camera-offset" adds a lifted black (level _CAM_B at zero exposure). c, k chosen so that the
# relative exposure x(z) / x(128/255) is 0.009 at z = 2/255 and 6.5 at z = 250/255, close to a
# measured Canon JPEG curve (0.010 and 6.0, OpenCV CalibrateDebevec; jaxgfx issue 16).
_CAM_C, _CAM_K, _CAM_B = 0.003, 1.5, 0.03


def _camera_fwd_b(x, b):
    x = jnp.maximum(x, 0.0)
    xt = x * x * (1.0 + _CAM_C) / (x + _CAM_C)
    xs = xt * (1.0 + _CAM_K) / (xt + _CAM_K)
    return b + (1.0 - b) * _srgb_fwd(xs)


def _camera_inv_b(z, b):
    s = jnp.clip((z - b) / (1.0 - b), 0.0, 1.0)
    xs = _srgb_inv(s)
    xt = _CAM_K * xs / (1.0 + _CAM_K - xs)
    return (xt + safe_sqrt(xt * xt + 4.0 * (1.0 + _CAM_C) * _CAM_C * xt)) / (2.0 * (1.0 + _CAM_C))


def _camera_fwd(x):
    return _camera_fwd_b(x, 0.0)


def _camera_inv(z):
    return _camera_inv_b(z, 0.0)


def _camera_offset_fwd(x):
    return _camera_fwd_b(x, _CAM_B)


def _camera_offset_inv(z):
    return _camera_inv_b(z, _CAM_B)


def _identity(v):
    return v


ANALYTIC_KINDS = {
    "linear": (_identity, _identity),
    "srgb": (_srgb_inv, _srgb_fwd),
    "camera": (_camera_inv, _camera_fwd),
    "camera-offset": (_camera_offset_inv, _camera_offset_fwd),
    "s-curve": (_scurve_inv, _scurve_fwd),
    "filmic": (_filmic_inv, _filmic_fwd),
    "log": (_log_inv, _log_fwd),
}


ANALYTIC_RESPONSES = tuple(ANALYTIC_KINDS)
"""Names of the fixed analytic response curves (the one list: :class:`CameraResponse`
kinds, synthetic ground truths and the fit's camera models are built from it)."""


def base_to_linear(kind, params, z):
    """Un-anchored ``x = base(z)`` for normalised ``z`` ``(..., C)``."""
    if kind == "gamma":
        return safe_pow(jnp.clip(z, 0.0, 1.0), params)
    if kind == "polynomial":
        zc = jnp.clip(z, 0.0, 1.0)
        out = jnp.zeros_like(zc * params[0])
        for k in range(params.shape[0] - 1, -1, -1):  # Horner
            out = out * zc + params[k]
        return out
    if kind == "table":
        return jnp.exp(table_lookup(z, params))
    inv, _ = ANALYTIC_KINDS[kind]
    return inv(jnp.clip(z, 0.0, 1.0)) + 0.0 * params


def base_from_linear(kind, params, x):
    """Inverse of :func:`base_to_linear`: normalised level for un-anchored exposure ``x``."""
    if kind == "gamma":
        return safe_pow(jnp.maximum(x, 0.0), 1.0 / params)
    if kind == "polynomial":
        grid = jnp.linspace(0.0, 1.0, 4097, dtype=params.dtype)[:, None]
        xs = jax.lax.cummax(base_to_linear(kind, params, grid), axis=0)
        xs = xs + grid * 1e-7  # strictly increasing for interpolation
        return interp_channels(x, xs, jnp.broadcast_to(grid, xs.shape))
    if kind == "table":
        n = params.shape[0]
        grid = jnp.broadcast_to(
            jnp.linspace(0.0, 1.0, n, dtype=params.dtype)[:, None], params.shape
        )
        lx = jnp.log(jnp.maximum(x, _TINY))
        return interp_channels(lx, params, grid)
    _, fwd = ANALYTIC_KINDS[kind]
    return fwd(x) + 0.0 * params
