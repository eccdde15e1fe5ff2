"""Deterministic, stratified pixel sampling for response recovery, and table helpers."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["select_samples", "level_index", "monotone_repair"]


def _stride_for(h, w, max_candidates):
    s = 1
    while (h // s) * (w // s) > max_candidates:
        s += 1
    return s


def select_samples(
    key,
    z,
    *,
    n_samples=2048,
    n_bins=32,
    max_candidates=1 << 16,
    border=2,
    flat_weight=1.0,
    flat_reach=0,
):
    """Pick ``P = n_bins * (n_samples // n_bins)`` pixels per channel for calibration.

    ``z``: ``(N, H, W, C)`` normalised stack. Pixels are stratified by the stack sum
    ``s = Σ_j z_j`` (monotone in scene radiance for a monotone response) into ``n_bins``
    equal-width bins over ``[0, N]``; within each bin the pixels with the smallest local
    gradient of ``s`` (max abs difference to the 4 neighbours, so edges and misregistered
    pixels are avoided) are taken, ties broken by a small uniform jitter from ``key``;
    ``border`` pixels at the image edge are never taken. ``flat_reach > 0`` measures the
    gradient by central differences ``s(p + d) − s(p − d)`` at that distance, which skip the
    pixel itself (so the choice does not favour pixels by their own noise); ``flat_weight``
    scales the gradient against the jitter (0: random within the bin). Candidates are a
    regular sub-grid with at most ``max_candidates`` pixels (cheap on large images).

    Returns ``(samples, valid)``: ``samples`` ``(C, P, N)`` levels and ``valid`` ``(C, P)``
    bool (False where a bin had fewer pixels than its quota).
    """
    n, h, w, c = z.shape
    stride = _stride_for(h, w, max_candidates)
    oy = (h - 1 - ((h - 1) // stride) * stride) // 2
    ox = (w - 1 - ((w - 1) // stride) * stride) // 2
    ys = np.arange(oy, h, stride)
    xs = np.arange(ox, w, stride)

    def at(dy, dx):  # stack sum at the candidates shifted by (dy, dx), edge-clamped
        yy = np.clip(ys + dy, 0, h - 1)
        xx = np.clip(xs + dx, 0, w - 1)
        return jnp.sum(z[:, yy[:, None], xx[None, :], :], axis=0)

    s_c = at(0, 0)  # (h', w', C)
    if flat_reach == 0:
        g_c = (
            jnp.max(
                jnp.stack(
                    [jnp.abs(at(dy, dx) - s_c) for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0))]
                ),
                axis=0,
            )
            / n
        )
    else:  # central differences that skip the pixel itself: no selection on its own noise
        d = flat_reach
        g_c = (
            jnp.max(
                jnp.stack(
                    [
                        jnp.abs(at(dy, dx) - at(-dy, -dx))
                        for dy, dx in ((0, d), (d, 0), (d, d), (d, -d))
                    ]
                ),
                axis=0,
            )
            / n
        )
    b = min(border, (h - 1) // 2, (w - 1) // 2)
    inner = ((ys >= b) & (ys < h - b))[:, None] & ((xs >= b) & (xs < w - b))[None, :]
    in_c = jnp.broadcast_to(jnp.asarray(inner)[..., None], s_c.shape)
    zc = z[:, ys[:, None], xs[None, :], :]  # (N, h', w', C)
    m = s_c.shape[0] * s_c.shape[1]
    jitter = jax.random.uniform(key, (m, c), dtype=z.dtype)
    score = flat_weight * g_c.reshape(m, c) + 1e-3 * jitter
    score = score + jnp.where(in_c.reshape(m, c), 0.0, 10.0)
    bins = jnp.clip(jnp.floor(s_c.reshape(m, c) / n * n_bins), 0, n_bins - 1).astype(jnp.int32)
    per_bin = max(n_samples // n_bins, 1)

    def one_channel(bin_c, score_c, zc_c):
        order = jnp.argsort(bin_c.astype(score_c.dtype) * 100.0 + score_c)
        counts = jnp.bincount(bin_c, length=n_bins)
        starts = jnp.cumsum(counts) - counts
        j = jnp.arange(per_bin)
        pos = starts[:, None] + j[None, :]  # (n_bins, per_bin)
        ok = j[None, :] < counts[:, None]
        idx = order[jnp.clip(pos, 0, m - 1)].reshape(-1)
        return zc_c[:, idx].T, ok.reshape(-1)  # (P, N), (P,)

    zflat = zc.reshape(n, m, c)
    samples, valid = jax.vmap(one_channel, in_axes=(1, 1, 2))(bins, score, zflat)
    return samples, valid


def level_index(z, n_levels):
    """Integer level ``round(z · (n_levels - 1))`` for normalised ``z``."""
    return jnp.clip(jnp.round(z * (n_levels - 1)), 0, n_levels - 1).astype(jnp.int32)


def monotone_repair(g, anchor_index, *, eps=1e-5):
    """Make a log-exposure table ``g`` ``(L, C)`` strictly increasing, working outward from
    the anchor knot: above it a running maximum, below it a running minimum (so a spurious
    value at one end cannot drag the rest of the curve), then ``eps`` per knot is added
    wherever the curve would be flat. Values that already increase are unchanged."""
    up = jax.lax.cummax(g[anchor_index:], axis=0)
    down = jax.lax.cummin(g[: anchor_index + 1][::-1], axis=0)[::-1]
    g = jnp.concatenate([down[:-1], up], axis=0)
    # enforce strictness: g_k >= g_{k-1} + eps via running max of (g_k - k eps)
    k = jnp.arange(g.shape[0], dtype=g.dtype)[:, None]
    h = jax.lax.cummax(g - k * eps, axis=0) + k * eps
    return h
