"""The particle tracer (``ptracer``) against the path tracer: same expectation, variance ratio.

    python -m benchmarks.ptracer [--quick] [--keys 16] [--spp 16] [--out FILE]

Scene (float64, 8x8 pixels, depth 3): a diffuse floor and back wall, a rough-conductor sphere
(alpha 0.3) and a small rectangle area light facing down, partly in view (the scene of
``tests/render/test_ptracer.py::test_equals_path_tracer_in_expectation_area_light``). Both
integrators render ``keys`` independent images (``jax.random.split(key(2), keys)``) of ``spp``
samples per pixel each (the particle tracer: ``W H spp`` light paths).

Prints one JSON document: the machine block, per integrator the channel means of the image,
their standard errors from the spread over the keys and ``seconds`` (first call: compile +
run); ``z_channel_means`` (Welch z of ``ptracer - path``); ``pixel_variance_ratio_median``
(per channel, the median over the pixels of the ratio of the per-key variances, ptracer /
path) and ``image_mean_variance_ratio`` (the same ratio for the variance of the image mean).
``--quick``: 4 keys x 4 spp.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

from benchmarks._report import emit, machine
from jaxgfx.render import load_scene, render

jax.config.update("jax_enable_x64", True)

SCENE = {
    "camera": {
        "origin": [0, 1.2, 4],
        "target": [0, 0.8, 0],
        "up": [0, 1, 0],
        "fov": 55,
        "width": 8,
        "height": 8,
    },  # fmt: skip
    "shapes": [
        {
            "type": "rectangle",
            "center": [0, 0, 0],
            "normal": [0, 1, 0],
            "size": [6, 6],
            "material": "floor",
        },  # fmt: skip
        {
            "type": "rectangle",
            "center": [0, 1.5, -1.5],
            "normal": [0, 0, 1],
            "size": [6, 3],
            "material": "wall",
        },  # fmt: skip
        {"type": "sphere", "center": [0.3, 0.5, 0], "radius": 0.5, "material": "gloss"},
    ],
    "materials": {
        "floor": {"type": "diffuse", "reflectance": [0.7, 0.5, 0.3]},
        "wall": {"type": "diffuse", "reflectance": 0.6},
        "gloss": {"type": "roughconductor", "alpha": 0.3},
    },
    "emitters": [
        {
            "type": "area",
            "radiance": [6, 6, 6],
            "shape": {
                "type": "rectangle",
                "center": [-0.6, 2.2, 0.2],
                "normal": [0, -1, 0],
                "size": [0.8, 0.8],
            },
        },  # fmt: skip
    ],
}


def _renders(scene, keys, spp, integrator):
    f = jax.jit(jax.vmap(lambda k: render(scene, k, spp=spp, integrator=integrator,
                                          max_depth=3)))  # fmt: skip
    t0 = time.perf_counter()
    out = np.asarray(f(keys))
    return out, time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--keys", type=int, default=16)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    keys_n, spp = (4, 4) if a.quick else (a.keys, a.spp)
    doc = {"machine": machine(), "keys": keys_n, "spp": spp, "max_depth": 3}
    scene = load_scene(SCENE)
    keys = jax.random.split(jax.random.key(2), keys_n)
    imgs = {}
    for name in ("ptracer", "path"):
        img, sec = _renders(scene, keys, spp, name)
        imgs[name] = img
        m = img.mean(axis=(1, 2))  # (keys, 3)
        doc[name] = {
            "channel_means": m.mean(0),
            "channel_mean_standard_errors": m.std(0, ddof=1) / np.sqrt(keys_n),
            "seconds": round(sec, 2),
        }
    pt, pa = imgs["ptracer"], imgs["path"]
    mt, ma = pt.mean(axis=(1, 2)), pa.mean(axis=(1, 2))
    se = np.sqrt(mt.var(0, ddof=1) / keys_n + ma.var(0, ddof=1) / keys_n)
    doc["z_channel_means"] = (mt.mean(0) - ma.mean(0)) / se
    vt, va = pt.var(0, ddof=1), pa.var(0, ddof=1)
    ok = va > 0
    ratio = np.where(ok, vt / np.where(ok, va, 1.0), np.nan)
    doc["pixel_variance_ratio_median"] = np.nanmedian(ratio.reshape(-1, 3), axis=0)
    doc["image_mean_variance_ratio"] = mt.var(0, ddof=1) / ma.var(0, ddof=1)
    emit(doc, a.out)


if __name__ == "__main__":
    main()
