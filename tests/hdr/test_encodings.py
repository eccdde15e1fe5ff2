"""HDR pixel encodings: known values, quantisation bounds, limits, table vs libtiff, jit."""

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.hdr.encodings import (
    half_roundtrip,
    logluv24_decode,
    logluv24_encode,
    logluv24_uv_table,
    logluv32_decode,
    logluv32_encode,
    rgbe_decode,
    rgbe_encode,
)
from jaxgfx.io.hdr_rgbe import float_from_rgbe, rgbe_from_float

rgbe_encode_j = jax.jit(rgbe_encode)
rgbe_decode_j = jax.jit(rgbe_decode, static_argnames=("offset",))
l32e, l32d = jax.jit(logluv32_encode), jax.jit(logluv32_decode)
l24e, l24d = jax.jit(logluv24_encode), jax.jit(logluv24_decode)
l32d64 = jax.jit(lambda w: logluv32_decode(w, dtype=jnp.float64))
l24d64 = jax.jit(lambda w: logluv24_decode(w, dtype=jnp.float64))
D65 = np.array([0.95047, 1.0, 1.08883])


def _uv(XYZ):
    """u'v' through colour-science (independent oracle)."""
    return colour.Luv_to_uv(colour.XYZ_to_Luv(np.asarray(XYZ, np.float64)))


def _log_uniform(rng, lo, hi, shape):
    return np.exp(rng.uniform(np.log(lo), np.log(hi), shape))


def _random_XYZ(rng, n, lo, hi):
    """Random in-gamut colours: linear sRGB chromaticities times log-uniform luminance."""
    rgb = rng.uniform(0.05, 1.0, (n, 3))
    XYZ = colour.RGB_to_XYZ(rgb, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False)
    return XYZ / XYZ[:, 1:2] * _log_uniform(rng, lo, hi, (n, 1))


# ----------------------------------------------------------------------------- RGBE


def test_rgbe_known_values_and_limits():
    x = jnp.array(
        [[1.0, 0.5, 0.0], [0.0, 0.0, 0.0], [1e-39, 0, 0], [np.inf, 1, 1], [-1.0, np.nan, 3.0]],
        jnp.float32,
    )
    np.testing.assert_array_equal(
        rgbe_encode_j(x),
        [[128, 64, 0, 129], [0, 0, 0, 0], [0, 0, 0, 0], [255] * 4, [0, 0, 192, 130]],
    )
    np.testing.assert_array_equal(
        rgbe_decode_j(jnp.array([[128, 64, 0, 129], [9, 9, 9, 0]], jnp.uint8), offset=0.0),
        [[1.0, 0.5, 0.0], [0.0, 0.0, 0.0]],
    )
    np.testing.assert_allclose(
        rgbe_decode_j(jnp.array([128, 64, 0, 129], jnp.uint8)), [1.00390625, 0.50390625, 0.00390625]
    )


def test_rgbe_matches_numpy_file_codec_and_bound(rng):
    x = _log_uniform(rng, 1e-30, 1e30, (4000, 3)).astype(np.float32)
    enc = np.asarray(rgbe_encode_j(jnp.asarray(x)))
    np.testing.assert_array_equal(enc, rgbe_from_float(x))  # the .hdr writer's bytes
    dec = np.asarray(rgbe_decode_j(jnp.asarray(enc)))
    np.testing.assert_array_equal(dec, float_from_rgbe(enc))
    rel = np.abs(dec.max(-1) / x.max(-1) - 1)
    assert rel.max() <= 2.0**-8 * (1 + 1e-5)  # Ward 1991: half a mantissa step of >= 128
    assert rel.max() > 2.0**-9  # the bound is attained, not loose


def test_rgbe_x64(x64, rng):
    x = _log_uniform(rng, 1e-37, 1e37, (1000, 3))
    x[0] = [1e39, 0, 0]
    enc = rgbe_encode_j(jnp.asarray(x))
    np.testing.assert_array_equal(enc, rgbe_from_float(x))
    np.testing.assert_array_equal(enc[0], [255] * 4)
    dec = jax.jit(lambda e: rgbe_decode(e, dtype=jnp.float64))(enc)
    assert dec.dtype == jnp.float64


