"""I/O and HDR-encoding benchmarks: speed vs OpenCV and quantisation error vs float16.

Run: ``python -m benchmarks.io [--size 512] [--out results.json]``. Prints one JSON object.
Timings are the median of ``--repeat`` runs (wall clock, host CPU).
"""

from __future__ import annotations

import argparse
import os
import tempfile

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import cv2  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from benchmarks._report import emit, machine  # noqa: E402
from benchmarks._timing import first_and_median  # noqa: E402
from jaxgfx.hdr.encodings import (  # noqa: E402
    half_roundtrip,
    logluv24_decode,
    logluv24_encode,
    logluv32_decode,
    logluv32_encode,
    rgbe_decode,
    rgbe_encode,
)
from jaxgfx.io import read_exr, read_hdr, write_exr, write_hdr  # noqa: E402


def _time(fn, repeat):
    return first_and_median(fn, repeat)[1]  # after a warm-up call (compilation, caches)


def _uv(XYZ):
    den = XYZ[..., 0] + 15 * XYZ[..., 1] + 3 * XYZ[..., 2]
    return np.stack([4 * XYZ[..., 0] / den, 9 * XYZ[..., 1] / den], -1)


def quantisation_table(n=200_000, seed=0):
    """Relative error of each encoding over luminance 1e-6..1e6 (log-uniform), float64."""
    jax.config.update("jax_enable_x64", True)
    rng = np.random.default_rng(seed)
    Y = np.exp(rng.uniform(np.log(1e-6), np.log(1e6), n))
    # in-gamut colours: linear sRGB in [0.05, 1] through the sRGB -> XYZ (D65) matrix
    M = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    chroma = rng.uniform(0.05, 1.0, (n, 3)) @ M.T
    XYZ = chroma / chroma[:, 1:2] * Y[:, None]
    out = {}

    def stats(rel):
        rel = rel[np.isfinite(rel)]
        return {
            "max": float(rel.max()),
            "mean": float(rel.mean()),
            "p99": float(np.quantile(rel, 0.99)),
        }

    rgb = XYZ  # RGBE acts on any positive triple
    dec = np.asarray(jax.jit(lambda e: rgbe_decode(e, dtype=jnp.float64))(rgbe_encode(rgb)))
    out["rgbe"] = {
        "max_channel_rel": stats(np.abs(dec.max(-1) / rgb.max(-1) - 1)),
        "all_channels_rel": stats(np.abs(dec / rgb - 1).ravel()),
        "bits_per_pixel": 32,
    }
    dec = np.asarray(jax.jit(lambda w: logluv32_decode(w, dtype=jnp.float64))(logluv32_encode(XYZ)))
    out["logluv32"] = {
        "Y_rel": stats(np.abs(dec[:, 1] / Y - 1)),
        "uv_abs": stats(np.abs(_uv(dec) - _uv(XYZ)).max(-1)),
        "all_channels_rel": stats(np.abs(dec / XYZ - 1).ravel()),
        "bits_per_pixel": 32,
    }
    dec = np.asarray(jax.jit(lambda w: logluv24_decode(w, dtype=jnp.float64))(logluv24_encode(XYZ)))
    inr = (Y > 2.5e-4) & (Y < 15.7)
    out["logluv24"] = {
        "Y_rel_in_range": stats(np.abs(dec[inr, 1] / Y[inr] - 1)),
        "uv_abs_in_range": stats(np.abs(_uv(dec[inr]) - _uv(XYZ[inr])).max(-1)),
        "fraction_of_1e-6..1e6_in_range": float(inr.mean()),
        "bits_per_pixel": 24,
    }
    h = np.asarray(jax.jit(half_roundtrip)(jnp.asarray(XYZ)))
    finite = np.isfinite(h).all(-1) & (XYZ >= 2.0**-14).all(-1)
    out["half"] = {
        "rel_normal_range": stats(np.abs(h[finite] / XYZ[finite] - 1).ravel()),
        "fraction_normal": float(finite.mean()),
        "bits_per_pixel": 48,
    }
    jax.config.update("jax_enable_x64", False)
    return out


def speed(size, repeat):
    rng = np.random.default_rng(1)
    img = np.exp(rng.normal(0, 2, (size, size, 3))).astype(np.float32)
    img[: size // 4] = 1.0  # some constant area, as in real images
    res = {"size": size}
    with tempfile.TemporaryDirectory() as d:
        ph, pc, pe = f"{d}/a.hdr", f"{d}/b.hdr", f"{d}/c.exr"
        bgr = np.ascontiguousarray(img[..., ::-1])
        res["write_hdr_jaxgfx_s"] = _time(lambda: write_hdr(ph, img), repeat)
        res["write_hdr_opencv_s"] = _time(lambda: cv2.imwrite(pc, bgr), repeat)
        flags = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR
        res["read_hdr_jaxgfx_s"] = _time(lambda: read_hdr(ph), repeat)
        res["read_hdr_opencv_s"] = _time(lambda: cv2.imread(pc, flags), repeat)
        res["hdr_bytes_jaxgfx"] = os.path.getsize(ph)
        res["hdr_bytes_opencv"] = os.path.getsize(pc)
        res["write_exr_zip_s"] = _time(lambda: write_exr(pe, img), repeat)
        res["read_exr_s"] = _time(lambda: read_exr(pe), repeat)
    x = jnp.asarray(img)
    enc = jax.jit(rgbe_encode)
    res["rgbe_encode_jax_s"] = _time(lambda: enc(x).block_until_ready(), repeat)
    from jaxgfx.io.hdr_rgbe import rgbe_from_float

    res["rgbe_encode_numpy_s"] = _time(lambda: rgbe_from_float(img), repeat)
    l32 = jax.jit(logluv32_encode)
    res["logluv32_encode_jax_s"] = _time(lambda: l32(x).block_until_ready(), repeat)
    l24 = jax.jit(logluv24_encode)
    res["logluv24_encode_jax_s"] = _time(lambda: l24(x).block_until_ready(), repeat)
    return res


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    result = {"benchmark": "io", "machine": machine(opencv=cv2.__version__)}
    result["quantisation"] = quantisation_table()
    if a.size > 0:
        result["speed"] = speed(a.size, a.repeat)
    emit(result, a.out)


if __name__ == "__main__":
    main()
