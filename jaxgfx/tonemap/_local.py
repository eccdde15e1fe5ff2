"""Local (spatially varying) tone-mapping operators: Reinhard's dodging and burning, the
lecture's contrast inversion, Durand & Dorsey's bilateral base/detail split and Fattal's
gradient-domain compression."""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._math import safe_div, safe_log, safe_pow, safe_sqrt
from ..image.filters import bilateral_filter, gaussian_blur
from ._common import (
    LOG_DELTA,
    check_encode,
    check_hdr,
    check_scalar,
    check_weights,
    encode_display,
    image_mean,
    log_average,
    recolor,
    split_luminance,
    static_saturation,
    stats_or_default,
)
from ._poisson import divergence, forward_gradients, solve_poisson_neumann

__all__ = [
    "tonemap_Reinhard2002_local",
    "tonemap_contrast_inversion",
    "tonemap_Durand2002",
    "tonemap_Fattal2002",
]

_ALPHA1 = 1.0 / (2.0 * math.sqrt(2.0))  # Reinhard 2002: centre Gaussian alpha_1
_RATIO = 1.6  # centre/surround ratio and scale step


def _blur(L, sigma, **kw):
    return gaussian_blur(L[..., None], sigma, **kw)[..., 0]


def gaussian_stack(L, sigmas):
    """Gaussian blurs of ``L (..., H, W)`` at several static ``sigmas`` -> ``(n, ..., H, W)``.

    One FFT of the symmetrically padded image (pad ``ceil(3 max sigma)``), one product with
    each Gaussian's transfer function and a batched inverse FFT: the cost of ``n`` large blurs
    is about that of one (XLA's CPU convolution is slow). The transfer functions are the DFTs
    of the sampled, normalised kernels (truncated at 3 sigma), so the result equals the
    spatial convolution with reflect padding (no ringing for sigma < 1 px)."""
    H, W = L.shape[-2:]
    R = int(math.ceil(3.0 * max(sigmas)))
    pad = [(0, 0)] * (L.ndim - 2) + [(R, R), (R, R)]
    P = jnp.pad(L, pad, mode="symmetric")
    Hp, Wp = P.shape[-2:]
    F = jnp.fft.rfft2(P)

    def kernel(n, sigma, real):
        d = np.minimum(np.arange(n), n - np.arange(n)).astype(np.float64)
        r = max(1, int(math.ceil(3.0 * sigma)))
        k = np.where(d <= r, np.exp(-0.5 * (d / sigma) ** 2), 0.0)
        k /= k.sum()
        return (np.fft.rfft(k) if real else np.fft.fft(k)).real

    T = np.stack([np.outer(kernel(Hp, s, False), kernel(Wp, s, True)) for s in sigmas])
    T = jnp.asarray(T.reshape((len(sigmas),) + (1,) * (L.ndim - 2) + T.shape[-2:]), L.dtype)
    out = jnp.fft.irfft2(F[None] * T, s=(Hp, Wp))
    return out[..., R : R + H, R : R + W].astype(L.dtype)


def _prepare(hdr, saturation, encode, weights):
    x = check_hdr(hdr)
    check_scalar(saturation, "saturation", lo=0.0)
    check_encode(encode)
    check_weights(weights)
    return x


# ------------------------------------------------------------ Reinhard 2002 local


@functools.partial(jax.jit, static_argnames=("num_scales", "encode", "weights"))
def _reinhard_local(x, key, phi, epsilon, saturation, adaptation, *, num_scales, encode, weights):
    L, kind = split_luminance(x, weights)
    la, _ = stats_or_default(L, adaptation)
    Lm = key * safe_div(L, la)
    V1 = gaussian_stack(Lm, [_ALPHA1 * _RATIO**i / math.sqrt(2.0) for i in range(num_scales + 1)])
    sel = V1[0]
    alive = jnp.ones(Lm.shape, bool)
    for i in range(num_scales):
        s = _RATIO**i
        V = (V1[i] - V1[i + 1]) / (jnp.exp2(phi) * key / (s * s) + V1[i])
        ok = alive & (jnp.abs(V) < epsilon)
        sel = jnp.where(ok, V1[i], sel)
        alive = ok
    Ld = Lm / (1.0 + sel)
    return encode_display(recolor(x, L, Ld, saturation, kind), encode)


