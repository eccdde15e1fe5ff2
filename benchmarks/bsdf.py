"""Benchmark: BSDF eval/sample throughput and texture lookup, each against a peer in the same run.

Peers: a vectorised NumPy GGX conductor eval (same formula, float32) and OpenCV ``cv2.remap``
(bilinear, wrap) for texture lookup. Prints one JSON object. Run:
``python -m benchmarks.bsdf [--n 262144] [--repeat 5] [--out FILE]``.
"""

from __future__ import annotations

import argparse
import math
import time

import cv2
import jax
import jax.numpy as jnp
import numpy as np

from benchmarks._report import emit, machine
from jaxgfx.render.bsdf import Diffuse, RoughConductor, RoughPlastic
from jaxgfx.render.bsdf.texture import Texture, lookup


def _time(fn, repeat):
    fn()  # warm-up / compile
    best = math.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def np_ggx_eval(alpha, wo, wi):
    h = wo + wi
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    a2 = alpha * alpha
    t = (h[:, 0] ** 2 + h[:, 1] ** 2) / a2 + h[:, 2] ** 2
    d = 1.0 / (np.pi * a2 * t * t)

    def g1(v):
        xy = a2 * (v[:, 0] ** 2 + v[:, 1] ** 2)
        return 2.0 * v[:, 2] / (v[:, 2] + np.sqrt(v[:, 2] ** 2 + xy))

    ok = (wo[:, 2] > 0) & (wi[:, 2] > 0)
    return np.where(ok, d * g1(wo) * g1(wi) / (4 * wo[:, 2]), 0.0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=1 << 18)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", default=None, help="also write the JSON here")
    args = ap.parse_args()
    n = args.n
    rng = np.random.default_rng(0)
    wo = rng.normal(size=(n, 3)).astype(np.float32)
    wi = rng.normal(size=(n, 3)).astype(np.float32)
    wo[:, 2] = np.abs(wo[:, 2])
    wi[:, 2] = np.abs(wi[:, 2])
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    u1 = rng.uniform(size=n).astype(np.float32)
    u2 = rng.uniform(size=(n, 2)).astype(np.float32)
    jwo, jwi, ju1, ju2 = map(jnp.asarray, (wo, wi, u1, u2))
    out = {"benchmark": "bsdf", "machine": machine(opencv=cv2.__version__), "n": n}

    ev = jax.jit(lambda b, wo, wi: b.eval(wo, wi))
    sp = jax.jit(lambda b, wo, u1, u2: b.sample(wo, u1, u2).weight)
    gc = RoughConductor(0.3)
    for name, b in [
        ("diffuse", Diffuse(0.5)),
        ("roughconductor_ggx", gc),
        ("roughconductor_beckmann", RoughConductor(0.3, distribution="beckmann")),
        ("roughplastic", RoughPlastic(0.5, 0.3)),
    ]:
        te = _time(lambda b=b: ev(b, jwo, jwi).block_until_ready(), args.repeat)
        ts = _time(lambda b=b: sp(b, jwo, ju1, ju2).block_until_ready(), args.repeat)
        out[f"{name}_eval_Msamples_per_s"] = round(n / te / 1e6, 2)
        out[f"{name}_sample_Msamples_per_s"] = round(n / ts / 1e6, 2)
    tnp = _time(lambda: np_ggx_eval(0.3, wo, wi), args.repeat)
    out["numpy_ggx_eval_Msamples_per_s"] = round(n / tnp / 1e6, 2)
    err = np.max(np.abs(np.asarray(ev(gc, jwo, jwi))[:, 0] - np_ggx_eval(0.3, wo, wi)))
    out["ggx_eval_max_abs_diff_vs_numpy"] = float(err)

    img = rng.uniform(size=(512, 512, 3)).astype(np.float32)
    uv = rng.uniform(size=(n, 2)).astype(np.float32)
    tex = Texture(img)
    lk = jax.jit(lookup)
    juv = jnp.asarray(uv)
    tl = _time(lambda: lk(tex, juv).block_until_ready(), args.repeat)
    mx = (uv[:, 0] * 512 - 0.5).reshape(512, -1)
    my = (uv[:, 1] * 512 - 0.5).reshape(512, -1)
    tcv = _time(
        lambda: cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP), args.repeat
    )
    out["texture_bilinear_Mlookups_per_s"] = round(n / tl / 1e6, 2)
    out["opencv_remap_Mlookups_per_s"] = round(n / tcv / 1e6, 2)
    ref = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP).reshape(-1, 3)
    out["texture_max_abs_diff_vs_opencv"] = float(np.max(np.abs(np.asarray(lk(tex, juv)) - ref)))
    emit(out, args.out)


if __name__ == "__main__":
    main()
