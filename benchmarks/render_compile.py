"""Compile time as a metric: what the ``configs/inverse_material.yaml`` fit step compiles.

    python -m benchmarks.render_compile [--config configs/inverse_material.yaml]
                                        [--variants default,one_pass_per_step] [--out FILE]

Each variant runs in a **fresh Python process** with JAX's persistent compilation cache off
(a cold start, as ``jaxgfx fit`` on a new problem): the fit step of
``jaxgfx.optim._loop._step`` for the config (render -> loss -> ``value_and_grad`` -> Adam), as
``jaxgfx.optim.fit`` builds it, timed in stages (``jax.stages``): ``trace_s`` (``.trace``),
``lower_s`` (``.lower``), ``compile_s`` (``.compile()``, XLA), their process CPU seconds, the
size of the StableHLO module (characters, ops) and of the optimised HLO (characters), a census
of the loss's jaxpr (equations per ``jaxgfx`` function and per primitive), and a warm step's
median seconds (3 calls). Variants (``estimator.RAYS_PER_STEP`` etc. patched in the
child before tracing):

* ``default``: the code as it is.
* ``checkpointed``: a pass scan of one step and a bounce loop of one bounce checkpointed
  anyway (``estimator.CHECKPOINT_ONE_STEP``, ``_bounce.BOUNCE_CHECKPOINT = "always"``; before
  issue 22).
* ``one_pass_per_step``: ``render_partial`` with one sample pass per scan step (the layout
  before issue 22).
* ``one_render_for_both_keys``: the decorrelated loss's two images (``optim._estimators``)
  rendered by one program vmapped over the two keys instead of two render calls (a
  measurement only: same keys and values, the backward then runs over both images).
* ``scan_over_both_keys``: the two images from one render program in a ``lax.map`` over the
  two keys (XLA inlines the two calls of ``default``, so it compiles the forward twice; a
  measurement: the backward then runs over both scan steps).
* ``reduce_sums``: ``sum_last`` / ``max_last`` (and so ``vdot``, ``safe_norm``) as
  ``jnp.sum`` / ``jnp.max`` reductions instead of unrolled adds (re-checks the "a reduction
  kernel per sum is 10x slower to run" of docs/performance.md on the fit's render).
* ``forward_only``: the loss (both renders) jitted alone, no gradient, no Adam: the forward's
  share of the step's compile (``trace_s`` not separated: ``lower_s`` is trace + lower).
* ``grad_ratio:forward``, ``grad_ratio:grad_ad``, ``grad_ratio:grad_replay``: not the fit
  step but issue 22's other compile target, ``jit(grad)`` against the forward render on the
  two-sphere scene (``configs/scenes/inverse.yaml``, path depth 4, 64², 64 spp; d mean / d α
  by plain AD or path replay), each program compiled in its own process (``_grad_child``);
  ``+bounce_checkpoint_off`` / ``+bounce_checkpoint_no_cse`` set
  ``_bounce.BOUNCE_CHECKPOINT`` (e.g. ``grad_ratio:grad_ad+bounce_checkpoint_off``).
* XLA compile options (``lowered.compile(compiler_options=...)``, the warm step and the
  ``--images`` render compiled with them): ``opt_level_0/1/2``
  (``xla_backend_optimization_level``), ``no_expensive_passes``
  (``xla_llvm_disable_expensive_passes``), ``split_1`` / ``split_8``
  (``xla_cpu_parallel_codegen_split_count``), ``fast_math`` (``xla_cpu_enable_fast_math``),
  ``no_fusion_emitters`` (``xla_cpu_use_fusion_emitters``), ``no_concurrency_scheduler``
  (``xla_cpu_enable_concurrency_optimized_scheduler``);
  join with ``+``, alone or after a variant above (``default+opt_level_1``).

Prints one JSON document (``machine`` block first; the load average is the other jobs').
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(ROOT, "configs", "inverse_material.yaml")
VARIANTS = (
    "default",
    "checkpointed",
    "one_pass_per_step",
    "one_render_for_both_keys",
    "scan_over_both_keys",
    "forward_only",
    "reduce_sums",
)
# XLA compile options (``lowered.compile(compiler_options=...)``), one per variant name; a
# variant may join several names with ``+`` (e.g. ``opt_level_1+no_expensive_passes``)
COMPILER_VARIANTS = {
    "opt_level_0": {"xla_backend_optimization_level": 0},
    "opt_level_1": {"xla_backend_optimization_level": 1},
    "opt_level_2": {"xla_backend_optimization_level": 2},
    "no_expensive_passes": {"xla_llvm_disable_expensive_passes": True},
    "split_1": {"xla_cpu_parallel_codegen_split_count": 1},
    "split_8": {"xla_cpu_parallel_codegen_split_count": 8},
    "fast_math": {"xla_cpu_enable_fast_math": True},
    "no_fusion_emitters": {"xla_cpu_use_fusion_emitters": False},
    "no_concurrency_scheduler": {"xla_cpu_enable_concurrency_optimized_scheduler": False},
}


def _jaxpr_census(fn, *args, top=10) -> dict:
    """Equations of ``jax.make_jaxpr(fn)(*args)`` (the fit's loss, forward only), every nested
    jaxpr flattened (a jitted function called twice counts twice), grouped by the innermost
    ``jaxgfx`` function they were traced from (for the equations of a jitted library function
    such as ``jnp.where``: the function that called it) and by primitive."""
    import collections

    import jax
    from jax._src import source_info_util as siu
    from jax.extend import core as jcore

    by_fn, by_prim = collections.Counter(), collections.Counter()

    def subs(eqn):
        for v in eqn.params.values():
            for x in v if isinstance(v, (list, tuple)) else (v,):
                if isinstance(x, jcore.ClosedJaxpr):
                    yield x.jaxpr
                elif isinstance(x, jcore.Jaxpr):
                    yield x

    def where(e, default):
        for fr in siu.user_frames(e.source_info.traceback):
            if "/jaxgfx/" in fr.file_name:
                return fr.file_name.split("/jaxgfx/")[-1] + ":" + fr.function_name
        return default

    def walk(j, parent="?"):
        # equations inside a jitted library function (jnp.where, jnp.cross, ...) carry no
        # jaxgfx frame of their own: they count for the call site of that function
        for e in j.eqns:
            inner = list(subs(e))
            for sj in inner:
                walk(sj, where(e, parent))
            if inner:
                continue
            by_fn[where(e, parent)] += 1
            by_prim[e.primitive.name] += 1

    walk(jax.make_jaxpr(fn)(*args).jaxpr)
    return {
        "loss_jaxpr_eqns": sum(by_fn.values()),
        "loss_jaxpr_top_functions": by_fn.most_common(top),
        "loss_jaxpr_top_primitives": by_prim.most_common(top),
    }


GRAD_KINDS = ("forward", "grad_ad", "grad_replay")


def _grad_child(kind: str, depth: int = 4, res: int = 64, spp: int = 64) -> dict:
    """Compile CPU seconds of the two-sphere scene's (``configs/scenes/inverse.yaml``, path
    tracing, ``depth``, ``res``², ``spp``) forward render or ``jit(grad)`` of its image mean
    w.r.t. the metal's α (``PathIntegrator(adjoint="ad" | "replay")``), as
    ``benchmarks.gradients --sections replay`` builds them; one program per fresh process."""
    os.environ["JAXGFX_CACHE_DIR"] = "off"
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from benchmarks.gradients import INVERSE, _with_res
    from jaxgfx.config import read_yaml
    from jaxgfx.render.integrators import PathIntegrator
    from jaxgfx.render.render import render
    from jaxgfx.render.scene import load_scene

    scene = load_scene(_with_res(read_yaml(INVERSE), res))
    dyn, static = eqx.partition(scene, eqx.is_array)
    path = "materials.metal.alpha"
    alpha = scene.get(path)
    integ = PathIntegrator(max_depth=depth, adjoint="replay" if kind == "grad_replay" else "ad")

    def image(a, dyn, k):
        return render(eqx.combine(dyn, static).replace(path, a), k, spp=spp, integrator=integ)

    f = image if kind == "forward" else jax.grad(lambda a, d, k: jnp.mean(image(a, d, k)))
    w0, c0 = time.perf_counter(), time.process_time()
    lowered = jax.jit(f).lower(alpha, dyn, jax.random.key(0))
    w1, c1 = time.perf_counter(), time.process_time()
    compiled = lowered.compile()
    w2, c2 = time.perf_counter(), time.process_time()
    return {
        "variant": f"grad_ratio:{kind}", "depth": depth, "res": res, "spp": spp,
        "trace_lower_s": w1 - w0, "trace_lower_cpu_s": c1 - c0,
        "compile_s": w2 - w1, "compile_cpu_s": c2 - c1,
        "stablehlo_ops": sum(1 for ln in lowered.as_text().splitlines() if " = " in ln),
        "optimized_hlo_chars": len(compiled.as_text()),
        "temp_MB": compiled.memory_analysis().temp_size_in_bytes / 2**20,
    }  # fmt: skip


def _child(config: str, variant: str, image_dir: str | None = None) -> dict:
    os.environ["JAXGFX_CACHE_DIR"] = "off"
    import jax
    import numpy as np

    import jaxgfx.render.estimator as E

    parts = variant.split("+")
    copts = {}
    for part in parts[1:] if parts[0] in VARIANTS else parts:
        if part not in COMPILER_VARIANTS:
            raise SystemExit(f"variant: unknown part {part!r} (one of {sorted(COMPILER_VARIANTS)})")
        copts.update(COMPILER_VARIANTS[part])
    variant_name, variant = variant, (parts[0] if parts[0] in VARIANTS else "default")
    if variant == "one_pass_per_step":
        E.RAYS_PER_STEP = None
        defaults = list(E.render_partial.__kwdefaults__.items())
        E.render_partial.__kwdefaults__ = {
            k: (None if k == "rays_per_step" else v) for k, v in defaults
        }
    elif variant == "checkpointed":
        import jaxgfx.render.integrators._bounce as PI

        E.CHECKPOINT_ONE_STEP = True
        PI.BOUNCE_CHECKPOINT = "always"
    elif variant == "one_render_for_both_keys":
        import jaxgfx.optim._estimators as OE

        def two_images(image_fn, key):  # the same two keys, one (vmapped) render program
            imgs = jax.vmap(image_fn)(jax.random.split(key))
            return jax.lax.stop_gradient(imgs[0]), imgs[1]

        OE._two_images = two_images
    elif variant == "scan_over_both_keys":
        import jaxgfx.optim._estimators as OE

        def two_images(image_fn, key):  # the same two keys, one render program in a scan
            imgs = jax.lax.map(image_fn, jax.random.split(key))
            return jax.lax.stop_gradient(imgs[0]), imgs[1]

        OE._two_images = two_images
    elif variant == "reduce_sums":
        import jax.numpy as jnp

        import jaxgfx._math as M

        def reduce(op, x, keepdims):  # jnp.sum / jnp.max: one reduction per short sum
            return (jnp.sum if op is jnp.add else jnp.max)(x, axis=-1, keepdims=keepdims)

        M._unrolled_last = reduce
    elif variant not in ("default", "forward_only"):
        raise SystemExit(f"variant: expected one of {VARIANTS}, got {variant!r}")

    import functools

    from jaxgfx.config import load_config
    from jaxgfx.optim import _loop as L
    from jaxgfx.pipelines.fit import FitConfig
    from jaxgfx.pipelines.fit.job import _initial, _target
    from jaxgfx.pipelines.fit.loss import cached_loss
    from jaxgfx.pipelines.fit.targets import prepare_fit

    cfg = load_config(FitConfig, config)
    prep = prepare_fit(cfg, base_dir=os.path.dirname(os.path.abspath(config)))
    target, _ = _target(cfg, prep)
    params, bounds, cam_args = _initial(cfg, prep)
    loss = cached_loss(cfg, prep.paths, prep.ldr, target.grey, target.mask is not None)
    import jax.numpy as jnp

    args = (prep.scene, jnp.asarray(target.pixels), cam_args)
    tx = L._named_optimizer("adam", ())
    spec = L._bound_spec(params, bounds)
    u0 = L.to_unconstrained(params, bounds)
    state = tx.init(u0)
    key = jax.random.key(0)
    static = dict(loss=loss, tx=tx, spec=spec, use_key=True)
    step = functools.partial(L._step, **static)
    out = {"variant": variant_name, "compiler_options": copts}

    def clocks():
        return time.perf_counter(), time.process_time()

    if variant == "forward_only":  # the loss alone (both renders, no gradient, no Adam)
        fwd = jax.jit(functools.partial(L._value, **static))
        w0, c0 = clocks()
        lowered = fwd.trace(u0, key, args).lower()
        w2, c2 = clocks()
        fwd_c = lowered.compile(compiler_options=copts or None)
        w3, c3 = clocks()
        out.update(trace_s=None, lower_s=w2 - w0, lower_cpu_s=c2 - c0, compile_s=w3 - w2,
                   compile_cpu_s=c3 - c2, optimized_hlo_chars=len(fwd_c.as_text()))  # fmt: skip
        out["loss"] = float(fwd_c(u0, key, args))
        return out
    w0, c0 = clocks()
    traced = L._step.trace(u0, state, key, np.int32(0), args, **static)
    w1, c1 = clocks()
    lowered = traced.lower()
    w2, c2 = clocks()
    compiled = lowered.compile(compiler_options=copts or None)
    w3, c3 = clocks()
    out.update(
        trace_s=w1 - w0, trace_cpu_s=c1 - c0, lower_s=w2 - w1, lower_cpu_s=c2 - c1,
        compile_s=w3 - w2, compile_cpu_s=c3 - c2,
    )  # fmt: skip
    text = lowered.as_text()
    out["stablehlo_chars"] = len(text)
    out["stablehlo_ops"] = sum(1 for ln in text.splitlines() if " = " in ln)
    try:
        out["optimized_hlo_chars"] = len(compiled.as_text())
    except Exception:  # pragma: no cover - depends on the jax version
        out["optimized_hlo_chars"] = None
    out.update(_jaxpr_census(functools.partial(L._value, **static), u0, key, args))
    res = compiled(u0, state, key, np.int32(0), args)
    jax.block_until_ready(res)
    del step
    ts, cs = [], []
    for i in range(5):  # the compiled step itself (a plain call would compile it again)
        t, c = clocks()
        jax.block_until_ready(compiled(u0, state, key, np.int32(i + 1), args))
        ts.append(time.perf_counter() - t)
        cs.append(time.process_time() - c)
    out["step_s"] = float(np.median(ts))
    out["step_cpu_s"] = float(np.median(cs))
    out["loss"] = float(res[2])
    if image_dir:  # the render of the fit's image (initial scene, fixed key), same options
        from jaxgfx.render import render

        r = cfg.render
        rend = jax.jit(
            lambda sc, k: render(sc, k, spp=r.spp, integrator=r.integrator_spec,
                                 max_depth=r.max_depth)
        )  # fmt: skip
        img = rend.lower(prep.scene, key).compile(compiler_options=copts or None)(prep.scene, key)
        path = os.path.join(image_dir, variant_name.replace("+", "_") + ".npy")
        np.save(path, np.asarray(img))
        out["image"] = path
    return out


def run_variant(variant: str, *, config: str = CONFIG, images: str | None = None) -> dict:
    """One variant's row (see the module docstring) measured in a fresh Python process with
    the compilation cache off (``JAXGFX_CACHE_DIR=off``), plus ``process_wall_s`` (the whole
    child process) and ``load_avg_after``. ``SystemExit`` with the child's stderr on failure."""
    env = dict(os.environ, JAXGFX_CACHE_DIR="off")
    env["PYTHONPATH"] = os.pathsep.join([ROOT, env.get("PYTHONPATH", "")])
    t = time.perf_counter()
    p = subprocess.run(
        [sys.executable, "-m", "benchmarks.render_compile", "--config", config,
         "--child", variant] + (["--images", images] if images else []),
        env=env, capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip
    if p.returncode != 0:
        raise SystemExit(p.stderr[-3000:])
    row = json.loads(p.stdout.strip().splitlines()[-1])
    row["process_wall_s"] = time.perf_counter() - t
    row["load_avg_after"] = [round(x, 2) for x in os.getloadavg()]
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=CONFIG)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--out", default=None)
    ap.add_argument(
        "--images",
        default=None,
        help="save each variant's render (.npy) here; rows get max |Δ| to the first row's",
    )
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.images:
        os.makedirs(a.images, exist_ok=True)
    if a.child and a.child.startswith("grad_ratio:"):
        kind, _, ckpt = a.child.split(":", 1)[1].partition("+bounce_checkpoint_")
        if ckpt:  # e.g. grad_ratio:grad_ad+bounce_checkpoint_off (or _no_cse)
            import jaxgfx.render.integrators._bounce as PI

            PI.BOUNCE_CHECKPOINT = ckpt
        row = _grad_child(kind)
        row["variant"] = "grad_ratio:" + a.child.split(":", 1)[1]
        print(json.dumps(row), flush=True)
        return
    if a.child:
        print(json.dumps(_child(a.config, a.child, a.images)), flush=True)
        return
    from benchmarks._report import emit, machine

    doc = {"benchmark": "render_compile", "machine": machine(), "config": a.config, "rows": []}
    for v in a.variants.split(","):
        row = run_variant(v, config=a.config, images=a.images)
        if a.images:
            import numpy as np

            img = np.load(row["image"])
            ref = np.load(doc["rows"][0]["image"]) if doc["rows"] else img
            row["image_max_abs_diff_vs_first"] = float(np.max(np.abs(img - ref)))
        doc["rows"].append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    emit(doc, a.out)


if __name__ == "__main__":
    main()
