"""Batches of keys: ``render`` per key in a Python loop vs ``jax.vmap`` / ``lax.map`` over keys.

    python -m benchmarks.render_keys [--quick] [--res 32] [--spp 4] [--keys 8] [--out FILE]

Scene: ``configs/scenes/example.yaml`` at ``res``² (default 32²), ``spp`` samples per pixel,
``direct`` and ``path`` (max_depth 3; ``--quick``: ``direct`` only). For ``K`` keys
(``jax.random.split(key(0), K)``):

* ``loop``: one jitted ``render(scene, k)`` called per key from Python;
* ``vmap``: ``jax.jit(jax.vmap(lambda k: render(scene, k)))(keys)``;
* ``map``: ``jax.jit(lambda ks: lax.map(lambda k: render(scene, k), ks))(keys)``;
* ``grad_loop`` / ``grad_vmap``: the same for ``jax.value_and_grad`` of the image mean w.r.t.
  a scale of the floor's reflectance and the area light's radiance (the FD-vs-AD driver of
  tests/render/_gradient_scenes.py vmaps this over keys).

Per variant: ``first_s`` (the first call: tracing + compilation + one run), ``per_key_s`` (median
of ``repeat`` calls after it, divided by ``K``; the loop's calls interleaved with the others so
load changes hit all alike) and ``max_abs_diff`` to the loop's images / gradients (0 when
bit-identical). The machine may be shared: compare ratios within one run.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks._report import emit, machine
from benchmarks._timing import interleaved_times
from jaxgfx.config import read_yaml
from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "configs", "scenes", "example.yaml")
PARAMS = ("materials.floor.reflectance", "emitters.area.0.radiance")


def _log(*a):
    print(*a, file=sys.stderr, flush=True)


def _max_diff(a, b):
    a = jax.tree_util.tree_leaves(a)
    b = jax.tree_util.tree_leaves(b)
    pairs = zip(a, b, strict=True)
    return max(float(np.max(np.abs(np.asarray(x) - np.asarray(y)))) for x, y in pairs)


def bench(scene, keys, integrator, spp, repeat):
    K = keys.shape[0]
    opts = dict(spp=spp, integrator=integrator)
    bases = [scene.get(p) for p in PARAMS]

    def loss(x, k):
        s = scene
        for i, (p, b) in enumerate(zip(PARAMS, bases, strict=True)):
            s = s.replace(p, b * x[i])
        return jnp.mean(render(s, k, **opts))

    x0 = jnp.ones((len(PARAMS),), jnp.float32)
    one = jax.jit(lambda k: render(scene, k, **opts))
    vm = jax.jit(jax.vmap(lambda k: render(scene, k, **opts)))
    mp = jax.jit(lambda ks: jax.lax.map(lambda k: render(scene, k, **opts), ks))
    vg = jax.jit(jax.value_and_grad(loss))
    vg_vm = jax.jit(jax.vmap(jax.value_and_grad(loss), in_axes=(None, 0)))

    fns = {
        "loop": lambda: [one(k) for k in keys],
        "vmap": lambda: vm(keys),
        "map": lambda: mp(keys),
        "grad_loop": lambda: [vg(x0, k) for k in keys],
        "grad_vmap": lambda: vg_vm(x0, keys),
    }
    t = interleaved_times(fns, repeat)
    ref = np.stack([np.asarray(x) for x in fns["loop"]()])
    gref = jax.tree_util.tree_map(lambda *xs: np.stack(xs), *fns["grad_loop"]())
    diffs = {
        "vmap": _max_diff(fns["vmap"](), ref),
        "map": _max_diff(fns["map"](), ref),
        "grad_vmap": _max_diff(fns["grad_vmap"](), gref),
    }
    out = {}
    for name, (first, med) in t.items():
        out[name] = {"first_s": round(first, 3), "per_key_s": med / K}
        if name in diffs:
            out[name]["max_abs_diff"] = diffs[name]
    for name, base in (("vmap", "loop"), ("map", "loop"), ("grad_vmap", "grad_loop")):
        out[name]["per_key_vs_" + base] = out[name]["per_key_s"] / out[base]["per_key_s"]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--keys", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--integrators", default=None, help="comma-separated (default direct,path)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    desc = read_yaml(EXAMPLE)
    desc["camera"]["width"] = desc["camera"]["height"] = a.res
    scene = load_scene(desc)
    keys = jax.random.split(jax.random.key(0), a.keys)
    names = a.integrators or ("direct" if a.quick else "direct,path")
    res = {
        "benchmark": "render_keys",
        "machine": machine(),
        "scene": f"example.yaml {a.res}x{a.res}",
        "spp": a.spp,
        "keys": a.keys,
        "results": {},
    }
    for name in names.split(","):
        t0 = time.perf_counter()
        res["results"][name] = bench(scene, keys, name, a.spp, 1 if a.quick else a.repeat)
        _log(f"{name}: {time.perf_counter() - t0:.0f} s")
    emit(res, a.out)


if __name__ == "__main__":
    main()
