"""Global tone-mapping operators: one curve for every pixel (lecture 2, "global operators").

Every operator maps linear relative radiance to display values in [0, 1]; the curve acts on
luminance and colour is restored by :func:`jaxgfx.tonemap._common.recolor` (saturation
exponent ``s``). ``*_curve`` functions are the scalar luminance curves, shared with
:func:`jaxgfx.tonemap.inverse_tonemap`.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp

from .._math import safe_div, safe_pow
from ..color.transfer import ACES_NARKOWICZ2015
from ._common import (
    check_encode,
    check_hdr,
    check_scalar,
    check_weights,
    encode_display,
    recolor,
    split_luminance,
    static_saturation,
    stats_or_default,
)

__all__ = [
    "tonemap_exposure",
    "tonemap_Drago2003",
    "tonemap_Reinhard2002",
    "tonemap_Reinhard2005",
    "tonemap_ACES_Narkowicz2015",
    "tonemap_Hable2010",
]

_LOG_HALF = math.log(0.5)


# ------------------------------------------------------------------------ luminance curves


def exposure_curve(L, la, mx, *, exposure, gamma):
    y = L * jnp.exp2(exposure)
    return y if gamma is None else safe_pow(y, 1.0 / gamma)


@functools.partial(jax.jit, static_argnames=("encode",))
def _exposure_per_channel(x, exposure, gamma, *, encode):
    return encode_display(exposure_curve(x, None, None, exposure=exposure, gamma=gamma), encode)


def drago_curve(L, la, mx, *, bias, ld_max):
    """Drago et al. (2003) eq. 4 on world luminance normalised by the log-average."""
    Lw = safe_div(L, la)
    Lwmax = safe_div(mx, la)
    p = jnp.log(bias) / _LOG_HALF
    scale = safe_div(ld_max * 0.01, jnp.log10(Lwmax + 1.0))
    base = jnp.log(2.0 + 8.0 * safe_pow(safe_div(Lw, Lwmax), p))
    return scale * jnp.log1p(Lw) / base


def reinhard_curve(L, la, mx, *, key, white):
    """Reinhard et al. (2002) eqs. 2 and 4; ``white`` in scaled units (None: the maximum)."""
    Lm = key * safe_div(L, la)
    Lwhite = key * safe_div(mx, la) if white is None else white
    return Lm * (1.0 + safe_div(Lm, Lwhite * Lwhite)) / (1.0 + Lm)


_ACES = ACES_NARKOWICZ2015  # the one definition: jaxgfx.color.aces_narkowicz2015


def aces_curve(L, la, mx, *, exposure):
    """Narkowicz (2015) rational fit of the ACES RRT+ODT, on ``0.18 * 2^exposure * L / L_avg``."""
    a, b, c, d, e = _ACES
    x = 0.18 * jnp.exp2(exposure) * safe_div(L, la)
    return x * (a * x + b) / (x * (c * x + d) + e)


def _hable(x, A, B, C, D, E, F):
    return (x * (A * x + C * B) + D * E) / (x * (A * x + B) + D * F) - E / F


def hable_curve(L, la, mx, *, exposure, shoulder, linear, angle, toe, toe_num, toe_den, white):
    """Hable (2010) "Uncharted 2" filmic curve, ``F(2 x) / F(W)`` on ``x = 0.18 * 2^ev L/L_avg``."""
    x = 0.18 * jnp.exp2(exposure) * safe_div(L, la)
    args = (shoulder, linear, angle, toe, toe_num, toe_den)
    return _hable(2.0 * x, *args) / _hable(white, *args)


# ------------------------------------------------------------------------ operators


def _finish(x, L, kind, Ld, saturation, encode):
    return encode_display(recolor(x, L, Ld, saturation, kind), encode)


@functools.partial(jax.jit, static_argnames=("curve", "encode", "weights"))
def _apply_curve(x, params, saturation, adaptation, *, curve, encode, weights):
    L, kind = split_luminance(x, weights)
    la, mx = stats_or_default(L, adaptation)
    Ld = curve(L, la, mx, **params)
    return _finish(x, L, kind, Ld, saturation, encode)


def _prepare(hdr, saturation, encode, weights):
    x = check_hdr(hdr)
    check_scalar(saturation, "saturation", lo=0.0)
    check_encode(encode)
    check_weights(weights)
    return x


def tonemap_exposure(
    hdr,
    *,
    exposure=0.0,
    gamma=1.0,
    saturation=1.0,
    encode="srgb",
    weights="rec709",
    per_channel=False,
):
    """Exposure, gamma and clip: ``L_d = min(1, (2^exposure L)^(1/gamma))``.

    The simplest global operator of the lecture (linear scaling + clipping + a power curve).
    Everything above ``2^-exposure`` is clipped (no gradient there).

    Args:
        hdr: linear radiance ``(..., H, W, 3)``, ``(..., H, W, 1)`` or luminance
            ``(..., H, W)``, finite and >= 0.
        exposure: stops (``2^exposure`` multiplies the radiance).
        gamma: > 0, extra display gamma applied to the luminance (1 = none).
        saturation: colour exponent ``s`` of ``(C/L)^s L_d`` (1 keeps the hue and saturation).
        encode: ``"srgb"`` (default) or ``"linear"`` output in [0, 1].
        weights: luminance weights, ``"rec709"`` or ``"rec601"``.
        per_channel: static; apply the curve to R, G, B separately (the classic per-channel
            clip: bright colours desaturate towards white) instead of to the luminance
            (hue kept); ``saturation`` is then unused.

    Returns:
        Display image of the input's shape, values in [0, 1].

    Example:
        >>> tonemap_exposure(jnp.full((1, 1), 0.25), exposure=1.0, encode="linear")
        Array([[0.5]], dtype=float32...)
    """
    x = _prepare(hdr, saturation, encode, weights)
    saturation = static_saturation(saturation)
    check_scalar(exposure, "exposure")
    check_scalar(gamma, "gamma", lo=0.0)
    if isinstance(gamma, (int, float)) and not isinstance(gamma, bool) and float(gamma) == 1.0:
        gamma = None  # static fast path: no power
    if per_channel:
        return _exposure_per_channel(x, exposure, gamma, encode=encode)
    params = {"exposure": exposure, "gamma": gamma}
    return _apply_curve(
        x, params, saturation, None, curve=exposure_curve, encode=encode, weights=weights
    )


def tonemap_Drago2003(
    hdr,
    *,
    bias=0.85,
    ld_max=100.0,
    saturation=1.0,
    encode="srgb",
    weights="rec709",
    adaptation=None,
):
    """Adaptive logarithmic mapping (Drago, Myszkowski, Annen & Chiba, Eurographics 2003).

    With ``L_w = L / L_avg`` (log-average luminance, the scene key) and ``L_wmax = max L_w``::

        L_d = (L_dmax * 0.01 / log10(L_wmax + 1))
              * log(L_w + 1) / log(2 + 8 (L_w / L_wmax)^(log b / log 0.5))

    The base of the logarithm moves from 2 (dark pixels) to 10 (the brightest pixel, which maps
    to ``L_dmax / 100``). The lecture's formula (lecture 2, "adaptive logarithmic mapping").

    Args:
        hdr: linear radiance ``(..., H, W, 3)``, ``(..., H, W, 1)`` or ``(..., H, W)``, >= 0.
        bias: ``b`` in (0, 1); 0.7-0.9 typical; lower = brighter dark and mid tones.
        ld_max: display maximum in cd/m^2 (100 maps the brightest pixel to 1).
        saturation: colour exponent ``s``.
        encode: ``"srgb"`` (default; the paper asks for a gamma) or ``"linear"``.
        weights: luminance weights.
        adaptation: optional :class:`AdaptationStats` replacing the per-image log-average
            and maximum (video: :func:`smooth_adaptation`).

    Returns:
        Display image, input shape, [0, 1].

    Differences from OpenCV's ``TonemapDrago``: OpenCV takes ``log`` of exact zeros (NaN
    output), and min-max normalises the result over all channels; here zeros map to 0 and the
    brightest luminance maps to ``ld_max / 100``.

    Example:
        >>> float(tonemap_Drago2003(jnp.array([[1.0, 4.0]]), encode="linear")[0, 1])
        1.0
    """
    x = _prepare(hdr, saturation, encode, weights)
    saturation = static_saturation(saturation)
    check_scalar(bias, "bias", lo=0.0, hi=1.0)
    check_scalar(ld_max, "ld_max", lo=0.0)
    params = {"bias": bias, "ld_max": ld_max}
    return _apply_curve(
        x, params, saturation, adaptation, curve=drago_curve, encode=encode, weights=weights
    )


def tonemap_Reinhard2002(
    hdr,
    *,
    key=0.18,
    white=None,
    saturation=1.0,
    encode="srgb",
    weights="rec709",
    adaptation=None,
):
    """Photographic tone reproduction, global operator (Reinhard, Stark, Shirley & Ferwerda,
    SIGGRAPH 2002, eqs. 1-4).

    ``L_m = a L / L_avg`` (key ``a``), ``L_d = L_m (1 + L_m / L_white^2) / (1 + L_m)``.

    Args:
        hdr: linear radiance, >= 0 (see :func:`tonemap_Drago2003`).
        key: ``a`` > 0, the brightness of the mid grey (0.18: "normal-key" scene).
        white: ``L_white`` > 0 in scaled units (the smallest luminance mapped to 1); ``None``
            (default) uses the maximum scaled luminance, as the paper suggests.
        saturation, encode, weights, adaptation: see :func:`tonemap_Drago2003`.

    Example:
        >>> img = jnp.array([[1.0, 1.0]])  # L_avg = 1: L_m = 0.18, L_white = 0.18
        >>> round(float(tonemap_Reinhard2002(img, encode="linear")[0, 0]), 6)
        1.0
    """
    x = _prepare(hdr, saturation, encode, weights)
    saturation = static_saturation(saturation)
    check_scalar(key, "key", lo=0.0)
    if white is not None:
        check_scalar(white, "white", lo=0.0)
    params = {"key": key, "white": white}
    return _apply_curve(
        x, params, saturation, adaptation, curve=reinhard_curve, encode=encode, weights=weights
    )


def tonemap_ACES_Narkowicz2015(
    hdr, *, exposure=0.0, saturation=1.0, encode="srgb", weights="rec709", adaptation=None
):
    """Filmic curve: Narkowicz's (2015) fit of the ACES reference rendering transform.

    ``f(x) = x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)`` on
    ``x = 0.18 * 2^exposure * L / L_avg`` (auto-exposure: the log-average goes to mid grey).
    Toe and shoulder like film; saturates to 1 at ``x ~ 10``.

    Example:
        >>> float(tonemap_ACES_Narkowicz2015(jnp.ones((1, 1)), encode="linear")[0, 0])  # f(0.18)
        0.2668...
    """
    x = _prepare(hdr, saturation, encode, weights)
    saturation = static_saturation(saturation)
    check_scalar(exposure, "exposure")
    return _apply_curve(
        x,
        {"exposure": exposure},
        saturation,
        adaptation,
        curve=aces_curve,
        encode=encode,
        weights=weights,
    )


def tonemap_Hable2010(
    hdr,
    *,
    exposure=0.0,
    shoulder=0.15,
    linear=0.50,
    angle=0.10,
    toe=0.20,
    toe_num=0.02,
    toe_den=0.30,
    white=11.2,
    saturation=1.0,
    encode="srgb",
    weights="rec709",
    adaptation=None,
):
    """Filmic curve of Hable (2010, "Uncharted 2", GDC): ``F(2x) / F(W)`` with
    ``F(x) = (x(Ax + CB) + DE) / (x(Ax + B) + DF) - E/F`` on ``x = 0.18 * 2^ev L / L_avg``.

    ``A`` shoulder strength, ``B`` linear strength, ``C`` linear angle, ``D`` toe strength,
    ``E/F`` toe numerator/denominator, ``W`` linear white point; defaults are Hable's.

    Example:
        >>> float(tonemap_Hable2010(jnp.ones((1, 1)), encode="linear")[0, 0])
        0.1283...
    """
    x = _prepare(hdr, saturation, encode, weights)
    saturation = static_saturation(saturation)
    check_scalar(exposure, "exposure")
    for name, v in (("shoulder", shoulder), ("linear", linear), ("toe", toe)):
        check_scalar(v, name, lo=0.0)
    check_scalar(angle, "angle", lo=0.0)
    check_scalar(toe_num, "toe_num", lo=0.0)
    check_scalar(toe_den, "toe_den", lo=0.0)
    check_scalar(white, "white", lo=0.0)
    params = dict(
        exposure=exposure,
        shoulder=shoulder,
        linear=linear,
        angle=angle,
        toe=toe,
        toe_num=toe_num,
        toe_den=toe_den,
        white=white,
    )
    return _apply_curve(
        x, params, saturation, adaptation, curve=hable_curve, encode=encode, weights=weights
    )


# ------------------------------------------------------------------ Reinhard & Devlin 2005


@functools.partial(jax.jit, static_argnames=("encode", "weights", "normalize"))
def _reinhard2005(x, intensity, light_adapt, color_adapt, *, encode, weights, normalize):
    L, kind = split_luminance(x, weights)
    C = x if kind == "rgb" else (L[..., None] if kind == "single" else L[..., None])
    delta = 1e-6 * jnp.mean(L, axis=(-2, -1), keepdims=True) + 1e-30
    logL = jnp.log(L + delta)
    log_mean = jnp.mean(logL, axis=(-2, -1), keepdims=True)
    lmin = jnp.min(logL, axis=(-2, -1), keepdims=True)
    lmax = jnp.max(logL, axis=(-2, -1), keepdims=True)
    k = safe_div(lmax - log_mean, lmax - lmin, fill=0.5)
    m = 0.3 + 0.7 * safe_pow(k, 1.4)
    f = jnp.exp(-intensity)
    chan_mean = jnp.mean(C, axis=(-3, -2), keepdims=True)
    gray_mean = jnp.mean(L, axis=(-2, -1), keepdims=True)[..., None]
    glob = color_adapt * chan_mean + (1.0 - color_adapt) * gray_mean
    local = color_adapt * C + (1.0 - color_adapt) * L[..., None]
    adapt = light_adapt * local + (1.0 - light_adapt) * glob
    y = safe_div(C, C + safe_pow(f * adapt, m[..., None]))
    if normalize:
        lo = jnp.min(y, axis=(-3, -2, -1), keepdims=True)
        hi = jnp.max(y, axis=(-3, -2, -1), keepdims=True)
        y = safe_div(y - lo, hi - lo)
    if kind == "lum":
        y = y[..., 0]
    return encode_display(y, encode)


def tonemap_Reinhard2005(
    hdr,
    *,
    intensity=0.0,
    light_adapt=1.0,
    color_adapt=0.0,
    normalize=True,
    encode="srgb",
    weights="rec709",
):
    """Photoreceptor model of Reinhard & Devlin (IEEE TVCG 2005), the operator behind
    OpenCV's ``TonemapReinhard``.

    Per channel ``C / (C + (exp(-f) I_a)^m)``: the adaptation ``I_a`` mixes the pixel's channel
    and luminance (``color_adapt``) and its local and image-mean values (``light_adapt``);
    the contrast ``m = 0.3 + 0.7 k^1.4`` follows the log-key ``k = (log L_max - log L_avg) /
    (log L_max - log L_min)``. Then min-max normalised to [0, 1] (``normalize=True``, as the
    paper and OpenCV).

    Args:
        intensity: ``f`` in [-8, 8] (brightness; higher = brighter).
        light_adapt: ``c`` in [0, 1] (1 = fully local adaptation per pixel).
        color_adapt: ``a`` in [0, 1] (1 = each channel adapts on its own).

    Example:
        >>> float(tonemap_Reinhard2005(jnp.array([[0.0, 1.0]]), encode="linear")[0, 1])
        1.0
    """
    x = check_hdr(hdr)
    check_encode(encode)
    check_weights(weights)
    check_scalar(intensity, "intensity", lo=-8.0, hi=8.0, lo_open=False, hi_open=False)
    check_scalar(light_adapt, "light_adapt", lo=0.0, hi=1.0, lo_open=False, hi_open=False)
    check_scalar(color_adapt, "color_adapt", lo=0.0, hi=1.0, lo_open=False, hi_open=False)
    return _reinhard2005(
        x,
        intensity,
        light_adapt,
        color_adapt,
        encode=encode,
        weights=weights,
        normalize=bool(normalize),
    )
