"""Validation and normalisation of exposure stacks (Python boundary, before tracing)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._checks import check_finite, is_concrete

__all__ = ["prepare_stack", "code_max_for", "normalize_stack"]


def code_max_for(dtype) -> float:
    """Largest code value for an image dtype: 255 (uint8), 65535 (uint16), 1.0 (floats)."""
    dt = np.dtype(dtype)
    if dt == np.uint8:
        return 255.0
    if dt == np.uint16:
        return 65535.0
    if np.issubdtype(dt, np.floating):
        return 1.0
    raise TypeError(f"images: expected uint8, uint16 or float pixels, got dtype {dt}")


def prepare_stack(
    images, exposure_times, *, min_frames: int = 1, sort: bool = True, raw: bool = False
):
    """Check a bracketed stack and return ``(z, t, code_max, squeeze)``.

    ``images``: ``(N, H, W, C)`` or ``(N, H, W)`` array, or a sequence of N equally shaped
    frames; uint8, uint16 or floats in ``[0, 1]``. ``exposure_times``: ``(N,)`` seconds > 0.
    Returns normalised levels ``z`` of shape ``(N, H, W, C)`` in ``[0, 1]`` (float32, or
    float64 for float64 input), times ``t`` ``(N,)`` sorted ascending (frames reordered
    with them when ``sort``), the code maximum and whether a channel axis was added.
    With ``raw=True`` the frames are returned unconverted and unsorted (integer codes stay
    integers; see :func:`normalize_stack`, which does the rest inside jit).
    """
    if isinstance(images, (list, tuple)):
        if len(images) == 0:
            raise ValueError("images: expected at least one frame, got an empty sequence")
        shapes = {tuple(np.shape(im)) for im in images}
        if len(shapes) != 1:
            raise ValueError(
                f"images: all frames must have the same shape (H, W[, C]), got {sorted(shapes)}"
            )
        dtypes = {np.dtype(getattr(im, "dtype", np.asarray(im).dtype)) for im in images}
        if len(dtypes) != 1:
            raise TypeError(
                f"images: all frames must share one dtype, got {sorted(map(str, dtypes))}"
            )
        images = jnp.stack([jnp.asarray(im) for im in images])
    if isinstance(images, (str, bytes)) or images is None:
        raise TypeError(f"images: expected an array, got {type(images).__name__}")
    images = jnp.asarray(images)
    if images.dtype == jnp.bool_:
        raise TypeError("images: expected uint8, uint16 or float pixels, got bool")
    code_max = code_max_for(images.dtype)
    if images.ndim not in (3, 4):
        raise ValueError(
            f"images: expected shape (N, H, W) or (N, H, W, C), got shape {images.shape}"
        )
    if images.size == 0:
        raise ValueError(f"images: expected a non-empty stack, got shape {images.shape}")
    squeeze = images.ndim == 3
    if squeeze:
        images = images[..., None]
    n = images.shape[0]
    if n < min_frames:
        raise ValueError(f"images: this method needs at least {min_frames} exposures, got N={n}")
    if isinstance(exposure_times, (str, bytes)) or exposure_times is None:
        raise TypeError(f"exposure_times: expected an array of N={n} times in seconds")
    t = jnp.asarray(exposure_times)
    if not jnp.issubdtype(t.dtype, jnp.floating):
        t = t.astype(jnp.float32)
    if t.ndim != 1 or t.shape[0] != n:
        raise ValueError(
            f"exposure_times: expected shape ({n},) matching the {n} frames, got {t.shape}"
        )
    if not is_concrete(t):
        # traced (jit / grad / vmap): the same check inside the program, raised at run time
        t = eqx.error_if(
            t,
            ~jnp.all(jnp.isfinite(t) & (t > 0)),
            "exposure_times: expected finite values > 0 seconds",
        )
    if is_concrete(t):
        a = np.asarray(t)
        if not np.all(np.isfinite(a)) or np.any(a <= 0):
            raise ValueError(f"exposure_times: expected finite values > 0 seconds, got {a}")
        if min_frames >= 2 and np.unique(a).size < 2:
            raise ValueError(
                "exposure_times: response recovery needs at least 2 distinct exposure times, "
                f"got {a}"
            )
    if jnp.issubdtype(images.dtype, jnp.floating):
        z = images
        check_finite(z, "images")
        if is_concrete(z):
            a = np.asarray(z)
            if a.min() < 0 or a.max() > 1:
                raise ValueError(
                    "images: float pixels must be normalised to [0, 1], "
                    f"got range [{a.min():.4g}, {a.max():.4g}]"
                )
    elif raw:
        z = images
    else:
        ftype = jnp.float64 if t.dtype == jnp.float64 else jnp.float32
        z = images.astype(ftype) / code_max
    if raw:
        return z, t, code_max, squeeze
    t = t.astype(z.dtype)
    if sort:
        order = jnp.argsort(t)
        t = t[order]
        z = z[order]
    return z, t, code_max, squeeze


def normalize_stack(images, t, code_max):
    """Traced counterpart of ``prepare_stack(raw=True)``: levels to ``[0, 1]`` and frames
    sorted by ascending time. Returns ``(z, t)``."""
    if jnp.issubdtype(images.dtype, jnp.floating):
        z = images
    else:
        ftype = jnp.float64 if t.dtype == jnp.float64 else jnp.float32
        z = images.astype(ftype) / code_max
    t = t.astype(z.dtype)
    order = jnp.argsort(t)
    return z[order], t[order]
