"""Actual exposure ratios of a bracket from adjacent frame pairs
(:func:`pairwise_exposure_ratio`, :func:`estimate_exposure_ratios`)."""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_choice
from jaxgfx._math import safe_div, safe_log, safe_sqrt
from jaxgfx.hdr.noise import NoiseModel

from ._common import _channels, _jsonable, _levels, _times

__all__ = ["ExposureRatios", "pairwise_exposure_ratio", "estimate_exposure_ratios"]


class ExposureRatios(eqx.Module):
    """Measured exposure ratios ``t_k / t_ref`` with standard errors, vs the nominal ones.

    ``ratios``, ``se``, ``nominal``, ``deviation_stops`` (``log2(measured / nominal)``),
    ``deviation_se_stops``: ``(N,)`` in input frame order. ``pair_ratios``, ``pair_se``,
    ``pair_n``: ``(N-1,)`` adjacent pairs in increasing nominal time (``order``).
    """

    ratios: jax.Array
    se: jax.Array
    nominal: jax.Array
    deviation_stops: jax.Array
    deviation_se_stops: jax.Array
    pair_ratios: jax.Array
    pair_se: jax.Array
    pair_n: jax.Array
    order: jax.Array
    reference: jax.Array

    def to_dict(self) -> dict:
        return {k: _jsonable(v) for k, v in self.__dict__.items()}


# ---------------------------------------------------------------------------------------------
# exposure ratios


def _pair_ratio(ya, yb, va, vb, valid, robust, iters):
    """Ratio ``b / a`` (robust weighted ratio of sums) and its sandwich s.e.

    ``ya, yb``: (M, C) normalised; ``va, vb``: noise-variance callables of frames a, b, or None.
    """
    vmask = valid.astype(ya.dtype)
    r = safe_div(jnp.sum(vmask * yb), jnp.sum(vmask * ya))
    s = jnp.maximum((ya + yb) / (1.0 + r), 0.0)  # pixel level in frame b's units
    if va is not None:
        # GLS-like weights s / var(e): shot noise cancels in cov(ya + yb, yb - r ya), so the
        # weights are nearly independent of the residual.
        var_e = vb(s) + r**2 * va(s / r)
        base = vmask * safe_div(s, var_e)
        sig = safe_sqrt(var_e)
    else:
        # ratio of sums; residuals standardised as Poisson-like (std ~ sqrt(level))
        base = vmask
        sig = safe_sqrt(s)
    w = base
    if robust is not None:
        # Huber start (c = 1.345) then Tukey biweight (c = robust); the scale is the weighted
        # RMS of the standardised residuals (median-free, so r stays smooth in the data)
        def step(it, w):
            r = safe_div(jnp.sum(w * yb), jnp.sum(w * ya))
            u = safe_div(yb - r * ya, sig)
            h = safe_div(w, base)
            scale = safe_sqrt(safe_div(jnp.sum(vmask * h * u * u), jnp.sum(vmask * h)))
            z = safe_div(jnp.abs(u), scale)
            huber = jnp.where(z > 1.345, safe_div(jnp.full_like(z, 1.345), z), 1.0)
            tukey = jnp.where(z < robust, (1.0 - (z / robust) ** 2) ** 2, 0.0)
            return base * jnp.where(it < 2, huber, tukey)

        w = jax.lax.fori_loop(0, iters, step, w)
    r = safe_div(jnp.sum(w * yb), jnp.sum(w * ya))
    e = yb - r * ya
    den = jnp.sum(w * ya)
    se = safe_sqrt(safe_div(jnp.sum((w * e) ** 2), den * den))
    n = jnp.sum(valid)
    # no usable pixel: the ratio is unknown (NaN), not 0
    return jnp.where(n > 0, r, jnp.nan), jnp.where(n > 0, se, jnp.nan), n


def pairwise_exposure_ratio(
    a,
    b,
    *,
    black,
    white,
    noise: NoiseModel | None = None,
    saturation: float = 0.95,
    min_signal: float = 0.01,
    robust: float | None = 4.685,
):
    """Exposure ratio ``t_b / t_a`` of two frames of the same static scene, with its s.e.

    Uses the pixels whose normalised signal is in ``(min_signal, saturation)`` in both frames and
    the ratio-of-sums estimator ``r = sum w y_b / sum w y_a`` (no errors-in-variables bias, unlike
    a regression of ``y_b`` on ``y_a``; it is the Poisson maximum-likelihood ratio when
    ``w = 1``). With a ``noise`` model (in normalised units), ``w = s / var(y_b - r y_a)`` (GLS
    weights, ``s`` the pixel level). Outliers (moving objects, hot pixels) are removed by
    iteratively reweighting: two Huber (1964) steps, then Tukey's biweight with tuning constant
    ``robust`` (in standard deviations of the standardised residual; ``None`` disables). The
    scale is an iterated weighted RMS (median-free), so ``r`` is a smooth function of the images
    away from the selection thresholds: jittable and differentiable in ``a``, ``b``,
    ``black``, ``white`` (the pixel selection itself is piecewise constant). The standard error
    is the sandwich (delta-method) estimate ``sqrt(sum (w e)^2) / sum w y_a``, ``e = y_b - r y_a``.

    Args:
      a, b: frames ``(H, W)`` / ``(H, W, C)`` (raw units), same shape.
      black, white: levels, scalar or ``(C,)``.

    Returns:
      ``(ratio, se, n_pixels)`` scalars; ratio and se are NaN when no pixel is usable.
    """
    a = as_float_array(a, "a")
    b = as_float_array(b, "b")
    if a.shape != b.shape:
        raise ValueError(f"b: expected the shape of a {a.shape}, got {b.shape}")
    if a.ndim == 2:
        a, b = a[..., None], b[..., None]
    if a.ndim != 3:
        raise ValueError(f"a: expected (H, W) or (H, W, C), got shape {a.shape}")
    bl, wl = _levels(black, white, a.shape[-1], a.dtype)
    return _pair_core(a, b, bl, wl, noise, saturation, min_signal, robust=robust)


