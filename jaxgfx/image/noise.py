"""Noise models (additive Gaussian, salt-and-pepper, impulse, Poisson–Gaussian camera noise)
and temporal averaging of bursts.

Randomness only through an explicit ``jax.random`` key (first argument). Pixel-replacement
noises corrupt whole pixels (all channels together) of a channels-last ``(..., H, W, C)``
image unless ``per_channel=True``; a 2-d array is one grey image ``(H, W)``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import (
    as_float_array,
    check_choice,
    check_finite,
    check_image,
    check_nonnegative,
    is_concrete,
)
from .._math import safe_sqrt

__all__ = [
    "add_gaussian_noise",
    "add_salt_and_pepper",
    "add_impulse_noise",
    "add_poisson_gaussian_noise",
    "temporal_average",
    "TEMPORAL_AVERAGE_METHODS",
    "POISSON_GAUSSIAN_METHODS",
]


def _check_amount(amount, name="amount"):
    check_nonnegative(amount, name)
    if is_concrete(amount) and np.any(np.asarray(amount) > 1):
        raise ValueError(f"{name}: expected a fraction in [0, 1], got {amount!r}")
    return amount


def _pixel_shape(x, per_channel):
    """Shape of the per-pixel random draws (channel axis kept as 1 unless per_channel)."""
    if per_channel or x.ndim == 2:
        return x.shape
    return x.shape[:-1] + (1,)


def add_gaussian_noise(key, image, *, sigma, clip=False):
    """Additive white Gaussian noise: ``y = x + σ·z``, ``z ~ N(0, 1)`` i.i.d. per value.

    Args:
        key: a ``jax.random`` key.
        image: any shape (values in image units).
        sigma: standard deviation ``σ >= 0`` (scalar or broadcastable, e.g. per channel).
        clip: clip the result to [0, 1].

    Returns:
        Same shape/dtype as ``image``. Reparameterised: differentiable w.r.t. ``image`` and
        ``sigma`` (``dy/dσ = z``).

    Example:
        >>> y = add_gaussian_noise(jax.random.key(0), jnp.zeros((64, 64)), sigma=0.0)
        >>> float(jnp.abs(y).max())
        0.0
    """
    x = check_image(image, min_ndim=0)
    check_nonnegative(sigma, "sigma")
    return _gaussian(key, x, jnp.asarray(sigma, x.dtype), bool(clip))


@functools.partial(jax.jit, static_argnums=(3,))
def _gaussian(key, x, sigma, clip):
    y = x + sigma * jax.random.normal(key, x.shape, x.dtype)
    return jnp.clip(y, 0.0, 1.0) if clip else y


def add_salt_and_pepper(
    key, image, *, amount, salt_vs_pepper=0.5, low=0.0, high=1.0, per_channel=False
):
    """Salt-and-pepper (data drop-out) noise: a random fraction of pixels set to black/white.

    Each pixel is corrupted independently with probability ``amount``; a corrupted pixel
    becomes ``high`` ("salt") with probability ``salt_vs_pepper`` and ``low`` ("pepper")
    otherwise. The number of corrupted pixels is Binomial(n_pixels, amount).

    Args:
        key: a ``jax.random`` key.
        image: ``(H, W)`` or ``(..., H, W, C)``.
        amount: corruption probability in [0, 1].
        salt_vs_pepper: probability that a corrupted pixel is salt, in [0, 1].
        low, high: pepper / salt values.
        per_channel: corrupt each channel value independently (as skimage's ``random_noise``)
            instead of whole pixels.

    Returns:
        Same shape/dtype as ``image``.

    Example:
        >>> y = add_salt_and_pepper(jax.random.key(0), jnp.full((8, 8), 0.5), amount=1.0)
        >>> bool(jnp.all((y == 0.0) | (y == 1.0)))
        True
    """
    x = check_image(image)
    _check_amount(amount)
    _check_amount(salt_vs_pepper, "salt_vs_pepper")
    return _salt_pepper(key, x, amount, salt_vs_pepper, low, high, bool(per_channel))


@functools.partial(jax.jit, static_argnums=(6,))
def _salt_pepper(key, x, amount, salt_vs_pepper, low, high, per_channel):
    k1, k2 = jax.random.split(key)
    shape = _pixel_shape(x, per_channel)
    hit = jax.random.uniform(k1, shape, x.dtype) < amount
    salt = jax.random.uniform(k2, shape, x.dtype) < salt_vs_pepper
    value = jnp.where(salt, jnp.asarray(high, x.dtype), jnp.asarray(low, x.dtype))
    return jnp.where(hit, value, x)


def add_impulse_noise(key, image, *, amount, value=1.0, per_channel=False):
    """Impulse noise: random pixels replaced by ``value`` (white by default).

    Each pixel independently with probability ``amount`` (in [0, 1]). Same conventions (and,
    for a given key, the same corrupted pixels) as :func:`add_salt_and_pepper` with
    ``salt_vs_pepper=1, high=value``.

    Example:
        >>> y = add_impulse_noise(jax.random.key(0), jnp.zeros((8, 8)), amount=1.0, value=0.7)
        >>> round(float(y.min()), 6)
        0.7
    """
    x = check_image(image)
    _check_amount(amount)
    return _salt_pepper(key, x, amount, 1.0, 0.0, value, bool(per_channel))


POISSON_GAUSSIAN_METHODS = ("exact", "gaussian")


def add_poisson_gaussian_noise(key, image, *, gain, read_sigma, method="exact", clip=False):
    """Camera noise: photon shot noise (Poisson) plus read noise (Gaussian).

    The image holds the expected signal ``x >= 0`` in output units; one electron produces
    ``gain`` output units, so ``y = gain · Poisson(x / gain) + read_sigma · z``. Then
    ``E[y] = x`` and ``Var[y] = gain · x + read_sigma²`` (the affine noise-level function of
    Foi et al., "Practical Poissonian-Gaussian noise modeling...", IEEE TIP 2008).

    ``method="exact"`` draws true Poisson counts (not differentiable w.r.t. ``image``/``gain``
    through the sample); ``method="gaussian"`` uses the heteroscedastic normal approximation
    ``y = x + sqrt(gain·x + read_sigma²) · z``, reparameterised and differentiable in
    ``image``, ``gain`` and ``read_sigma`` (accurate when ``x/gain`` is above ~10 electrons).
    Negative inputs are treated as 0 signal.

    Args:
        key: a ``jax.random`` key.
        image: any shape, expected signal ``x`` in output units.
        gain: output units per electron, ``> 0``.
        read_sigma: read-noise standard deviation ``>= 0`` in output units.

    Example:
        >>> y = add_poisson_gaussian_noise(jax.random.key(0), jnp.zeros(4), gain=0.01,
        ...                                read_sigma=0.0)
        >>> float(jnp.abs(y).max())
        0.0
    """
    x = check_image(image, min_ndim=0)
    check_choice(method, "method", POISSON_GAUSSIAN_METHODS)
    check_nonnegative(gain, "gain")
    if is_concrete(gain) and np.any(np.asarray(gain) <= 0):
        raise ValueError(f"gain: expected a finite value > 0, got {gain!r}")
    check_nonnegative(read_sigma, "read_sigma")
    return _poisson_gaussian(
        key, x, jnp.asarray(gain, x.dtype), jnp.asarray(read_sigma, x.dtype), method, bool(clip)
    )


@functools.partial(jax.jit, static_argnums=(4, 5))
def _poisson_gaussian(key, x, gain, read_sigma, method, clip):
    k1, k2 = jax.random.split(key)
    signal = jnp.maximum(x, 0.0)
    z = jax.random.normal(k2, x.shape, x.dtype)
    if method == "exact":
        counts = jax.random.poisson(k1, signal / gain, x.shape)
        y = gain * counts.astype(x.dtype) + read_sigma * z
    else:
        y = signal + safe_sqrt(gain * signal + read_sigma * read_sigma) * z
    return jnp.clip(y, 0.0, 1.0) if clip else y


TEMPORAL_AVERAGE_METHODS = ("mean", "median", "trimmed")


def temporal_average(frames, *, axis=0, method="mean", trim=0.1):
    """Combine a burst of aligned frames of a static scene into one image.

    Averaging ``N`` frames with independent zero-mean noise keeps the signal and divides the
    noise variance by ``N`` ("temporal filtering", lecture 1). ``"median"`` and
    ``"trimmed"`` (mean after dropping the ``floor(trim · N)`` lowest and highest values of
    each pixel, as ``scipy.stats.trim_mean``) are robust to outliers such as impulse noise.

    Args:
        frames: array with the frame axis ``axis`` (e.g. ``(N, H, W, C)``), ``N >= 1``.
        method: ``"mean"``, ``"median"`` or ``"trimmed"``.
        trim: fraction cut from each end for ``"trimmed"``, ``0 <= trim < 0.5``.

    Returns:
        ``frames`` with ``axis`` removed. Differentiable w.r.t. ``frames`` (sub-gradient
        through the sort for median/trimmed).

    Example:
        >>> float(temporal_average(jnp.array([1.0, 2.0, 9.0]), method="median"))
        2.0
    """
    x = as_float_array(frames, "frames")
    check_finite(x, "frames")
    check_choice(method, "method", TEMPORAL_AVERAGE_METHODS)
    if isinstance(axis, bool) or not isinstance(axis, (int, np.integer)):
        raise TypeError(f"axis: expected an integer, got {type(axis).__name__}")
    if not -x.ndim <= axis < x.ndim:
        raise ValueError(f"axis: expected an axis of frames with shape {x.shape}, got {axis}")
    if x.shape[axis] < 1:
        raise ValueError(f"frames: expected at least one frame along axis {axis}")
    if not (isinstance(trim, (int, float, np.number)) and 0.0 <= float(trim) < 0.5):
        raise ValueError(f"trim: expected a number in [0, 0.5), got {trim!r}")
    return _temporal(x, int(axis), method, float(trim))


@functools.partial(jax.jit, static_argnums=(1, 2, 3))
def _temporal(x, axis, method, trim):
    if method == "mean":
        return jnp.mean(x, axis=axis)
    if method == "median":
        return jnp.median(x, axis=axis)
    n = x.shape[axis]
    cut = int(np.floor(trim * n))
    s = jnp.sort(x, axis=axis)
    s = jax.lax.slice_in_dim(s, cut, n - cut, axis=axis % x.ndim)
    return jnp.mean(s, axis=axis)
