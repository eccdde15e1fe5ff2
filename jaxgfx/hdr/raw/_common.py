"""Shared pieces of the RAW steps: CFA planes (:mod:`jaxgfx.image.bayer` patterns), the
canonical ``(N, H, W, C)`` stack, level and time checks, strict-JSON arrays."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_choice, check_finite, is_concrete
from jaxgfx.image.bayer import BAYER_PATTERNS

__all__ = ["CFA_PATTERNS", "cfa_channels", "cfa_channel_names"]

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
