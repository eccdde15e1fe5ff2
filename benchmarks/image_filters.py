"""Speed of jaxgfx.image filters vs OpenCV and scikit-image / scipy, in the same run.

Usage::

    python -m benchmarks.image_filters            # 1024x1024x3 float32
    python -m benchmarks.image_filters --quick    # 256x256x3
    python -m benchmarks.image_filters --sweep    # + direct/separable/FFT crossover sweep

Prints one JSON document. jaxgfx is jitted; ``compile_s`` is lower+compile time, ``jax_s`` the
median steady-state time (``block_until_ready``) over ``--repeats`` runs; peers are timed the
same way on NumPy arrays. ``ratio_cv2`` = jax_s / cv2_s (lower is better).
"""

from __future__ import annotations

import argparse
import json

import cv2
import jax.numpy as jnp
import numpy as np
import scipy
import scipy.ndimage as ndi
import skimage
import skimage.feature
import skimage.filters
import skimage.restoration

from benchmarks._report import emit, machine
from benchmarks._timing import time_jax, time_np
from jaxgfx import image as jimg


def bench_filters(n, repeats):
    rng = np.random.default_rng(0)
    # smooth-ish content + noise in [0, 1]
    base = cv2.GaussianBlur(rng.random((n, n, 3)).astype(np.float32), (0, 0), 4)
    img = np.clip((base - base.min()) / np.ptp(base) + 0.05 * rng.standard_normal(base.shape), 0, 1)
    img = img.astype(np.float32)
    gray = img.mean(-1)
    gray_u8 = (gray * 255).astype(np.uint8)
    x = jnp.asarray(img)
    xg = jnp.asarray(gray)
    B = cv2.BORDER_REFLECT_101
    cases = {
        "gaussian_sigma3": (
            lambda a: jimg.gaussian_blur(a, 3.0),
            (x,),
            lambda: cv2.GaussianBlur(img, (19, 19), 3.0, borderType=B),
            lambda: skimage.filters.gaussian(
                img, 3.0, truncate=3.0, mode="mirror", channel_axis=-1
            ),
        ),
        "box_r5": (
            lambda a: jimg.box_blur(a, 11),
            (x,),
            lambda: cv2.blur(img, (11, 11), borderType=B),
            lambda: ndi.uniform_filter(img, (11, 11, 1), mode="mirror"),
        ),
        "median_5x5": (
            lambda a: jimg.median_filter(a, 5),
            (x,),
            lambda: cv2.medianBlur(img, 5),
            lambda: ndi.median_filter(img, (5, 5, 1), mode="mirror"),
        ),
        "bilateral_brute_s2_r0.1_gray": (
            lambda a: jimg.bilateral_filter(a, 2.0, 0.1, method="brute"),
            (xg,),
            lambda: cv2.bilateralFilter(gray, 0, 0.1, 2.0),
            lambda: skimage.restoration.denoise_bilateral(
                gray, win_size=7, sigma_color=0.1, sigma_spatial=2.0, mode="reflect"
            ),
        ),
        "bilateral_grid_s8_r0.1_gray": (
            lambda a: jimg.bilateral_filter(a, 8.0, 0.1, method="grid", range_bins=10),
            (xg,),
            lambda: cv2.bilateralFilter(gray, 0, 0.1, 8.0),
            None,
        ),
        "sobel_xy": (
            lambda a: jimg.sobel(a),
            (x,),
            lambda: (
                cv2.Sobel(img, -1, 1, 0, borderType=B),
                cv2.Sobel(img, -1, 0, 1, borderType=B),
            ),
            lambda: [
                (skimage.filters.sobel_h(img[..., c]), skimage.filters.sobel_v(img[..., c]))
                for c in range(3)
            ],
        ),
        "canny_sigma1.4_gray": (
            lambda a: jimg.canny(a, 1.4, 0.1, 0.3),
            (xg,),
            lambda: cv2.Canny(cv2.GaussianBlur(gray_u8, (0, 0), 1.4), 25, 75),
            lambda: skimage.feature.canny(gray, 1.4, 0.1, 0.3),
        ),
    }
    if hasattr(jimg, "demosaic"):
        mosaic = img[..., 1].copy()
        cases["demosaic"] = (
            lambda a: jimg.demosaic(a),
            (jnp.asarray(mosaic),),
            lambda: cv2.cvtColor((mosaic * 65535).astype(np.uint16), cv2.COLOR_BayerRG2RGB),
            None,
        )
    out = {}
    for name, (jf, args, cvf, skf) in cases.items():
        row = {}
        try:
            row["compile_s"], row["jax_s"] = time_jax(jf, *args, repeats=repeats)
        except Exception as e:  # noqa: BLE001 - report and continue
            row["jax_error"] = f"{type(e).__name__}: {e}"[:200]
        row["cv2_s"] = time_np(cvf, repeats)
        if skf is not None:
            row["skimage_or_scipy_s"] = time_np(skf, max(1, repeats // 2))
        if "jax_s" in row:
            row["ratio_cv2"] = row["jax_s"] / row["cv2_s"]
            if skf is not None:
                row["ratio_skimage"] = row["jax_s"] / row["skimage_or_scipy_s"]
        out[name] = row
        print(name, json.dumps(row), flush=True, file=__import__("sys").stderr)
    return out


def bench_sweep(n, repeats):
    """Direct vs FFT for 2-d kernels, and 1-d pass direct vs FFT, over kernel size."""
    rng = np.random.default_rng(1)
    x = jnp.asarray(rng.random((n, n, 3)).astype(np.float32))
    res = {"n": n, "2d": {}, "1d": {}}
    for k in (3, 5, 7, 9, 11, 13, 17):
        ker = jnp.asarray(rng.random((k, k)).astype(np.float32))
        row = {}
        for method in ("direct", "fft"):
            _, row[method] = time_jax(
                lambda a, kk, m=method: jimg.convolve(a, kk, method=m), x, ker, repeats=repeats
            )
        res["2d"][k] = row
        print("2d", k, row, flush=True, file=__import__("sys").stderr)
    one = jnp.ones((1,), jnp.float32)
    for k in (9, 17, 33, 49, 65, 97, 129):
        ker = jnp.asarray(rng.random(k).astype(np.float32))
        row = {}
        for method in ("direct", "fft"):
            _, row[method] = time_jax(
                lambda a, kk, m=method: jimg.convolve_separable(a, one, kk, method=m),
                x,
                ker,
                repeats=repeats,
            )
        res["1d"][k] = row
        print("1d", k, row, flush=True, file=__import__("sys").stderr)
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="256x256x3 instead of 1024x1024x3")
    ap.add_argument("--size", type=int, default=None)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--sweep", action="store_true", help="run the crossover sweep")
    ap.add_argument("--sweep-only", action="store_true")
    ap.add_argument("--out", default=None, help="also write the JSON here")
    args = ap.parse_args(argv)
    n = args.size or (256 if args.quick else 1024)
    peers = dict(
        opencv=cv2.__version__,
        opencv_threads=cv2.getNumThreads(),
        skimage=skimage.__version__,
        scipy=scipy.__version__,
    )
    result = {
        "benchmark": "image_filters",
        "machine": machine(**peers),
        "size": [n, n, 3],
        "dtype": "float32",
    }
    if not args.sweep_only:
        result["filters"] = bench_filters(n, args.repeats)
    if args.sweep or args.sweep_only:
        result["crossover"] = bench_sweep(min(n, 512), args.repeats)
    emit(result, args.out)


if __name__ == "__main__":
    main()
