"""One way to time a render, for jaxgfx and Mitsuba 3 alike (every render benchmark uses it).

Both systems are timed the way a user runs them: warm (a first call, reported separately as
``first_call_s`` and ``compile_s`` = first call minus the warm median), wall clock, both on all
cores (XLA's and Dr.Jit's default thread pools), a **new seed / key per call**, the result
synchronised (jaxgfx: ``block_until_ready``; Mitsuba: ``dr.eval`` + ``dr.sync_thread``),
median of ``repeats >= 3`` warm calls, interleaved round-robin with the other system so that a
change of the machine's load hits both alike. For each call the harness also records the
process CPU seconds (``time.process_time``: all threads of this process) and, on Linux, the
CPU seconds that *other* processes used meanwhile (``/proc/stat`` busy time minus ours), so a
contended measurement is visible in its own row (``other_cores``: other processes' CPU seconds
per wall second).

Both renderers get the same scene description (jaxgfx ``load_scene(desc)``; Mitsuba
``mi.load_dict(to_mitsuba_dict(desc))``). Mitsuba's figure is checked against its known
throughput (:data:`MITSUBA_MIN_SAMPLES_PER_CORE`): a figure far below it means that Mitsuba
was starved (load, thread pool, a per-call overhead at a tiny size) and the row is flagged
``mitsuba_suspect`` instead of reported as a ratio worth believing. :func:`load_gate` refuses
(or flags) a run that starts above a load threshold; the lead re-runs published tables on a
quiet machine.
"""

from __future__ import annotations

import copy
import os
import sys
import time

import jax
import numpy as np

__all__ = [
    "LLVM19",
    "MITSUBA_MIN_SAMPLES_PER_CORE",
    "cpu_seconds_of_others",
    "load_gate",
    "import_mitsuba",
    "JaxgfxRender",
    "MitsubaRender",
    "interleave",
    "compare",
    "blob_mesh_desc",
    "two_spheres_desc",
]

LLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"

MITSUBA_MIN_SAMPLES_PER_CORE = {"llvm": 2.0e6, "scalar": 0.3e6}
"""Lower bounds of Mitsuba 3's path-tracing throughput per core (samples/s, depth <= 5) below
which its figure is not believed. Measured on this project's 2-core box, quiet: ``llvm_ad_rgb``
3.5-6 M samples/s per thread on the shipped scenes (issue 22: 9.4-12 M/s on two spheres, 7-9 M/s
on a 5 k-triangle mesh, both cores); ``scalar_rgb`` ~1 M/s (955 ns per depth-3 sample,
docs/performance.md). The old mesh table's 174-264 k/s (load 20) is 8-10x below the bound."""


def _log(*a):
    print(*a, file=sys.stderr, flush=True)


# -------------------------------------------------------------------------------------------
# the machine


def _proc_stat_busy() -> float | None:
    """Seconds of CPU time all processes have used (``/proc/stat``, Linux), else ``None``."""
    try:
        with open("/proc/stat", encoding="ascii") as fh:
            f = fh.readline().split()
    except OSError:
        return None
    ticks = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    user, nice, system, _idle, _iowait, irq, softirq, steal = (int(x) for x in f[1:9])
    return (user + nice + system + irq + softirq + steal) / ticks


def cpu_seconds_of_others(busy0, cpu0, busy1, cpu1) -> float | None:
    """CPU seconds other processes used between two ``(_proc_stat_busy(), process_time())``
    readings (``None`` where ``/proc/stat`` is missing); clock-tick resolution (10 ms)."""
    if busy0 is None or busy1 is None:
        return None
    return max((busy1 - busy0) - (cpu1 - cpu0), 0.0)


