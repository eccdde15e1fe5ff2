"""Gradient benchmark: cost of a gradient vs a forward render, memory vs spp and depth, bias.

    python -m benchmarks.gradients [--quick] [--sections speed,glossy,...] [--out FILE]

1. Speed: seconds per ``jax.grad`` of an L2 image loss (w.r.t. every material and emitter
   parameter of the scene) vs one forward render at the same spp, on
   ``configs/scenes/example.yaml`` (path, depth 3) and a mesh scene (the example with its metal
   sphere replaced by a 6 240-triangle UV-sphere mesh); also the decorrelated gradient
   (``jaxgfx.optim.decorrelated``: one extra forward pass). One warm-up call each,
   then the medians of ``repeat`` rounds calling each in turn (the machine may be shared:
   compare ratios within one run).
2. Memory: XLA's temporary buffer size (``jit(grad).lower().compile().memory_analysis()``) of
   the gradient vs spp (depth 3) and vs depth (spp 4) on the example scene at 32².
3. Statistics (``grad_stats``): mean, standard error, SNR, work-normalised variance and bias
   against same-key central finite differences for d(image mean)/dα on the glossy scene of
   issue 10, ``sampling="detached"`` (default) vs ``"attached"``.
4. Gradient vs forward on the glossy scene of issue 10 (path, depth 4): seconds of
   ``jit(grad)`` of the image mean w.r.t. α vs ``jit(render)`` at the same spp (both take α and
   the scene as arguments; one warm-up call each, then the medians of ``repeat`` rounds that
   call both in turn, so load changes on a shared machine affect both alike).
5. Visibility: d(image mean)/d(x of an occluder sphere between a diffuse floor and an area
   light) by AD and by central FD of the same key: plain AD misses the moving shadow boundary;
   ``visibility="edge"`` adds it (edge sampling).
6. Path replay (``--sections replay``): on ``configs/scenes/inverse.yaml`` (two spheres, GGX
   metal + diffuse clay, area light + constant environment; 64², 64 spp), ``jit(grad)`` of the
   image mean w.r.t. the metal's α with ``PathIntegrator(adjoint="ad")`` and
   ``adjoint="replay"`` (path replay backpropagation; also with the forward radiance recomputed
   instead of kept, ``estimator.REPLAY_KEEPS_RADIANCE = False``) against the forward render,
   at path depths 2, 4 and 8: seconds per call (medians of interleaved rounds, a new key per
   call, ``block_until_ready``), lower + compile seconds of each program and XLA's temporary
   buffer (``memory_analysis().temp_size_in_bytes``) of the same compiled programs. The load
   average before and after is recorded (``_render_harness.load_gate``, not refused).
7. Path replay memory (``--sections replay_memory``): XLA's temporary buffer of the same
   ``jit(grad)`` programs (AD, replay) at 32² vs path depth 2, 4, 8, 16 (16 spp: one pass
   step) and vs spp 16, 64, 256 (depth 4; 1, 1, 4 checkpointed pass steps of 64 passes);
   compile only.

Prints one JSON document (progress to stderr).
"""

from __future__ import annotations

import argparse
import copy
import os
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from benchmarks._report import emit, machine
from benchmarks._timing import interleaved_times
from jaxgfx.config import read_yaml
from jaxgfx.render.geometry.mesh_io import make_uv_sphere
from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import grad_stats

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "configs", "scenes", "example.yaml")
sys.path.insert(0, os.path.join(ROOT, "tests", "render"))


def _log(*a):
    print(*a, file=sys.stderr, flush=True)


def _with_res(desc, w):
    d = copy.deepcopy(desc)
    d["camera"]["width"] = d["camera"]["height"] = int(w)
    return d


PARAMS = [
    "materials.metal.alpha",
    "materials.floor.reflectance",
    "emitters.area.0.radiance",
    "emitters.point.intensities",
    "emitters.environment.radiance",
]


def _params(scene):
    return {p: scene.get(p) for p in PARAMS}


def _apply(scene, params):
    for p, v in params.items():
        scene = scene.replace(p, v)
    return scene


