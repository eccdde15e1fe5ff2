"""Frequency-domain filtering: generic ``fft_filter`` and ideal / Gaussian / Butterworth
low-, high- and band-pass filters.

Frequencies are in **cycles per pixel** (Nyquist = 0.5); the radial frequency of the DFT bin
``(ky, kx)`` of an ``H × W`` image is ``r = sqrt((ky/H)² + (kx/W)²)`` with ``ky, kx`` the
signed indices of ``numpy.fft.fftfreq``. Filtering multiplies the 2-D DFT by a real transfer
function, i.e. circular convolution (``padding="wrap"``, exact for periodic images). With
``padding="reflect"`` the image is first extended to ``2H × 2W`` by mirror symmetry (edge
value repeated, ``scipy.ndimage`` "reflect" / NumPy "symmetric"); its periodic extension is
then continuous, which removes the wrap-around artefacts at the borders, and the result equals
convolution with reflected borders.

Shape convention: ``(H, W)`` grey or channels-last ``(..., H, W, C)``; the filter acts on the
two spatial axes of every image and channel. Images are real; outputs are real.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_choice, check_image, check_positive, is_concrete
from .._math import safe_log

__all__ = [
    "fft_filter",
    "frequency_grid",
    "lowpass_transfer",
    "fourier_lowpass",
    "fourier_highpass",
    "fourier_bandpass",
    "FOURIER_FILTER_KINDS",
    "FOURIER_PADDINGS",
]

FOURIER_PADDINGS = ("wrap", "reflect")


def _ideal(r2, cutoff, order):
    del order
    return (r2 <= cutoff * cutoff).astype(r2.dtype)


def _gaussian(r2, cutoff, order):
    del order
    return jnp.exp(-r2 / (2.0 * cutoff * cutoff))


def _butterworth(r2, cutoff, order):
    # 1 / (1 + (r/c)^(2n)) = sigmoid(-n · log(r²/c²)), stable for any ratio and order
    g = jax.nn.sigmoid(-order * (safe_log(r2) - 2.0 * jnp.log(cutoff)))
    return jnp.where(r2 > 0, g, 1.0)


#: Low-pass transfer functions ``H(r², cutoff, order)`` selectable by name.
FOURIER_FILTER_KINDS = {"ideal": _ideal, "gaussian": _gaussian, "butterworth": _butterworth}


def frequency_grid(shape, *, dtype=jnp.float32, real=True):
    """DFT sample frequencies (cycles/pixel) of an ``(H, W)`` image.

    Returns ``(fy, fx)`` with shapes ``(H, 1)`` and ``(1, W // 2 + 1)`` (``real=True``, the
    ``rfft2`` half-plane) or ``(1, W)`` (full ``fft2`` grid), in NumPy's unshifted order.

    Example:
        >>> fy, fx = frequency_grid((4, 4))
        >>> fx.ravel().tolist(), fy.ravel().tolist()
        ([0.0, 0.25, 0.5], [0.0, 0.25, -0.5, -0.25])
    """
    h, w = (int(s) for s in shape)
    fy = jnp.asarray(np.fft.fftfreq(h), dtype)[:, None]
    fx = np.fft.rfftfreq(w) if real else np.fft.fftfreq(w)
    return fy, jnp.asarray(fx, dtype)[None, :]


def lowpass_transfer(fy, fx, cutoff, *, kind="gaussian", order=2.0):
    """Low-pass transfer function ``H(f)`` at frequencies ``(fy, fx)`` (cycles/pixel).

    With ``r = sqrt(fy² + fx²)`` and ``c = cutoff``:

    - ``"ideal"``: ``H = 1`` for ``r <= c`` else 0 (zero gradient w.r.t. ``c`` a.e.);
    - ``"gaussian"``: ``H = exp(-r² / (2c²))``; ``c`` is the frequency-domain standard
      deviation ``σ_f``, equal to a spatial Gaussian blur of ``σ = 1 / (2π σ_f)`` pixels;
    - ``"butterworth"``: ``H = 1 / (1 + (r/c)^(2n))`` with ``n = order`` (Butterworth 1930),
      ``H(c) = 1/2``; tends to the ideal filter as ``n → ∞``.

    (Gonzalez & Woods, *Digital Image Processing*, ch. 4.)

    Example:
        >>> float(lowpass_transfer(0.0, 0.1, 0.1, kind="butterworth"))
        0.5
    """
    check_choice(kind, "kind", FOURIER_FILTER_KINDS)
    fy, fx = jnp.asarray(fy), jnp.asarray(fx)
    dtype = jnp.result_type(fy, fx, cutoff, order, 1.0)
    r2 = (fy * fy + fx * fx).astype(dtype)
    return FOURIER_FILTER_KINDS[kind](r2, jnp.asarray(cutoff, dtype), jnp.asarray(order, dtype))


def _spatial_axes(x):
    return (-2, -1) if x.ndim == 2 else (-3, -2)


def _pad(x, padding):
    if padding == "wrap":
        return x
    ay, ax = _spatial_axes(x)
    x = jnp.concatenate([x, jnp.flip(x, ay)], axis=ay)
    return jnp.concatenate([x, jnp.flip(x, ax)], axis=ax)


def _crop(y, shape, padding):
    if padding == "wrap":
        return y
    ay, ax = _spatial_axes(y)
    h, w = shape[ay], shape[ax]
    y = jax.lax.slice_in_dim(y, 0, h, axis=y.ndim + ay)
    return jax.lax.slice_in_dim(y, 0, w, axis=y.ndim + ax)


def _padded_shape(x, padding):
    """``(h, w)`` of the image as filtered: doubled by every padding but ``"wrap"``."""
    ay, ax = _spatial_axes(x)
    scale = 1 if padding == "wrap" else 2
    return (x.shape[ay] * scale, x.shape[ax] * scale)


def _padded_grid(x, padding):
    """``frequency_grid`` (rfft2 half-plane) of the padded image, in the image's dtype."""
    return frequency_grid(_padded_shape(x, padding), dtype=x.dtype)