def tonemap_Reinhard2002_local(
    hdr,
    *,
    key=0.18,
    phi=8.0,
    epsilon=0.05,
    num_scales=8,
    saturation=1.0,
    encode="srgb",
    weights="rec709",
    adaptation=None,
):
    """Photographic tone reproduction with automatic dodging and burning (Reinhard, Stark,
    Shirley & Ferwerda, SIGGRAPH 2002, eqs. 5-9).

    ``L_m = a L / L_avg``; centre ``V_1(s)`` and surround ``V_2(s) = V_1(1.6 s)`` are Gaussian
    blurs of ``L_m`` (``sigma = s / 4``, scales ``s = 1.6^i``, ``i < num_scales``). The
    activity ``V = (V_1 - V_2) / (2^phi a / s^2 + V_1)`` picks, per pixel, the largest scale
    ``s_m`` whose whole neighbourhood is free of strong contrast (``|V| < epsilon``);
    ``L_d = L_m / (1 + V_1(s_m))``: a pixel darker than its surround is dodged (brightened),
    a brighter one burnt. The scale choice is piecewise constant, so ``phi`` and ``epsilon``
    have zero gradient almost everywhere; ``key`` is smooth.

    Args:
        key: ``a`` > 0. phi: sharpening ``phi`` (paper: 8). epsilon: threshold (0.05).
        num_scales: static number of scales (8 spans 1..27 px; surround up to 43 px).
        saturation, encode, weights, adaptation: see :func:`tonemap_Drago2003`.

    Example:
        >>> y = tonemap_Reinhard2002_local(jnp.ones((4, 4)), encode="linear")
        >>> round(float(y[0, 0]), 5)  # flat image: 0.18 / (1 + 0.18)
        0.15254
    """
    x = _prepare(hdr, saturation, encode, weights)
    saturation = static_saturation(saturation)
    check_scalar(key, "key", lo=0.0)
    check_scalar(phi, "phi")
    check_scalar(epsilon, "epsilon", lo=0.0)
    if isinstance(num_scales, bool) or not isinstance(num_scales, int) or num_scales < 1:
        raise ValueError(f"num_scales: expected an int >= 1, got {num_scales!r}")
    return _reinhard_local(
        x,
        key,
        phi,
        epsilon,
        saturation,
        adaptation,
        num_scales=num_scales,
        encode=encode,
        weights=weights,
    )


# ------------------------------------------------------------ contrast inversion (lecture 2)


@functools.partial(jax.jit, static_argnames=("radius", "encode", "weights"))
def _contrast_inversion(x, k, strength, sigma, saturation, *, radius, encode, weights):
    L, kind = split_luminance(x, weights)
    Lw = safe_div(L, log_average(L))
    # the offset keeps B^c smooth at B = 0 (black neighbourhoods); scale invariant like Lw
    blur = _blur(Lw, sigma, radius=radius) + LOG_DELTA * image_mean(Lw)
    y = safe_div(Lw, k * safe_pow(blur, strength))
    Ld = y / (1.0 + y)
    return encode_display(recolor(x, L, Ld, saturation, kind), encode)


def tonemap_contrast_inversion(
    hdr,
    *,
    k=4.0,
    strength=0.3,
    sigma=8.0,
    radius=None,
    saturation=1.0,
    encode="srgb",
    weights="rec709",
):
    """The lecture's contrast inversion, order-keeping: ``y = L_w / (k * B^c)``,
    ``L_d = y / (1 + y)``, with ``B = blur_sigma(L_w)`` and ``L_w = L / L_avg``.

    The lecture divides each pixel by ``k`` times its Gaussian-blurred neighbourhood
    (``c = 1``): next to a bright source the surround is pushed darker than the flat level --
    the "contrast inversion" painters (Kuindzhi) use to make the sun look brighter than the sky.
    But with ``c = 1`` every flat region goes to the same ``1/k``, so the order of whole
    regions is lost (a window larger than ``sigma`` ends as dark as the wall, its border
    darker). Here the division is partial, ``B^c`` with ``0 < c <= 1``: a flat region at
    ``L_w = v`` goes to ``y = v^(1-c) / k`` (a global power-law compression that keeps the
    order of regions), and the surround of a source ``S`` times brighter is still darkened by
    about ``(f S)^-c`` (``f``: the source's share of the blur window). ``y / (1 + y)`` replaces
    the lecture's clipping, so bright regions stay ordered instead of all saturating. Zeros stay
    black.

    Args:
        k: > 0; the log-average maps to ``1 / (1 + k)`` (4: 0.2, a mid grey).
        strength: ``c`` in (0, 1]: how much of the neighbourhood is divided out (1: the
            lecture's formula, order of regions lost; default 0.3).
        sigma: > 0, blur in pixels; may be traced when ``radius`` (static) is given.
        radius: static blur radius (default ``ceil(3 sigma)``).

    Example:
        >>> float(tonemap_contrast_inversion(jnp.ones((5, 5)), encode="linear")[2, 2])
        0.2
    """
    x = _prepare(hdr, saturation, encode, weights)
    saturation = static_saturation(saturation)
    check_scalar(k, "k", lo=0.0)
    check_scalar(strength, "strength", lo=0.0, hi=1.0, hi_open=False)
    check_scalar(sigma, "sigma", lo=0.0)
    if radius is None:
        if isinstance(sigma, jax.core.Tracer):
            raise ValueError("radius: sigma is traced; pass a static radius=int")
        radius = max(1, int(math.ceil(3.0 * float(sigma))))
    return _contrast_inversion(
        x, k, strength, sigma, saturation, radius=int(radius), encode=encode, weights=weights
    )