@functools.partial(jax.jit, static_argnames=("robust",))
def _pair_core(a, b, bl, wl, noise, saturation, min_signal, *, robust):
    c = a.shape[-1]
    ya = ((a - bl) / (wl - bl)).reshape(-1, c)
    yb = ((b - bl) / (wl - bl)).reshape(-1, c)
    return _pair_select_ratio(ya, yb, noise, saturation, min_signal, robust)


def _pair_select_ratio(ya, yb, noise, saturation, min_signal, robust):
    """Select pixels by the level ``s = (y_a + y_b) / (1 + r0)``, not by ``y_a`` and ``y_b``
    themselves: in the shot-noise regime ``s`` is uncorrelated with ``y_b − r y_a``, so the
    selection does not bias the ratio (selecting ``y_a > min_signal`` keeps the pixels whose
    noise pushed ``a`` up: measured −0.8 % on a pair whose short frame peaks at 1.3 % of
    white). ``r0`` is a first ratio over the pixels valid in both frames; truly clipped
    pixels (``y ≥ (1 + saturation) / 2``) are always excluded."""
    first = (ya > min_signal) & (ya < saturation) & (yb > min_signal) & (yb < saturation)
    r0 = safe_div(jnp.sum(jnp.where(first, yb, 0.0)), jnp.sum(jnp.where(first, ya, 0.0)))
    r0 = jnp.where(r0 > 0, r0, 1.0)
    s = (ya + yb) / (1.0 + r0)
    hard = 0.5 * (1.0 + saturation)
    valid = (
        (s > min_signal)
        & (s < saturation)
        & (s * r0 < saturation)
        & (ya < hard)
        & (yb < hard)
        & (s * r0 > min_signal)
    )
    v = None if noise is None else noise.variance
    return _pair_ratio(ya, yb, v, v, valid, robust, iters=6)


def estimate_exposure_ratios(
    stack,
    nominal_times,
    *,
    black,
    white,
    noise: NoiseModel | None = None,
    reference: str = "first",
    cfa_pattern: str | None = None,
    saturation: float = 0.95,
    min_signal: float = 0.01,
    robust: float | None = 4.685,
) -> ExposureRatios:
    """Actual exposure ratios of a bracketed stack, compared with the nominal (EXIF) ones.

    Frames are ordered by nominal time; each adjacent pair gives ``r_k = t_{k+1} / t_k`` with
    ``pairwise_exposure_ratio`` (pixels valid in both frames, all channels pooled). Ratios to
    the reference frame are chained products, ``log R = sum log r``, with variances
    ``sum (se_k / r_k)^2`` (adjacent pairs share a frame; that small correlation is ignored).
    A pair without usable pixels (e.g. both frames saturated) gives NaN for the frames that
    are chained through it.

    Args:
      stack: ``(N, H, W[, C])`` frames or ``(N, H, W)`` mosaics with ``cfa_pattern``; N >= 2.
      nominal_times: ``(N,)`` nominal exposure times (> 0), any order.
      reference: ``"first"`` (input frame 0) or ``"longest"``.

    Returns:
      ``ExposureRatios`` (measured ``ratios`` with ``se``, ``nominal`` ratios and the
      deviation in stops ``log2(measured / nominal)`` with its s.e.).
    """
    check_choice(reference, "reference", ("first", "longest"))
    x = _channels(stack, "stack", cfa_pattern, min_frames=2)
    n, h, w, c = x.shape
    t = _times(nominal_times, "nominal_times", n).astype(x.dtype)
    bl, wl = _levels(black, white, c, x.dtype)
    out = _ratios_core(
        x, t, bl, wl, noise, saturation, min_signal, robust=robust, reference=reference
    )
    return ExposureRatios(*out)


@functools.partial(jax.jit, static_argnames=("robust", "reference"))
def _ratios_core(x, t, bl, wl, noise, saturation, min_signal, *, robust, reference):
    n = x.shape[0]
    order = jnp.argsort(t)
    xs = x[order]

    def pair(a, b):
        return _pair_core(a, b, bl, wl, noise, saturation, min_signal, robust=robust)

    r, se, npx = jax.vmap(pair)(xs[:-1], xs[1:])
    good = r > 0  # False for NaN (pair without usable pixels): NaN propagates down the chain
    logr = jnp.where(good, safe_log(jnp.where(good, r, 1.0)), jnp.nan)
    vlog = safe_div(se, r) ** 2
    cum_l = jnp.concatenate([jnp.zeros(1, x.dtype), jnp.cumsum(logr)])  # sorted positions
    cum_v = jnp.concatenate([jnp.zeros(1, x.dtype), jnp.cumsum(vlog)])
    pos = jnp.argsort(order)  # position of each input frame in sorted order
    ref = jnp.asarray(0) if reference == "first" else jnp.argmax(t)
    log_ratio = cum_l[pos] - cum_l[pos[ref]]
    var_log = jnp.abs(cum_v[pos] - cum_v[pos[ref]])
    ratios = jnp.exp(log_ratio)
    nominal = t / t[ref]
    dev = (log_ratio - jnp.log(nominal)) / np.log(2.0)
    sd_log = safe_sqrt(var_log)
    del n
    return ratios, ratios * sd_log, nominal, dev, sd_log / np.log(2.0), r, se, npx, order, ref
