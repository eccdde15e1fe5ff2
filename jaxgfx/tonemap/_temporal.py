"""Video: temporal smoothing of the adaptation statistics (lecture 2, flicker)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._checks import check_choice
from .._math import safe_log
from ._common import AdaptationStats, check_hdr, check_scalar, image_stats, split_luminance
from ._registry import ADAPTIVE_METHODS, TONEMAP_METHODS

__all__ = ["smooth_adaptation", "smoothed_stats", "flicker"]


@jax.jit
def _ema(stats: AdaptationStats, rate):
    logs = jnp.stack([safe_log(stats.log_average), safe_log(stats.maximum)], -1)  # (T, 2)

    def step(carry, s):
        new = carry + rate * (s - carry)
        return new, new

    _, out = jax.lax.scan(step, logs[0], logs)
    out = jnp.exp(out)
    return AdaptationStats(out[:, 0], out[:, 1])


def smoothed_stats(frames, *, rate=0.1, weights="rec709") -> AdaptationStats:
    """Exponential moving average (in log space) of each frame's adaptation statistics.

    ``s_t = s_{t-1} + rate * (log stat_t - s_{t-1})``, ``s_0 = log stat_0``, for the
    log-average and the maximum luminance, inside ``lax.scan``. ``rate = 1``: no smoothing.

    Args:
        frames: ``(T, H, W, 3)``, ``(T, H, W, 1)`` or ``(T, H, W)`` linear radiance.
        rate: in (0, 1], the weight of the new frame (time constant ~ ``1/rate`` frames).
    """
    x = check_hdr(frames, "frames")
    L, _ = split_luminance(x, weights)
    if L.ndim != 3:
        raise ValueError(f"frames: expected (T, H, W[, C]) video, got shape {x.shape}")
    check_scalar(rate, "rate", lo=0.0, hi=1.0, hi_open=False)
    return _ema(image_stats(L), rate)


def smooth_adaptation(frames, *, method="reinhard", rate=0.1, weights="rec709", **params):
    """Tone map a video with temporally smoothed adaptation (no flicker from one blinking light).

    Per-frame operators adapt to each frame's log-average and maximum; one light switching
    on and off changes both and makes the whole frame pump. Here they are replaced by their
    exponential moving average (:func:`smoothed_stats`) and passed as ``adaptation=`` to the
    operator (lecture 2: "mix the mean luminance with the means of the previous frames").

    Args:
        frames: ``(T, H, W, 3)`` (or single-channel) linear radiance.
        method: one of ``"drago"``, ``"reinhard"``, ``"filmic"``, ``"hable"``,
            ``"reinhard_local"``.
        rate: EMA weight of the new frame, (0, 1].
        params: the operator's parameters.

    Returns:
        ``(T, H, W, C)`` display frames.
    """
    check_choice(method, "method", ADAPTIVE_METHODS)
    stats = smoothed_stats(frames, rate=rate, weights=weights)
    return TONEMAP_METHODS[method](frames, adaptation=stats, weights=weights, **params)


@jax.jit
def _flicker(frames, mask):
    L, _ = split_luminance(frames, "rec709")
    m = jnp.sum(L * mask, axis=(-2, -1)) / jnp.maximum(jnp.sum(mask), 1.0)
    return jnp.mean(jnp.abs(jnp.diff(m)))


def flicker(frames, *, mask=None):
    """Mean absolute frame-to-frame jump of the mean display luminance (0 = steady).

    Args:
        frames: ``(T, H, W, 3)`` / ``(T, H, W)`` display values.
        mask: optional ``(H, W)`` weights selecting the region to measure (e.g. everything but
            the blinking light).
    """
    x = check_hdr(frames, "frames")
    L, _ = split_luminance(x, "rec709")
    if mask is None:
        mask = jnp.ones(L.shape[-2:], x.dtype)
    mask = jnp.asarray(mask, x.dtype)
    if mask.shape != L.shape[-2:]:
        raise ValueError(f"mask: expected shape {L.shape[-2:]}, got {mask.shape}")
    return _flicker(x, mask)