def speed(desc, *, spp, depth, repeat):
    from jaxgfx.optim import decorrelated

    scene = load_scene(desc)
    key = jax.random.key(0)
    params = _params(scene)
    target = render(scene, jax.random.key(99), spp=spp, integrator="path", max_depth=depth)

    @jax.jit
    def fwd(params, key):
        return render(_apply(scene, params), key, spp=spp, integrator="path", max_depth=depth)

    def loss(params, key):
        return jnp.mean((fwd(params, key) - target) ** 2)

    @jax.jit
    def fwd_attached(params, key):
        s = _apply(scene, params)
        return render(s, key, spp=spp, integrator="path", max_depth=depth, sampling="attached")

    grad = jax.jit(jax.grad(loss))
    dfwd = decorrelated(fwd)
    dgrad = jax.jit(jax.grad(lambda p, k: jnp.mean((dfwd(p, k) - target) ** 2)))
    out = {}
    runs = (
        ("forward", fwd),
        ("forward_attached", fwd_attached),
        ("grad", grad),
        ("grad_decorrelated", dgrad),
    )
    times = interleaved_times({k: (lambda f=f: f(params, key)) for k, f in runs}, repeat)
    for name, (first, med) in times.items():
        out[name] = {"time_s": round(med, 4), "compile_s": round(max(first - med, 0), 2)}
        _log(name, out[name])
    out["grad_over_forward"] = round(out["grad"]["time_s"] / out["forward"]["time_s"], 2)
    out["decorrelated_over_forward"] = round(
        out["grad_decorrelated"]["time_s"] / out["forward"]["time_s"], 2
    )
    return out


def memory(desc, *, spps, depths):
    scene = load_scene(desc)
    params = _params(scene)

    def temp_mb(spp, depth):
        def loss(p):
            img = render(_apply(scene, p), jax.random.key(0), spp=spp, max_depth=depth)
            return jnp.mean(img**2)

        c = jax.jit(jax.grad(loss)).lower(params).compile()
        return round(c.memory_analysis().temp_size_in_bytes / 2**20, 3)

    out = {"vs_spp_depth3": {}, "vs_depth_spp4": {}}
    for spp in spps:
        out["vs_spp_depth3"][spp] = temp_mb(spp, 3)
        _log("memory spp", spp, out["vs_spp_depth3"][spp])
    for d in depths:
        out["vs_depth_spp4"][d] = temp_mb(4, d)
        _log("memory depth", d, out["vs_depth_spp4"][d])
    return out


def glossy_ratio(*, w, spp, repeat):
    """Seconds of ``jit(grad(mean(render)))`` w.r.t. α vs ``jit(render)``, glossy scene."""
    import _gradient_scenes as G

    scene = G.make_scene(G.glossy_scene(0.15, w))
    key = jax.random.key(0)
    alpha = jnp.float32(0.15)

    def image(a, s, k):
        return render(s.replace("materials.metal.alpha", a), k, spp=spp, max_depth=4)

    fwd = eqx.filter_jit(image)
    grad = eqx.filter_jit(jax.grad(lambda a, s, k: jnp.mean(image(a, s, k))))
    out = {"res": w, "spp": spp, "integrator": "path", "max_depth": 4, "repeat": repeat}
    fns = {"forward": fwd, "grad_mean": grad}
    times = interleaved_times(
        {k: (lambda f=f: f(alpha, scene, key)) for k, f in fns.items()}, repeat
    )
    for name, (first, med) in times.items():
        out[name] = {"time_s": round(med, 4), "compile_s": round(max(first - med, 0), 2)}
        _log("glossy", name, out[name])
    out["grad_over_forward"] = round(out["grad_mean"]["time_s"] / out["forward"]["time_s"], 2)
    return out


def statistics_alpha(*, spp, n):
    import _gradient_scenes as G

    scene = G.make_scene(G.glossy_scene(0.15, 8))
    out = {}
    for sampling in ("detached", "attached"):

        def loss(a, k, sampling=sampling):
            s = scene.replace("materials.metal.alpha", a)
            img = render(s, k, spp=spp, integrator="path", max_depth=4, sampling=sampling)
            return jnp.mean(img)

        st = grad_stats(loss, jnp.float32(0.15), jax.random.key(1), n, fd_step=0.0075)
        out[sampling] = {
            k: float(v) for k, v in st._asdict().items() if v is not None and np.ndim(v) == 0
        }
        _log("grad_stats", sampling, out[sampling])
    return out


