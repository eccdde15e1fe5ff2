"""HDR pixel encodings as jittable JAX functions: RGBE, LogLuv 32/24 and half floats.

These model the quantisation of the HDR file formats (lecture 2, "storing HDR"), so that a
pipeline can be evaluated on exactly the values a file would hold.

* **RGBE** (Ward, "Real Pixels", Graphics Gems II, 1991): shared exponent
  ``E = e + 128`` with ``max(R, G, B) = f 2**e``, ``f`` in ``[0.5, 1)``; mantissas
  ``M = floor(c 2**(8 - e))``; decoding ``c = (M + offset) 2**(E - 136)`` (``offset=0.5``:
  Radiance; ``0.0``: OpenCV). Identical bytes to :func:`jaxgfx.io.hdr_rgbe.rgbe_from_float`.
* **LogLuv32** (Larson, "LogLuv encoding for full-gamut, high-dynamic range images", JGT 1998;
  libtiff ``tif_luv.c``): sign bit + 15-bit ``Le = floor(256 (log2 Y + 64))`` and 8-bit
  ``ue = floor(410 u')``, ``ve = floor(410 v')`` (CIE 1976 u'v'); packed in one uint32 as
  ``Le << 16 | ue << 8 | ve`` (bit 31 = sign of Y). Range ``|Y|`` in ``[5.4e-20, 1.8e19]``,
  relative luminance step ``2**(1/256) - 1 = 0.27 %`` (max error 0.135 %).
* **LogLuv24** (same paper): 10-bit ``L10 = floor(64 (log2 Y + 12))`` (``Y`` in
  ``[2.4e-4, 15.7]``, step 1.09 %) and a 14-bit index of a 0.0035 x 0.0035 cell in u'v' inside
  the visible gamut, packed as ``L10 << 14 | index`` in a uint32 (< 2**24). The cell table has
  libtiff's geometry (``UV_SQSIZ = 0.0035``, ``UV_VSTART = 0.01694``, 163 rows) but is computed
  here from the spectral locus of the CIE 1931 2° observer (tabulated data from colour-science,
  imported lazily on first use) closed by the purple line. It has 16193 cells (libtiff's
  ``uvcode.h``, generated in 1997 from a coarser locus, has 16289) with row starts within 0.006
  (1.7 cells) and widths within 4 cells of libtiff's, so the 14-bit indices are NOT
  interchangeable with libtiff files. Out-of-gamut u'v' are clamped into the table (row first,
  then column), not mapped along hue angles as libtiff.
* **Half** (IEEE 754 binary16, OpenEXR): :func:`half_roundtrip`.

LogLuv functions take and return CIE XYZ ``(..., 3)`` (convert RGB with ``jaxgfx.color``).
All encoders round down (no dithering), like libtiff with ``SGILOGENCODE_NODITHER``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Shaped, UInt

from .._checks import as_float_array

__all__ = [
    "rgbe_encode",
    "rgbe_decode",
    "logluv32_encode",
    "logluv32_decode",
    "logluv24_encode",
    "logluv24_decode",
    "half_roundtrip",
    "logluv24_uv_table",
    "ENCODINGS",
]

# Shape-annotated aliases (module level so linters do not parse the shape strings).
_Triple = Shaped[ArrayLike, "*batch 3"]
_TripleOut = Float[Array, "*batch 3"]
_RGBEIn = UInt[ArrayLike, "*batch 4"]
_RGBEOut = UInt[Array, "*batch 4"]
_WordIn = UInt[ArrayLike, "*batch"]
_WordOut = UInt[Array, "*batch"]
_AnyIn = Shaped[ArrayLike, "..."]
_AnyOut = Float[Array, "..."]

U_NEUTRAL = 4.0 / 19.0  # u'v' of equal-energy white (X = Y = Z), used for black pixels
V_NEUTRAL = 9.0 / 19.0
UV_SQSIZ = 0.0035
UV_VSTART = 0.01694
UV_NVS = 163


def _check_last(x, n: int, name: str):
    if x.ndim < 1 or x.shape[-1] != n:
        raise ValueError(f"{name}: expected shape (..., {n}), got {x.shape}")


def _check_uint(x, name: str):
    arr = jnp.asarray(x)
    if not jnp.issubdtype(arr.dtype, jnp.integer):
        raise TypeError(f"{name}: expected an unsigned integer array, got dtype {arr.dtype}")
    return arr


# ----------------------------------------------------------------------------- RGBE


def rgbe_encode(rgb: _Triple) -> _RGBEOut:
    """Encode linear RGB ``(..., 3)`` to Radiance RGBE bytes ``(..., 4)`` uint8 (Ward 1991).

    Pixels with ``max < 2**-127`` (or NaN / negative channels, stored as 0) encode to zeros;
    ``max >= 2**128`` or ``inf`` saturates to ``(255, 255, 255, 255)``.

    >>> rgbe_encode(jnp.array([1.0, 0.5, 0.0])).tolist()
    [128, 64, 0, 129]
    """
    rgb = as_float_array(rgb, "rgb")
    _check_last(rgb, 3, "rgb")
    return _rgbe_encode(rgb)


@jax.jit
def _rgbe_encode(rgb):
    rgb = jnp.where(jnp.isnan(rgb) | (rgb < 0), 0.0, rgb)
    v = jnp.max(rgb, axis=-1)
    # 2**128 is not a float32: there only inf saturates.
    sat = (v >= 2.0**128) if float(jnp.finfo(v.dtype).max) >= 2.0**128 else jnp.isinf(v)
    _, e = jnp.frexp(jnp.where(sat, 1.0, v))
    zero = ~(v > 0) | (e < -126)  # max < 2**-127 (integer test: XLA flushes subnormals)
    e = jnp.where(zero | sat, 0, e)
    vs = jnp.where(zero | sat, 1.0, v)
    # Two exact power-of-two scalings (2**-e fits every float32 exponent of a normal max).
    scaled = rgb * jnp.ldexp(jnp.ones_like(vs), -e)[..., None] * 256.0
    mant = jnp.clip(jnp.floor(scaled), 0, 255).astype(jnp.uint8)
    exp = (e + 128).astype(jnp.uint8)[..., None]
    out = jnp.concatenate([mant, exp], axis=-1)
    out = jnp.where(zero[..., None], jnp.uint8(0), out)
    return jnp.where(sat[..., None], jnp.uint8(255), out)


def rgbe_decode(rgbe: _RGBEIn, *, offset: float = 0.5, dtype=jnp.float32) -> _TripleOut:
    """Decode RGBE bytes ``(..., 4)`` to RGB ``(..., 3)``: ``(M + offset) 2**(E - 136)``, 0 if E=0.

    ``offset=0.5`` (default) is Radiance's bin centre (max relative error ``2**-8`` on the
    largest channel); ``0.0`` reproduces OpenCV's reader.

    >>> rgbe_decode(jnp.array([128, 64, 0, 129], jnp.uint8), offset=0.0).tolist()
    [1.0, 0.5, 0.0]
    """
    rgbe = _check_uint(rgbe, "rgbe")
    _check_last(rgbe, 4, "rgbe")
    dtype = jnp.dtype(dtype)
    return _rgbe_decode(rgbe, jnp.asarray(offset, dtype), dtype=dtype)


@functools.partial(jax.jit, static_argnames=("dtype",))
def _rgbe_decode(rgbe, offset, *, dtype):
    e = rgbe[..., 3].astype(jnp.int32)
    m = rgbe[..., :3].astype(dtype) + offset
    scale = jnp.ldexp(jnp.ones(e.shape, dtype), e - 136)
    return jnp.where((e > 0)[..., None], m * scale[..., None], jnp.zeros((), dtype))


# ----------------------------------------------------------------------------- LogLuv helpers


def _xyz_to_uv(XYZ):
    X, Y, Z = XYZ[..., 0], XYZ[..., 1], XYZ[..., 2]
    den = X + 15.0 * Y + 3.0 * Z
    ok = (den > 0) & (Y > 0)
    safe = jnp.where(ok, den, 1.0)
    u = jnp.where(ok, 4.0 * X / safe, U_NEUTRAL)
    v = jnp.where(ok, 9.0 * Y / safe, V_NEUTRAL)
    return u, v


def _uv_Y_to_xyz(u, v, Y):
    # x = 9u / (6u - 16v + 12), y = 4v / (6u - 16v + 12)  =>  X = 9u/(4v) Y, Z = (12-3u-20v)/(4v) Y
    vs = jnp.maximum(v, 1e-6)
    X = 9.0 * u / (4.0 * vs) * Y
    Z = (12.0 - 3.0 * u - 20.0 * vs) / (4.0 * vs) * Y
    return jnp.stack([X, Y, Z], axis=-1)


# ----------------------------------------------------------------------------- LogLuv32


def logluv32_encode(XYZ: _Triple) -> _WordOut:
    """Encode CIE XYZ ``(..., 3)`` to 32-bit LogLuv words ``(...,)`` uint32 (Larson 1998).

    Word layout: bit 31 sign of Y, bits 16..30 ``Le = floor(256 (log2|Y| + 64))`` (0 encodes
    zero, values clamp at 0x7fff), bits 8..15 ``ue = floor(410 u')``, bits 0..7
    ``ve = floor(410 v')`` (clamped to 0..255). ``|Y| <= 5.4e-20`` encodes as zero luminance.

    >>> hex(int(logluv32_encode(jnp.array([0.95047, 1.0, 1.08883]))))  # D65 white, Y = 1
    '0x400051c0'
    """
    XYZ = as_float_array(XYZ, "XYZ")
    _check_last(XYZ, 3, "XYZ")
    return _logluv32_encode(XYZ)


@jax.jit
def _logluv32_encode(XYZ):
    Y = XYZ[..., 1]
    aY = jnp.abs(Y)
    tiny = ~(aY > 5.4136769e-20)  # also catches NaN
    big = aY >= 1.8371976e19
    safeY = jnp.where(tiny | big, 1.0, aY)
    Le = jnp.floor(256.0 * (jnp.log2(safeY) + 64.0))
    Le = jnp.where(tiny, 0.0, jnp.where(big, 0x7FFF, jnp.clip(Le, 0, 0x7FFF)))
    Le = Le.astype(jnp.uint32) | jnp.where((Y < 0) & ~tiny, jnp.uint32(0x8000), jnp.uint32(0))
    u, v = _xyz_to_uv(jnp.where(Y[..., None] < 0, -XYZ, XYZ))
    ue = jnp.clip(jnp.floor(410.0 * u), 0, 255).astype(jnp.uint32)
    ve = jnp.clip(jnp.floor(410.0 * v), 0, 255).astype(jnp.uint32)
    return (Le << 16) | (ue << 8) | ve


def logluv32_decode(word: _WordIn, *, dtype=jnp.float32) -> _TripleOut:
    """Decode 32-bit LogLuv words ``(...,)`` to CIE XYZ ``(..., 3)`` (Larson 1998).

    ``Y = ±2**((Le + 0.5) / 256 - 64)`` (0 when ``Le = 0``), ``u' = (ue + 0.5) / 410``,
    ``v' = (ve + 0.5) / 410``.
    """
    return _logluv32_decode(_check_uint(word, "word"), dtype=jnp.dtype(dtype))


@functools.partial(jax.jit, static_argnames=("dtype",))
def _logluv32_decode(word, *, dtype):
    word = word.astype(jnp.uint32)
    Le = ((word >> 16) & 0x7FFF).astype(dtype)
    sign = jnp.where((word >> 31) == 1, -1.0, 1.0).astype(dtype)
    Y = jnp.where(Le > 0, sign * jnp.exp2((Le + 0.5) / 256.0 - 64.0), 0.0).astype(dtype)
    u = (((word >> 8) & 0xFF).astype(dtype) + 0.5) / 410.0
    v = ((word & 0xFF).astype(dtype) + 0.5) / 410.0
    return _uv_Y_to_xyz(u, v, Y).astype(dtype)


# ----------------------------------------------------------------------------- LogLuv24


def _spectral_locus_uv() -> np.ndarray:
    """u'v' of the CIE 1931 2° spectral locus, 380..700 nm in 1 nm steps (colour-science data)."""
    import colour  # lazy: heavy import, needed once to build the LogLuv24 table

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz = np.array([cmfs[lam] for lam in np.arange(380.0, 701.0)], dtype=np.float64)
    den = xyz @ np.array([1.0, 15.0, 3.0])
    return np.stack([4 * xyz[:, 0] / den, 9 * xyz[:, 1] / den], axis=-1)


@functools.cache
def logluv24_uv_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The LogLuv24 u'v' cell table ``(ustart, nus, ncum)``, each of length 163.

    Row ``i`` covers ``v'`` in ``[0.01694 + 0.0035 i, 0.01694 + 0.0035 (i + 1))`` and holds
    ``nus[i]`` cells of width 0.0035 from ``ustart[i]``: the u' extent of the visible gamut
    (spectral locus 380..700 nm closed by the purple line) over that band. ``ncum`` is the
    exclusive cumulative count, so the 14-bit index of cell ``(i, j)`` is ``ncum[i] + j``.
    Computed once on the host (NumPy, float64).
    """
    loc = _spectral_locus_uv()
    poly = np.concatenate([loc, loc[:1]])  # closing edge = purple line
    a, b = poly[:-1], poly[1:]
    ustart = np.zeros(UV_NVS)
    nus = np.zeros(UV_NVS, np.int64)
    for i in range(UV_NVS):
        v0 = UV_VSTART + i * UV_SQSIZ
        vs = np.linspace(v0, v0 + UV_SQSIZ, 9)
        # u of every polygon edge crossing each sample line, plus vertices inside the band
        us = [loc[(loc[:, 1] >= v0) & (loc[:, 1] <= v0 + UV_SQSIZ), 0]]
        for vv in vs:
            cross = (a[:, 1] - vv) * (b[:, 1] - vv) <= 0
            da = b[cross, 1] - a[cross, 1]
            t = np.where(da != 0, (vv - a[cross, 1]) / np.where(da != 0, da, 1.0), 0.0)
            us.append(a[cross, 0] + t * (b[cross, 0] - a[cross, 0]))
        us = np.concatenate(us)
        if us.size == 0:
            raise RuntimeError(f"LogLuv24 table: row {i} does not meet the gamut")
        ustart[i] = us.min()
        nus[i] = max(1, int(np.ceil((us.max() - us.min()) / UV_SQSIZ)))
    ncum = np.concatenate([[0], np.cumsum(nus)[:-1]])
    if ncum[-1] + nus[-1] > 1 << 14:
        raise RuntimeError("LogLuv24 table exceeds 14 bits")
    return ustart, nus, ncum


def _uv_to_index(u, v):
    ustart, nus, ncum = (jnp.asarray(t) for t in logluv24_uv_table())
    vi = jnp.clip(jnp.floor((v - UV_VSTART) / UV_SQSIZ), 0, UV_NVS - 1).astype(jnp.int32)
    ui = jnp.floor((u - ustart[vi].astype(u.dtype)) / UV_SQSIZ)
    ui = jnp.clip(ui, 0, nus[vi] - 1).astype(jnp.int32)
    return (ncum[vi] + ui).astype(jnp.uint32)


def _index_to_uv(c, dtype):
    ustart, _, ncum = logluv24_uv_table()
    c = c.astype(jnp.int32)
    vi = jnp.clip(jnp.searchsorted(jnp.asarray(ncum), c, side="right") - 1, 0, UV_NVS - 1)
    ui = c - jnp.asarray(ncum)[vi]
    u = jnp.asarray(ustart, dtype)[vi] + (ui.astype(dtype) + 0.5) * UV_SQSIZ
    v = UV_VSTART + (vi.astype(dtype) + 0.5) * UV_SQSIZ
    return u, v


def logluv24_encode(XYZ: _Triple) -> _WordOut:
    """Encode CIE XYZ ``(..., 3)`` to 24-bit LogLuv words ``(...,)`` uint32 (Larson 1998).

    ``L10 = floor(64 (log2 Y + 12))`` in bits 14..23 (``Y <= 2.4283e-4`` → 0, ``Y >= 15.742``
    → 1023; negative Y is not representable and encodes as 0) and the 14-bit u'v' cell index
    of :func:`logluv24_uv_table` in bits 0..13.

    >>> int(logluv24_encode(jnp.array([0.95047, 1.0, 1.08883]))) >> 14  # Y = 1
    768
    """
    XYZ = as_float_array(XYZ, "XYZ")
    _check_last(XYZ, 3, "XYZ")
    logluv24_uv_table()  # built eagerly (NumPy, colour-science), not while tracing
    return _logluv24_encode(XYZ)


@jax.jit
def _logluv24_encode(XYZ):
    Y = XYZ[..., 1]
    lo = ~(Y > 0.00024283)
    hi = Y >= 15.742
    safeY = jnp.where(lo | hi, 1.0, Y)
    L = jnp.clip(jnp.floor(64.0 * (jnp.log2(safeY) + 12.0)), 0, 1023)
    L = jnp.where(lo, 0, jnp.where(hi, 1023, L)).astype(jnp.uint32)
    u, v = _xyz_to_uv(XYZ)
    return (L << 14) | _uv_to_index(u, v)


def logluv24_decode(word: _WordIn, *, dtype=jnp.float32) -> _TripleOut:
    """Decode 24-bit LogLuv words ``(...,)`` to CIE XYZ ``(..., 3)``.

    ``Y = 2**((L10 + 0.5) / 64 - 12)`` (0 when ``L10 = 0``); u'v' = centre of the indexed cell.
    """
    word = _check_uint(word, "word")
    logluv24_uv_table()
    return _logluv24_decode(word, dtype=jnp.dtype(dtype))


@functools.partial(jax.jit, static_argnames=("dtype",))
def _logluv24_decode(word, *, dtype):
    word = word.astype(jnp.uint32)
    L = ((word >> 14) & 0x3FF).astype(dtype)
    Y = jnp.where(L > 0, jnp.exp2((L + 0.5) / 64.0 - 12.0), 0.0).astype(dtype)
    u, v = _index_to_uv(word & 0x3FFF, dtype)
    return _uv_Y_to_xyz(u, v, Y).astype(dtype)


# ----------------------------------------------------------------------------- half


@jax.custom_jvp
def _half_rt(x):
    return x.astype(jnp.float16).astype(x.dtype)


@_half_rt.defjvp
def _half_rt_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    return _half_rt(x), t


def half_roundtrip(x: _AnyIn) -> _AnyOut:
    """Round ``x`` to IEEE binary16 (OpenEXR ``HALF``) and back, keeping ``x``'s dtype.

    Round-to-nearest-even; relative step ``2**-10`` (max relative error ``2**-11``) for
    ``|x|`` in ``[6.1e-5, 65504]``, subnormals down to ``2**-24``, ``|x| >= 65520`` → ``inf``.
    The derivative is the straight-through identity (d/dx = 1), so quantisation can sit inside
    a differentiable pipeline.

    >>> float(half_roundtrip(jnp.float32(0.1)))
    0.0999755859375
    """
    x = as_float_array(x, "x")
    return _half_rt(x)


#: Registered encode/decode pairs, selectable by name from configs.
ENCODINGS = {
    "rgbe_Ward1991": (rgbe_encode, rgbe_decode),
    "logluv32_Larson1998": (logluv32_encode, logluv32_decode),
    "logluv24_Larson1998": (logluv24_encode, logluv24_decode),
}
