"""RAW sensor calibration from bracketed exposures: black/white levels, linearity, exposure
ratios, and a gathered, JSON-reportable :class:`RawCalibration`.

Conventions: a *mosaic* is a raw Bayer frame ``(..., H, W)`` in DN; ``cfa_channels`` splits it
into ``C = 4`` half-resolution planes ordered by position in the 2x2 tile
(``(0,0), (0,1), (1,0), (1,1)``; for ``"RGGB"``: R, G1, G2, B). Without a CFA pattern a stack
is ``(N, H, W)`` (one channel) or ``(N, H, W, C)``. Normalised signal is
``y = (raw - black) / (white - black)``. Every estimate comes with a standard error.
References: EMVA 1288 release 4.0 (2021) for black level, saturation and linearity; Janesick,
*Photon Transfer* (SPIE 2007); Robertson, Borman & Stevenson (2003) and Grossberg & Nayar
(2003) for exposure ratios from image pairs; Huber (1964) for the robust weights.
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_choice, check_finite, is_concrete
from jaxgfx._math import safe_div, safe_log, safe_sqrt
from jaxgfx.hdr.noise import NoiseModel, fit_noise_from_bracket, fit_photon_transfer
from jaxgfx.image.bayer import BAYER_PATTERNS

__all__ = [
    "CFA_PATTERNS",
    "cfa_channels",
    "cfa_channel_names",
    "Measurement",
    "WhiteLevel",
    "Linearity",
    "ExposureRatios",
    "RawCalibration",
    "estimate_black_level",
    "estimate_white_level",
    "linearity_check",
    "pairwise_exposure_ratio",
    "estimate_exposure_ratios",
    "calibrate_raw_stack",
]

CFA_PATTERNS = BAYER_PATTERNS  # the Bayer tiles of jaxgfx.image.bayer (one list)


def _jsonable(x):
    """Array -> nested lists with NaN/Inf as None (strict JSON)."""
    a = np.asarray(x)
    if a.dtype == bool:
        return a.tolist()
    a = a.astype(float)
    if a.ndim == 0:
        v = float(a)
        return v if math.isfinite(v) else None
    return [_jsonable(v) for v in a]


def cfa_channel_names(pattern: str = "RGGB") -> tuple[str, ...]:
    """Names of the 4 planes of ``cfa_channels``: ``"RGGB" -> ("R", "G1", "G2", "B")``."""
    check_choice(pattern, "cfa_pattern", CFA_PATTERNS)
    names, ng = [], 0
    for ch in pattern:
        if ch == "G":
            ng += 1
            names.append(f"G{ng}")
        else:
            names.append(ch)
    return tuple(names)


def cfa_channels(mosaic, pattern: str = "RGGB"):
    """Split a Bayer mosaic ``(..., H, W)`` (H, W even) into planes ``(..., H/2, W/2, 4)``.

    Plane ``k`` holds the pixels at position ``(k // 2, k % 2)`` of each 2x2 tile, i.e. the
    pattern's letters in order (``cfa_channel_names``). Pure indexing: jittable, differentiable.

    Example: ``cfa_channels(jnp.arange(16.).reshape(4, 4))[0, 0] -> [0, 1, 4, 5]``.
    """
    check_choice(pattern, "cfa_pattern", CFA_PATTERNS)
    m = as_float_array(mosaic, "mosaic")
    if m.ndim < 2 or m.shape[-1] % 2 or m.shape[-2] % 2 or m.shape[-1] == 0:
        raise ValueError(f"mosaic: expected (..., H, W) with even H and W, got shape {m.shape}")
    planes = [m[..., i::2, j::2] for i in (0, 1) for j in (0, 1)]
    return jnp.stack(planes, axis=-1)


def _channels(stack, name, cfa_pattern, *, min_frames=1):
    """Canonical ``(N, H, W, C)`` float stack."""
    arr = as_float_array(stack, name)
    if cfa_pattern is not None:
        if arr.ndim == 2:
            arr = arr[None]
        if arr.ndim != 3:
            raise ValueError(f"{name}: expected mosaics (N, H, W), got shape {arr.shape}")
        arr = cfa_channels(arr, cfa_pattern)
    else:
        if arr.ndim == 3:
            arr = arr[..., None]
        if arr.ndim != 4:
            raise ValueError(f"{name}: expected (N, H, W) or (N, H, W, C), got shape {arr.shape}")
    if arr.shape[0] < min_frames:
        raise ValueError(f"{name}: expected at least {min_frames} frames, got {arr.shape[0]}")
    if arr.size == 0:
        raise ValueError(f"{name}: expected a non-empty stack, got shape {arr.shape}")
    check_finite(arr, name)
    return arr


def _levels(black, white, c, dtype):
    if black is None:
        raise ValueError("black: expected a black level (scalar or per channel), got None")
    if white is None:
        raise ValueError("white: expected a white level (scalar or per channel), got None")
    b = as_float_array(black, "black")
    w = as_float_array(white, "white")
    if b.ndim > 1 or b.size not in (1, c):
        raise ValueError(f"black: expected a scalar or ({c},) array, got shape {b.shape}")
    if w.ndim > 1 or w.size not in (1, c):
        raise ValueError(f"white: expected a scalar or ({c},) array, got shape {w.shape}")
    b = jnp.broadcast_to(b.astype(dtype), (c,))
    w = jnp.broadcast_to(w.astype(dtype), (c,))
    if is_concrete(b) and is_concrete(w) and np.any(np.asarray(w) <= np.asarray(b)):
        raise ValueError(f"white: expected white > black per channel, got {w} vs {b}")
    return b, w


def _times(times, name, n):
    t = as_float_array(times, name)
    if t.shape != (n,):
        raise ValueError(f"{name}: expected shape ({n},) (one per frame), got {t.shape}")
    if is_concrete(t) and not np.all(np.asarray(t) > 0):
        raise ValueError(f"{name}: expected exposure times > 0, got {np.asarray(t)}")
    return t


# ---------------------------------------------------------------------------------------------
# result containers


class Measurement(eqx.Module):
    """A measured quantity ``value`` with its standard error ``se`` (same shape)."""

    value: jax.Array
    se: jax.Array

    def to_dict(self) -> dict:
        return {"value": _jsonable(self.value), "se": _jsonable(self.se)}


class WhiteLevel(eqx.Module):
    """Saturation level estimate.

    ``value``/``se``: median and its standard error of the piled-up top values where ``saturated``;
    elsewhere ``value`` is the observed maximum (a lower bound on the white level) and ``se``
    is NaN. ``fraction``: share of pixels in the pile-up.
    """

    value: jax.Array
    se: jax.Array
    saturated: jax.Array
    fraction: jax.Array

    def to_dict(self) -> dict:
        return {
            "value": _jsonable(self.value),
            "se": _jsonable(self.se),
            "saturated": _jsonable(self.saturated),
            "fraction": _jsonable(self.fraction),
        }


class Linearity(eqx.Module):
    """Per-channel line fit of mean normalised signal vs exposure time (see ``linearity_check``)."""

    slope: jax.Array
    slope_se: jax.Array
    intercept: jax.Array
    intercept_se: jax.Array
    r2: jax.Array
    max_rel_deviation: jax.Array
    is_linear: jax.Array
    means: jax.Array
    n_pixels: jax.Array
    tolerance: float = eqx.field(static=True, default=0.01)

    def to_dict(self) -> dict:
        out = {k: _jsonable(getattr(self, k)) for k in _LIN_KEYS}
        out["criterion"] = (
            f"max relative deviation from the line <= {self.tolerance} and "
            f"|intercept| <= {self.tolerance} * largest mean"
        )
        return out


_LIN_KEYS = (
    "slope",
    "slope_se",
    "intercept",
    "intercept_se",
    "r2",
    "max_rel_deviation",
    "is_linear",
    "means",
    "n_pixels",
)


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
# black level


@functools.partial(jax.jit, static_argnames=("iterations",))
def _sigma_clipped_mean(x, n_sigma, iterations=5):
    """Per column of ``x (M, C)``: sigma-clipped mean, its s.e., and the kept count."""

    def one(v):
        med = jnp.median(v)
        mad = 1.4826 * jnp.median(jnp.abs(v - med))
        scale = jnp.where(mad > 0, mad, jnp.std(v))
        center = med
        keep = jnp.ones_like(v, bool)
        for _ in range(iterations):
            keep = jnp.abs(v - center) <= n_sigma * scale
            n = jnp.sum(keep)
            center = safe_div(jnp.sum(jnp.where(keep, v, 0.0)), n)
            var = safe_div(jnp.sum(jnp.where(keep, (v - center) ** 2, 0.0)), n - 1.0)
            scale = jnp.where(var > 0, safe_sqrt(var), scale)
        n = jnp.sum(keep)
        var = safe_div(jnp.sum(jnp.where(keep, (v - center) ** 2, 0.0)), n - 1.0)
        return center, safe_sqrt(safe_div(var, n)), n

    return jax.vmap(one, in_axes=1)(x)


def estimate_black_level(
    dark_frames_or_masked_pixels, *, per_channel_pattern: str | None = "RGGB", n_sigma=3.0
) -> Measurement:
    """Black (offset) level from dark frames or optically masked pixels, robustly.

    Sigma-clipped mean (EMVA 1288 sec. 8 uses the dark mean): start from the median and
    ``1.4826 * MAD``, then 5 rounds of keeping ``|x - center| <= n_sigma * std`` and re-estimating
    mean and std from the kept pixels. Hot pixels and cosmic-ray hits are rejected; for Gaussian
    noise the clipped mean is unbiased. ``se = std / sqrt(n_kept)`` (pixels treated as
    independent; spatially correlated fixed-pattern noise makes it optimistic).

    Args:
      dark_frames_or_masked_pixels: with ``per_channel_pattern`` (default ``"RGGB"``): dark
        mosaics ``(..., H, W)`` (H, W even), one estimate per CFA channel ``(4,)``; with
        ``None``: any array, one pooled scalar estimate.
      n_sigma: clipping threshold in standard deviations (> 0).

    Returns:
      ``Measurement(value, se)`` in the data's units (DN).

    Example: 4096 pixels of ``512 + N(0, 3)`` give ``512 +- 0.047``.
    """
    if per_channel_pattern is None:
        x = as_float_array(dark_frames_or_masked_pixels, "dark_frames_or_masked_pixels")
        x = x.reshape(-1, 1)
    else:
        x = as_float_array(dark_frames_or_masked_pixels, "dark_frames_or_masked_pixels")
        if x.ndim < 2 or x.shape[-1] % 2 or x.shape[-2] % 2:
            raise ValueError(
                "dark_frames_or_masked_pixels: expected mosaics (..., H, W) with even H, W for "
                f"per_channel_pattern={per_channel_pattern!r}, got shape {x.shape}"
            )
        x = cfa_channels(x, per_channel_pattern).reshape(-1, 4)
    if x.shape[0] < 3:
        raise ValueError(
            f"dark_frames_or_masked_pixels: expected at least 3 pixels per channel, got {x.shape}"
        )
    check_finite(x, "dark_frames_or_masked_pixels")
    if not isinstance(n_sigma, (int, float)) or not n_sigma > 0:
        raise ValueError(f"n_sigma: expected a number > 0, got {n_sigma!r}")
    value, se, _ = _sigma_clipped_mean(x, float(n_sigma))
    if per_channel_pattern is None:
        value, se = value[0], se[0]
    return Measurement(value, se)


# ---------------------------------------------------------------------------------------------
# white level


@jax.jit
def _pileup(x, tol, min_fraction, min_count, ratio):
    def one(v):
        top = jnp.max(v)
        piled = v >= top - tol
        below = (v >= top - 3 * tol) & ~piled
        n_p = jnp.sum(piled)
        n_b = jnp.sum(below)
        frac = n_p / v.shape[0]
        sat = (frac >= min_fraction) & (n_p >= min_count) & (n_p > ratio * 0.5 * n_b)
        med = jnp.nanmedian(jnp.where(piled, v, jnp.nan))
        mean = safe_div(jnp.sum(jnp.where(piled, v, 0.0)), n_p)
        var = safe_div(jnp.sum(jnp.where(piled, (v - mean) ** 2, 0.0)), n_p - 1.0)
        se = 1.2533 * safe_sqrt(safe_div(var, n_p))  # s.e. of a median (Gaussian pile)
        return (
            jnp.where(sat, med, top),
            jnp.where(sat, se, jnp.nan),
            sat,
            jnp.where(sat, frac, 0.0),
        )

    return jax.vmap(one, in_axes=1)(x)


def estimate_white_level(
    stack,
    *,
    per_channel_pattern: str | None = None,
    tolerance=None,
    min_fraction: float = 1e-3,
    min_count: int = 16,
    pileup_ratio: float = 4.0,
) -> WhiteLevel:
    """Saturation (white) level from the histogram pile-up at the top of a bracketed stack.

    Clipped pixels pile up at (or within noise of) one value at the top of the histogram. With
    ``M`` the maximum and ``tol`` the tolerance, the data are declared saturated when the pile
    ``[M - tol, M]`` holds at least ``min_fraction`` of the pixels and ``min_count`` pixels, and
    is more than ``pileup_ratio`` times denser than the band ``[M - 3 tol, M - tol)`` below it
    (a smooth unclipped tail has a *falling* density towards its maximum). The white level is
    the median of the pile (the clip code itself for hard clipping, where unclipped values
    just below it fall in the pile too), with ``se = 1.2533 std / sqrt(n)``.
    Data that never saturate report ``saturated = False``, ``value = M`` (a lower bound) and
    ``se = NaN``. (EMVA 1288 sec. 6.5 defines saturation from the same pile-up.)

    Args:
      stack: frames ``(N, H, W)`` / ``(N, H, W, C)``, or mosaics ``(N, H, W)`` with
        ``per_channel_pattern``; all frames are pooled, so the brightest frames supply the pile.
      tolerance: width of the pile in data units; default ``2e-3 * M``.

    Returns:
      ``WhiteLevel(value, se, saturated, fraction)``, each ``(C,)``.
    """
    x = _channels(stack, "stack", per_channel_pattern)
    c = x.shape[-1]
    x = x.reshape(-1, c)
    if tolerance is None:
        tol = 2e-3 * jnp.max(jnp.abs(x))
    else:
        tol = as_float_array(tolerance, "tolerance")
        if is_concrete(tol) and not np.all(np.asarray(tol) >= 0):
            raise ValueError(f"tolerance: expected >= 0, got {tolerance!r}")
    value, se, sat, frac = _pileup(x, tol, min_fraction, min_count, pileup_ratio)
    return WhiteLevel(value, se, sat, frac)


# ---------------------------------------------------------------------------------------------
# linearity


@jax.jit
def _linearity_core(y, t, saturation, min_signal, tol):
    # y: (N, M, C) normalised, t: (N,)
    valid = jnp.all((y > min_signal) & (y < saturation), axis=0)  # (M, C)
    n_pix = jnp.sum(valid, axis=0)
    means = safe_div(jnp.sum(jnp.where(valid[None], y, 0.0), axis=1), n_pix)  # (N, C)
    n = t.shape[0]
    tm = jnp.mean(t)
    sxx = jnp.sum((t - tm) ** 2)
    mm = jnp.mean(means, axis=0)
    slope = jnp.sum((t - tm)[:, None] * (means - mm), axis=0) / sxx
    icpt = mm - slope * tm
    fit = slope * t[:, None] + icpt
    ssr = jnp.sum((means - fit) ** 2, axis=0)
    sst = jnp.sum((means - mm) ** 2, axis=0)
    s2 = ssr / (n - 2)
    slope_se = jnp.sqrt(s2 / sxx)
    icpt_se = jnp.sqrt(s2 * (1.0 / n + tm**2 / sxx))
    r2 = 1.0 - safe_div(ssr, sst)
    dev = jnp.max(jnp.abs(safe_div(means - fit, fit)), axis=0)
    is_lin = (dev <= tol) & (jnp.abs(icpt) <= tol * jnp.max(means, axis=0)) & (n_pix > 0)
    return slope, slope_se, icpt, icpt_se, r2, dev, is_lin, means, n_pix


def linearity_check(
    stack,
    exposure_times,
    *,
    black,
    white,
    cfa_pattern: str | None = None,
    saturation: float = 0.95,
    min_signal: float = 0.02,
    tolerance: float = 0.01,
) -> Linearity:
    """Per-channel linearity of mean signal vs exposure time (EMVA 1288 sec. 6.6 style).

    Pixels are kept when their normalised signal ``y = (raw - black) / (white - black)`` lies in
    ``(min_signal, saturation)`` in *every* frame (unsaturated and above the noise), so each
    frame's mean ``m_k`` is over the same pixels and a scene (not only a flat field) can be
    used. An ordinary least-squares line ``m_k = slope * t_k + intercept`` is fitted per channel,
    with standard errors from the residual variance (``N - 2`` dof; needs ``N >= 3``), ``r2``,
    and the linearity error ``max_k |m_k - fit_k| / fit_k``.

    ``is_linear``: max relative deviation ``<= tolerance`` (default 1 %) and
    ``|intercept| <= tolerance * max_k m_k`` (a non-zero intercept means a wrong black level or
    an offset non-linearity), and at least one pixel was usable.

    Returns:
      ``Linearity`` with ``(C,)`` fields (``means``: ``(N, C)``), slope in normalised units
      per unit of ``exposure_times``.
    """
    x = _channels(stack, "stack", cfa_pattern, min_frames=3)
    n, h, w, c = x.shape
    t = _times(exposure_times, "exposure_times", n)
    b, wl = _levels(black, white, c, x.dtype)
    y = ((x - b) / (wl - b)).reshape(n, -1, c)
    out = _linearity_core(y, t.astype(x.dtype), saturation, min_signal, tolerance)
    return Linearity(*out, tolerance=float(tolerance))


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


# ---------------------------------------------------------------------------------------------
# everything together


class RawCalibration(eqx.Module):
    """Everything measured from one bracketed RAW stack (see ``calibrate_raw_stack``)."""

    black: Measurement
    white: WhiteLevel
    linearity: Linearity | None
    ratios: ExposureRatios
    noise: NoiseModel | None
    noise_se: dict | None
    exposure_times: jax.Array
    cfa_pattern: str | None = eqx.field(static=True, default=None)
    black_method: str = eqx.field(static=True, default="given")
    linearity_frames: tuple = eqx.field(static=True, default=())
    linearity_note: str = eqx.field(static=True, default="")
    noise_method: str = eqx.field(static=True, default="")

    def to_dict(self) -> dict:
        """JSON-ready nested dict (NaN/Inf written as ``null``)."""
        names = list(cfa_channel_names(self.cfa_pattern)) if self.cfa_pattern is not None else None
        return {
            "cfa_pattern": self.cfa_pattern,
            "channels": names,
            "exposure_times": _jsonable(self.exposure_times),
            "black_level": {**self.black.to_dict(), "method": self.black_method},
            "white_level": self.white.to_dict(),
            "linearity": None
            if self.linearity is None
            else {**self.linearity.to_dict(), "frames": list(self.linearity_frames)},
            "linearity_note": self.linearity_note,
            "exposure_ratios": self.ratios.to_dict(),
            "noise": None
            if self.noise is None
            else {
                **self.noise.to_dict(),
                **{k: _jsonable(v) for k, v in (self.noise_se or {}).items()},
                "method": self.noise_method,
            },
        }


def calibrate_raw_stack(
    mosaics,
    exposure_times,
    *,
    cfa_pattern: str | None = "RGGB",
    black=None,
    white=None,
    dark_frames=None,
    noise_pairs=None,
    bracket_noise: bool = True,
) -> RawCalibration:
    """Calibrate a camera from a bracketed RAW stack of a static scene.

    Steps (each reported with standard errors):
      1. black level: ``black`` if given; else ``estimate_black_level(dark_frames)`` if dark
         frames are given; else from the stack itself: for each adjacent pair the raw values
         obey ``x_b = r x_a + B (1 - r)``, so an affine fit gives ``B = c / (1 - r)`` (pairs
         combined by inverse variance; assumes a linear sensor and a static scene).
      2. white level: ``white`` if given (se 0), else ``estimate_white_level`` of the stack; a
         stack that never saturates uses its maximum (``saturated`` False in the report).
      3. ``linearity_check`` on the longest run of >= 3 consecutive exposures that share
         >= 64 usable pixels per channel (``linearity_frames``); when there is none the
         report's ``linearity_note`` says why instead of a check on zero pixels,
      4. ``estimate_exposure_ratios`` vs the nominal times,
      5. the noise model in normalised units: ``fit_photon_transfer`` on ``noise_pairs`` (two
         identical exposures per level, ``(2, H, W)`` or ``(P, 2, H, W)`` mosaics) when given;
         otherwise (``bracket_noise``) :func:`jaxgfx.hdr.noise.fit_noise_from_bracket` from the
         bracket itself with the measured ratios, its read variance replaced by the temporal
         variance of ``dark_frames`` when >= 2 are given. ``noise_method`` says which.

    Args:
      mosaics: ``(N, H, W)`` raw mosaics (``cfa_pattern`` set) or ``(N, H, W[, C])`` frames
        (``cfa_pattern=None``).
      exposure_times: ``(N,)`` nominal (EXIF) exposure times in seconds.

    Returns:
      ``RawCalibration`` (``.to_dict()`` for a JSON report).
    """
    if cfa_pattern is not None:
        check_choice(cfa_pattern, "cfa_pattern", CFA_PATTERNS)
    x = _channels(mosaics, "mosaics", cfa_pattern, min_frames=2)
    n, h, w, c = x.shape
    t = _times(exposure_times, "exposure_times", n)
    # white first (it does not need black)
    if white is None:
        wl = estimate_white_level(x)
    else:
        wv = jnp.broadcast_to(as_float_array(white, "white"), (c,))
        wl = WhiteLevel(wv, jnp.zeros_like(wv), jnp.ones(c, bool), jnp.zeros_like(wv))
    black_method = "given"
    if black is not None:
        bv = jnp.broadcast_to(as_float_array(black, "black"), (c,))
        bm = Measurement(bv, jnp.zeros_like(bv))
    elif dark_frames is not None:
        bm = estimate_black_level(dark_frames, per_channel_pattern=cfa_pattern)
        bm = Measurement(jnp.broadcast_to(bm.value, (c,)), jnp.broadcast_to(bm.se, (c,)))
        black_method = "dark_frames"
    else:
        bm = Measurement(*_black_from_pairs(x, t, wl.value))
        black_method = "affine_pairs"
    lin = None
    lin_frames, lin_note = _linearity_window(x, t, bm.value, wl.value)
    if lin_frames:
        idx = np.asarray(lin_frames)
        lin = linearity_check(x[idx], t[idx], black=bm.value, white=wl.value)
    ratios = estimate_exposure_ratios(x, t, black=bm.value, white=wl.value)
    noise = noise_se = None
    noise_method = ""
    if noise_pairs is None and bracket_noise:
        rat = np.asarray(ratios.ratios)
        if np.all(np.isfinite(rat)) and np.all(rat > 0):
            try:
                noise, info = fit_noise_from_bracket(x, rat, black=bm.value, white=wl.value)
            except ValueError as e:
                noise_method = f"not estimated: {e}"
            else:
                noise_se = {
                    k: info[k]
                    for k in (
                        "gain_se",
                        "read_variance_se",
                        "chi2_reduced",
                        "gain_e_per_dn",
                        "gain_e_per_dn_se",
                        "read_noise_dn",
                        "read_noise_dn_se",
                    )
                }
                noise_method = "bracket: variance of y_b - r y_a of adjacent frames"
        else:
            noise_method = "not estimated: an exposure ratio could not be measured"
    if noise is not None and dark_frames is not None:
        dk = _channels(dark_frames, "dark_frames", cfa_pattern, min_frames=1)
        if dk.shape[0] >= 2:  # temporal variance of the darks: read noise without shot noise
            rv = jnp.mean(jnp.var(dk, axis=0, ddof=1), axis=(0, 1)) / (wl.value - bm.value) ** 2
            noise = NoiseModel(noise.gain, rv, noise.black_level, noise.white_level)
            noise_method += "; read variance from the dark frames"
    if noise_pairs is not None:
        noise_method = "flat pairs (photon transfer)"
        pairs = as_float_array(noise_pairs, "noise_pairs")
        if pairs.ndim == 3:
            pairs = pairs[None]
        if pairs.ndim != 4 or pairs.shape[1] != 2:
            raise ValueError(
                f"noise_pairs: expected (2, H, W) or (P, 2, H, W) mosaics, got shape {pairs.shape}"
            )
        if cfa_pattern is not None:
            pairs = cfa_channels(pairs, cfa_pattern)
        else:
            pairs = pairs[..., None]
        noise, info = fit_photon_transfer(pairs, black=bm.value, white=wl.value)
        noise_se = {k: info[k] for k in ("gain_se", "read_variance_se", "chi2_reduced")}
    return RawCalibration(
        black=bm,
        white=wl,
        linearity=lin,
        ratios=ratios,
        noise=noise,
        noise_se=noise_se,
        exposure_times=t,
        cfa_pattern=cfa_pattern,
        black_method=black_method,
        linearity_frames=lin_frames,
        linearity_note=lin_note,
        noise_method=noise_method,
    )


def _linearity_window(x, t, black, white, *, min_signal=0.02, saturation=0.95, min_pixels=64):
    """Frames (input indices, by increasing time) for the linearity check: the longest run of
    >= 3 consecutive exposures with >= ``min_pixels`` pixels per channel inside
    ``(min_signal, saturation)`` in every frame of the run (ties: most pixels). Returns
    ``(frames, note)``; ``frames`` is empty, and ``note`` says why, when no run qualifies."""
    n = x.shape[0]
    if n < 3:
        return (), f"not run: the linearity check needs >= 3 frames, got {n}"
    order = np.argsort(np.asarray(t))
    y = (np.asarray(x)[order] - np.asarray(black)) / (np.asarray(white) - np.asarray(black))
    ok = (y > min_signal) & (y < saturation)  # (N, H, W, C)
    best, best_key = (), (0, -1)
    most = (0, ())
    for i in range(n):
        common = ok[i]
        for j in range(i + 1, n):
            common = common & ok[j]
            cnt = int(common.reshape(-1, common.shape[-1]).sum(axis=0).min())
            if j - i + 1 >= 3 and cnt > most[0]:
                most = (cnt, tuple(int(v) for v in order[i : j + 1]))
            if j - i + 1 >= 3 and cnt >= min_pixels and (j - i + 1, cnt) > best_key:
                best_key = (j - i + 1, cnt)
                best = tuple(int(v) for v in order[i : j + 1])
    if best:
        frames = sorted(best, key=lambda k: float(np.asarray(t)[k]))
        note = (
            f"frames {frames} (input order; by increasing time): the longest run of "
            f"consecutive exposures with >= {min_pixels} pixels per channel in "
            f"({min_signal}, {saturation}) of white in all of them ({best_key[1]} pixels); "
            "times are the nominal ones, so shutter errors show as non-linearity"
        )
        return tuple(frames), note
    return (), (
        f"not run: no 3 consecutive exposures share >= {min_pixels} pixels per channel in "
        f"({min_signal}, {saturation}) of white (best: {most[0]} pixels in frames "
        f"{list(most[1])}); the bracket steps are too large for this scene"
    )


@jax.jit
def _black_from_pairs(x, t, white):
    """Black level from affine fits ``x_b = r x_a + B (1 - r)`` of adjacent frame pairs.

    Per channel and adjacent pair (increasing time): OLS of raw ``x_b`` on raw ``x_a`` over
    pixels usable in both (provisional black = the stack minimum), HC0 sandwich covariance,
    ``B = c / (1 - r)`` with a delta-method variance; pairs combined by inverse variance.
    Regression dilution is negligible when the scene's spread dwarfs the noise.
    """
    lo = jnp.min(x, axis=(0, 1, 2))
    xs = x[jnp.argsort(t)].reshape(x.shape[0], -1, x.shape[-1])
    y = (xs - lo) / (white - lo)
    ok = (y > 0.02) & (y < 0.95)

    def fit(a, b, va, vb):  # (M,) each
        m = (va & vb).astype(a.dtype)
        n = jnp.sum(m)
        am = safe_div(jnp.sum(m * a), n)
        bm = safe_div(jnp.sum(m * b), n)
        sxx = jnp.sum(m * (a - am) ** 2)
        r = safe_div(jnp.sum(m * (a - am) * (b - bm)), sxx)
        c = bm - r * am
        e = m * (b - c - r * a)
        # HC0 covariance of (c, r): (X'X)^-1 X' diag(e^2) X (X'X)^-1
        xtx = jnp.array([[n, jnp.sum(m * a)], [jnp.sum(m * a), jnp.sum(m * a * a)]])
        meat = jnp.array(
            [[jnp.sum(e * e), jnp.sum(e * e * a)], [jnp.sum(e * e * a), jnp.sum(e * e * a * a)]]
        )
        inv = jnp.linalg.inv(xtx)
        cov = inv @ meat @ inv
        one_r = 1.0 - r
        grad = jnp.array([1.0 / one_r, c / one_r**2])
        return c / one_r, grad @ cov @ grad

    f = jax.vmap(jax.vmap(fit, in_axes=(1, 1, 1, 1)), in_axes=(0, 0, 0, 0))
    bk, vk = f(xs[:-1], xs[1:], ok[:-1], ok[1:])  # (N-1, C)
    w = 1.0 / vk
    value = jnp.sum(w * bk, axis=0) / jnp.sum(w, axis=0)
    return value, jnp.sqrt(1.0 / jnp.sum(w, axis=0))
