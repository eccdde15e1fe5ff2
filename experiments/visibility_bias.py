"""Bias of shape derivatives from moving silhouettes and shadows (issue 10, "Visibility").

    python -m experiments.visibility_bias [--size 16] [--keys 16] [--spp 32] [--h 0.05]
                                         [--integrator direct] [--max-depth 3]
                                         [--strategy mis] [--occluder sphere|mesh]
                                         [--out FILE]

Scene: a diffuse sphere (or, ``--occluder mesh``, a 20-triangle icosahedron) moves sideways
(parameter: its centre's x, or every vertex's x) in front of an area light
that faces the camera and lights a diffuse floor, plus a constant environment; the sphere's
silhouette crosses the light and the lit floor in the image, and its shadow edge moves on the
floor. Loss: the mean of the image columns right of the sphere's projected centre (the image
mean would nearly cancel the left and right edges, which move in opposite directions). Per
key: the reverse-mode gradient without
(``visibility=None``) and with edge sampling (``visibility="edge"``), and central finite
differences of the same renderer with the same key (common random numbers), step ``h`` (world
units). Prints JSON: means, standard errors over the keys, and the paired AD − FD differences.
"""

from __future__ import annotations

import argparse
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from experiments._common import emit_json
from jaxgfx.render import Spheres, load_scene, render

CENTER = [0.2, 0.6, 0.0]


def scene_desc(size: int, occluder: str = "sphere") -> dict:
    if occluder == "sphere":
        occ = {"type": "sphere", "center": CENTER, "radius": 0.4, "material": "white"}
    else:  # an icosahedron mesh (20 triangles; below the BVH threshold of load_scene)
        gen = {"name": "icosphere", "level": 0, "radius": 0.4, "center": CENTER}
        occ = {"type": "mesh", "generator": gen, "material": "white"}
    return {
        "camera": {
            "origin": [0, 1.2, 4.0],
            "target": [0, 0.5, 0],
            "fov": 40,
            "width": size,
            "height": size,
        },
        "shapes": [
            occ,
            {
                "type": "rectangle",
                "center": [0, 0, 0],
                "normal": [0, 1, 0],
                "size": [6, 6],
                "material": "floor",
            },
        ],
        "materials": {
            "white": {"type": "diffuse", "reflectance": 0.6},
            "floor": {"type": "diffuse", "reflectance": 0.5},
        },
        "emitters": [
            {
                "type": "area",
                "shape": {
                    "type": "rectangle",
                    "center": [0, 1.3, -1.5],
                    "normal": [0, -0.6, 1],
                    "size": [1.4, 0.9],
                },
                "radiance": 5.0,
            },
            {"type": "constant", "radiance": 0.2},
        ],
    }


def measure(size, keys, spp, h, integrator, max_depth=3, strategy="mis", occluder="sphere"):
    from jaxgfx.render.visibility import project

    scene = load_scene(scene_desc(size, occluder))
    if occluder == "sphere":
        si = next(i for i, s in enumerate(scene.shapes) if isinstance(s, Spheres))
        path = f"shapes.{si}.centers"
    else:
        si = next(i for i, s in enumerate(scene.shapes) if hasattr(s, "vertices"))
        path = f"shapes.{si}.vertices"
    c0 = scene.get(path)
    e = jnp.asarray([1.0, 0.0, 0.0], c0.dtype)
    col = float(project(scene.camera, jnp.asarray(CENTER, c0.dtype))[0][0])
    wts = jnp.asarray(np.arange(size)[None, :] + 0.5 >= col, c0.dtype) * jnp.ones((size, 1))

    def loss(x, key, vis):
        sc = scene.replace(path, c0 + e * x)
        img = render(
            sc,
            key,
            spp=spp,
            integrator=integrator,
            max_depth=max_depth,
            strategy=strategy,
            visibility=vis,
        )
        return jnp.sum(img.mean(-1) * wts) / (size * size)

    g_plain = jax.jit(jax.grad(lambda x, k: loss(x, k, None)))
    g_edge = jax.jit(jax.grad(lambda x, k: loss(x, k, "edge")))
    val = jax.jit(lambda x, k: loss(x, k, None))
    ks = jax.random.split(jax.random.key(2026), keys)
    x0 = jnp.zeros((), c0.dtype)
    rows = []
    secs = np.zeros(3)
    for i, k in enumerate(ks):
        row, ts = [], []
        for fn, x in ((g_plain, x0), (g_edge, x0), (val, x0 + h)):
            t = time.perf_counter()
            row.append(float(fn(x, k)))
            ts.append(time.perf_counter() - t)
        if i > 0:  # the first key's calls include compilation
            secs += ts
        fd = (row[2] - float(val(x0 - h, k))) / (2 * h)
        rows.append((row[0], row[1], fd))
    secs /= max(keys - 1, 1)
    a = np.asarray(rows, np.float64)
    n = a.shape[0]

    def ms(v):
        return {"mean": float(v.mean()), "stderr": float(v.std(ddof=1) / np.sqrt(n))}

    return {
        "size": size,
        "keys": keys,
        "spp": spp,
        "h": h,
        "integrator": integrator,
        "strategy": strategy,
        "occluder": occluder,
        "max_depth": max_depth if integrator == "path" else 2,
        "ad_plain": ms(a[:, 0]),
        "ad_edge": ms(a[:, 1]),
        "fd": ms(a[:, 2]),
        "plain_minus_fd": ms(a[:, 0] - a[:, 2]),
        "edge_minus_fd": ms(a[:, 1] - a[:, 2]),
        "seconds_per_call": {"grad_plain": secs[0], "grad_edge": secs[1], "forward": secs[2]},
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--size", type=int, default=16)
    p.add_argument("--keys", type=int, default=16)
    p.add_argument("--spp", type=int, default=32)
    p.add_argument("--h", type=float, default=0.05)
    p.add_argument("--integrator", default="direct")
    p.add_argument("--max-depth", type=int, default=3)
    p.add_argument("--strategy", default="mis")
    p.add_argument("--occluder", default="sphere", choices=("sphere", "mesh"))
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    res = measure(a.size, a.keys, a.spp, a.h, a.integrator, a.max_depth, a.strategy, a.occluder)
    emit_json(res, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