# ------------------------------------------------------------ Durand & Dorsey 2002

_DURAND_DELTA = 1e-4  # zeros sit 4 decades below the mean luminance


@functools.partial(
    jax.jit, static_argnames=("sigma_spatial", "method", "range_bins", "encode", "weights")
)
def _durand(
    x, contrast, sigma_range, saturation, *, sigma_spatial, method, range_bins, encode, weights
):
    L, kind = split_luminance(x, weights)
    delta = _DURAND_DELTA * image_mean(L) + 1e-30
    logL = jnp.log10(L + delta)
    if method == "grid":
        base = bilateral_filter(
            logL[..., None], sigma_spatial, sigma_range, method="grid", range_bins=range_bins
        )[..., 0]
    else:
        radius = max(1, int(round(1.5 * sigma_spatial)))
        base = bilateral_filter(
            logL[..., None], sigma_spatial, sigma_range, method="brute", radius=radius
        )[..., 0]
    detail = logL - base
    bmax = jnp.max(base, axis=(-2, -1), keepdims=True)
    bmin = jnp.min(base, axis=(-2, -1), keepdims=True)
    # compress, never expand: a base spanning less than log10(contrast) decades (a constant
    # image: only rounding noise of the grid) keeps its contrast instead of being stretched
    cf = jnp.minimum(safe_div(jnp.log10(contrast), bmax - bmin, fill=1.0), 1.0)
    # L / (L + delta): exact zeros come back to black (the offset only keeps the log finite)
    Ld = jnp.power(10.0, (base - bmax) * cf + detail) * safe_div(L, L + delta)
    return encode_display(recolor(x, L, Ld, saturation, kind), encode)


def lum_shape(x):
    """Shape of the luminance ``(..., H, W)`` of an operator input."""
    return x.shape[:-1] if (x.ndim >= 3 and x.shape[-1] in (1, 3)) else x.shape


def durand_range_bins(x, sigma_range):
    """Static number of range cells: covers ``log10(L + delta)`` of any image of this size
    (``max L <= H W mean L``, ``delta = 1e-4 mean L``)."""
    H, W = lum_shape(x)[-2:]
    n = H * W
    span = math.log10(n / _DURAND_DELTA + 1.0)
    return max(1, int(math.ceil(span / float(sigma_range)))) + 1