# ----------------------------------------------------------------------------- LogLuv32


def test_logluv32_known_word():
    w = int(l32e(jnp.asarray(D65, jnp.float32)))
    assert w >> 16 == 256 * 64  # Y = 1 -> Le = 16384
    assert (w >> 8) & 0xFF == int(410 * 0.19783)  # D65 u' = 0.19783
    assert w & 0xFF == int(410 * 0.46832)  # D65 v' = 0.46832


def test_logluv32_error_bounds(x64, rng):
    XYZ = _random_XYZ(rng, 5000, 1e-19, 1e18)
    dec = np.asarray(l32d64(l32e(jnp.asarray(XYZ))))
    relY = np.abs(dec[:, 1] / XYZ[:, 1] - 1)
    assert relY.max() <= 2 ** (1 / 512) - 1 + 1e-9  # 0.135 %: half a 1/256 log2 step
    duv = np.abs(_uv(dec) - _uv(XYZ))
    assert duv.max() <= 0.5 / 410 + 1e-9  # half an 8-bit u'v' step


def test_logluv32_float32_error(rng):
    XYZ = _random_XYZ(rng, 5000, 1e-6, 1e6).astype(np.float32)
    dec = np.asarray(l32d(l32e(jnp.asarray(XYZ))))
    assert np.max(np.abs(dec[:, 1] / XYZ[:, 1] - 1)) <= 0.003  # 0.3 % over the range


def test_logluv32_limits_and_sign(x64):
    Y = jnp.array([0.0, 1e-25, 5.5e-20, 1e25, -2.0, np.nan])
    XYZ = jnp.stack([Y, Y, Y], -1)
    dec = np.asarray(l32d64(l32e(XYZ)))
    assert np.all(np.isfinite(dec))
    assert dec[0, 1] == 0 and dec[1, 1] == 0 and dec[5, 1] == 0
    assert dec[2, 1] == pytest.approx(5.5e-20, rel=3e-3)
    assert dec[3, 1] == pytest.approx(2 ** ((0x7FFF + 0.5) / 256 - 64))  # clamped at the top
    assert dec[4, 1] == pytest.approx(-2.0, rel=2e-3)
    np.testing.assert_allclose(_uv(-dec[4]), _uv([1.0, 1.0, 1.0]), atol=0.5 / 410 + 1e-9)


# ----------------------------------------------------------------------------- LogLuv24


def test_uv_table_against_libtiff():
    ustart, nus, ncum = logluv24_uv_table()
    assert len(ustart) == 163 and ncum[0] == 0
    np.testing.assert_array_equal(ncum[1:], np.cumsum(nus)[:-1])
    # libtiff uvcode.h (Larson 1997): UV_NDIVS = 16289 and the first rows' (ustart, nus)
    assert abs(ncum[-1] + nus[-1] - 16289) < 0.01 * 16289
    lib_nus = [4, 6, 7, 9, 10, 12, 14, 15, 17, 18, 21, 22, 23, 26, 27, 29, 31, 32, 34, 36]
    lib_ustart = [0.247663, 0.243779, 0.241684, 0.237874, 0.235906, 0.232153, 0.228352]
    assert np.max(np.abs(nus[:20] - lib_nus)) <= 2
    assert np.max(np.abs(ustart[:7] - lib_ustart)) <= 0.0035
    assert nus[-1] == pytest.approx(21, abs=2) and nus[140] == pytest.approx(177, abs=2)


def test_logluv24_every_index_roundtrips():
    ustart, nus, ncum = logluv24_uv_table()
    n = int(ncum[-1] + nus[-1])
    words = (jnp.uint32(512) << 14) | jnp.arange(n, dtype=jnp.uint32)
    again = l24e(l24d(words))
    np.testing.assert_array_equal(np.asarray(again), np.asarray(words))