def visibility(*, spp, n):
    desc = {
        "camera": {"origin": [0, 3, 3], "target": [0, 0, 0], "fov": 50, "width": 8, "height": 8},
        "shapes": [
            {"type": "sphere", "center": [0.2, 0.8, 0], "radius": 0.3, "material": "floor"},
            {
                "type": "rectangle",
                "center": [0, 0, 0],
                "normal": [0, 1, 0],
                "size": [4, 4],
                "material": "floor",
            },
        ],
        "materials": {"floor": {"type": "diffuse", "reflectance": 0.6}},
        "emitters": [
            {
                "type": "area",
                "radiance": 10.0,
                "shape": {
                    "type": "rectangle",
                    "center": [0, 2.0, 0],
                    "normal": [0, -1, 0],
                    "size": [0.6, 0.6],
                },
            },
            {"type": "constant", "radiance": 0.1},
        ],
    }
    scene = load_scene(desc)
    c0 = scene.get("shapes.0.centers")

    out = {}
    for vis in (None, "edge"):  # plain AD, then edge sampling (docs/render_gradients.md)

        def loss(x, k, vis=vis):
            s = scene.replace("shapes.0.centers", c0.at[0, 0].set(x))
            return jnp.mean(render(s, k, spp=spp, integrator="direct", visibility=vis))

        st = grad_stats(loss, jnp.float32(0.2), jax.random.key(2), n, fd_step=0.02)
        res = {k: float(v) for k, v in st._asdict().items() if v is not None and np.ndim(v) == 0}
        out["plain" if vis is None else vis] = res
        _log("visibility", vis, res)
    return out


INVERSE = os.path.join(ROOT, "configs", "scenes", "inverse.yaml")


def _replay_program(scene, kind, depth, spp):
    """``(compiled, compile_s, temp_bytes)`` of ``kind`` (``forward``, ``grad_ad``,
    ``grad_replay``, ``grad_replay_recompute``) of the image mean w.r.t. the metal's α."""
    import time

    import jaxgfx.render.estimator as E
    from jaxgfx.render.integrators import PathIntegrator

    dyn, static = eqx.partition(scene, eqx.is_array)
    alpha = scene.get("materials.metal.alpha")
    path = "materials.metal.alpha"
    adjoint = "ad" if kind in ("forward", "grad_ad") else "replay"
    integ = PathIntegrator(max_depth=depth, adjoint=adjoint)

    def image(a, dyn, k):
        s = eqx.combine(dyn, static).replace(path, a)
        return render(s, k, spp=spp, integrator=integ)

    f = image if kind == "forward" else jax.grad(lambda a, dyn, k: jnp.mean(image(a, dyn, k)))
    keep = E.REPLAY_KEEPS_RADIANCE
    E.REPLAY_KEEPS_RADIANCE = kind != "grad_replay_recompute"
    try:
        t0 = time.perf_counter()
        c = jax.jit(f).lower(alpha, dyn, jax.random.key(0)).compile()
        compile_s = time.perf_counter() - t0
    finally:
        E.REPLAY_KEEPS_RADIANCE = keep
    return c, compile_s, c.memory_analysis().temp_size_in_bytes


def replay_memory(*, res, spp, depths, spps, depth_spp=4, kinds=("grad_ad", "grad_replay")):
    """XLA's temporary buffer (MB) of ``jit(grad)`` by AD and by path replay vs path depth
    (at ``spp``) and vs spp (at depth ``depth_spp``); compile only."""
    from benchmarks._render_harness import load_gate

    out = {"scene": "configs/scenes/inverse.yaml", "res": res, "spp": spp}
    out["load_before"] = load_gate(None)
    scene = load_scene(_with_res(read_yaml(INVERSE), res))
    seen = {}
    for label, pts, arg in (("vs_depth", depths, "depth"), ("vs_spp", spps, "spp")):
        tab = {}
        for x in pts:
            depth, spp_ = (x, spp) if arg == "depth" else (depth_spp, x)
            for kind in kinds:
                if (kind, depth, spp_) not in seen:
                    _, cs, temp = _replay_program(scene, kind, depth, spp_)
                    seen[kind, depth, spp_] = round(temp / 2**20, 3)
                    _log("replay memory", kind, depth, spp_, seen[kind, depth, spp_], f"{cs:.1f} s")
                tab.setdefault(kind, {})[x] = seen[kind, depth, spp_]
        out[f"temp_MB_{label}"] = tab
    out["load_after"] = load_gate(None)
    return out