@functools.partial(jax.jit, static_argnums=(1, 2))
def _filter_fn(x, fn, padding, *params):
    """Real-FFT filtering of ``x`` by ``fn(fy, fx, *params)`` (jitted, fn static: only for
    the module's own transfer functions, whose identity is fixed)."""
    fy, fx = _padded_grid(x, padding)
    return _filter_rfft(x, fn(fy, fx, *params).astype(x.dtype), padding)


@functools.partial(jax.jit, static_argnums=(2,))
def _filter_rfft(x, tf, padding):
    """Real-FFT filtering of ``x`` by transfer values ``tf`` on the rfft2 half-plane."""
    xp = _pad(x, padding)
    axes = _spatial_axes(xp)
    h, w = xp.shape[axes[0]], xp.shape[axes[1]]
    if x.ndim > 2:
        tf = tf[..., None]
    spec = jnp.fft.rfft2(xp, axes=axes)
    y = jnp.fft.irfft2(spec * tf, s=(h, w), axes=axes).astype(x.dtype)
    return _crop(y, x.shape, padding)


@functools.partial(jax.jit, static_argnums=(2,))
def _filter_array(x, transfer, padding):
    xp = _pad(x, padding)
    axes = _spatial_axes(xp)
    tf = transfer[..., None] if x.ndim > 2 else transfer
    y = jnp.real(jnp.fft.ifft2(jnp.fft.fft2(xp, axes=axes) * tf, axes=axes)).astype(x.dtype)
    return _crop(y, x.shape, padding)


def fft_filter(image, transfer, *, padding="wrap"):
    """Multiply the 2-D DFT of each image/channel by ``transfer`` and transform back.

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)`` real image.
        transfer: either a callable ``transfer(fy, fx) -> H`` of the frequencies in
            cycles/pixel (``fy (Hp, 1)``, ``fx (1, Wp//2+1)`` of the padded grid; must be
            real and even, ``H(-f) = H(f)``, it is evaluated on the ``rfft2`` half-plane), or
            an array of shape ``(Hp, Wp)`` on the full unshifted ``fft2`` grid (``Hp, Wp`` =
            ``H, W`` for ``"wrap"``, ``2H, 2W`` for ``"reflect"``); complex arrays are allowed
            (e.g. a phase ramp shifts the image) and the real part of the result is returned.
        padding: ``"wrap"`` (circular) or ``"reflect"`` (mirror extension, see module doc).

    Returns:
        Real array of the shape and dtype of ``image``; differentiable w.r.t. ``image`` and
        the transfer values / parameters.

    Example:
        >>> x = jnp.cos(2 * jnp.pi * 2 * jnp.arange(8) / 8) * jnp.ones((8, 1))
        >>> y = fft_filter(x, lambda fy, fx: 0.5 * jnp.ones_like(fy * fx))
        >>> float(y[0, 0])
        0.5
    """
    x = check_image(image)
    check_choice(padding, "padding", FOURIER_PADDINGS)
    if callable(transfer):
        # evaluated here, not as a static argument of a jitted core: a user's callable (a
        # new lambda at every call) would compile a new program each time
        fy, fx = _padded_grid(x, padding)
        return _filter_rfft(x, jnp.asarray(transfer(fy, fx)).astype(x.dtype), padding)
    tf = jnp.asarray(transfer)
    want = _padded_shape(x, padding)
    if tf.shape != want:
        raise ValueError(
            f"transfer: expected a callable or an array of shape {want} (the "
            f"{'' if padding == 'wrap' else 'padded '}fft2 grid), got shape {tf.shape}"
        )
    return _filter_array(x, tf, padding)


