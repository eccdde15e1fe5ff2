"""Issue 22's targets as ratios, from one command: jaxgfx and Mitsuba 3 measured in the same run.

    python -m benchmarks.fitloop [--quick] [--out FILE] [--no-mitsuba]
                                 [--max-load 1.0 | --allow-load]
                                 [--sections throughput,compile,gradient,fit]

One row per target of issue 22 ("The fit loop at the speed of Mitsuba 3"), each measured by the
benchmark that owns it (imported here, not copied):

* ``throughput``: samples/s of jaxgfx ÷ Mitsuba 3 (``llvm_ad_rgb``), path depth 4, 16 spp, by
  ``benchmarks.render.ratios`` (the two spheres of ``configs/scenes/inverse.yaml`` at 96x72 and
  384x288, the 5 120-triangle blob at 80x64 and 320x256), and the same harness
  (``benchmarks/_render_harness.py``) with jaxgfx's ``direct`` integrator against Mitsuba's own
  ``direct`` plugin on the two spheres (Mitsuba's ``path`` at depth 2, the same estimator, is
  in the JSON too).
* ``compile``: the cold compile (trace + lower + XLA, wall) of the ``configs/inverse_material.yaml``
  fit step, default and ``optimizer.fast_compile``, each in a fresh process with the cache off
  (``benchmarks.render_compile.run_variant``); the whole cold ``jaxgfx fit`` of that config (a
  subprocess, ``JAXGFX_CACHE_DIR=off``, to a temporary ``--out``), default and ``fast_compile``;
  the forward render compile of the two-sphere scene and ``jit(grad)`` compile ÷ that forward's
  (AD and path replay; ``render_compile``'s ``grad_ratio:*`` children, 64², 64 spp, depth 4).
* ``gradient``: ``jit(grad)`` ÷ forward seconds at equal spp on the glossy two-sphere scene,
  path depth 4, AD and path replay (``benchmarks.gradients.replay``), next to Mitsuba 3's own
  ``prb`` gradient (``dr.backward`` of the image mean w.r.t. the metal's alpha) ÷ its forward
  (the same ``prb`` scene, no gradient), interleaved in this process: the peer's own ratio,
  context for the <= 2x target. Memory flat in depth: XLA's temporary buffer of replay's
  ``jit(grad)`` at depth 8 ÷ depth 2 (``benchmarks.gradients.replay_memory``, 32², 16 spp;
  "flat" read as <= 1.10).
* ``fit``: from a cold process to alpha within 2 % on the example fit (``benchmarks.inverse``'s
  ``run_jaxgfx`` / ``run_mitsuba``, each in a fresh process): seconds from the process's start
  (imports, scene, target, compile) to the step after which the running mean of 5 iterates stays
  within 2 % (``inverse.time_to_within``), jaxgfx ÷ Mitsuba (Mitsuba's from the call of
  ``run_mitsuba``, which imports mitsuba: the jax / jaxgfx imports the benchmark needs to
  convert the scene are not counted against it). Two jaxgfx rows: the cache off
  (``JAXGFX_CACHE_DIR=off``) and JAX's persistent cache warm (a third process after one that
  filled a fresh cache folder, as a second run of the CLI finds it). Mitsuba runs in a fresh
  process next to each; Dr.Jit's own kernel cache on disk is left as it is (warm after its
  first run on a machine).

Every timed row records the 1-minute load average when it started, the CPU seconds of this
process and its children (``cpu_s``, ``cores`` = CPU / wall) and the CPU seconds other processes
used meanwhile (``other_cores``, ``/proc/stat``), as the render harness does. The run refuses to
start above ``--max-load`` (default 1.0) unless ``--allow-load``, which marks every row
``loaded: true``.

Prints the JSON document (without the benchmarks' raw output, which ``--out FILE`` keeps), then a
Markdown table (also written next to ``--out`` as ``.md``) with the columns: target (as the
issue states it), case, jaxgfx, Mitsuba 3 (same run), ratio, target, verdict (met / not met /
not measured), conditions (load, other processes' cores).
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import math
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(ROOT, "configs", "inverse_material.yaml")
SECTIONS = ("throughput", "compile", "gradient", "fit")


def _log(*a):
    print(*a, file=sys.stderr, flush=True)


# -------------------------------------------------------------------------------------------
# the targets and their verdicts


@dataclasses.dataclass(frozen=True)
class Target:
    """One target of issue 22. ``on="ratio"``: the row's ``ratio`` is compared with
    ``threshold``; ``on="value"``: the jaxgfx figure itself (an absolute target)."""

    id: str
    section: str
    text: str  # as the issue states it
    op: str  # "<=" or ">="
    threshold: float
    on: str  # "ratio" | "value"
    ratio_of: str  # what the ratio divides ("" for an absolute target)
    unit: str  # of the compared figure ("×" for ratios)


TARGETS = (
    Target("path_analytic", "throughput",
           "Path-traced analytic scenes >= 0.33x Mitsuba 3's samples/s",
           ">=", 0.33, "ratio", "jaxgfx ÷ Mitsuba samples/s", "×"),
    Target("direct_analytic", "throughput", "direct >= 0.5x",
           ">=", 0.5, "ratio", "jaxgfx ÷ Mitsuba samples/s", "×"),
    Target("path_mesh", "throughput", "5k-100k-triangle meshes >= 0.33x",
           ">=", 0.33, "ratio", "jaxgfx ÷ Mitsuba samples/s", "×"),
    Target("fit_step_compile", "compile",
           "Cold compile of the configs/inverse_material.yaml fit step <= 6 s",
           "<=", 6.0, "value", "", "s"),
    Target("fit_cold_wall", "compile", "the whole cold `jaxgfx fit` of that config <= 15 s wall",
           "<=", 15.0, "value", "", "s"),
    Target("grad_compile_ratio", "compile", "`jit(grad)` compiles in <= 2x its forward's compile",
           "<=", 2.0, "ratio", "grad compile ÷ forward compile", "×"),
    Target("forward_compile", "compile", "a forward render compile <= 3 s",
           "<=", 3.0, "value", "", "s"),
    Target("grad_time_ratio", "gradient",
           "`jit(grad)` <= 2x the forward time at equal spp on the glossy path-traced scene",
           "<=", 2.0, "ratio", "grad s ÷ forward s", "×"),
    Target("memory_flat", "gradient", "memory flat in depth (read: depth 8 <= 1.10x depth 2)",
           "<=", 1.10, "ratio", "temp MB depth 8 ÷ depth 2", "×"),
    Target("time_to_2pct", "fit",
           "From a cold process to alpha within 2 % on the example fit: <= 2x Mitsuba 3's time "
           "for its own loop in the same run, compile included",
           "<=", 2.0, "ratio", "jaxgfx s ÷ Mitsuba s", "×"),
)  # fmt: skip
TARGET = {t.id: t for t in TARGETS}


def verdict(target: Target, row: dict) -> str:
    """``"met"``, ``"not met"`` or ``"not measured"`` for ``row`` against ``target``: the
    unrounded ``row["ratio"]`` (or ``row["jaxgfx"]`` for an absolute target) against the
    threshold, the bound itself counting as met. A missing figure is ``"not met"`` when the row
    says so (``"missing_is_unmet"``: e.g. the fit never settled within 2 %), else
    ``"not measured"`` (no peer, a section skipped)."""
    value = row.get("ratio") if target.on == "ratio" else row.get("jaxgfx")
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "not met" if row.get("missing_is_unmet") else "not measured"
    if target.op == "<=":
        return "met" if value <= target.threshold else "not met"
    if target.op == ">=":
        return "met" if value >= target.threshold else "not met"
    raise ValueError(f"target {target.id}: op must be '<=' or '>=', got {target.op!r}")


def _num(x, unit="", nd=3):
    if x is None:
        return "—"
    ax = abs(x)
    s = f"{x:.{nd}g}" if ax < 1000 else f"{x:.0f}"
    return f"{s} {unit}".strip() if unit not in ("×",) else f"{s}×"


def _target_cell(t: Target) -> str:
    unit = "×" if t.unit == "×" else " " + t.unit
    bound = f"{'≤' if t.op == '<=' else '≥'} {t.threshold:g}{unit}"
    return f"{bound} ({t.ratio_of})" if t.ratio_of else bound


def table_markdown(rows: list[dict]) -> str:
    """The Markdown table of ``rows`` (each with ``target``, ``case``, ``jaxgfx_text``,
    ``mitsuba_text``, ``ratio``, ``verdict`` and the conditions: ``load_avg``, ``cores`` =
    this run's CPU per wall second, ``other_cores``, ``loaded``), one line per row."""
    head = ("| target (issue 22) | case | jaxgfx | Mitsuba 3 (same run) | ratio | target | "
            "verdict | conditions |")  # fmt: skip
    lines = [head, "|" + "---|" * 8]
    for r in rows:
        t = TARGET[r["target"]]
        cond = []
        if r.get("load_avg") is not None:
            cond.append(f"load {r['load_avg'][0]:.2f}")
        if r.get("cores") is not None:
            cond.append(f"this run {r['cores']:.2f} cores")
        if r.get("other_cores") is not None:
            cond.append(f"others {r['other_cores']:.2f} cores")
        if r.get("loaded"):
            cond.append("**loaded**")
        v = r.get("verdict") or verdict(t, r)
        why = r.get("unreliable_because")
        notes = "; ".join(([f"not reliable: {why}"] if why else []) + (r.get("notes") or []))
        cells = [
            t.text,
            r.get("case", ""),
            r.get("jaxgfx_text") or _num(r.get("jaxgfx")),
            r.get("mitsuba_text") or _num(r.get("mitsuba")),
            _num(r.get("ratio"), "×") if t.on == "ratio" else "—",
            _target_cell(t),
            f"**{v}{'?' if why else ''}**" + (f" ({notes})" if notes else ""),
            ", ".join(cond),
        ]
        lines.append("| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines)


def run_caption(doc: dict) -> str:
    """One line under the table: when, how long, the load gate, quick or full."""
    g = doc["load_gate"]
    load = g.get("load_avg")
    return (
        f"`python -m benchmarks.fitloop{' --quick' if doc.get('quick') else ''}`: "
        f"{doc.get('started', '?')}, {doc.get('duration_s', 0):.0f} s, sections "
        f"{','.join(doc.get('sections', []))}; load average at the start "
        f"{'?' if load is None else '/'.join(f'{x:.2f}' for x in load)}, after "
        f"{'/'.join(f'{x:.2f}' for x in doc.get('load_avg_after') or [])}"
        + (" — **loaded** (started above --max-load with --allow-load)" if g["loaded"] else "")
        + f"; {doc['machine'].get('cpus')} CPUs, Mitsuba {doc['machine'].get('mitsuba')}."
    )


def finish_rows(rows: list[dict], *, loaded: bool) -> list[dict]:
    """Each row with its ``verdict``, ``loaded`` flag (the run's load gate) and ``reliable``
    (``False`` where the row gives ``unreliable_because``, e.g. Mitsuba below its known
    throughput: the verdict is then printed as ``met?`` / ``not met?``)."""
    for r in rows:
        if r["target"] not in TARGET:
            raise KeyError(f"row for an unknown target {r['target']!r}")
        r["loaded"] = bool(loaded)
        r["verdict"] = verdict(TARGET[r["target"]], r)
        r["reliable"] = not r.get("unreliable_because")
    return rows


def _row(target, case, *, jaxgfx=None, mitsuba=None, ratio=None, probe=None, **kw) -> dict:
    row = {"target": target, "case": case, "jaxgfx": jaxgfx, "mitsuba": mitsuba, "ratio": ratio}
    if probe is not None:
        row.update(probe.block)
    row.update(kw)
    return row


# -------------------------------------------------------------------------------------------
# conditions of a measurement


def _children_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


class Probe:
    """``with Probe() as p: ...`` then ``p.block``: the 1-minute load average at the start
    (``load_avg``, 1/5/15), wall seconds, CPU seconds of this process and its finished
    children (``cpu_s``, ``cores``) and other processes' CPU per wall second
    (``other_cores``; ``None`` without ``/proc/stat``)."""

    def __enter__(self):
        from benchmarks import _render_harness as H

        self._H = H
        self.load = [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None
        self.busy0 = H._proc_stat_busy()
        self.cpu0 = time.process_time() + _children_cpu()
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        wall = time.perf_counter() - self.t0
        cpu1 = time.process_time() + _children_cpu()
        busy1 = self._H._proc_stat_busy()
        others = self._H.cpu_seconds_of_others(self.busy0, self.cpu0, busy1, cpu1)
        cpu = cpu1 - self.cpu0
        self.block = {
            "load_avg": self.load,
            "wall_s": round(wall, 3),
            "cpu_s": round(cpu, 3),
            "cores": round(cpu / wall, 2) if wall > 0 else None,
            "other_cores": None if others is None or wall <= 0 else round(others / wall, 2),
        }
        return False


# -------------------------------------------------------------------------------------------
# 1. throughput


def _harness_conditions(res: dict) -> dict:
    """Conditions of an interleaved harness row: jaxgfx's CPU, cores and the largest
    ``other_cores`` of the systems in it."""
    oth = [v.get("other_cores") for v in res.values() if isinstance(v, dict)]
    oth = [x for x in oth if x is not None]
    j = res["jaxgfx"]
    return {"cpu_s": j["cpu_s"], "cores": j["cores"], "other_cores": max(oth) if oth else None}


def section_throughput(mi, *, quick: bool, repeats: int = 3):
    from benchmarks import _render_harness as H
    from benchmarks import render as R

    rows, raw = [], {}
    load0 = list(os.getloadavg())
    raw["ratios"] = R.ratios(mi, repeats=repeats, quick=quick)
    for r in raw["ratios"]:
        mesh = r["scene"].startswith("mesh")
        j = r["jaxgfx"]["samples_per_s"] / 1e6
        m = r["mitsuba"]["samples_per_s"] / 1e6 if "mitsuba" in r else None
        unreliable = r.get("mitsuba_suspect")
        case = (f"{r.get('triangles', '')}-triangle mesh" if mesh else "two spheres") + (
            f", {r['width']}×{r['height']}, path depth 4, 16 spp"
        )
        rows.append(_row(
            "path_mesh" if mesh else "path_analytic", case, jaxgfx=j, mitsuba=m,
            ratio=None if m is None else j / m, jaxgfx_text=f"{j:.3g} M samples/s",
            mitsuba_text=None if m is None else f"{m:.3g} M samples/s",
            unreliable_because=unreliable,
            load_avg=[round(x, 2) for x in load0], **_harness_conditions(r),
        ))  # fmt: skip
    raw["direct"] = []
    for w, h in ((96, 72),) if quick else ((96, 72), (384, 288)):
        load = [round(x, 2) for x in os.getloadavg()]
        desc = H.two_spheres_desc(w, h)
        renders = {"jaxgfx": H.JaxgfxRender(desc, spp=16, integrator="direct", max_depth=None)}
        if mi is not None:
            renders["mitsuba"] = H.MitsubaRender(mi, desc, spp=16, integrator={"type": "direct"})
            # Mitsuba's path tracer at depth 2: the same estimator (emitter + BSDF sample, MIS)
            renders["mitsuba_path_depth2"] = H.MitsubaRender(mi, desc, spp=16, integrator="direct")
        res = H.interleave(renders, repeats=repeats)
        j = res["jaxgfx"]["samples_per_s"] / 1e6
        m = res["mitsuba"]["samples_per_s"] / 1e6 if "mitsuba" in res else None
        unreliable = None if mi is None else H.mitsuba_suspect(res["mitsuba"])
        raw["direct"].append({"width": w, "height": h, "spp": 16, **res})
        _log(json.dumps(raw["direct"][-1]))
        rows.append(_row(
            "direct_analytic", f"two spheres, {w}×{h}, direct, 16 spp (Mitsuba `direct`)",
            jaxgfx=j, mitsuba=m, ratio=None if m is None else j / m,
            jaxgfx_text=f"{j:.3g} M samples/s",
            mitsuba_text=None if m is None else f"{m:.3g} M samples/s",
            unreliable_because=unreliable, load_avg=load, **_harness_conditions(res),
        ))  # fmt: skip
    return rows, raw


# -------------------------------------------------------------------------------------------
# 2. compile


def fast_compile_variant() -> str:
    """``benchmarks.render_compile``'s variant name for ``jaxgfx.optim.FAST_COMPILE_OPTIONS``
    (what ``optimizer.fast_compile: true`` compiles the step with)."""
    from benchmarks.render_compile import COMPILER_VARIANTS
    from jaxgfx.optim import FAST_COMPILE_OPTIONS

    names = [n for n, o in COMPILER_VARIANTS.items() if o.items() <= FAST_COMPILE_OPTIONS.items()]
    got = {k: v for n in names for k, v in COMPILER_VARIANTS[n].items()}
    if got != dict(FAST_COMPILE_OPTIONS):
        raise RuntimeError(f"no render_compile variant spells FAST_COMPILE_OPTIONS ({got})")
    return "+".join(names)


def cold_fit(*, fast_compile: bool = False, steps: int | None = None) -> dict:
    """Wall seconds of ``jaxgfx fit configs/inverse_material.yaml`` in a subprocess with the
    compilation cache off (``JAXGFX_CACHE_DIR=off``) to a temporary ``--out``; with
    ``fast_compile`` a copy of the config with ``optimizer.fast_compile: true``. Also the
    run's own ``compile_seconds`` / ``target_seconds`` / ``seconds`` (its result.json)."""
    import yaml

    from jaxgfx.config import read_yaml

    with tempfile.TemporaryDirectory(prefix="jaxgfx_fitloop_fit_") as tmp:
        cfg = CONFIG
        if fast_compile:
            data = copy.deepcopy(read_yaml(CONFIG))
            data["scene"] = os.path.join(os.path.dirname(CONFIG), data["scene"])
            data["optimizer"] = {**data["optimizer"], "fast_compile": True}
            cfg = os.path.join(tmp, "inverse_material_fast.yaml")
            with open(cfg, "w", encoding="utf-8") as fh:
                yaml.safe_dump(data, fh)
        out = os.path.join(tmp, "out")
        env = dict(os.environ, JAXGFX_CACHE_DIR="off")
        env["PYTHONPATH"] = os.pathsep.join([ROOT, env.get("PYTHONPATH", "")])
        cmd = [sys.executable, "-m", "jaxgfx.cli", "fit", cfg, "--out", out, "--quiet"]
        if steps is not None:
            cmd += ["--steps", str(steps)]
        t = time.perf_counter()
        p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=ROOT)
        wall = time.perf_counter() - t
        if p.returncode != 0:
            raise SystemExit(f"jaxgfx fit failed:\n{p.stderr[-3000:]}")
        with open(os.path.join(out, "result.json"), encoding="utf-8") as fh:
            res = json.load(fh)
    return {
        "wall_s": wall,
        "fast_compile": fast_compile,
        "compile_seconds": res.get("compile_seconds"),
        "target_seconds": res.get("target_seconds"),
        "steps_seconds": res.get("seconds"),
        "params": res.get("params"),
        "last_line": p.stdout.strip().splitlines()[-1] if p.stdout.strip() else "",
    }


def section_compile(mi, *, quick: bool):
    from benchmarks import render_compile as RC

    rows, raw = [], {"fit_step": {}, "cold_fit": {}, "grad_ratio": {}}
    labels = (("default", "default"),) if quick else (
        ("default", "default"), ("fast_compile", fast_compile_variant()))  # fmt: skip
    for label, variant in labels:
        with Probe() as p:
            r = RC.run_variant(variant)
        raw["fit_step"][label] = r
        _log("fit step", label, json.dumps(r)[:400])
        total = r["trace_s"] + r["lower_s"] + r["compile_s"]
        cpu = r["trace_cpu_s"] + r["lower_cpu_s"] + r["compile_cpu_s"]
        rows.append(_row(
            "fit_step_compile", f"fit step, {label} (fresh process, cache off)", jaxgfx=total,
            jaxgfx_text=f"{total:.1f} s (trace {r['trace_s']:.1f} + lower {r['lower_s']:.1f} + "
                        f"XLA {r['compile_s']:.1f})",
            notes=[f"process CPU {cpu:.1f} s"], probe=p,
        ))  # fmt: skip
    for label, fast in (("default", False),) if quick else (("default", False),
                                                             ("fast_compile", True)):  # fmt: skip
        with Probe() as p:
            r = cold_fit(fast_compile=fast)
        raw["cold_fit"][label] = r
        _log("cold fit", label, json.dumps(r))
        rows.append(_row(
            "fit_cold_wall", f"`jaxgfx fit`, {label}, JAXGFX_CACHE_DIR=off", jaxgfx=r["wall_s"],
            jaxgfx_text=f"{r['wall_s']:.1f} s (step compile {r['compile_seconds']:.1f}, "
                        f"target {r['target_seconds']:.1f}, steps {r['steps_seconds']:.1f})",
            probe=p,
        ))  # fmt: skip
    probes = {}
    for kind in ("forward", "grad_ad", "grad_replay"):
        with Probe() as p:
            raw["grad_ratio"][kind] = RC.run_variant(f"grad_ratio:{kind}")
        probes[kind] = p
        _log("grad ratio", kind, json.dumps(raw["grad_ratio"][kind]))
    g = raw["grad_ratio"]

    def total(k):
        return g[k]["trace_lower_s"] + g[k]["compile_s"]

    def cpu_total(k):
        return g[k]["trace_lower_cpu_s"] + g[k]["compile_cpu_s"]

    fwd = total("forward")
    case = "two spheres, path depth 4, 64², 64 spp (fresh process, cache off)"
    rows.append(_row(
        "forward_compile", "forward render: " + case, jaxgfx=fwd,
        jaxgfx_text=f"{fwd:.1f} s (trace + lower {g['forward']['trace_lower_s']:.1f} + XLA "
                    f"{g['forward']['compile_s']:.1f})",
        notes=[f"process CPU {cpu_total('forward'):.1f} s"], probe=probes["forward"],
    ))  # fmt: skip
    for kind, name in (("grad_ad", "AD"), ("grad_replay", "path replay")):
        xla = g[kind]["compile_s"] / g["forward"]["compile_s"]
        by_cpu = cpu_total(kind) / cpu_total("forward")
        rows.append(_row(
            "grad_compile_ratio", f"jit(grad) d mean / d alpha, {name}: " + case,
            jaxgfx=total(kind), ratio=total(kind) / fwd,
            jaxgfx_text=f"{total(kind):.1f} s against the forward's {fwd:.1f} s",
            notes=[f"XLA only {xla:.2f}×", f"by process CPU {by_cpu:.2f}×"], probe=probes[kind],
        ))  # fmt: skip
    return rows, raw


# -------------------------------------------------------------------------------------------
# 3. gradient vs forward time, memory


def mitsuba_grad_over_forward(mi, desc, *, spp: int, max_depth: int = 4, repeats: int = 3):
    """Mitsuba 3's ``prb`` on ``desc`` (``to_mitsuba_dict``): seconds of the gradient of the
    image mean w.r.t. the metal's alpha (render with the parameter's gradient enabled,
    ``dr.backward``, the gradient evaluated) against the same scene's forward render (the
    parameter without gradient) and Mitsuba's ``path`` forward, interleaved in the harness
    (warm, a new seed per call, synchronised); the harness rows plus ``grad_over_forward``."""
    import numpy as np

    from benchmarks import _render_harness as H

    class PrbCall(H.MitsubaRender):
        def __init__(self, grad):
            super().__init__(
                mi, desc, spp=spp, integrator={"type": "prb", "max_depth": int(max_depth)}
            )
            self.params = mi.traverse(self.scene)
            self.key = next(k for k in self.params.keys() if k.endswith("alpha.value"))
            self.a0 = float(np.array(self.params[self.key]).ravel()[0])
            self.grad, self.last_grad = grad, None
            self.info = {**self.info, "integrator": "prb", "param": self.key}

        def call(self, seed):
            dr = self.dr
            a = mi.Float(self.a0)
            if self.grad:
                dr.enable_grad(a)
            self.params[self.key] = a
            self.params.update()
            img = mi.render(self.scene, self.params, spp=self.spp, seed=int(seed))
            if self.grad:
                dr.backward(dr.mean(img, axis=None))
                g = dr.grad(a)
                dr.eval(g)
                self.last_grad = float(np.array(g).ravel()[0])
            dr.eval(img)
            dr.sync_thread()
            return img

    renders = {"forward": PrbCall(False), "grad": PrbCall(True),
               "forward_path": H.MitsubaRender(mi, desc, spp=spp, max_depth=max_depth)}  # fmt: skip
    res = H.interleave(renders, repeats=repeats)
    res["grad"]["d_mean_d_alpha"] = renders["grad"].last_grad
    res["grad_over_forward"] = res["grad"]["time_s"] / res["forward"]["time_s"]
    res["grad_over_path_forward"] = res["grad"]["time_s"] / res["forward_path"]["time_s"]
    return res


def section_gradient(mi, *, quick: bool):
    from benchmarks import _render_harness as H
    from benchmarks import gradients as G

    res, spp, repeat = (32, 16, 3) if quick else (64, 16, 5)
    raw = {}
    with Probe() as p:
        raw["jaxgfx"] = G.replay(res=res, spp=spp, depths=[4], repeat=repeat,
                                 recompute_depths=())  # fmt: skip
    d4 = raw["jaxgfx"]["depth_4"]
    m = None
    if mi is not None:
        with Probe() as pm:
            m = mitsuba_grad_over_forward(mi, H.two_spheres_desc(res, res), spp=spp,
                                          repeats=repeat)  # fmt: skip
        m["conditions"] = pm.block
        raw["mitsuba_prb"] = m
        _log("mitsuba prb", json.dumps(m))
    rows = []
    fwd = d4["forward"]["time_s"]
    case = f"two spheres (GGX metal), path depth 4, {res}², {spp} spp"
    for kind, name in (("grad_ad", "AD"), ("grad_replay", "path replay")):
        t = d4[kind]["time_s"]
        mt = None if m is None else m["grad_over_forward"]
        rows.append(_row(
            "grad_time_ratio", f"{name}, {case}", jaxgfx=t, mitsuba=mt, ratio=t / fwd,
            jaxgfx_text=f"{t:.4g} s against the forward's {fwd:.4g} s",
            mitsuba_text=None if m is None else (
                f"prb: {m['grad']['time_s']:.4g} s against its forward's "
                f"{m['forward']['time_s']:.4g} s = {mt:.2f}× (the peer's own ratio)"),
            probe=p,
        ))  # fmt: skip
    with Probe() as p:
        raw["memory"] = G.replay_memory(res=32, spp=16, depths=[2, 8], spps=[],
                                        kinds=("grad_replay",))  # fmt: skip
    mb = raw["memory"]["temp_MB_vs_depth"]["grad_replay"]
    rows.append(_row(
        "memory_flat", "path replay jit(grad), XLA temp buffer, 32², 16 spp, depth 2 → 8",
        jaxgfx=mb[8], ratio=mb[8] / mb[2],
        jaxgfx_text=f"{mb[2]:.2f} MB at depth 2, {mb[8]:.2f} MB at depth 8", probe=p,
    ))  # fmt: skip
    return rows, raw


# -------------------------------------------------------------------------------------------
# 4. time to alpha within 2 %


def _child_inverse(system: str, t0: float, steps: int | None) -> dict:
    """In a fresh process: ``benchmarks.inverse.run_jaxgfx`` or ``run_mitsuba`` on the example
    fit; seconds from ``t0`` (the parent's ``time.time()`` just before starting this process)
    to the step after which alpha stays within 2 % (``cold_to_2pct_s``), counting everything
    before the first step (imports, scene, target, compile) and the steps up to it; for
    Mitsuba from the call of ``run_mitsuba`` (it imports mitsuba; the jax / jaxgfx imports of
    this benchmark are not Mitsuba's)."""
    t_enter = time.time() - t0
    from benchmarks import inverse as I

    if system == "jaxgfx":
        from jaxgfx.pipelines.fit import enable_compilation_cache

        cache = enable_compilation_cache()  # as the CLI and benchmarks.inverse do
    else:
        cache = None
    cfg = I.problem_config(steps)
    n = int(cfg["optimizer"]["steps"])
    t_start = time.time() - t0
    t = time.perf_counter()
    if system == "jaxgfx":
        r = I.run_jaxgfx(cfg)
    else:
        r = I.run_mitsuba(cfg, n, int(cfg["render"]["spp"]), float(cfg["optimizer"]["lr"]))
        r.pop("target", None)
    wall = time.perf_counter() - t
    curve = r.pop("curve")
    steps_s = float(curve["seconds"][-1])
    # everything in the call that is not a step (scene, target, compile; and the few ms of
    # bookkeeping after the last step, so an upper bound by those). jaxgfx: from the process's
    # start (its imports are jaxgfx's own cost). Mitsuba: from the call of run_mitsuba, which
    # imports mitsuba itself; the jax / jaxgfx imports this benchmark needs for the scene
    # conversion (``process_to_fit_s``) are not Mitsuba's and are not counted.
    before_steps = (t_start if system == "jaxgfx" else 0.0) + wall - steps_s
    settle = r.get("time_to_2pct_alpha")
    return {
        "system": system, "steps": n, "cache_dir": cache, "process_to_module_s": t_enter,
        "process_to_fit_s": t_start, "fit_call_wall_s": wall, "steps_s": steps_s,
        "before_first_step_s": before_steps,
        "cold_to_2pct_s": None if settle is None else before_steps + settle,
        "process_wall_s": time.time() - t0, **r,
    }  # fmt: skip


def _run_inverse_child(system: str, cache_dir: str, steps: int | None) -> dict:
    env = dict(os.environ, JAXGFX_CACHE_DIR=cache_dir)
    env["PYTHONPATH"] = os.pathsep.join([ROOT, env.get("PYTHONPATH", "")])
    cmd = [sys.executable, "-m", "benchmarks.fitloop", "--child", f"inverse_{system}"]
    cmd += ["--t0", repr(time.time())] + ([] if steps is None else ["--steps", str(steps)])
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=ROOT)
    if p.returncode != 0:
        raise SystemExit(f"{system} child failed:\n{p.stderr[-3000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def section_fit(mi, *, quick: bool, steps: int | None = None):
    rows, raw = [], {}
    with tempfile.TemporaryDirectory(prefix="jaxgfx_fitloop_cache_") as cache:
        plan = [("cache_off", "jaxgfx", "off"), ("cache_fill", "jaxgfx", cache),
                ("cache_warm", "jaxgfx", cache)]  # fmt: skip
        if mi is not None:  # a fresh Mitsuba process next to each reported jaxgfx row
            plan.insert(0, ("mitsuba_1", "mitsuba", "off"))
            plan.append(("mitsuba_2", "mitsuba", "off"))
        probes = {}
        for name, system, cdir in plan:
            with Probe() as p:
                raw[name] = _run_inverse_child(system, cdir, steps)
            raw[name]["conditions"] = probes[name] = p.block
            _log("fit", name, json.dumps(raw[name]))
    for name, peer, label in (
        ("cache_off", "mitsuba_1", "cold process, JAX compilation cache off"),
        ("cache_warm", "mitsuba_2", "cold process, JAX persistent cache warm (filled by the "
                                    "process before)"),
    ):  # fmt: skip
        j = raw[name]
        m = raw.get(peer)
        jt, mt = j["cold_to_2pct_s"], None if m is None else m["cold_to_2pct_s"]
        notes = []
        if jt is None:
            notes.append(f"jaxgfx never stays within 2 % in {j['steps']} steps "
                         f"(ends at alpha {j['final_alpha']:.4f})")  # fmt: skip
            if mt:  # a lower bound: the whole run did not get there
                notes.append(f"ratio > {j['process_wall_s'] / mt:.2f}× (its whole run)")
        if m is not None and mt is None:
            notes.append(f"Mitsuba never stays within 2 % (ends at {m['final_alpha']:.4f})")
        settled = (f"{jt:.1f} s" if jt is not None else "never") + (
            f" (whole run {j['process_wall_s']:.1f} s, before the first step "
            f"{j['before_first_step_s']:.1f} s)")  # fmt: skip
        rows.append(_row(
            "time_to_2pct", label, jaxgfx=jt, mitsuba=mt,
            ratio=None if jt is None or mt is None else jt / mt,
            missing_is_unmet=jt is None, jaxgfx_text=settled,
            mitsuba_text=None if m is None else (
                (f"{mt:.1f} s" if mt is not None else "never")
                + f" (fresh process; before the first step {m['before_first_step_s']:.1f} s)"),
            notes=notes, **{k: probes[name][k] for k in ("load_avg", "cpu_s", "cores",
                                                          "other_cores", "wall_s")},
        ))  # fmt: skip
    return rows, raw


SECTION_FUNCS = {
    "throughput": section_throughput,
    "compile": section_compile,
    "gradient": section_gradient,
    "fit": section_fit,
}


# -------------------------------------------------------------------------------------------
# the command


def parse_sections(values) -> list[str]:
    """Section names from ``--sections`` (comma- and/or space-separated), in
    :data:`SECTIONS` order; an unknown name is an error naming it."""
    got = [s.strip() for v in values for s in str(v).split(",") if s.strip()]
    bad = [s for s in got if s not in SECTIONS]
    if bad:
        raise ValueError(f"--sections: unknown {bad} (choose from {', '.join(SECTIONS)})")
    return [s for s in SECTIONS if s in got]


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.fitloop", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: small sizes, fewer cases (a few minutes)")  # fmt: skip
    ap.add_argument("--out", default=None, help="write the whole JSON here (and the table as .md)")
    ap.add_argument("--no-mitsuba", action="store_true", help="jaxgfx only (no peer figures)")
    ap.add_argument("--sections", nargs="+", default=[",".join(SECTIONS)],
                    help=f"subset of {','.join(SECTIONS)} (comma- or space-separated)")  # fmt: skip
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--max-load", type=float, default=1.0,
                   help="refuse to measure when the 1-min load average is above this")  # fmt: skip
    g.add_argument("--allow-load", action="store_true",
                   help="measure above --max-load anyway (rows marked loaded: true)")  # fmt: skip
    ap.add_argument("--steps", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--t0", type=float, default=None, help=argparse.SUPPRESS)
    return ap


def main(argv=None) -> int:
    ap = build_parser()
    a = ap.parse_args(argv)
    if a.child:
        system = a.child.removeprefix("inverse_")
        if system not in ("jaxgfx", "mitsuba"):
            ap.error(f"--child: unknown {a.child!r}")
        print(json.dumps(_child_inverse(system, a.t0 or time.time(), a.steps)), flush=True)
        return 0
    try:
        sections = parse_sections(a.sections)
    except ValueError as e:
        ap.error(str(e))
    from benchmarks import _render_harness as H
    from benchmarks._report import emit, machine

    gate = H.load_gate(a.max_load, refuse=not a.allow_load)
    mi, variant = (None, None) if a.no_mitsuba else H.import_mitsuba()
    doc = {
        "benchmark": "fitloop",
        "machine": machine(mitsuba=None if mi is None else mi.__version__, mitsuba_variant=variant),
        "quick": a.quick,
        "started": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
        "sections": sections,
        "load_gate": gate,
        "section_seconds": {},
        "rows": [],
        "raw": {},
    }
    t_run = time.perf_counter()
    for s in sections:
        t = time.perf_counter()
        _log(f"== {s}")
        rows, raw = SECTION_FUNCS[s](mi, quick=a.quick)
        doc["rows"] += rows
        doc["raw"][s] = raw
        doc["section_seconds"][s] = round(time.perf_counter() - t, 1)
    doc["duration_s"] = round(time.perf_counter() - t_run, 1)
    doc["load_avg_after"] = [round(x, 2) for x in os.getloadavg()]
    finish_rows(doc["rows"], loaded=gate["loaded"])
    table = table_markdown(doc["rows"]) + "\n\n" + run_caption(doc)
    doc["table_markdown"] = table
    emit(doc, a.out, printed={k: v for k, v in doc.items() if k not in ("raw", "table_markdown")})
    print("\n" + table, flush=True)
    if a.out:
        with open(os.path.splitext(a.out)[0] + ".md", "w", encoding="utf-8") as fh:
            fh.write(table + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
