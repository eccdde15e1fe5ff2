"""Eager calls against jitted calls: what a script that never writes ``jax.jit`` pays.

Run: ``python -m benchmarks.eager [--size 512] [--repeat 5] [--out FILE]``. For each public
function, on the same float32 image passed as an argument (never closed over, which would let
XLA constant-fold it), the median wall time of a second and later *eager* call (``f(x)``) and of
a ``jax.jit(f)`` call, both waited for with ``block_until_ready``, plus the first eager call
(compilation included). A function whose public entry validates eagerly and then runs one
compiled core has a ratio near 1; a function that runs op by op pays one dispatch per
primitive. Prints one JSON document (``benchmarks/_report.py``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _cases(n):
    import jax.numpy as jnp

    import jaxgfx.color as C
    import jaxgfx.hdr as H
    import jaxgfx.image as I
    import jaxgfx.tonemap as T

    rng = np.random.default_rng(0)
    rgb = jnp.asarray(rng.random((n, n, 3), np.float32))
    grey = rgb[..., 0]
    hdr = rgb * 100.0
    stack = jnp.stack([jnp.clip(rgb * s, 0, 1) for s in (0.25, 1.0, 4.0)])
    times = jnp.array([0.25, 1.0, 4.0])
    ldr = jnp.round(jnp.clip(stack, 0, 1) ** (1 / 2.2) * 255).astype(jnp.uint8)
    resp = H.recover_response(ldr, times, method="debevec")
    return {
        "image.gaussian_blur": (lambda a: I.gaussian_blur(a, 2.0), rgb),
        "image.box_blur": (lambda a: I.box_blur(a, 5), rgb),
        "image.median_filter": (lambda a: I.median_filter(a, 3), rgb),
        "image.bilateral_filter": (lambda a: I.bilateral_filter(a, 2.0, 0.1), rgb),
        "image.unsharp_mask": (lambda a: I.unsharp_mask(a, 1.0, 0.5), rgb),
        "image.sharpen": (lambda a: I.sharpen(a), rgb),
        "image.laplacian_of_gaussian": (lambda a: I.laplacian_of_gaussian(a, 1.5), grey),
        "image.sobel": (lambda a: I.sobel(a), grey),
        "image.canny": (lambda a: I.canny(a, 1.5, 0.05, 0.15), grey),
        "image.soft_canny": (lambda a: I.soft_canny(a, 1.5, 0.05, 0.15), grey),
        "image.demosaic": (lambda a: I.demosaic(I.bayer_mosaic(a)), rgb),
        "color.srgb_to_lab": (lambda a: C.xyz_to_lab(C.rgb_to_xyz(C.srgb_to_linear(a))), rgb),
        "color.delta_e_2000": (lambda a: C.delta_e_2000(a * 100, a[::-1] * 100), rgb),
        "color.rgb_to_hsv": (lambda a: C.rgb_to_hsv(a), rgb),
        "tonemap.Drago2003": (lambda a: T.tonemap_Drago2003(a), hdr),
        "tonemap.Reinhard2002_local": (lambda a: T.tonemap_Reinhard2002_local(a), hdr),
        "tonemap.Durand2002": (lambda a: T.tonemap_Durand2002(a), hdr),
        "hdr.exposure_fusion": (lambda a: H.exposure_fusion(a), stack),
        "hdr.rgbe_roundtrip": (lambda a: H.rgbe_decode(H.rgbe_encode(a)), hdr),
        "hdr.recover_response_debevec": (
            lambda a: H.recover_response(a, times, method="debevec").params,
            ldr,
        ),
        "hdr.recover_response_robertson": (
            lambda a: H.recover_response(a, times, method="robertson").params,
            ldr,
        ),
        "hdr.merge_radiance": (lambda a: H.merge_radiance(a, times, resp), ldr),
    }


def run(n, repeat):
    import jax

    from benchmarks._timing import median_time

    out = {}
    for name, (f, a) in _cases(n).items():
        t0 = time.perf_counter()
        jax.block_until_ready(f(a))
        first = time.perf_counter() - t0
        eager = median_time(lambda f=f, a=a: f(a), repeat)
        jf = jax.jit(f)
        jax.block_until_ready(jf(a))
        jitted = median_time(lambda jf=jf, a=a: jf(a), repeat)
        out[name] = {
            "eager_first_s": round(first, 4),
            "eager_ms": round(eager * 1e3, 3),
            "jit_ms": round(jitted * 1e3, 3),
            "eager_over_jit": round(eager / jitted, 2),
        }
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", default=None, help="also write the JSON here")
    a = ap.parse_args(argv)

    from benchmarks._report import emit, machine

    doc = {"benchmark": "eager", "machine": machine(), "size": a.size, "repeat": a.repeat}
    doc["results"] = run(a.size, a.repeat)
    emit(doc, a.out)


if __name__ == "__main__":
    main()
