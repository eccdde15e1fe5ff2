"""Where path replay's gradient time goes (issue 22): forward vs ``jit(grad)`` by AD, by path
replay, and by path replay with its local VJPs replaced by the replayed terms' primal
("re-trace only": the backward pass traces every path again but transposes nothing).

    python -m benchmarks.replay_profile [--res 64] [--spp 16] [--depths 4] [--repeat 5]
        [--kinds forward,grad_ad,grad_replay,grad_retrace_only] [--out FILE]

``configs/scenes/inverse.yaml`` at ``res``² (64², 16 spp: one pass step of 65 536 rays, no pass
checkpoint), d(image mean)/dα of the metal. Each program is compiled after
``jax.clear_caches()`` (the custom VJP's traced backward is memoised, so the re-trace-only
variant would otherwise reuse the real one); the re-trace-only variant's cotangent is
``1e-30 · Σ terms`` so that XLA keeps the replay. Then ``repeat`` interleaved rounds (a new key
per call, ``block_until_ready``), medians of process CPU seconds and wall seconds, ratios to the
forward within the run; the load average before and after. Prints one JSON document.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import types

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from benchmarks._report import emit, machine
from jaxgfx.config import read_yaml
from jaxgfx.render.integrators import PathIntegrator
from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
INVERSE = os.path.join(ROOT, "configs", "scenes", "inverse.yaml")
KINDS = ("forward", "grad_ad", "grad_replay", "grad_retrace_only")


def _retrace_vjp(f, x, has_aux=False):
    """``jax.vjp`` stand-in: the primal only; the cotangent is ``1e-30 · Σ`` of the output."""
    out = f(x)
    s = jnp.sum(out[0] if has_aux else out) * 1e-30

    def vjp_fn(_):
        return (jax.tree_util.tree_map(lambda t: jnp.zeros_like(t) + s.astype(t.dtype), x),)

    return (out[0], vjp_fn, out[1]) if has_aux else (out, vjp_fn)


def _program(scene, kind, depth, spp):
    import jaxgfx.render.integrators._replay as R  # noqa: PLC0415

    dyn, static = eqx.partition(scene, eqx.is_array)
    alpha = scene.get("materials.metal.alpha")
    integ = PathIntegrator(max_depth=depth, adjoint="ad" if kind in KINDS[:2] else "replay")

    def image(a, dyn, k):
        s = eqx.combine(dyn, static).replace("materials.metal.alpha", a)
        return render(s, k, spp=spp, integrator=integ)

    f = image if kind == "forward" else jax.grad(lambda a, dyn, k: jnp.mean(image(a, dyn, k)))
    jax.clear_caches()
    real = R.jax
    if kind == "grad_retrace_only":
        R.jax = types.SimpleNamespace(**{k: getattr(real, k) for k in dir(real) if k[:2] != "__"})
        R.jax.vjp = _retrace_vjp
    try:
        t0 = time.perf_counter()
        c = jax.jit(f).lower(alpha, dyn, jax.random.key(0)).compile()
        cs = time.perf_counter() - t0
    finally:
        R.jax = real
    return c, cs, c.memory_analysis().temp_size_in_bytes, (alpha, dyn)


def profile(*, res, spp, depths, repeat, kinds):
    desc = read_yaml(INVERSE)
    desc["camera"]["width"] = desc["camera"]["height"] = int(res)
    scene = load_scene(desc)
    out = {"scene": "configs/scenes/inverse.yaml", "res": res, "spp": spp}
    out["load_before"] = list(os.getloadavg())
    counter = [0]

    def call(c, args):
        counter[0] += 1
        t, w = time.process_time(), time.perf_counter()
        jax.block_until_ready(c(*args, jax.random.key(counter[0])))
        return time.process_time() - t, time.perf_counter() - w

    for depth in depths:
        row, comp = {}, {}
        for kind in kinds:
            c, cs, temp, args = _program(scene, kind, depth, spp)
            comp[kind] = (c, args)
            row[kind] = {"compile_s": round(cs, 1), "temp_MB": round(temp / 2**20, 2)}
            print(depth, kind, row[kind], file=sys.stderr, flush=True)
        for c, args in comp.values():
            call(c, args)
        samples = {k: [] for k in comp}
        for _ in range(repeat):
            for k, (c, args) in comp.items():
                samples[k].append(call(c, args))
        for k, v in samples.items():
            v = np.asarray(v)
            row[k]["cpu_s"] = round(float(np.median(v[:, 0])), 4)
            row[k]["wall_s"] = round(float(np.median(v[:, 1])), 4)
        if "forward" in row:
            f = row["forward"]
            for k in kinds:
                if k != "forward":
                    row[k]["cpu_over_fwd"] = round(row[k]["cpu_s"] / f["cpu_s"], 2)
                    row[k]["wall_over_fwd"] = round(row[k]["wall_s"] / f["wall_s"], 2)
        print(depth, row, file=sys.stderr, flush=True)
        out[f"depth_{depth}"] = row
    out["load_after"] = list(os.getloadavg())
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--depths", default="4")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--out")
    a = ap.parse_args(argv)
    kinds = a.kinds.split(",")
    bad = sorted(set(kinds) - set(KINDS))
    if bad:
        ap.error(f"--kinds: unknown {bad}; expected some of {list(KINDS)}")
    result = {"benchmark": "replay_profile", "machine": machine()}
    result["replay_profile"] = profile(
        res=a.res,
        spp=a.spp,
        depths=[int(x) for x in a.depths.split(",")],
        repeat=a.repeat,
        kinds=kinds,
    )
    emit(result, a.out)


if __name__ == "__main__":
    main()