def tonemap_Durand2002(
    hdr,
    *,
    contrast=5.0,
    sigma_spatial=None,
    sigma_range=0.4,
    method="grid",
    range_bins=None,
    saturation=1.0,
    encode="srgb",
    weights="rec709",
):
    """Fast bilateral filtering for the display of HDR images (Durand & Dorsey, SIGGRAPH 2002).

    In ``log10`` luminance the bilateral filter splits a *base* layer (large-scale
    illumination, edges kept) from the *detail* (texture, reflectance). Only the base is
    compressed, to a contrast of ``contrast : 1``, and the detail is added back::

        log L_d = (base - max base) * min(1, log10(contrast) / (max base - min base)) + detail

    so the brightest base value maps to 1; a base spanning less than ``contrast`` is kept,
    not stretched (a constant image is white).

    Args:
        contrast: > 1, target contrast of the base layer (paper and pfstmo: 5).
        sigma_spatial: spatial sigma in pixels (static); default 2% of the larger image side
            (the paper's choice).
        sigma_range: > 0, range sigma in log10 units (0.4); may be traced with ``range_bins``
            (``"grid"``) -- the default covers every image of this size.
        method: ``"grid"`` (bilateral grid, Chen et al. 2007: cost independent of sigmas) or
            ``"brute"`` (exact, ``jaxgfx.image.bilateral_filter``; slow for large sigmas).
        range_bins: static range cells of the grid.
        saturation, encode, weights: see :func:`tonemap_Drago2003`.

    The logarithm is taken of ``L + delta``, ``delta = 1e-4 * mean(L)``, and the result is
    multiplied by ``L / (L + delta)``: exact zeros display black.

    Example:
        >>> float(tonemap_Durand2002(jnp.ones((4, 4)), encode="linear")[0, 0])
        1.0
    """
    x = _prepare(hdr, saturation, encode, weights)
    saturation = static_saturation(saturation)
    check_scalar(contrast, "contrast", lo=1.0)
    check_scalar(sigma_range, "sigma_range", lo=0.0)
    if method not in ("grid", "brute"):
        raise ValueError(f"method: expected 'grid' or 'brute', got {method!r}")
    L_shape = lum_shape(x)
    if sigma_spatial is None:
        sigma_spatial = max(1.0, 0.02 * max(L_shape[-2:]))
    if isinstance(sigma_spatial, jax.core.Tracer):
        raise ValueError("sigma_spatial: expected a concrete number (it sets the grid size)")
    check_scalar(sigma_spatial, "sigma_spatial", lo=0.0)
    if method == "grid" and range_bins is None:
        if isinstance(sigma_range, jax.core.Tracer):
            raise ValueError("range_bins: sigma_range is traced; pass a static range_bins=int")
        range_bins = durand_range_bins(x, sigma_range)
    return _durand(
        x,
        contrast,
        sigma_range,
        saturation,
        sigma_spatial=float(sigma_spatial),
        method=method,
        range_bins=None if range_bins is None else int(range_bins),
        encode=encode,
        weights=weights,
    )


# ------------------------------------------------------------ Fattal, Lischinski & Werman 2002


def _downsample(H):
    b = _blur(H, 1.0, radius=2)
    return b[..., ::2, ::2]


def _central_grad_mag(H, level):
    Hp = jnp.pad(H, [(0, 0)] * (H.ndim - 2) + [(1, 1), (1, 1)], mode="edge")
    gx = (Hp[..., 1:-1, 2:] - Hp[..., 1:-1, :-2]) / 2.0 ** (level + 1)
    gy = (Hp[..., 2:, 1:-1] - Hp[..., :-2, 1:-1]) / 2.0 ** (level + 1)
    return gx * gx + gy * gy


def fattal_levels(H: int, W: int, min_size: int = 32) -> int:
    """Gaussian-pyramid levels of the attenuation: the coarsest level keeps >= ``min_size``
    pixels on its shorter side (Fattal et al.: "at least 32 x 32")."""
    n = min(H, W)
    return max(1, int(math.floor(math.log2(max(n, 1) / min_size))) + 1) if n >= min_size else 1


def _quantile_hw(y, q):
    flat = y.reshape(y.shape[:-2] + (-1,))
    return jnp.quantile(flat, q, axis=-1)[..., None, None]


@functools.partial(jax.jit, static_argnames=("levels", "screen", "encode", "weights"))
def _fattal(
    x,
    alpha,
    beta,
    gamma,
    noise,
    black_point,
    white_point,
    saturation,
    *,
    levels,
    screen,
    encode,
    weights,
):
    L, kind = split_luminance(x, weights)
    delta = 1e-4 * image_mean(L) + 1e-30
    H0 = safe_log(L + delta)
    pyr = [H0]
    for _ in range(1, levels):
        pyr.append(_downsample(pyr[-1]))
    Phi = None
    for k in reversed(range(levels)):
        m2 = _central_grad_mag(pyr[k], k)
        mag = safe_sqrt(m2)
        a = alpha * (jnp.mean(mag, axis=(-2, -1), keepdims=True) + 1e-6)
        phi = jnp.power(jnp.sqrt(m2 + (noise * a) ** 2) / a, beta - 1.0)
        if Phi is None:
            Phi = phi
        else:
            Phi = jax.image.resize(Phi, phi.shape, "linear") * phi
    gx, gy = forward_gradients(H0)
    Gx, Gy = gx * Phi, gy * Phi
    # global compression c: the least-squares scale of grad H0 onto G; I = c H0 + J, where J
    # integrates what is left, screened beyond ~screen_length px (long thin images: no drift)
    axes = (-2, -1)
    c = safe_div(
        jnp.sum(Gx * gx + Gy * gy, axis=axes, keepdims=True),
        jnp.sum(gx * gx + gy * gy, axis=axes, keepdims=True),
    )
    J = solve_poisson_neumann(divergence(Gx - c * gx, Gy - c * gy), screen)
    I = c * (H0 - jnp.mean(H0, axis=axes, keepdims=True)) + J
    # L / (L + delta): exact zeros come back to black (the offset only keeps the log finite)
    Lout = jnp.exp(gamma * (I - jnp.max(I, axis=axes, keepdims=True))) * safe_div(L, L + delta)
    lo = _quantile_hw(Lout, black_point)
    hi = _quantile_hw(Lout, 1.0 - white_point)
    # degenerate (constant or black) images: scale by the upper quantile (white / black)
    Ld = jnp.where(hi > lo, (Lout - lo) / jnp.where(hi > lo, hi - lo, 1.0), safe_div(Lout, hi))
    return encode_display(recolor(x, L, Ld, saturation, kind), encode)