def replay(*, res, spp, depths, repeat, recompute_depths=(4,), mem_spps=()):
    """Forward vs ``jit(grad)`` by AD and by path replay (section 6 of the module docstring)."""
    from benchmarks._render_harness import load_gate

    out = {"scene": "configs/scenes/inverse.yaml", "res": res, "spp": spp}
    out["load_before"] = load_gate(None)
    scene = load_scene(_with_res(read_yaml(INVERSE), res))
    dyn, _ = eqx.partition(scene, eqx.is_array)
    alpha = scene.get("materials.metal.alpha")

    def program(kind, depth, spp_=spp):
        return _replay_program(scene, kind, depth, spp_)

    counter = [0]

    def call(c):
        counter[0] += 1
        return c(alpha, dyn, jax.random.key(counter[0]))

    for depth in depths:
        kinds = ["forward", "grad_ad", "grad_replay"]
        if depth in recompute_depths:
            kinds.append("grad_replay_recompute")
        row, compiled = {}, {}
        for kind in kinds:
            c, cs, temp = program(kind, depth)
            compiled[kind] = c
            row[kind] = {"compile_s": round(cs, 2), "temp_MB": round(temp / 2**20, 3)}
            _log("replay depth", depth, kind, row[kind])
        times = interleaved_times({k: (lambda c=c: call(c)) for k, c in compiled.items()}, repeat)
        for kind, (_, med) in times.items():
            row[kind]["time_s"] = round(med, 4)
        fwd = row["forward"]
        for kind in kinds[1:]:
            row[kind]["over_forward"] = round(row[kind]["time_s"] / fwd["time_s"], 2)
            row[kind]["compile_over_forward"] = round(row[kind]["compile_s"] / fwd["compile_s"], 2)
        _log("replay depth", depth, row)
        out[f"depth_{depth}"] = row
    if mem_spps:
        mem = {}
        for spp_ in mem_spps:
            for kind in ("grad_ad", "grad_replay", "grad_replay_recompute"):
                _, _, temp = program(kind, 4, spp_)
                mem.setdefault(kind, {})[spp_] = round(temp / 2**20, 3)
        out["temp_MB_vs_spp_depth4"] = mem
        _log("replay memory vs spp", mem)
    out["load_after"] = load_gate(None)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out")
    ap.add_argument(
        "--sections",
        default="speed,glossy,memory,stats,visibility",
        help="comma-separated subset of speed,glossy,memory,stats,visibility,replay,replay_memory",
    )
    ap.add_argument(
        "--replay-memory-kinds",
        default="grad_ad,grad_replay",
        help="replay_memory section: which programs (grad_ad, grad_replay, forward)",
    )
    ap.add_argument(
        "--replay-mem-spps",
        default="",
        help="replay section: also XLA's temporary buffer of jit(grad) at depth 4 for these "
        "comma-separated spp (AD, replay, replay recomputing the forward; compile only)",
    )
    a = ap.parse_args(argv)
    sections = set(a.sections.split(","))
    q = a.quick
    example = read_yaml(EXAMPLE)
    mesh = copy.deepcopy(example)
    m = make_uv_sphere(40, radius=1.0, center=(0.0, 1.0, 0.0))
    mesh["shapes"][0] = {
        "type": "mesh",
        "vertices": np.asarray(m.vertices).tolist(),
        "faces": np.asarray(m.faces).tolist(),
        "material": "metal",
    }
    res = 32 if q else 64
    spp = 4 if q else 16
    result = {"benchmark": "gradients", "machine": machine()}
    if "memory" in sections:
        result["memory_MB"] = memory(
            _with_res(example, 32),
            spps=[1, 4, 16] if q else [1, 4, 16, 64, 256],
            depths=[2, 3, 4] if q else [2, 3, 4, 6, 8],
        )
    if "speed" in sections:
        result["speed"] = {
            "example": speed(_with_res(example, res), spp=spp, depth=3, repeat=3),
            "mesh": speed(_with_res(mesh, res // 2), spp=spp, depth=3, repeat=3),
        }
    if "glossy" in sections:
        result["glossy_grad_vs_forward"] = glossy_ratio(
            w=16 if q else 32, spp=spp, repeat=3 if q else 15
        )
    if "stats" in sections:
        result["grad_stats_alpha"] = statistics_alpha(spp=32 if q else 128, n=4 if q else 16)
    if "visibility" in sections:
        result["visibility"] = visibility(spp=32 if q else 128, n=4 if q else 16)
    if "replay" in sections:
        result["replay"] = replay(
            res=32 if q else 64,
            spp=16 if q else 64,
            depths=[2, 4] if q else [2, 4, 8],
            repeat=3 if q else 5,
            mem_spps=tuple(int(x) for x in a.replay_mem_spps.split(",") if x),
        )
    if "replay_memory" in sections:
        result["replay_memory"] = replay_memory(
            res=32,
            spp=16,
            depths=[2, 4] if q else [2, 4, 8, 16],
            spps=[16, 64] if q else [16, 64, 256],
            kinds=tuple(a.replay_memory_kinds.split(",")),
        )
    emit(result, a.out)


if __name__ == "__main__":
    main()
