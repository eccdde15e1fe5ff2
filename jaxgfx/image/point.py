"""Point operators: histograms, contrast stretch, gamma, tone curves, histogram equalisation.

A point operator maps every pixel value independently, ``x = f^{-1}(y)`` (lecture 1 of the
course notes). All functions are pure, jittable and vmappable; continuous parameters are
differentiable.

Shape convention (shared by :mod:`jaxgfx.image`): a 2-d array is one grey image ``(H, W)``;
an array with ``ndim >= 3`` is channels-last ``(..., H, W, C)``. A batch of grey images must
therefore carry a trailing channel axis of size 1: ``(B, H, W, 1)``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import as_float_array, check_finite, check_image, check_positive, is_concrete
from .._math import safe_div, safe_pow

__all__ = [
    "histogram",
    "cumulative_histogram",
    "stretch_contrast",
    "gamma_correct",
    "tone_curve_linear",
    "tone_curve_spline",
    "equalize_histogram",
    "equalize_histogram_soft",
    "adjust_brightness_contrast",
]


def _to_hwc(x):
    """Return ``(x3, gray)`` where ``x3`` is ``(..., H, W, C)`` (grey images get C = 1)."""
    if x.ndim == 2:
        return x[..., None], True
    return x, False


def _check_bins(bins):
    if isinstance(bins, bool) or not isinstance(bins, (int, np.integer)):
        raise TypeError(f"bins: expected a positive integer, got {type(bins).__name__}")
    if bins < 1:
        raise ValueError(f"bins: expected a positive integer, got {bins}")
    return int(bins)


def _check_range(range_):
    try:
        lo, hi = (float(v) for v in range_)
    except (TypeError, ValueError):
        raise ValueError(f"range: expected a pair of numbers (lo, hi), got {range_!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
        raise ValueError(f"range: expected finite lo < hi, got {range_!r}")
    return lo, hi


def _bin_index(x, lo, hi, bins):
    """Bin index in ``[0, bins)`` (``hi`` falls in the last bin) and an in-range mask."""
    t = (x - lo) / (hi - lo) * bins
    idx = jnp.clip(jnp.floor(t), 0, bins - 1).astype(jnp.int32)
    valid = (x >= lo) & (x <= hi)
    return idx, valid


def _histogram_hwc(x3, lo, hi, bins):
    """Per-image, per-channel counts of ``x3 (..., H, W, C)`` → ``(..., bins, C)`` int32."""
    *batch, h, w, c = x3.shape
    n_img = int(np.prod(batch, dtype=np.int64))
    flat = x3.reshape(n_img, h * w, c)
    idx, valid = _bin_index(flat, lo, hi, bins)
    group = jnp.arange(n_img)[:, None, None] * (bins * c) + idx * c + jnp.arange(c)
    counts = jax.ops.segment_sum(
        valid.astype(jnp.int32).ravel(), group.ravel(), num_segments=n_img * bins * c
    )
    return counts.reshape(*batch, bins, c)


@functools.partial(jax.jit, static_argnums=(1, 2, 3, 4))
def _cumulative(x, lo, hi, bins, normalize):
    """Histogram (``normalize=None``) or cumulative histogram of a checked image (jitted)."""
    x3, gray = _to_hwc(x)
    h = _histogram_hwc(x3, lo, hi, bins)
    h = h[..., 0] if gray else h
    if normalize is None:
        return h
    axis = 0 if h.ndim == 1 else -2
    c = jnp.cumsum(h, axis=axis)
    if normalize:
        total = jnp.take(c, -1, axis=axis)
        total = total if h.ndim == 1 else total[..., None, :]
        c = safe_div(c.astype(x.dtype), total.astype(x.dtype))
    return c


def histogram(image, *, bins=256, range=(0.0, 1.0)):  # noqa: A002 (NumPy's name)
    """Per-channel intensity histogram (counts), like ``numpy.histogram`` per channel.

    Bins are ``bins`` equal intervals of ``range = (lo, hi)``; each bin is half-open
    ``[e_k, e_{k+1})`` except the last, which includes ``hi``. Values outside ``range`` are not
    counted (NumPy's rule).

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``.
        bins: number of bins (static).
        range: ``(lo, hi)`` with ``lo < hi`` (static Python numbers).

    Returns:
        int32 counts: ``(bins,)`` for a grey ``(H, W)`` image, else ``(..., bins, C)``
        (one histogram per image of the batch and per channel). Not differentiable (use
        :func:`equalize_histogram` for the CDF-based mapping).

    Example:
        >>> histogram(jnp.array([[0.0, 0.2], [0.7, 1.0]]), bins=2).tolist()
        [2, 2]
    """
    x = check_image(image)
    bins = _check_bins(bins)
    lo, hi = _check_range(range)
    return _cumulative(x, lo, hi, bins, None)


def cumulative_histogram(image, *, bins=256, range=(0.0, 1.0), normalize=False):  # noqa: A002
    """Cumulative histogram: ``H_k = sum_{j <= k} h_j`` (same shapes as :func:`histogram`).

    With ``normalize=True`` the counts are divided by the total number of in-range values of
    each histogram, giving the empirical CDF sampled at the right bin edges (float, in [0, 1]).

    Example:
        >>> cumulative_histogram(jnp.array([[0.0, 0.2], [0.7, 1.0]]), bins=2).tolist()
        [2, 4]
    """
    x = check_image(image)
    bins = _check_bins(bins)
    lo, hi = _check_range(range)
    return _cumulative(x, lo, hi, bins, bool(normalize))


def _check_fraction(v, name):
    if is_concrete(v):
        a = np.asarray(v)
        if a.ndim != 0 or not np.issubdtype(a.dtype, np.number):
            raise TypeError(f"{name}: expected a scalar number, got {v!r}")
        if not (0.0 <= float(a) <= 1.0):
            raise ValueError(f"{name}: expected a fraction in [0, 1], got {v!r}")
    return v


def stretch_contrast(image, *, low=0.05, high=0.95, per_channel=False, clip=True):
    """Linear contrast stretch between the ``low`` and ``high`` quantiles (the n% rule).

    ``out = (y - y_lo) / (y_hi - y_lo)`` where ``y_lo, y_hi`` are the ``low`` / ``high``
    quantiles of each image (``jnp.quantile``, linear interpolation), taken over all channels
    together (keeps hue) or, with ``per_channel=True``, per channel (a crude white balance).
    The darkest ``low`` fraction maps to 0, the brightest ``1 - high`` fraction to 1; with
    ``clip=True`` the result is clipped to [0, 1]. A flat image (``y_hi == y_lo``) maps to 0
    with zero gradient. ``low = 0, high = 1`` is the min–max stretch of the lecture formula
    ``f^{-1}(y) = (y - y_min) · 255 / (y_max - y_min)`` (here scaled to [0, 1]).

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``; each image of the batch is stretched alone.
        low, high: quantile fractions, ``0 <= low < high <= 1``.

    Returns:
        Array of the input shape and dtype; differentiable w.r.t. ``image``.

    Example:
        >>> stretch_contrast(jnp.array([[1.0, 2.0], [3.0, 5.0]]), low=0.0, high=1.0).tolist()
        [[0.0, 0.25], [0.5, 1.0]]
    """
    x = check_image(image)
    _check_fraction(low, "low")
    _check_fraction(high, "high")
    if is_concrete(low) and is_concrete(high) and not float(low) < float(high):
        raise ValueError(f"low, high: expected low < high, got low={low!r}, high={high!r}")
    x3, gray = _to_hwc(x)
    out = _stretch(x3, low, high, bool(per_channel), bool(clip))
    return out[..., 0] if gray else out


@functools.partial(jax.jit, static_argnums=(3, 4))
def _stretch(x3, low, high, per_channel, clip):
    axes = (-3, -2) if per_channel else (-3, -2, -1)
    q = jnp.stack([jnp.asarray(low, x3.dtype), jnp.asarray(high, x3.dtype)])
    lo, hi = jnp.quantile(x3, q, axis=axes, keepdims=True)
    out = safe_div(x3 - lo, hi - lo)
    if clip:
        out = jnp.clip(out, 0.0, 1.0)
    return out


def gamma_correct(image, gamma, *, gain=1.0):
    """Gamma correction ``y = c · x^γ`` (``c = gain``); negative inputs map to 0.

    Args:
        image: any shape, linear values ``x >= 0``.
        gamma: exponent ``γ > 0`` (scalar or broadcastable, e.g. per channel ``(C,)``).
            ``γ = 1/2.2`` encodes linear light for a 2.2 display.
        gain: multiplier ``c``.

    Returns:
        Same shape as the broadcast of the inputs. Gradients w.r.t. ``image``, ``gamma`` and
        ``gain`` are finite everywhere; at ``x = 0`` the value is 0 and all gradients are 0
        (the one-sided derivative ``γ x^{γ-1}`` is infinite there for ``γ < 1``).

    Example:
        >>> float(gamma_correct(0.25, 0.5, gain=2.0))
        1.0
    """
    x = as_float_array(image, "image")
    check_finite(x, "image")
    check_positive(gamma, "gamma")
    if is_concrete(gain):
        check_finite(as_float_array(gain, "gain"), "gain")
    return _gamma(x, gamma, gain)


@jax.jit
def _gamma(x, gamma, gain):
    return gain * safe_pow(x, gamma)


def _check_curve(xs, ys):
    xs = as_float_array(xs, "xs")
    ys = as_float_array(ys, "ys")
    if xs.ndim != 1 or xs.shape[0] < 2:
        raise ValueError(f"xs: expected a 1-d array of at least 2 knots, got shape {xs.shape}")
    if ys.shape != xs.shape:
        raise ValueError(f"ys: expected shape {xs.shape} (same as xs), got {ys.shape}")
    check_finite(xs, "xs")
    check_finite(ys, "ys")
    if is_concrete(xs) and not np.all(np.diff(np.asarray(xs)) > 0):
        raise ValueError("xs: expected strictly increasing knot positions")
    return xs, ys


def tone_curve_linear(image, xs, ys):
    """Piecewise-linear tone curve through the control points ``(xs[k], ys[k])``.

    ``out = ys[k] + (x - xs[k]) (ys[k+1] - ys[k]) / (xs[k+1] - xs[k])`` for
    ``xs[k] <= x <= xs[k+1]``; constant ``ys[0]`` / ``ys[-1]`` outside ``[xs[0], xs[-1]]``.
    The curve is monotone exactly when ``ys`` is (non-decreasing ``ys`` → order-preserving
    curve); parameterise ``ys`` as a cumulative sum of softplus increments to enforce it in an
    optimisation.

    Args:
        image: any shape.
        xs: ``(K,)`` strictly increasing knot positions, ``K >= 2``.
        ys: ``(K,)`` knot values.

    Returns:
        Same shape as ``image``; differentiable w.r.t. ``image``, ``xs`` and ``ys``.

    Example:
        >>> xs, ys = jnp.array([0.0, 0.5, 1.0]), jnp.array([0.0, 0.8, 1.0])
        >>> round(float(tone_curve_linear(0.25, xs, ys)), 6)
        0.4
    """
    x = as_float_array(image, "image")
    check_finite(x, "image")
    xs, ys = _check_curve(xs, ys)
    dtype = jnp.result_type(x, xs, ys)
    return jnp.interp(x.astype(dtype), xs.astype(dtype), ys.astype(dtype))


def _pchip_slopes(xs, ys):
    """Fritsch–Carlson (1980) slopes as in SciPy's ``PchipInterpolator`` (Fritsch–Butland
    weighted harmonic mean inside, the three-point shape-preserving rule at the ends)."""
    h = jnp.diff(xs)
    delta = jnp.diff(ys) / h
    if xs.shape[0] == 2:
        return jnp.stack([delta[0], delta[0]])
    h0, h1 = h[:-1], h[1:]
    d0, d1 = delta[:-1], delta[1:]
    w1 = 2.0 * h1 + h0
    w2 = h1 + 2.0 * h0
    same = d0 * d1 > 0
    # (w1 + w2) / (w1/d0 + w2/d1) written without divisions by the deltas.
    den = jnp.where(same, w1 * d1 + w2 * d0, 1.0)
    inner = jnp.where(same, (w1 + w2) * d0 * d1 / den, 0.0)

    def edge(ha, hb, da, db):
        d = ((2.0 * ha + hb) * da - ha * db) / (ha + hb)
        d = jnp.where(jnp.sign(d) != jnp.sign(da), 0.0, d)
        big = (jnp.sign(da) != jnp.sign(db)) & (jnp.abs(d) > jnp.abs(3.0 * da))
        return jnp.where(big, 3.0 * da, d)

    first = edge(h[0], h[1], delta[0], delta[1])
    last = edge(h[-1], h[-2], delta[-1], delta[-2])
    return jnp.concatenate([first[None], inner, last[None]])


def tone_curve_spline(image, xs, ys):
    """Monotone cubic (PCHIP) tone curve through ``(xs[k], ys[k])``.

    Piecewise cubic Hermite interpolation with the Fritsch–Carlson slopes (Fritsch & Carlson,
    "Monotone piecewise cubic interpolation", SIAM J. Numer. Anal. 1980; slope formulas as in
    SciPy's ``PchipInterpolator``): C¹, passes through every knot, and monotone on every
    interval where the data are, so a non-decreasing ``ys`` gives a non-decreasing curve without
    the overshoot of a natural cubic spline. Outside ``[xs[0], xs[-1]]`` the curve is constant
    (``ys[0]`` / ``ys[-1]``), unlike SciPy, which extrapolates the end cubics.

    Args:
        image: any shape.
        xs: ``(K,)`` strictly increasing, ``K >= 2`` (``K = 2`` gives the straight line).
        ys: ``(K,)`` knot values.

    Returns:
        Same shape as ``image``; differentiable w.r.t. ``image`` and ``ys`` (and ``xs``).

    Example:
        >>> float(tone_curve_spline(0.5, jnp.array([0.0, 1.0]), jnp.array([0.0, 2.0])))
        1.0
    """
    x = as_float_array(image, "image")
    check_finite(x, "image")
    xs, ys = _check_curve(xs, ys)
    dtype = jnp.result_type(x, xs, ys)
    return _pchip_eval(x.astype(dtype), xs.astype(dtype), ys.astype(dtype))


@jax.jit
def _pchip_eval(x, xs, ys):
    m = _pchip_slopes(xs, ys)
    xc = jnp.clip(x, xs[0], xs[-1])
    k = jnp.clip(jnp.searchsorted(xs, xc, side="right") - 1, 0, xs.shape[0] - 2)
    x0, x1 = xs[k], xs[k + 1]
    y0, y1 = ys[k], ys[k + 1]
    h = x1 - x0
    t = (xc - x0) / h
    t2, t3 = t * t, t * t * t
    h00 = 2 * t3 - 3 * t2 + 1
    h10 = t3 - 2 * t2 + t
    h01 = -2 * t3 + 3 * t2
    h11 = t3 - t2
    return h00 * y0 + h10 * h * m[k] + h01 * y1 + h11 * h * m[k + 1]


def equalize_histogram(image, *, bins=256, per_channel=False):
    """Histogram equalisation: map each value through the image's empirical CDF.

    Same algorithm as ``skimage.exposure.equalize_hist``: a ``bins``-bin histogram over the
    image's own range ``[min, max]``, its normalised cumulative sum ``cdf`` sampled at the bin
    centres, and ``out = interp(x, centres, cdf)``. Output lies in ``(0, 1]`` with an
    approximately uniform histogram. Statistics are over all channels together (as skimage) or,
    with ``per_channel=True``, per channel; each image of a batch is equalised alone. A flat
    image (one value everywhere) maps to 0.5, the middle of the output range, as
    ``skimage.exposure.equalize_hist`` (it has no histogram to equalise).

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``.
        bins: number of histogram bins (static).

    Returns:
        Same shape and dtype as ``image``. The gradient w.r.t. ``image`` is the CDF's
        piecewise-linear slope (the histogram itself is treated as constant).

    Example:
        >>> float(equalize_histogram(jnp.array([[0.0, 1.0], [2.0, 3.0]]), bins=4)[0, 0])
        0.25
    """
    x = check_image(image)
    bins = _check_bins(bins)
    x3, gray = _to_hwc(x)
    out = _equalize(x3, bins, bool(per_channel))
    return out[..., 0] if gray else out


@functools.partial(jax.jit, static_argnums=(1, 2))
def _equalize(x3, bins, per_channel):
    *batch, h, w, c = x3.shape
    # groups of values that share one histogram: (G, N)
    if per_channel:
        g = jnp.moveaxis(x3, -1, -3).reshape(-1, h * w)
    else:
        g = x3.reshape(-1, h * w * c)

    def one(v):
        vs = jax.lax.stop_gradient(v)
        lo, hi = jnp.min(vs), jnp.max(vs)
        flat = hi <= lo
        span = jnp.where(flat, 1.0, hi - lo)
        idx, _ = _bin_index(vs, lo, lo + span, bins)
        counts = jnp.zeros(bins, v.dtype).at[idx].add(1.0)
        cdf = jnp.cumsum(counts) / v.shape[0]
        centres = lo + (jnp.arange(bins, dtype=v.dtype) + 0.5) * (span / bins)
        out = jnp.interp(v, centres, cdf)
        return jnp.where(flat, jnp.full_like(out, 0.5), out)

    out = jax.vmap(one)(g)
    if per_channel:
        out = jnp.moveaxis(out.reshape(*batch, c, h, w), -3, -1)
    else:
        out = out.reshape(x3.shape)
    return out


def equalize_histogram_soft(image, bandwidth, *, bins=256, per_channel=False):
    """Differentiable histogram equalisation through a Gaussian-kernel CDF.

    Replaces the empirical CDF by its kernel-smoothed version
    ``F(t) = (1/N) sum_j Φ((t - x_j) / h)`` (``Φ`` the standard normal CDF, ``h`` =
    ``bandwidth``), evaluated on ``bins`` equally spaced points spanning the image's
    ``[min, max]`` and linearly interpolated: ``out = interp(x, t_k, F(t_k))``. Unlike
    :func:`equalize_histogram` the result is differentiable w.r.t. every pixel *through the
    histogram* and w.r.t. ``h``; as ``h → 0`` it tends to the empirical CDF (hard
    equalisation). Cost ``O(N · bins)`` per image.

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``.
        bandwidth: kernel width ``h > 0`` in image units (e.g. 1/256 to 1/32 for [0, 1] data).
        bins: number of evaluation points of ``F`` (static, >= 2).
        per_channel: one CDF per channel instead of one for all channels together.

    Example:
        >>> y = equalize_histogram_soft(jnp.array([[0.0, 1.0], [2.0, 3.0]]), 1e-3, bins=4)
        >>> y.tolist()
        [[0.125, 0.375], [0.625, 0.875]]
    """
    x = check_image(image)
    check_positive(bandwidth, "bandwidth")
    bins = _check_bins(bins)
    if bins < 2:
        raise ValueError(f"bins: expected an integer >= 2, got {bins}")
    x3, gray = _to_hwc(x)
    out = _equalize_soft(x3, jnp.asarray(bandwidth, x3.dtype), bins, bool(per_channel))
    return out[..., 0] if gray else out


@functools.partial(jax.jit, static_argnums=(2, 3))
def _equalize_soft(x3, h, bins, per_channel):
    *batch, hh, ww, c = x3.shape
    if per_channel:
        g = jnp.moveaxis(x3, -1, -3).reshape(-1, hh * ww)
    else:
        g = x3.reshape(-1, hh * ww * c)

    def one(v):
        lo, hi = jnp.min(v), jnp.max(v)
        span = jnp.where(hi > lo, hi - lo, 1.0)
        t = lo + span * jnp.linspace(0.0, 1.0, bins, dtype=v.dtype)
        cdf = jnp.mean(jax.scipy.special.ndtr((t[:, None] - v[None, :]) / h), axis=1)
        return jnp.interp(v, t, cdf)

    out = jax.vmap(one)(g)
    if per_channel:
        return jnp.moveaxis(out.reshape(*batch, c, hh, ww), -3, -1)
    return out.reshape(x3.shape)


def adjust_brightness_contrast(image, brightness, contrast, *, pivot=0.5):
    """Linear brightness/contrast: ``out = (x - pivot) · contrast + pivot + brightness``.

    ``contrast = 1, brightness = 0`` is the identity; ``contrast > 1`` expands values around
    ``pivot`` (mid-grey by default), ``brightness`` is an additive offset in image units. No
    clipping. Differentiable in all arguments; ``brightness``/``contrast`` may be per-channel.

    Example:
        >>> round(float(adjust_brightness_contrast(0.75, 0.1, 2.0)), 6)
        1.1
    """
    x = as_float_array(image, "image")
    check_finite(x, "image")
    for v, n in ((brightness, "brightness"), (contrast, "contrast"), (pivot, "pivot")):
        if is_concrete(v):
            check_finite(as_float_array(v, n), n)
    return _brightness_contrast(x, brightness, contrast, pivot)


@jax.jit
def _brightness_contrast(x, brightness, contrast, pivot):
    return (x - pivot) * contrast + pivot + brightness