def fattal_screen(H: int, W: int) -> float:
    """Static screening ``1 / l^2`` of the Poisson solve, ``l = max(min(H, W), 32)`` px: small
    on ordinary images (the shorter side), it bounds the random-walk drift of the integrated
    field along the long axis of a thin image (where every attenuated field is integrable)."""
    return 1.0 / float(max(min(H, W), 32)) ** 2


def tonemap_Fattal2002(
    hdr,
    *,
    alpha=0.1,
    beta=0.85,
    gamma=0.8,
    noise=0.01,
    black_point=0.001,
    white_point=0.005,
    saturation=0.8,
    encode="srgb",
    weights="rec709",
):
    """Gradient-domain HDR compression (Fattal, Lischinski & Werman, SIGGRAPH 2002).

    In ``H = log L`` the gradients are attenuated, large ones more than small ones, by
    ``Phi = prod_k up(phi_k)`` over a Gaussian pyramid with
    ``phi_k = (alpha_k / |grad H_k|) (|grad H_k| / alpha_k)^beta`` and ``alpha_k = alpha *
    mean |grad H_k|``; the attenuated field ``G = Phi grad H`` is integrated back by solving
    ``Laplacian(I) = div G`` with Neumann borders, exactly, with a DCT
    (:func:`solve_poisson_neumann`; gradients by implicit differentiation), as
    ``I = c H + J``: ``c`` is the least-squares scale of ``grad H`` onto ``G`` and ``J`` solves
    the screened equation for ``G - c grad H`` (:func:`fattal_screen`), so that thin images do
    not drift. Then ``L_out = exp(gamma I) L / (L + delta)`` (zeros black), normalised so the
    ``black_point`` / ``1 - white_point`` quantiles map to 0 / 1 (pfstmo's defaults: 0.1 %
    and 0.5 %), colour with ``s = 0.8``.

    Args:
        alpha: > 0, gradient magnitude (relative to the mean) left unchanged (paper: 0.1).
        beta: > 0, attenuation exponent (paper 0.8-0.9; < 1 compresses).
        gamma: > 0, global contrast of the result (pfstmo's ``--gamma``).
        noise: >= 0, ``|grad H|`` is replaced by ``sqrt(|grad H|^2 + (noise alpha_k)^2)``:
            caps the amplification of tiny gradients (the paper's division by zero).
        black_point, white_point: quantiles clipped at 0 and 1.
        saturation, encode, weights: see :func:`tonemap_Drago2003`.

    Example:
        >>> float(tonemap_Fattal2002(jnp.ones((4, 4)), encode="linear")[1, 1])  # constant
        1.0
    """
    x = _prepare(hdr, saturation, encode, weights)
    saturation = static_saturation(saturation)
    check_scalar(alpha, "alpha", lo=0.0)
    check_scalar(beta, "beta", lo=0.0)
    check_scalar(gamma, "gamma", lo=0.0)
    check_scalar(noise, "noise", lo=0.0, lo_open=False)
    check_scalar(black_point, "black_point", lo=0.0, hi=0.5, lo_open=False)
    check_scalar(white_point, "white_point", lo=0.0, hi=0.5, lo_open=False)
    L_shape = lum_shape(x)
    levels = fattal_levels(*L_shape[-2:])
    return _fattal(
        x,
        alpha,
        beta,
        gamma,
        noise,
        black_point,
        white_point,
        saturation,
        levels=levels,
        screen=fattal_screen(*L_shape[-2:]),
        encode=encode,
        weights=weights,
    )