def _check_common(image, kind, padding, order):
    x = check_image(image)
    check_choice(kind, "kind", FOURIER_FILTER_KINDS)
    check_choice(padding, "padding", FOURIER_PADDINGS)
    check_positive(order, "order")
    return x


def _lp(fy, fx, cutoff, order, *, kind):
    return lowpass_transfer(fy, fx, cutoff, kind=kind, order=order)


def _hp(fy, fx, cutoff, order, *, kind):
    return 1.0 - lowpass_transfer(fy, fx, cutoff, kind=kind, order=order)


def _bp(fy, fx, low, high, order, *, kind):
    lp_high = lowpass_transfer(fy, fx, high, kind=kind, order=order)
    lp_low = lowpass_transfer(fy, fx, low, kind=kind, order=order)
    return lp_high * (1.0 - lp_low)


# one partial per kind, created once: static jit arguments hash by identity
_LP_FNS = {k: functools.partial(_lp, kind=k) for k in FOURIER_FILTER_KINDS}
_HP_FNS = {k: functools.partial(_hp, kind=k) for k in FOURIER_FILTER_KINDS}
_BP_FNS = {k: functools.partial(_bp, kind=k) for k in FOURIER_FILTER_KINDS}


def _as_param(v, x):
    return jnp.asarray(v, x.dtype)


def fourier_lowpass(image, cutoff, *, kind="gaussian", order=2.0, padding="wrap"):
    """Low-pass filter in the frequency domain: ``y = IDFT(H · DFT(x))``.

    ``H`` is :func:`lowpass_transfer` (``kind`` = ``"ideal"``, ``"gaussian"`` or
    ``"butterworth"``); ``cutoff`` in cycles/pixel (> 0; ``σ_f`` for the Gaussian). A
    sinusoid of frequency ``f`` is scaled by ``H(f)`` exactly (``padding="wrap"``, integer
    number of periods). Differentiable w.r.t. ``image``, ``cutoff`` and ``order``.

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``.
        cutoff: scalar > 0, cycles/pixel.
        kind: transfer function family.
        order: Butterworth order ``n > 0`` (ignored by the other kinds).
        padding: ``"wrap"`` or ``"reflect"``.

    Example:
        >>> x = jnp.cos(2 * jnp.pi * 0.25 * jnp.arange(16)) * jnp.ones((16, 1))
        >>> y = fourier_lowpass(x, 0.25, kind="butterworth")
        >>> round(float(y[0, 0]), 6)
        0.5
    """
    x = _check_common(image, kind, padding, order)
    check_positive(cutoff, "cutoff")
    fn = _LP_FNS[kind]
    return _filter_fn(x, fn, padding, _as_param(cutoff, x), _as_param(order, x))


def fourier_highpass(image, cutoff, *, kind="gaussian", order=2.0, padding="wrap"):
    """High-pass filter ``H_hp = 1 - H_lp`` (same arguments as :func:`fourier_lowpass`), so
    ``fourier_lowpass(x, c) + fourier_highpass(x, c) == x``; removes the mean (DC) exactly.

    Example:
        >>> float(jnp.abs(fourier_highpass(jnp.full((8, 8), 3.0), 0.1)).max()) < 1e-6
        True
    """
    x = _check_common(image, kind, padding, order)
    check_positive(cutoff, "cutoff")
    fn = _HP_FNS[kind]
    return _filter_fn(x, fn, padding, _as_param(cutoff, x), _as_param(order, x))


def fourier_bandpass(image, low, high, *, kind="gaussian", order=2.0, padding="wrap"):
    """Band-pass filter ``H_bp = H_lp(high) · (1 - H_lp(low))``, ``0 < low < high``.

    For ``kind="ideal"`` this keeps exactly the frequencies ``low < r <= high``. Arguments as
    :func:`fourier_lowpass`; differentiable w.r.t. ``low``, ``high``, ``order`` and ``image``.

    Example:
        >>> x = jnp.cos(2 * jnp.pi * 0.25 * jnp.arange(16)) * jnp.ones((16, 1))
        >>> float(jnp.abs(fourier_bandpass(x, 0.1, 0.3, kind="ideal") - x).max()) < 1e-6
        True
    """
    x = _check_common(image, kind, padding, order)
    check_positive(low, "low")
    check_positive(high, "high")
    if is_concrete(low) and is_concrete(high) and not float(low) < float(high):
        raise ValueError(f"low, high: expected 0 < low < high, got low={low!r}, high={high!r}")
    fn = _BP_FNS[kind]
    p = (_as_param(low, x), _as_param(high, x), _as_param(order, x))
    return _filter_fn(x, fn, padding, *p)
