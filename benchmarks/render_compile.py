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
  anyway (``estimator.CHECKPOINT_ONE_STEP``, ``_bounce.CHECKPOINT_ONE_BOUNCE``; before issue 22).
* ``one_pass_per_step``: ``render_partial`` with one sample pass per scan step (the layout
  before issue 22).
* ``one_render_for_both_keys``: the decorrelated loss's two images (``optim._estimators``)
  rendered by one program vmapped over the two keys instead of two render calls (a
  measurement only: same keys and values, the backward then runs over both images).

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
VARIANTS = ("default", "checkpointed", "one_pass_per_step", "one_render_for_both_keys")


def _jaxpr_census(fn, *args, top=10) -> dict:
    """Equations of ``jax.make_jaxpr(fn)(*args)`` (the fit's loss, forward only), every nested
    jaxpr flattened (a jitted function called twice counts twice), grouped by the innermost
    ``jaxgfx`` function they were traced from and by primitive."""
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

    def walk(j):
        for e in j.eqns:
            inner = list(subs(e))
            for sj in inner:
                walk(sj)
            if inner:
                continue
            name = "?"
            for fr in siu.user_frames(e.source_info.traceback):
                if "/jaxgfx/" in fr.file_name:
                    name = fr.file_name.split("/jaxgfx/")[-1] + ":" + fr.function_name
                    break
            by_fn[name] += 1
            by_prim[e.primitive.name] += 1

    walk(jax.make_jaxpr(fn)(*args).jaxpr)
    return {
        "loss_jaxpr_eqns": sum(by_fn.values()),
        "loss_jaxpr_top_functions": by_fn.most_common(top),
        "loss_jaxpr_top_primitives": by_prim.most_common(top),
    }


def _child(config: str, variant: str) -> dict:
    os.environ["JAXGFX_CACHE_DIR"] = "off"
    import jax
    import numpy as np

    import jaxgfx.render.estimator as E

    if variant == "one_pass_per_step":
        E.RAYS_PER_STEP = None
        defaults = list(E.render_partial.__kwdefaults__.items())
        E.render_partial.__kwdefaults__ = {
            k: (None if k == "rays_per_step" else v) for k, v in defaults
        }
    elif variant == "checkpointed":
        import jaxgfx.render.integrators._bounce as PI

        E.CHECKPOINT_ONE_STEP = True
        PI.CHECKPOINT_ONE_BOUNCE = True
    elif variant == "one_render_for_both_keys":
        import jaxgfx.optim._estimators as OE

        def two_images(image_fn, key):  # the same two keys, one (vmapped) render program
            imgs = jax.vmap(image_fn)(jax.random.split(key))
            return jax.lax.stop_gradient(imgs[0]), imgs[1]

        OE._two_images = two_images
    elif variant != "default":
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
    out = {"variant": variant}

    def clocks():
        return time.perf_counter(), time.process_time()

    w0, c0 = clocks()
    traced = L._step.trace(u0, state, key, np.int32(0), args, **static)
    w1, c1 = clocks()
    lowered = traced.lower()
    w2, c2 = clocks()
    compiled = lowered.compile()
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
    ts = []
    for i in range(3):
        t = time.perf_counter()
        jax.block_until_ready(step(u0, state, key, np.int32(i + 1), args))
        ts.append(time.perf_counter() - t)
    out["step_s"] = float(np.median(ts))
    out["loss"] = float(res[2])
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=os.path.join(ROOT, "configs", "inverse_material.yaml"))
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--out", default=None)
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        print(json.dumps(_child(a.config, a.child)), flush=True)
        return
    from benchmarks._report import emit, machine

    doc = {"benchmark": "render_compile", "machine": machine(), "config": a.config, "rows": []}
    env = dict(os.environ, JAXGFX_CACHE_DIR="off")
    env["PYTHONPATH"] = os.pathsep.join([ROOT, env.get("PYTHONPATH", "")])
    for v in a.variants.split(","):
        t = time.perf_counter()
        p = subprocess.run(
            [sys.executable, "-m", "benchmarks.render_compile", "--config", a.config,
             "--child", v],
            env=env, capture_output=True, text=True, cwd=ROOT,
        )  # fmt: skip
        if p.returncode != 0:
            raise SystemExit(p.stderr[-3000:])
        row = json.loads(p.stdout.strip().splitlines()[-1])
        row["process_wall_s"] = time.perf_counter() - t
        row["load_avg_after"] = [round(x, 2) for x in os.getloadavg()]
        doc["rows"].append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    emit(doc, a.out)


if __name__ == "__main__":
    main()