def load_gate(max_load: float | None, *, refuse: bool = True) -> dict:
    """The 1/5/15-minute load average now and whether it is above ``max_load`` (``None``: no
    limit). Above it: ``SystemExit`` when ``refuse``, else the block says ``"loaded": true``.
    Call it before measuring (the load average then is the other jobs', not this run's)."""
    load = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    loaded = bool(max_load is not None and load is not None and load[0] > max_load)
    if loaded and refuse:
        raise SystemExit(
            f"load average {load[0]:.2f} > {max_load}: the machine is shared; timings would "
            "measure the other jobs (pass --max-load to raise the limit, --allow-load to "
            "measure anyway with the rows flagged)"
        )
    return {
        "load_avg": None if load is None else [round(x, 2) for x in load],
        "max_load": max_load,
        "loaded": loaded,
    }


# -------------------------------------------------------------------------------------------
# the two renderers


def import_mitsuba(variant_pref=("llvm_ad_rgb", "scalar_rgb")):
    """Import mitsuba with the first working variant of ``variant_pref``: ``(mi, variant)`` or
    ``(None, None)``. Sets ``DRJIT_LIBLLVM_PATH`` to Debian's ``libLLVM.so.19.1`` when that
    exists and the variable is unset (``apt-get install libllvm19``)."""
    if any(v.startswith("llvm") for v in variant_pref) and "DRJIT_LIBLLVM_PATH" not in os.environ:
        if os.path.exists(LLVM19):
            os.environ["DRJIT_LIBLLVM_PATH"] = LLVM19
    try:
        import mitsuba as mi
    except ImportError:
        return None, None
    for v in variant_pref:
        if v not in mi.variants():
            continue
        try:
            mi.set_variant(v)
            if v.startswith("llvm"):  # Dr.Jit only fails when the backend is first used
                mi.load_dict({"type": "scene"})
                x = mi.Float(1.0) + 1.0
                mi.Float(x).numpy()
            return mi, v
        except Exception as e:  # pragma: no cover - depends on the installation
            _log(f"mitsuba variant {v} unavailable: {e}")
    return None, None


class JaxgfxRender:
    """``call(seed)``: ``render(scene, key(seed), ...)`` of a loaded description, synchronised
    (``block_until_ready``); ``render`` is jitted, the first call compiles."""

    system = "jaxgfx"

    def __init__(self, desc, *, spp, integrator="path", max_depth=4, accel=None, **options):
        from jaxgfx.render.render import render
        from jaxgfx.render.scene import load_scene

        t = time.perf_counter()
        self.scene = jax.block_until_ready(
            load_scene(desc) if accel is None else load_scene(desc, accel=accel)
        )
        self.load_s = time.perf_counter() - t
        self.samples = int(self.scene.width) * int(self.scene.height) * int(spp)
        self._render = render
        self._kw = dict(spp=spp, integrator=integrator, **options)
        if max_depth is not None:  # None: an integrator object carries its own
            self._kw["max_depth"] = max_depth
        self.info = {"accel": self.scene.accel}

    def call(self, seed):
        img = self._render(self.scene, jax.random.key(seed), **self._kw)
        return jax.block_until_ready(img)

    def mean(self, img):
        return float(np.asarray(img, np.float64)[..., :3].mean())


