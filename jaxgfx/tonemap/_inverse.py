"""Inverse tone mapping: from a display image back to relative radiance (lecture 2, "HDR
recovery"), for the global operators whose curve is monotone."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from .._checks import check_choice, check_image
from .._math import safe_div, safe_pow
from ..color.spaces import LUMINANCE_WEIGHTS
from ..color.transfer import srgb_to_linear
from ._common import AdaptationStats, check_encode, check_scalar, check_weights
from ._global import aces_curve, drago_curve, exposure_curve, hable_curve, reinhard_curve
from ._registry import GLOBAL_METHODS

__all__ = ["inverse_tonemap"]

_CURVES = {
    "exposure": exposure_curve,
    "drago": drago_curve,
    "reinhard": reinhard_curve,
    "filmic": aces_curve,
    "hable": hable_curve,
}
_DEFAULTS = {
    "exposure": {"exposure": 0.0, "gamma": 1.0},
    "drago": {"bias": 0.85, "ld_max": 100.0},
    "reinhard": {"key": 0.18, "white": None},
    "filmic": {"exposure": 0.0},
    "hable": dict(
        exposure=0.0,
        shoulder=0.15,
        linear=0.5,
        angle=0.1,
        toe=0.2,
        toe_num=0.02,
        toe_den=0.3,
        white=11.2,
    ),
}
_SPAN = 40.0  # bisection bracket: L_avg * exp(+-40)
_ITERS = 64


@functools.partial(jax.jit, static_argnames=("method", "encode", "weights"))
def _inverse(y, params, saturation, la, mx, *, method, encode, weights):
    y = jnp.clip(y, 0.0, 1.0)
    if encode == "srgb":
        y = srgb_to_linear(y)
    curve = _CURVES[method]
    rgb = y.ndim >= 3 and y.shape[-1] == 3
    if rgb:
        w = LUMINANCE_WEIGHTS[weights]
        inv_s = 1.0 / saturation
        Ld = safe_pow(
            w[0] * safe_pow(y[..., 0], inv_s)
            + w[1] * safe_pow(y[..., 1], inv_s)
            + w[2] * safe_pow(y[..., 2], inv_s),
            saturation,
        )
    else:
        Ld = y[..., 0] if y.ndim >= 3 else y
    la = jnp.asarray(la, y.dtype)[..., None, None]
    mx = jnp.asarray(mx, y.dtype)[..., None, None]
    lo = jnp.log(la) - _SPAN + jnp.zeros_like(Ld)
    hi = jnp.log(la) + _SPAN + jnp.zeros_like(Ld)

    def body(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        up = curve(jnp.exp(mid), la, mx, **params) < Ld
        return jnp.where(up, mid, lo), jnp.where(up, hi, mid)

    lo, hi = jax.lax.fori_loop(0, _ITERS, body, (lo, hi))
    L = jnp.where(Ld > 0, jnp.exp(0.5 * (lo + hi)), 0.0)
    if not rgb:
        return L[..., None] if y.ndim >= 3 else L
    ratio = safe_pow(safe_div(y, Ld[..., None], fill=1.0), inv_s)
    return ratio * L[..., None]


def inverse_tonemap(
    ldr,
    *,
    method="reinhard",
    adaptation: AdaptationStats | None = None,
    saturation=1.0,
    encode="srgb",
    weights="rec709",
    **params,
):
    """Invert a global operator: display values -> relative linear radiance.

    Luminance is recovered by bisection on the operator's monotone curve (64 halvings of
    ``log L`` over ``L_avg e^(+-40)``), colour by inverting ``(C/L)^s``: with ``y_c`` the
    linear display channels, ``L_d = (sum_c w_c y_c^(1/s))^s`` and ``C = (y_c / L_d)^(1/s) L``.

    What cannot come back: pixels the operator clipped (display value 1, e.g. above
    ``2^-exposure`` for ``"exposure"`` or ``L_white`` for ``"reinhard"``) return the smallest
    radiance that reaches 1, a lower bound; 8-bit quantisation becomes a relative error that
    grows with the curve's compression (``dL/L ~ dY / (L dY/dL)``); the statistics the
    operator adapted to (log-average, maximum) are not in the display image and must be
    given (``adaptation``), e.g. the values a fit or a sidecar recorded; without them the
    result is relative to an assumed ``L_avg = 1`` (maximum 100).

    Args:
        ldr: ``(..., H, W, 3)`` / ``(..., H, W)`` display values in [0, 1].
        method: ``"exposure"``, ``"drago"``, ``"reinhard"``, ``"filmic"`` or ``"hable"``.
        adaptation: the forward operator's :class:`AdaptationStats`.
        saturation: the forward operator's ``s``.
        encode: the display encoding of ``ldr``.
        params: the forward operator's curve parameters.

    Returns:
        Radiance of ``ldr``'s shape.
    """
    check_choice(method, "method", GLOBAL_METHODS)
    y = check_image(ldr, "ldr")
    check_encode(encode)
    check_weights(weights)
    check_scalar(saturation, "saturation", lo=0.0)
    unknown = set(params) - set(_DEFAULTS[method])
    if unknown:
        raise ValueError(
            f"params: unknown parameters {sorted(unknown)} for {method!r}; "
            f"expected some of {sorted(_DEFAULTS[method])}"
        )
    full = {**_DEFAULTS[method], **params}
    for name, v in full.items():
        if v is not None:
            check_scalar(v, name)
    if adaptation is None:
        adaptation = AdaptationStats(jnp.asarray(1.0), jnp.asarray(100.0))
    return _inverse(
        y,
        full,
        saturation,
        adaptation.log_average,
        adaptation.maximum,
        method=method,
        encode=encode,
        weights=weights,
    )
