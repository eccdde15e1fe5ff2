"""Argument validation at the Python boundary (before tracing).

These helpers raise ``ValueError`` / ``TypeError`` naming the argument and what was expected.
They only inspect static information (shapes, dtypes, Python scalars), so they are safe to
call at the top of a public function that may itself be traced by ``jax.jit``: concrete values
are checked when available (NaN/Inf, sign), tracers are let through.
"""

from __future__ import annotations

from collections.abc import Iterable

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "as_float_array",
    "check_image",
    "check_choice",
    "check_positive",
    "check_nonnegative",
    "check_finite",
    "check_odd_int",
    "check_positive_int",
    "is_concrete",
    "host_float_array",
]


def is_concrete(x) -> bool:
    """True when ``x`` holds actual values (not a tracer inside jit/grad/vmap)."""
    return not isinstance(x, jax.core.Tracer)


def host_float_array(x, name: str, dtype=None):
    """``x`` as a floating NumPy array when it is host data (a list, tuple or NumPy array);
    ``None`` for a JAX array, a tracer or a Python number (whose JAX array is weakly typed,
    which NumPy cannot express). Errors as :func:`as_float_array`."""
    if isinstance(x, (str, bytes)) or x is None:
        raise TypeError(f"{name}: expected an array of numbers, got {type(x).__name__}")
    if isinstance(x, (jax.Array, jax.core.Tracer, int, float, complex)):
        return None
    if isinstance(x, (list, tuple)) and any(
        isinstance(leaf, (jax.Array, jax.core.Tracer)) for leaf in jax.tree_util.tree_leaves(x)
    ):
        return None  # a list of JAX arrays or tracers: stacked by JAX (traced values stay)
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError) as e:
        raise TypeError(f"{name}: expected an array of numbers ({e})") from None
    if arr.dtype == np.bool_:
        raise TypeError(f"{name}: expected a numeric array, got a boolean array")
    if arr.dtype.kind not in "iufc":
        raise TypeError(f"{name}: expected an array of numbers, got dtype {arr.dtype}")
    if dtype is not None:
        return arr.astype(dtype)
    if arr.dtype.kind not in "f":
        arr = arr.astype(np.float32)
    return arr


def as_float_array(x, name: str, *, dtype=None):
    """Convert ``x`` to a floating JAX array; integers become float32 (values unchanged).

    Host data (lists, tuples, NumPy arrays) is converted with NumPy before it becomes a JAX
    array, so a scene or model built from a description compiles nothing here (JAX compiles
    each eager operation once per shape: a dtype conversion per parameter otherwise)."""
    host = host_float_array(x, name, dtype)
    if host is not None:  # device_put: jnp.asarray of a NumPy array compiles a copy per shape
        return jax.device_put(host)
    arr = jnp.asarray(x)
    if arr.dtype == jnp.bool_:
        raise TypeError(f"{name}: expected a numeric array, got a boolean array")
    if dtype is not None:
        return arr.astype(dtype)
    if not jnp.issubdtype(arr.dtype, jnp.floating):
        arr = arr.astype(jnp.float32)
    return arr


def check_image(
    image,
    name: str = "image",
    *,
    min_ndim: int = 2,
    channels: int | Iterable[int] | None = None,
    allow_nonfinite: bool = False,
):
    """Validate an image ``(..., H, W)`` or ``(..., H, W, C)`` and return it as a float array.

    ``channels``: if given, the last axis must have one of these sizes (the image must then be
    at least 3-d). Non-finite values raise unless ``allow_nonfinite`` (only checked on concrete
    arrays).
    """
    arr = as_float_array(image, name)
    if arr.ndim < min_ndim:
        raise ValueError(
            f"{name}: expected at least {min_ndim} dimensions (..., H, W[, C]), "
            f"got shape {arr.shape}"
        )
    if channels is not None:
        allowed = (channels,) if isinstance(channels, int) else tuple(channels)
        if arr.ndim < 3 or arr.shape[-1] not in allowed:
            raise ValueError(
                f"{name}: expected shape (..., H, W, C) with C in {allowed}, got shape {arr.shape}"
            )
    if arr.size == 0:
        raise ValueError(f"{name}: expected a non-empty image, got shape {arr.shape}")
    if not allow_nonfinite:
        check_finite(arr, name)
    return arr


def check_finite(x, name: str):
    """Raise ``ValueError`` if a concrete ``x`` holds NaN or Inf."""
    if is_concrete(x):
        a = np.asarray(x)
        if np.issubdtype(a.dtype, np.floating) and not np.all(np.isfinite(a)):
            n_bad = int(np.size(a) - np.count_nonzero(np.isfinite(a)))
            raise ValueError(f"{name}: expected finite values, found {n_bad} NaN/Inf entries")
    return x


def check_choice(value, name: str, choices: Iterable[str]):
    """Raise ``ValueError`` unless ``value`` is one of ``choices``."""
    choices = tuple(choices)
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name}: expected one of {choices}, got {value!r}")
    return value


def _check_sign(x, name, ok, what):
    if is_concrete(x):
        a = np.asarray(x)
        if a.dtype == object or not np.issubdtype(a.dtype, np.number):
            raise TypeError(f"{name}: expected a number, got {type(x).__name__}")
        if not np.all(np.isfinite(a)) or not np.all(ok(a)):
            raise ValueError(f"{name}: expected {what}, got {x!r}")
    return x


def check_positive(x, name: str):
    """Raise ``ValueError`` unless a concrete ``x`` is finite and > 0 (tracers pass)."""
    return _check_sign(x, name, lambda a: a > 0, "a finite value > 0")


def check_nonnegative(x, name: str):
    """Raise ``ValueError`` unless a concrete ``x`` is finite and >= 0 (tracers pass)."""
    return _check_sign(x, name, lambda a: a >= 0, "a finite value >= 0")


def check_positive_int(x, name: str):
    """Raise ``ValueError`` unless ``x`` is a positive Python ``int`` (``bool`` refused)."""
    if isinstance(x, bool) or not isinstance(x, int) or x < 1:
        raise ValueError(f"{name}: expected a positive integer, got {x!r}")
    return x


def check_odd_int(x, name: str, *, minimum: int = 1):
    """Raise unless ``x`` is a Python/NumPy integer, odd, and >= ``minimum``."""
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)):
        raise TypeError(f"{name}: expected an odd integer, got {type(x).__name__}")
    if x < minimum or x % 2 != 1:
        raise ValueError(f"{name}: expected an odd integer >= {minimum}, got {x}")
    return int(x)
