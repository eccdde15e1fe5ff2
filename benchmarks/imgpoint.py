"""Speed of jaxgfx.image point / noise / Fourier / Bayer ops vs OpenCV / SciPy / scikit-image.

Run: ``python -m benchmarks.imgpoint [--size 512] [--repeat 10] [--out FILE]``; prints one JSON
object. Times are medians over ``repeat`` runs of the jitted function after a warm-up call (compile
time reported separately), the peer measured in the same run on the same input.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import cv2  # noqa: E402
import jax  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
import skimage  # noqa: E402
from scipy import ndimage  # noqa: E402
from scipy.interpolate import PchipInterpolator  # noqa: E402
from skimage.exposure import equalize_hist  # noqa: E402

from benchmarks._report import emit, machine  # noqa: E402
from jaxgfx.image import bayer, fourier, noise, point  # noqa: E402


def _median_time(fn, repeat):
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        jax.block_until_ready(out)
        ts.append(time.perf_counter() - t)
    return float(np.median(ts))


def _bench_jax(f, args, repeat):
    jf = jax.jit(f)
    t = time.perf_counter()
    jax.block_until_ready(jf(*args))
    compile_s = time.perf_counter() - t
    return {"ms": 1e3 * _median_time(lambda: jf(*args), repeat), "compile_s": compile_s}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--out", default=None, help="also write the JSON here")
    a = ap.parse_args()
    n, r = a.size, a.repeat
    peers = dict(opencv=cv2.__version__, scipy=scipy.__version__, skimage=skimage.__version__)
    mach = machine(**peers)
    rng = np.random.default_rng(0)
    rgb = rng.random((n, n, 3)).astype(np.float32)
    gray = rgb[..., 0].copy()
    raw = np.asarray(bayer.bayer_mosaic(rgb, "RGGB"))
    raw16 = np.round(raw * 65535).astype(np.uint16)
    res = {}

    def peer(fn):
        return {"ms": 1e3 * _median_time(fn, r)}

    res["demosaic_malvar"] = _bench_jax(lambda x: bayer.demosaic(x, "RGGB"), (raw,), r)
    res["demosaic_bilinear"] = _bench_jax(
        lambda x: bayer.demosaic(x, "RGGB", method="bilinear"), (raw,), r
    )
    res["opencv_bayer_bilinear_u16"] = peer(lambda: cv2.cvtColor(raw16, cv2.COLOR_BayerBG2RGB))
    res["opencv_bayer_EA_u16"] = peer(lambda: cv2.cvtColor(raw16, cv2.COLOR_BayerBG2RGB_EA))

    sigma = 3.0
    res["fourier_lowpass_gaussian_wrap_rgb"] = _bench_jax(
        lambda x: fourier.fourier_lowpass(x, 1 / (2 * np.pi * sigma)), (rgb,), r
    )
    res["fourier_lowpass_gaussian_reflect_rgb"] = _bench_jax(
        lambda x: fourier.fourier_lowpass(x, 1 / (2 * np.pi * sigma), padding="reflect"), (rgb,), r
    )
    res["opencv_GaussianBlur_rgb"] = peer(
        lambda: cv2.GaussianBlur(rgb, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    )
    res["scipy_gaussian_filter_rgb"] = peer(
        lambda: ndimage.gaussian_filter(rgb, (sigma, sigma, 0), mode="reflect")
    )

    res["histogram_256_rgb"] = _bench_jax(lambda x: point.histogram(x, bins=256), (rgb,), r)
    res["opencv_calcHist_256_rgb"] = peer(
        lambda: [cv2.calcHist([rgb], [c], None, [256], [0, 1]) for c in range(3)]
    )
    res["equalize_histogram_gray"] = _bench_jax(point.equalize_histogram, (gray,), r)
    res["skimage_equalize_hist_gray"] = peer(lambda: equalize_hist(gray))
    xs = np.linspace(0, 1, 9)
    ys = np.sqrt(xs)
    res["tone_curve_spline_rgb"] = _bench_jax(
        lambda x: point.tone_curve_spline(x, xs, ys), (rgb,), r
    )
    pchip = PchipInterpolator(xs, ys)
    res["scipy_pchip_rgb"] = peer(lambda: pchip(rgb))
    res["stretch_contrast_rgb"] = _bench_jax(point.stretch_contrast, (rgb,), r)
    res["numpy_quantile_stretch_rgb"] = peer(
        lambda: np.clip(
            (rgb - np.quantile(rgb, 0.05)) / np.ptp(np.quantile(rgb, [0.05, 0.95])), 0, 1
        )
    )

    key = jax.random.key(0)
    res["add_gaussian_noise_rgb"] = _bench_jax(
        lambda k, x: noise.add_gaussian_noise(k, x, sigma=0.1), (key, rgb), r
    )
    res["numpy_gaussian_noise_rgb"] = peer(
        lambda: rgb + 0.1 * rng.standard_normal(rgb.shape, dtype=np.float32)
    )
    res["add_poisson_gaussian_noise_rgb"] = _bench_jax(
        lambda k, x: noise.add_poisson_gaussian_noise(k, x, gain=0.01, read_sigma=0.01),
        (key, rgb),
        r,
    )
    res["numpy_poisson_gaussian_noise_rgb"] = peer(
        lambda: 0.01 * rng.poisson(rgb / 0.01) + 0.01 * rng.standard_normal(rgb.shape)
    )

    emit({"benchmark": "imgpoint", "machine": mach, "size": n, "repeat": r, "results": res}, a.out)


if __name__ == "__main__":
    main()
