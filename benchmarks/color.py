"""Speed and accuracy of jaxgfx.color against colour-science, scikit-image and OpenCV.

Run: ``python -m benchmarks.color [--size 512] [--repeat 5] [--out FILE]``. Prints one JSON
object: per task, the median wall time (ms) of each implementation on the same float32 image
(jaxgfx jitted, compile time reported separately, ``block_until_ready`` included) and the max abs
difference to the float64 reference.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--out", default=None, help="also write the JSON here")
    args = p.parse_args(argv)

    import colour
    import cv2
    import jax
    import skimage
    import skimage.color as skc
    from colour.difference import delta_E_CIE2000

    import jaxgfx.color as jc
    from benchmarks._report import emit, machine
    from benchmarks._timing import median_time

    rng = np.random.default_rng(0)
    n = args.size
    srgb = rng.uniform(0, 1, (n, n, 3)).astype(np.float32)
    srgb64 = srgb.astype(np.float64)
    peers = dict(colour=colour.__version__, skimage=skimage.__version__, opencv=cv2.__version__)
    results = {"benchmark": "color", "machine": machine(**peers), "size": [n, n, 3], "tasks": {}}

    def run(task, impls, ref):
        out = {}
        for name, fn in impls.items():
            t0 = time.perf_counter()
            y = np.asarray(jax.block_until_ready(fn()))
            first = 1e3 * (time.perf_counter() - t0)
            ms = 1e3 * median_time(fn, args.repeat)
            err = float(np.max(np.abs(y.astype(np.float64) - ref)))
            out[name] = {"ms": round(ms, 3), "first_call_ms": round(first, 1), "max_abs_err": err}
        results["tasks"][task] = out

    # sRGB (encoded) -> CIELAB D65
    def lab_pipeline(x):
        return jc.xyz_to_lab(jc.rgb_to_xyz(jc.srgb_to_linear(x)))

    f_lab = jax.jit(lab_pipeline)
    # float64 reference with the *derived* sRGB matrix (colour-science's own sRGB matrix is the
    # standard's 4-decimal rounding, which alone moves L*a*b* by up to ~0.02)
    ref = colour.XYZ_to_Lab(
        colour.models.eotf_sRGB(srgb64) @ jc.rgb_to_xyz_matrix("srgb").T,
        colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"],
    )
    run(
        "srgb_to_lab",
        {
            "jaxgfx": lambda: f_lab(srgb),
            "skimage": lambda: skc.rgb2lab(srgb),
            "opencv": lambda: cv2.cvtColor(srgb, cv2.COLOR_RGB2Lab),
            "colour": lambda: colour.XYZ_to_Lab(
                colour.RGB_to_XYZ(srgb, "sRGB", apply_cctf_decoding=True, illuminant=None)
            ),
        },
        ref,
    )

    f_hsv = jax.jit(jc.rgb_to_hsv)
    ref = skc.rgb2hsv(srgb64)
    run(
        "rgb_to_hsv",
        {
            "jaxgfx": lambda: f_hsv(srgb),
            "skimage": lambda: skc.rgb2hsv(srgb),
            "opencv_h_scaled": lambda: (
                cv2.cvtColor(srgb, cv2.COLOR_RGB2HSV) * np.array([1 / 360, 1, 1], np.float32)
            ),
        },
        ref,
    )

    lab1 = ref_lab = np.asarray(f_lab(srgb))
    lab2 = ref_lab + rng.normal(0, 2, ref_lab.shape).astype(np.float32)
    f_de = jax.jit(jc.delta_e_2000)
    ref = delta_E_CIE2000(lab1.astype(np.float64), lab2.astype(np.float64))
    run(
        "delta_e_2000",
        {
            "jaxgfx": lambda: f_de(lab1, lab2),
            "skimage": lambda: skc.deltaE_ciede2000(lab1, lab2),
            "colour": lambda: delta_E_CIE2000(lab1, lab2),
        },
        ref,
    )

    lin = srgb * np.array([1.3, 1.0, 0.6], np.float32)
    f_gw = jax.jit(jc.white_balance_grey_world)
    f_wp = jax.jit(lambda x: jc.white_balance_white_patch(x, quantile=0.99))

    def np_gw(x):
        m = x.reshape(-1, 3).mean(0)
        return x * (m.mean() / m)

    def np_wp(x):
        q = np.quantile(x.reshape(-1, 3), 0.99, axis=0)
        return x * (q.mean() / q)

    run(
        "grey_world",
        {"jaxgfx": lambda: f_gw(lin), "numpy": lambda: np_gw(lin)},
        np_gw(lin.astype(np.float64)),
    )
    run(
        "white_patch_q0.99",
        {"jaxgfx": lambda: f_wp(lin), "numpy": lambda: np_wp(lin)},
        np_wp(lin.astype(np.float64)),
    )
    emit(results, args.out)


if __name__ == "__main__":
    main()