class MitsubaRender:
    """``call(seed)``: ``mi.render(scene, spp=spp, seed=seed)`` of the same description
    (``to_mitsuba_dict``), evaluated and synchronised (``dr.eval``, ``dr.sync_thread``).
    ``integrator``: a jaxgfx name (``mitsuba_integrator(integrator, max_depth=...)``) or a
    Mitsuba integrator dict used as it is (e.g. ``{"type": "direct"}``, Mitsuba's own)."""

    system = "mitsuba"

    def __init__(self, mi, desc, *, spp, integrator="path", max_depth=4):
        import drjit as dr

        from jaxgfx.render.scene.mitsuba import mitsuba_integrator, to_mitsuba_dict

        t = time.perf_counter()
        d = to_mitsuba_dict(desc, mi=mi)
        d["integrator"] = (
            dict(integrator)
            if isinstance(integrator, dict)
            else mitsuba_integrator(integrator, max_depth=max_depth)
        )
        d["sensor"]["sampler"]["sample_count"] = spp
        self.scene = mi.load_dict(d)
        self.load_s = time.perf_counter() - t
        self.mi, self.dr, self.spp = mi, dr, int(spp)
        self.samples = int(desc["camera"]["width"]) * int(desc["camera"]["height"]) * self.spp
        self.variant = mi.variant()
        self.threads = int(dr.thread_count()) if hasattr(dr, "thread_count") else None
        self.info = {"variant": self.variant, "threads": self.threads}

    def call(self, seed):
        img = self.mi.render(self.scene, spp=self.spp, seed=int(seed))
        self.dr.eval(img)
        self.dr.sync_thread()
        return img

    def mean(self, img):
        return float(np.asarray(img, np.float64)[..., :3].mean())


# -------------------------------------------------------------------------------------------
# timing


def _timed(fn, seed):
    b0, c0, t0 = _proc_stat_busy(), time.process_time(), time.perf_counter()
    out = fn(seed)
    t1, c1, b1 = time.perf_counter(), time.process_time(), _proc_stat_busy()
    return out, t1 - t0, c1 - c0, cpu_seconds_of_others(b0, c0, b1, c1)


def interleave(renders: dict, *, repeats: int = 3, seed0: int = 1000) -> dict:
    """Time each of ``renders`` (``{name: obj with .call(seed), .samples, .load_s, .mean}``):
    one first call each (compilation, Mitsuba's kernel JIT), then ``repeats`` rounds calling
    each once in turn with a new seed per call. Returns ``{name: row}`` with ``first_call_s``,
    ``compile_s`` (first minus warm median), ``time_s`` (median wall), ``cpu_s`` (median
    process CPU), ``cores`` (cpu / wall), ``other_cores`` (median CPU seconds of other processes
    per wall second), ``samples_per_s`` (samples / median wall), ``mean`` (image mean of the
    first call), ``load_s``."""
    if repeats < 3:
        raise ValueError(f"repeats: medians of at least 3 calls, got {repeats}")
    first, walls, cpus, others = {}, {n: [] for n in renders}, {n: [] for n in renders}, {}
    means = {}
    for name, r in renders.items():
        img, wall, cpu, _ = _timed(r.call, seed0)
        first[name] = (wall, cpu)
        means[name] = r.mean(img)
        others[name] = []
    seed = seed0
    for _ in range(repeats):
        for name, r in renders.items():
            seed += 1
            _, wall, cpu, oth = _timed(r.call, seed)
            walls[name].append(wall)
            cpus[name].append(cpu)
            if oth is not None:
                others[name].append(oth / wall)
    out = {}
    for name, r in renders.items():
        w, c = float(np.median(walls[name])), float(np.median(cpus[name]))
        out[name] = {
            **getattr(r, "info", {}),
            "load_s": round(r.load_s, 3),
            "first_call_s": round(first[name][0], 3),
            "compile_s": round(max(first[name][0] - w, 0.0), 3),
            "time_s": round(w, 5),
            "cpu_s": round(c, 5),
            "cores": round(c / w, 2),
            "other_cores": round(float(np.median(others[name])), 2) if others[name] else None,
            "samples_per_s": round(r.samples / w),
            "mean": means[name],
        }
    return out


def mitsuba_suspect(row: dict, cores: int | None = None) -> str | None:
    """Why Mitsuba's figure in ``row`` (an :func:`interleave` row) is not believed, or ``None``:
    below :data:`MITSUBA_MIN_SAMPLES_PER_CORE` times the cores it ran on."""
    kind = "llvm" if str(row.get("variant", "")).startswith("llvm") else "scalar"
    n = row.get("threads") or cores or os.cpu_count() or 1
    if kind == "scalar":
        n = 1  # scalar variants render on one thread per pixel block; be lenient
    bound = MITSUBA_MIN_SAMPLES_PER_CORE[kind] * n
    if row["samples_per_s"] < bound:
        return (
            f"Mitsuba {row['samples_per_s'] / 1e6:.2f} M samples/s < {bound / 1e6:.1f} M "
            f"({kind}, {n} threads): starved or per-call overhead; ratio not reliable"
        )
    return None


