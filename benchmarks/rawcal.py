"""Speed and accuracy of jaxgfx.hdr.{align, noise, raw_calibration} vs OpenCV / scikit-image /
SciPy / NumPy, measured in the same run. Prints one JSON object.

    python -m benchmarks.rawcal [--size 256] [--repeats 5] [--out FILE]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import cv2  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
import skimage  # noqa: E402
from scipy import ndimage  # noqa: E402
from skimage.registration import phase_cross_correlation  # noqa: E402

from benchmarks._report import emit, machine  # noqa: E402
from jaxgfx.hdr.align import mtb_align, phase_correlation, shift_image  # noqa: E402
from jaxgfx.hdr.noise import fit_photon_transfer  # noqa: E402
from jaxgfx.hdr.raw_calibration import pairwise_exposure_ratio  # noqa: E402


def _best(fn, repeats):
    """Best wall time of ``repeats`` calls (after one warm-up call that also compiles)."""
    out = fn()
    jax.block_until_ready(out)
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t)
    return min(ts), out


def _texture(rng, n, bw=0.2):
    f = np.fft.fft2(rng.standard_normal((n, n)))
    k2 = np.fft.fftfreq(n)[:, None] ** 2 + np.fft.fftfreq(n)[None, :] ** 2
    t = np.real(np.fft.ifft2(f * np.exp(-k2 / (2 * bw**2))))
    return 0.05 + 0.9 * ((t - t.min()) / (t.max() - t.min())) ** 2


def _fshift(img, dy, dx):
    k = np.fft.fftfreq(img.shape[0])
    ph = np.exp(-2j * np.pi * (k[:, None] * dy + k[None, :] * dx))
    return np.real(np.fft.ifft2(np.fft.fft2(img) * ph))


def bench_align(size, repeats, trials=8):
    rng = np.random.default_rng(0)
    n = size + 64
    c = 32
    win = cv2.createHanningWindow((size, size), cv2.CV_64F)
    pc1 = jax.jit(lambda a, b: phase_correlation(a, b))
    pc20 = jax.jit(lambda a, b: phase_correlation(a, b, upsample=20))
    mtb = jax.jit(lambda a, b: mtb_align(a, b, levels=4))
    cv_mtb = cv2.createAlignMTB(max_bits=4)  # same depth as levels=4
    err = {k: [] for k in ("jax_phase_up1", "jax_phase_up20", "skimage_up20", "cv2_phase")}
    err_mtb = {"jax_mtb": [], "cv2_mtb": []}
    times = {}
    for i in range(trials):
        base = _texture(rng, n)
        dy, dx = rng.uniform(-8, 8, 2)
        gain = rng.uniform(0.3, 1.8)
        ref = base[c : c + size, c : c + size]
        img = np.clip(gain * _fshift(base, dy, dx)[c : c + size, c : c + size], 0, 1)
        img = np.clip(img + 0.01 * rng.standard_normal(img.shape), 0, 1)
        a32, b32 = ref.astype(np.float32), img.astype(np.float32)
        res = {
            "jax_phase_up1": lambda a=a32, b=b32: pc1(a, b),
            "jax_phase_up20": lambda a=a32, b=b32: pc20(a, b),
            "skimage_up20": lambda a=ref, b=img: (
                -phase_cross_correlation(a * win, b * win, upsample_factor=20)[0]
            ),
            "cv2_phase": lambda a=ref, b=img: np.array(cv2.phaseCorrelate(a, b, win)[0])[::-1],
        }
        a8 = (ref * 255).astype(np.uint8)
        b8 = (img * 255).astype(np.uint8)
        res_mtb = {
            "jax_mtb": lambda a=a32, b=b32: mtb(a, b),
            # OpenCV returns the shift that registers img to ref: -shift, as (x, y)
            "cv2_mtb": lambda a=a8, b=b8: -np.array(cv_mtb.calculateShift(a, b))[::-1],
        }
        for name, fn in {**res, **res_mtb}.items():
            if i == 0:
                times[name], out = _best(fn, repeats)
            else:
                out = fn()
            e = float(np.max(np.abs(np.asarray(out, float) - [dy, dx])))
            (err if name in err else err_mtb)[name].append(e)
    return {
        "size": size,
        "trials": trials,
        "seconds_per_call": times,
        "max_abs_error_px": {k: {"mean": np.mean(v), "max": np.max(v)} for k, v in err.items()}
        | {k: {"mean": np.mean(v), "max": np.max(v)} for k, v in err_mtb.items()},
    }


def bench_shift(size, repeats):
    rng = np.random.default_rng(1)
    img = _texture(rng, size).astype(np.float32)
    s = (3.3, -1.7)
    f_bil = jax.jit(lambda im, s: shift_image(im, s))
    f_fft = jax.jit(lambda im, s: shift_image(im, s, mode="fft"))
    sj = jnp.array(s)
    t_bil, o_bil = _best(lambda: f_bil(img, sj), repeats)
    t_sp, o_sp = _best(lambda: ndimage.shift(img, s, order=1, mode="nearest"), repeats)
    t_fft, o_fft = _best(lambda: f_fft(img, sj), repeats)
    t_np, o_np = _best(lambda: _fshift(img, *s), repeats)
    return {
        "size": size,
        "seconds_per_call": {
            "jax_bilinear": t_bil,
            "scipy_ndimage_shift_order1": t_sp,
            "jax_fft": t_fft,
            "numpy_fft": t_np,
        },
        "max_abs_diff_bilinear_vs_scipy": float(np.max(np.abs(np.asarray(o_bil) - o_sp))),
        "max_abs_diff_fft_vs_numpy": float(np.max(np.abs(np.asarray(o_fft) - o_np))),
    }


def bench_noise(size, repeats):
    rng = np.random.default_rng(2)
    fw, read = 1000.0, 3.0
    ramp = np.linspace(0.01, 0.95, size * size).reshape(size, size)
    lam = np.broadcast_to(ramp[None, None, :, :, None], (4, 2, size, size, 4)) * fw
    lam = lam * np.array([0.25, 0.5, 0.75, 1.0])[:, None, None, None, None]
    frames = ((rng.poisson(lam) + read * rng.standard_normal(lam.shape)) / fw).astype(np.float32)
    fit = jax.jit(lambda f: fit_photon_transfer(f))
    t, (model, info) = _best(lambda: fit(frames), repeats)
    a = frames[3, 0, ..., 1]
    b = 1.9 * frames[3, 1, ..., 1]
    pr = jax.jit(lambda a, b: pairwise_exposure_ratio(a, b, black=0.0, white=2.0))
    t_r, (r, se, n) = _best(lambda: pr(a, b), repeats)
    return {
        "ptc_frames_shape": list(frames.shape),
        "ptc_seconds": t,
        "gain_true": 1 / fw,
        "gain": np.asarray(model.gain).tolist(),
        "gain_se": np.asarray(info["gain_se"]).tolist(),
        "read_variance_true": (read / fw) ** 2,
        "read_variance": np.asarray(model.read_variance).tolist(),
        "read_variance_se": np.asarray(info["read_variance_se"]).tolist(),
        "pair_ratio_seconds": t_r,
        "pair_ratio": [float(r), float(se)],
        "pair_ratio_true": 1.9,
    }


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--out", default=None, help="also write the JSON here")
    args = p.parse_args()
    peers = dict(opencv=cv2.__version__, scipy=scipy.__version__, skimage=skimage.__version__)
    out = {
        "benchmark": "rawcal",
        "machine": machine(**peers),
        "align": bench_align(args.size, args.repeats),
        "shift_image": bench_shift(args.size, args.repeats),
        "noise_and_ratio": bench_noise(args.size, args.repeats),
    }
    emit(out, args.out)


if __name__ == "__main__":
    main()