def test_logluv24_error_bounds(x64, rng):
    XYZ = _random_XYZ(rng, 5000, 2.5e-4, 15.0)
    dec = np.asarray(l24d64(l24e(jnp.asarray(XYZ))))
    assert np.max(np.abs(dec[:, 1] / XYZ[:, 1] - 1)) <= 2 ** (1 / 128) - 1 + 1e-9  # 0.54 %
    assert np.abs(_uv(dec) - _uv(XYZ)).max() <= 0.0035 / 2 + 1e-9  # half a table cell
    # limits: below 2.4283e-4 -> 0, above 15.742 -> top code 1023
    Y = jnp.array([0.0, 1e-4, 100.0])
    dec = np.asarray(l24d(l24e(jnp.stack([Y, Y, Y], -1))))
    assert dec[0, 1] == 0 and dec[1, 1] == 0
    assert dec[2, 1] == pytest.approx(2 ** (1023.5 / 64 - 12), rel=1e-6)
    assert np.all(np.isfinite(dec))


def test_logluv24_out_of_gamut_is_clamped():
    XYZ = jnp.array([[1.0, 1.0, -0.5], [0.0, 1.0, 5.0], [5.0, 0.1, 0.0]], jnp.float32)
    words = np.asarray(l24e(XYZ))
    _, nus, ncum = logluv24_uv_table()
    assert np.all((words & 0x3FFF) < ncum[-1] + nus[-1])
    assert np.all(np.isfinite(np.asarray(l24d(jnp.asarray(words)))))


# ----------------------------------------------------------------------------- half


def test_half_roundtrip_values_and_grad(rng):
    x = np.concatenate([_log_uniform(rng, 1e-8, 1e5, 2000), [65504.0, 65520.0, 1e-9]])
    x = x.astype(np.float32)
    out = np.asarray(jax.jit(half_roundtrip)(jnp.asarray(x)))
    with np.errstate(over="ignore"):
        np.testing.assert_array_equal(out, x.astype(np.float16).astype(np.float32))
    normal = (x >= 2.0**-14) & (x <= 65504)
    assert np.max(np.abs(out[normal] / x[normal] - 1)) <= 2.0**-11
    assert np.isposinf(out[-2]) and out[-1] == 0
    g = jax.grad(lambda v: jnp.sum(half_roundtrip(v) * 3.0))(jnp.asarray(x[:10]))
    np.testing.assert_array_equal(g, 3.0)  # straight-through derivative


def test_half_roundtrip_keeps_float64(x64):
    y = half_roundtrip(jnp.array([0.1], jnp.float64))
    assert y.dtype == jnp.float64 and float(y[0]) == 0.0999755859375


def test_vmap_and_bad_inputs():
    x = jnp.exp(jnp.linspace(-20.0, 20.0, 30)).reshape(2, 5, 3)
    np.testing.assert_array_equal(jax.jit(jax.vmap(rgbe_encode))(x), rgbe_encode_j(x))
    with pytest.raises(ValueError, match="rgb"):
        rgbe_encode(jnp.ones((4, 2)))
    with pytest.raises(TypeError, match="rgbe"):
        rgbe_decode(jnp.ones((4, 4)))
    with pytest.raises(ValueError, match="XYZ"):
        logluv32_encode(jnp.ones(4))
    with pytest.raises(TypeError, match="word"):
        logluv24_decode(jnp.ones(4))


def test_eager_codecs_compile_once(rng):
    """Eager calls run one compiled core each: new pixel values of the same shape neither
    retrace nor recompile; values against the NumPy file codec (jaxgfx.io.hdr_rgbe)."""
    from jaxgfx.hdr import encodings as enc

    before = {f: f._cache_size() for f in (enc._rgbe_encode, enc._logluv32_encode)}
    for scale in (1.0, 7.5):
        x = (rng.random((5, 7, 3)) * scale).astype(np.float32)
        np.testing.assert_array_equal(np.asarray(rgbe_encode(x)), rgbe_from_float(x))
        l32e(jnp.asarray(x))
    for f, n in before.items():
        assert f._cache_size() <= n + 1
