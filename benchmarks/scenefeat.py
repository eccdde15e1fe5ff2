"""Cost of scene features: textures and SDF shapes (prints JSON).

For a small scene (sphere + floor + area light, ``path`` depth 3) it reports, per variant, the
jaxpr / HLO size, the compile time and the forward throughput:

* ``plain``: untextured (must equal the program without texture support),
* ``checker``: the floor's reflectance is a checkerboard texture,
* ``bitmap``: the floor's reflectance is a 64x64 bilinear bitmap,
* ``sdf``: the analytic sphere replaced by an SDF sphere (sphere traced, max_steps 128).

The peer is the ``plain`` variant of the same run. Usage:
``python -m benchmarks.scenefeat [--size 64] [--spp 4] [--repeat 5] [--out FILE]``; the per-variant
rows are the document's ``results`` list.
"""

from __future__ import annotations

import argparse
import importlib
import time

import jax
import numpy as np

from benchmarks._report import emit, machine
from jaxgfx.render.integrators import PathIntegrator
from jaxgfx.render.scene import load_scene

_render_mod = importlib.import_module("jaxgfx.render.render")


def _desc(variant, size):
    floor = 0.5
    if variant == "checker":
        floor = {"type": "checkerboard", "color0": 0.8, "color1": 0.2, "scale": 4}
    elif variant == "bitmap":
        img = np.random.default_rng(0).uniform(0.1, 0.9, (64, 64, 3)).tolist()
        floor = {"type": "bitmap", "image": img}
    sphere = {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5, "material": "m"}
    if variant == "sdf":
        sphere = {
            "type": "sdf",
            "expr": {"op": "sphere", "center": [0, 0.5, 0], "radius": 0.5},
            "material": "m",
        }
    return {
        "camera": {
            "origin": [0, 1, 4],
            "target": [0, 0.5, 0],
            "fov": 40,
            "width": size,
            "height": size,
        },
        "shapes": [
            sphere,
            {
                "type": "rectangle",
                "center": [0, 0, 0],
                "normal": [0, 1, 0],
                "size": [4, 4],
                "material": "floor",
            },
        ],
        "materials": {
            "m": {"type": "diffuse", "reflectance": 0.5},
            "floor": {"type": "diffuse", "reflectance": floor},
        },
        "emitters": [
            {
                "type": "area",
                "shape": {"type": "rectangle", "center": [0, 2, 0], "normal": [0, -1, 0]},
                "radiance": 10,
            }
        ],
    }


def measure(variant, size=64, spp=4, repeat=5):
    scene = load_scene(_desc(variant, size))
    key = jax.random.key(0)

    def f(s, k):
        return _render_mod._render(s, k, spp, PathIntegrator(max_depth=3))

    jaxpr_lines = str(jax.make_jaxpr(f)(scene, key)).count("\n")
    lowered = jax.jit(f).lower(scene, key)
    hlo_chars = len(lowered.as_text())
    t0 = time.perf_counter()
    comp = lowered.compile()
    compile_s = time.perf_counter() - t0
    comp(scene, key).block_until_ready()
    t0 = time.perf_counter()
    for i in range(repeat):
        comp(scene, jax.random.key(i + 1)).block_until_ready()
    run_s = (time.perf_counter() - t0) / repeat
    return {
        "variant": variant,
        "size": size,
        "spp": spp,
        "jaxpr_lines": jaxpr_lines,
        "hlo_chars": hlo_chars,
        "compile_s": round(compile_s, 2),
        "run_s": round(run_s, 4),
        "samples_per_s": round(size * size * spp / run_s),
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--spp", type=int, default=4)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--variants", default="plain,checker,bitmap,sdf")
    p.add_argument("--out", default=None, help="also write the JSON here")
    a = p.parse_args(argv)
    doc = {"benchmark": "scenefeat", "machine": machine()}
    doc["results"] = [measure(v, a.size, a.spp, a.repeat) for v in a.variants.split(",")]
    emit(doc, a.out)


if __name__ == "__main__":
    main()
