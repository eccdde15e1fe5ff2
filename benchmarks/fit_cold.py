"""The cold ``jaxgfx fit`` timeline: where a fresh process's seconds go, phase by phase.

    python -m benchmarks.fit_cold [--config configs/inverse_material.yaml]
                                  [--variants default,fast_compile] [--repeats 2] [--out FILE]

Each run is a **fresh Python process** with JAX's persistent compilation cache off
(``JAXGFX_CACHE_DIR=off``: a cold start) that runs ``jaxgfx fit CONFIG --out TMP --quiet``
through :func:`jaxgfx.cli.main`, with timers around the phases (wall and process CPU seconds
from the process start): ``imports`` (``jaxgfx.cli``, ``jaxgfx.pipelines.fit``,
``jaxgfx.render``, ``jaxgfx.optim``, jax), ``load`` (config + scene, ``prepare_fit``),
``target`` (the synthetic target render), ``fit`` (the step's compile and the steps:
``compile_seconds`` and the steps' sum from ``result.json``), ``report`` (the preview renders)
and ``write``; ``other`` is the rest up to the process's end. JAX's own compile events
(``jax.monitoring``: trace, lower to StableHLO, XLA compile) are summed per phase and listed
per compiled function (wall seconds; they may overlap when programs compile in a thread).
Variants: ``default`` (the config as given), ``fast_compile``
(``optimizer.fast_compile: true``) and ``separate_programs``
(``JAXGFX_FIT_SHARED_RENDER=0``: the target at its own spp in one call, as before), joinable
with ``+``. ``--set section.key=value`` changes the config (e.g. ``--set
render.integrator=path --set optimizer.steps=100``). ``--warm-steps N``: instead, the
config's step compiled twice in one process (defaults, ``FAST_COMPILE_OPTIONS``) and called
N times each, alternating, medians of process CPU and wall per call. ``--gil``: whether
XLA's compile lets another Python thread run (a Python loop beside a compile; two compiles
in two threads against one after the other). Repeats are interleaved
(A B A B) so that a change of the machine's load falls on both. Prints one JSON document;
``machine.load_before`` / ``load_after`` and each run's ``load_after`` are the 1-minute load
averages (the other jobs on the shared machine).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PHASES = ("imports", "cli", "load", "pre_target", "target", "fit", "report", "write", "other")


def _child(config: str, variant: str) -> dict:
    t_start = time.perf_counter()
    c_start = time.process_time()
    marks = []  # (phase, wall s, cpu s) at each phase's end

    def mark(name):
        marks.append((name, time.perf_counter() - t_start, time.process_time() - c_start))

    import jax  # noqa: F401  (counted in imports)
    from jax import monitoring

    events = []  # (event, fun_name, start, end) in perf_counter seconds from t_start
    names = {"/jax/core/compile/jaxpr_trace_duration": "trace",
             "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
             "/jax/core/compile/backend_compile_duration": "xla"}

    def on_span(event, start, end, **kw):
        if event in names:
            events.append((names[event], str(kw.get("fun_name", "?")), start, end))

    monitoring.register_event_time_span_listener(on_span)
    import jaxgfx.cli as cli
    import jaxgfx.optim  # noqa: F401
    import jaxgfx.pipelines.fit as fitpkg
    import jaxgfx.render  # noqa: F401
    from jaxgfx.pipelines.fit import job, targets

    mark("imports")
    # the phases are wrapped where run_fit calls them
    orig_prepare, orig_target = job.prepare_fit, job._target
    orig_previews, orig_write = job._previews, job.write_outputs
    clock0 = time.time() - (time.perf_counter() - t_start)  # perf_counter 0 on time.time

    def wrap(fn, before, after):
        def inner(*a, **k):
            mark(before)
            out = fn(*a, **k)
            mark(after)
            return out
        return inner

    job.prepare_fit = wrap(orig_prepare, "cli", "load")
    job._target = wrap(orig_target, "pre_target", "target")
    job._previews = wrap(orig_previews, "fit", "report")
    job.write_outputs = wrap(orig_write, "report:post", "write")
    del targets, fitpkg
    out_dir = tempfile.mkdtemp(prefix="fit_cold_")
    args = ["fit", config, "--out", os.path.join(out_dir, "out"), "--quiet"]
    rc = cli.main(args)
    mark("other")
    with open(os.path.join(out_dir, "out", "result.json")) as f:
        result = json.load(f)
    # phases from the marks: each phase is the time since the previous mark
    phases, prev_w, prev_c = {}, 0.0, 0.0
    bounds = []
    for name, w, c in marks:
        key = name.split(":")[0]
        phases.setdefault(key, {"wall_s": 0.0, "cpu_s": 0.0})
        phases[key]["wall_s"] += w - prev_w
        phases[key]["cpu_s"] += c - prev_c
        bounds.append((key, prev_w, w))
        prev_w, prev_c = w, c

    def phase_of(t):
        for key, a, b in bounds:
            if a <= t < b:
                return key
        return "other"

    per_phase, per_fun = {}, {}
    for kind, fun, s, e in events:
        s0, e0 = s - clock0, e - clock0
        ph = per_phase.setdefault(phase_of(s0), {"trace": 0.0, "lower": 0.0, "xla": 0.0})
        ph[kind] += e0 - s0
        f = per_fun.setdefault(fun, {"trace": 0.0, "lower": 0.0, "xla": 0.0, "n_xla": 0})
        f[kind] += e0 - s0
        f["n_xla"] += kind == "xla"
    top = sorted(per_fun.items(), key=lambda kv: -(kv[1]["xla"] + kv[1]["trace"]))[:40]
    return {
        "variant": variant,
        "rc": rc,
        "wall_s": marks[-1][1],
        "cpu_s": marks[-1][2],
        "phases": phases,
        "compile_events_per_phase": per_phase,
        "compile_events_top": dict(top),
        "n_xla_compiles": sum(1 for e in events if e[0] == "xla"),
        "step_compile_s": result["compile_seconds"],
        "steps_s": result["seconds"],
        "step_median_s": result["seconds_per_step"],
        "n_steps": result["n_steps"],
        "target_s": result["target_seconds"],
        "params": result["params"],
    }


def _warm_child(config: str, n: int) -> dict:
    """The fit step of ``config`` compiled twice in this process (XLA's defaults and
    ``FAST_COMPILE_OPTIONS``) and called ``n`` times each, alternating A B B A ...: each
    call's process CPU and wall seconds (the medians compare the two programs' warm steps on a
    loaded machine); then the config's fit run with each program (``optimizer.steps``, same
    target and keys): the largest difference of the fitted values."""
    import dataclasses

    import jax

    from jaxgfx.optim import FAST_COMPILE_OPTIONS, compile_step, fit
    from jaxgfx.optim._loop import _setup
    from jaxgfx.pipelines.fit import FitJob, job, prepare_fit

    fj = FitJob.load(config, None)
    cfg, prep = fj.config, prepare_fit(fj.config, base_dir=fj.base_dir)
    adjoint = job.choose_adjoint(cfg, prep)["adjoint"]
    cfg = dataclasses.replace(cfg, render=dataclasses.replace(cfg.render, adjoint=adjoint))
    _, k_fit, k_show = jax.random.split(jax.random.key(cfg.seed), 3)
    target, _ = job._target(cfg, prep)
    inp = job._fit_inputs(cfg, prep, target, k_show)
    o = cfg.optimizer
    out = {"config": os.path.relpath(config, ROOT), "adjoint": adjoint, "programs": {}}
    steps = {}
    for name, opts in (("default", None), ("fast_compile", dict(FAST_COMPILE_OPTIONS))):
        c0 = time.process_time()
        steps[name] = compile_step(inp.loss, inp.params, optimizer=o.name, key=k_fit,
                                   args=inp.args, bounds=inp.bounds, compiler_options=opts)
        out["programs"][name] = {"compile_cpu_s": time.process_time() - c0,
                                 "compile_wall_s": steps[name].compile_seconds,
                                 "cpu_s": [], "wall_s": []}
    st = _setup(inp.loss, inp.params, o.name, o.lr, k_fit, inp.bounds, None)
    call = (st.u0, st.opt_state, st.step_key, np.int32(0), inp.args)
    for name in steps:  # one warm-up call each
        jax.block_until_ready(steps[name].compiled(*call))
    order = list(steps)
    for i in range(n):
        for name in order if i % 2 == 0 else order[::-1]:
            c0, t0 = time.process_time(), time.perf_counter()
            jax.block_until_ready(steps[name].compiled(*call))
            rec = out["programs"][name]
            rec["wall_s"].append(time.perf_counter() - t0)
            rec["cpu_s"].append(time.process_time() - c0)
    for rec in out["programs"].values():
        rec["median_cpu_s"] = float(np.median(rec["cpu_s"]))
        rec["median_wall_s"] = float(np.median(rec["wall_s"]))
        del rec["cpu_s"], rec["wall_s"]
    # the config's whole fit with each program: the fitted values and losses compared
    fits = {}
    for name, step in steps.items():
        res = fit(inp.loss, inp.params, optimizer=o.name, learning_rate=o.schedule(),
                  steps=o.steps, key=k_fit, args=inp.args, bounds=inp.bounds, progress=False,
                  tol=o.tol, step=step, compiler_options=None if name == "default"
                  else dict(FAST_COMPILE_OPTIONS))
        fits[name] = res
        out["programs"][name]["fit_median_step_s"] = float(np.median(res.seconds))
    a, b = (jax.tree.leaves(fits[n].params) for n in ("default", "fast_compile"))
    out["fit_steps"] = o.steps
    out["fit_max_abs_diff"] = max(float(np.max(np.abs(np.asarray(x, np.float64) - y)))
                                  for x, y in zip(a, b, strict=True))
    out["fit_max_rel_diff"] = max(
        float(np.max(np.abs(np.asarray(x, np.float64) - y) / np.maximum(np.abs(y), 1e-6)))
        for x, y in zip(a, b, strict=True))
    out["fit_loss_last"] = {n: float(r.loss[-1]) for n, r in fits.items()}
    d, f = out["programs"]["default"], out["programs"]["fast_compile"]
    out["fast_over_default_cpu"] = f["median_cpu_s"] / d["median_cpu_s"]
    out["fast_over_default_wall"] = f["median_wall_s"] / d["median_wall_s"]
    return out


def _gil_probe() -> dict:
    """Does XLA's CPU compile let another Python thread run? (1) a pure-Python loop in this
    thread while another thread compiles the fit's 8x8 direct-light render (32 spp): its rate
    against the loop alone; (2) two such compiles (16 and 64 spp) in two threads against one
    after the other (wall and process CPU)."""
    import threading

    import jax

    from jaxgfx.config import load_config
    from jaxgfx.pipelines.fit import FitConfig, prepare_fit
    from jaxgfx.render.estimator import resolve_integrator
    from jaxgfx.render.render import _render

    cfg = load_config(FitConfig, {
        "scene": os.path.join(ROOT, "configs", "scenes", "inverse.yaml"),
        "target": {"synthetic": {"materials.metal.alpha": 0.15}},
        "params": {"materials.metal.alpha": {"init": 0.5, "min": 0.01, "max": 1.0}},
        "render": {"spp": 4, "width": 8, "height": 8}})
    scene = prepare_fit(cfg).scene
    integ = resolve_integrator("direct", max_depth=2, rr_depth=None, strategy=None,
                               sampling=None, caller="gil_probe")

    def lowered(spp):
        return _render.lower(scene, jax.random.key(0), spp, integ)

    def loop_rate(seconds):
        n, t = 0, time.perf_counter()
        while time.perf_counter() - t < seconds:
            n += 1
        return n / seconds

    out = {"load_before": _load1()}
    alone = loop_rate(2.0)
    low = lowered(32)
    th = threading.Thread(target=low.compile)
    c0, t0 = time.process_time(), time.perf_counter()
    th.start()
    n = 0
    while th.is_alive():
        n += 1
    wall = time.perf_counter() - t0
    out["loop"] = {"rate_during_compile_over_alone": n / wall / alone,
                   "rate_alone_after_over_before": loop_rate(2.0) / alone,
                   "compile_wall_s": wall, "process_cpu_s": time.process_time() - c0}
    for mode in ("one_after_the_other", "two_threads", "one_after_the_other", "two_threads"):
        jax.clear_caches()  # else the second round reuses the first's executables
        lows = [lowered(spp) for spp in (16, 64)]
        c0, t0 = time.process_time(), time.perf_counter()
        if mode == "two_threads":
            ths = [threading.Thread(target=x.compile) for x in lows]
            for t in ths:
                t.start()
            for t in ths:
                t.join()
        else:
            for x in lows:
                x.compile()
        out.setdefault(mode, []).append({"wall_s": time.perf_counter() - t0,
                                         "cpu_s": time.process_time() - c0,
                                         "load": _load1()})
    return out


def _variant_env(variant: str, config: str, sets=()) -> tuple[dict, str]:
    """The child's environment and config file (a temporary copy next to ``config`` when the
    variant or ``--set`` changes it)."""
    import yaml

    from jaxgfx.config import read_yaml

    env = dict(os.environ, JAXGFX_CACHE_DIR="off", JAX_PLATFORMS="cpu")
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    data = read_yaml(config)
    changed = False
    for item in sets:  # section.key=value (YAML value)
        name, value = item.split("=", 1)
        section, key = name.split(".", 1)
        data[section] = {**(data.get(section) or {}), key: yaml.safe_load(value)}
        changed = True
    for part in variant.split("+"):
        if part == "default":
            continue
        if part == "fast_compile":
            data["optimizer"] = {**data.get("optimizer", {}), "fast_compile": True}
            changed = True
        elif part == "separate_programs":
            env["JAXGFX_FIT_SHARED_RENDER"] = "0"
        else:
            raise SystemExit(f"--variants: unknown variant part {part!r}")
    if changed:
        base = os.path.dirname(os.path.abspath(config))
        fd, config = tempfile.mkstemp(suffix=".yaml", dir=base, prefix=".fit_cold_")
        with os.fdopen(fd, "w") as f:
            yaml.safe_dump(data, f)
    return env, config


def _load1() -> float:
    return os.getloadavg()[0]


def _run_child(a, variant: str, child_args: list, what: str):
    """Run ``--child CHILD_ARGS`` in a fresh process with ``variant``'s environment and config
    (``_variant_env``; a temporary config is removed afterwards): its ``FIT_COLD_JSON`` document
    and the process's wall seconds. ``SystemExit`` naming ``what`` when the child fails."""
    env, cfg = _variant_env(variant, a.config, a.set)
    try:
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "benchmarks.fit_cold", "--config", cfg, "--child",
             *child_args],
            cwd=ROOT, env=env, capture_output=True, text=True,
        )
        outer = time.perf_counter() - t0
    finally:
        if cfg != a.config:
            os.remove(cfg)
    line = [x for x in proc.stdout.splitlines() if x.startswith("FIT_COLD_JSON ")]
    if not line:
        sys.stderr.write(proc.stdout[-2000:] + proc.stderr[-4000:])
        raise SystemExit(f"{what}: the child failed (rc {proc.returncode})")
    return json.loads(line[0].split(" ", 1)[1]), outer


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--config", default=os.path.join(ROOT, "configs", "inverse_material.yaml"))
    p.add_argument("--variants", default="default")
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a config entry, e.g. --set render.integrator=path")
    p.add_argument("--out", default=None)
    p.add_argument("--warm-steps", type=int, default=0, metavar="N",
                   help="instead: the warm step, default vs fast_compile, N calls each")
    p.add_argument("--gil", action="store_true",
                   help="instead: whether XLA's compile lets another Python thread run")
    p.add_argument("--child", default=None, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.gil:  # in this process (the compilation cache off)
        os.environ["JAXGFX_CACHE_DIR"] = "off"
        print(json.dumps(_gil_probe(), indent=1))
        return 0
    if a.child is not None:
        if a.child == "warm":
            doc = _warm_child(a.config, a.warm_steps)
        else:
            doc = _child(a.config, a.child)
        print("FIT_COLD_JSON " + json.dumps(doc))
        return 0
    if a.warm_steps:
        child, _ = _run_child(a, "default", ["warm", "--warm-steps", str(a.warm_steps)],
                              "warm steps")
        doc = {"load_before": _load1(), **child, "set": a.set, "load_after": _load1()}
        doc["config"] = os.path.relpath(a.config, ROOT)
        print(json.dumps(doc, indent=1))
        if a.out:
            with open(a.out, "w") as f:
                json.dump(doc, f, indent=1)
        return 0
    runs = []
    machine = {"cpus": os.cpu_count(), "load_before": _load1()}
    for r in range(a.repeats):
        for v in a.variants.split(","):
            run, outer = _run_child(a, v, [v], f"variant {v}")
            run.update(repeat=r, process_wall_s=outer, load_after=_load1())
            runs.append(run)
            ph = run["phases"]
            sys.stderr.write(
                f"{v} #{r}: {outer:.1f} s wall (process), {run['cpu_s']:.1f} s CPU; "
                + ", ".join(f"{k} {ph[k]['wall_s']:.1f}/{ph[k]['cpu_s']:.1f}"
                            for k in PHASES if k in ph)
                + f"; step compile {run['step_compile_s']:.1f} s; load {run['load_after']:.1f}\n"
            )
    machine["load_after"] = _load1()
    doc = {"machine": machine, "config": os.path.relpath(a.config, ROOT), "set": a.set,
           "runs": runs}
    text = json.dumps(doc, indent=1)
    if a.out:
        with open(a.out, "w") as f:
            f.write(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
