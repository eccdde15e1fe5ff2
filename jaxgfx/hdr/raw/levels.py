"""Black and white levels: :func:`estimate_black_level` (dark frames / masked pixels),
the affine-pairs estimate from the bracket itself, :func:`estimate_white_level` (the
histogram pile-up), with their result types."""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_finite, is_concrete
from jaxgfx._math import safe_div, safe_sqrt

from ._common import _channels, _jsonable, cfa_channels

__all__ = ["Measurement", "WhiteLevel", "estimate_black_level", "estimate_white_level"]


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