def compare(desc, *, mi=None, spp, integrator="path", max_depth=4, repeats=3, accel=None,
            jaxgfx_options=None) -> dict:  # fmt: skip
    """jaxgfx and (when ``mi`` is given) Mitsuba 3 on the same description, interleaved: a row
    ``{"jaxgfx": ..., "mitsuba": ..., "mitsuba_over_jaxgfx": ..., "mitsuba_suspect": ...}``."""
    renders = {
        "jaxgfx": JaxgfxRender(
            desc, spp=spp, integrator=integrator, max_depth=max_depth, accel=accel,
            **(jaxgfx_options or {}),
        )  # fmt: skip
    }
    if mi is not None:
        renders["mitsuba"] = MitsubaRender(
            mi, desc, spp=spp, integrator=integrator, max_depth=max_depth
        )
    res = interleave(renders, repeats=repeats)
    row = {"spp": spp, "integrator": integrator, "max_depth": max_depth, **res}
    if mi is not None:
        row["mitsuba_over_jaxgfx"] = round(
            res["mitsuba"]["samples_per_s"] / res["jaxgfx"]["samples_per_s"], 2
        )
        row["mitsuba_suspect"] = mitsuba_suspect(res["mitsuba"])
    return row


# -------------------------------------------------------------------------------------------
# the scenes of issue 22's table

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def two_spheres_desc(width, height):
    """``configs/scenes/inverse.yaml`` (GGX metal + diffuse sphere, floor, area light +
    constant environment) at ``width x height``."""
    from jaxgfx.config import read_yaml

    d = copy.deepcopy(read_yaml(os.path.join(ROOT, "configs", "scenes", "inverse.yaml")))
    d["camera"]["width"], d["camera"]["height"] = int(width), int(height)
    return d


def blob_mesh_desc(tmp_dir, width, height, *, level=4, seed=3):
    """A ``20 * 4**level``-triangle blob (5 120 at level 4) written as an OBJ into ``tmp_dir``
    (both renderers load the same file), a Beckmann rough conductor, on a diffuse floor, lit by
    a point light and an area light; ``(desc, n_triangles)``."""
    from jaxgfx.render.geometry.mesh_io import make_blob, save_obj

    m = make_blob(level, seed=seed, radius=0.5, center=(-0.15, 0.59, 0.0))
    path = os.path.join(tmp_dir, f"blob_{level}_{seed}.obj")
    save_obj(path, m)
    desc = {
        "camera": {"origin": [0, 1.4, 4.0], "target": [0, 0.6, 0], "up": [0, 1, 0], "fov": 45,
                   "width": int(width), "height": int(height)},  # fmt: skip
        "shapes": [
            {"type": "mesh", "file": path, "material": "metal"},
            {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 1, 0], "size": [10, 10],
             "material": "floor"},  # fmt: skip
        ],
        "materials": {
            "metal": {"type": "roughconductor", "distribution": "beckmann", "alpha": 0.3,
                      "eta": [0.2, 0.92, 1.1], "k": [3.9, 2.45, 2.14]},  # fmt: skip
            "floor": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]},
        },
        "emitters": [
            {"type": "area", "radiance": [10, 10, 10],
             "shape": {"type": "rectangle", "center": [0, 4, 1], "normal": [0, -1, 0],
                       "size": [2, 2]}},  # fmt: skip
            {"type": "point", "position": [2, 3, 2], "intensity": [20, 20, 20]},
        ],
    }
    return desc, int(m.faces.shape[0])
