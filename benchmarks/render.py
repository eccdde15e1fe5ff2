"""Renderer benchmark: samples/s of jaxgfx vs Mitsuba 3, compile time, equal-time error.

    python -m benchmarks.render [--quick] [--out FILE] [--plot DIR] [--ref-cache DIR]
                                [--no-mitsuba | --mitsuba-variant scalar_rgb]
                                [--sections ratios,speed,mesh,features,equal_time]
                                [--max-load 1.0 | --allow-load]

0. Ratios (issue 22's table; ``--sections ratios`` prints only it): path tracing, max_depth 4,
   16 spp, the two spheres of ``configs/scenes/inverse.yaml`` at 96x72 and 384x288 and a
   5 120-triangle blob mesh (OBJ, Beckmann conductor, point + area light, ``accel="auto"``) at
   80x64 and 320x256. Every timing in this script goes through ``benchmarks/_render_harness.py``:
   jaxgfx and Mitsuba interleaved in one process, warm, wall clock, all cores, a new seed per
   call, synchronised, medians of 3, process CPU and other processes' CPU recorded, Mitsuba's
   figure checked against its known throughput; the run refuses to start above
   ``--max-load``. ``passes`` (not a default section): interleaved A/B of the estimator's
   layout on the same scenes, one sample pass per scan step (before issue 22) against several
   (now), and several without wavefront shading (``PathIntegrator(chunk=None)``), with
   Mitsuba in the same round-robin, medians of 5. ``mesh_profile`` (not a default section):
   the Embree callbacks' share of a mesh render (5 k-triangle blob, 320x256, 16 spp, depth 4).

1. Speed. Scenes: ``configs/scenes/example.yaml`` at 128^2 and 256^2 with ``direct`` and
   ``path`` (max_depth 3), and a 99 224-triangle mesh scene (a UV sphere written as a PLY to a
   temporary folder, so both renderers load the same file) at 128^2, path depth 3, 4 spp (the
   others 16; ``--quick``: 4 spp, 128^2 only, a 6 240-triangle sphere). ``compile_s`` = first
   call minus the warm median; samples/s = W H spp / median. Mitsuba 3 renders the same scenes
   through :func:`jaxgfx.render.scene.mitsuba.to_mitsuba_dict` in ``llvm_ad_rgb`` when it
   works (sets ``DRJIT_LIBLLVM_PATH`` to Debian's ``libLLVM.so.19.1`` if present and unset),
   otherwise ``scalar_rgb``.
2. Equal-time error at 64^2 (example scene without its point light: a delta light cannot be
   reached by BSDF sampling, which would make that strategy biased): RMSE against a 4096-spp
   jaxgfx MIS reference (cached as .npy in ``--ref-cache``, default the system temp folder) vs
   seconds (m x the median time of one 4-spp call), for light sampling only, BSDF sampling
   only and MIS (power heuristic), at spp = 4 m, m = 1, 2, 4, ...: the library's
   ``render(..., strategy="light" | "bsdf" | "mis")``.

Prints one JSON document (progress to stderr); ``--plot DIR`` writes ``speed_vs_error.png``.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import sys
import tempfile
import time

import jax
import numpy as np

from benchmarks import _render_harness as H
from benchmarks._report import emit, machine
from benchmarks._timing import median_time
from jaxgfx.config import read_yaml
from jaxgfx.render.geometry.mesh_io import make_uv_sphere, save_ply
from jaxgfx.render.integrators import PathIntegrator
from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "configs", "scenes", "example.yaml")
LLVM19 = H.LLVM19


def _log(*a):
    print(*a, file=sys.stderr, flush=True)


def _with_res(desc, w, h=None):
    d = copy.deepcopy(desc)
    d["camera"]["width"], d["camera"]["height"] = int(w), int(h or w)
    return d


def mesh_scene(tmp_dir, n_rings=158, res=128):
    """Scene around a ``4 n (n - 1)``-triangle UV sphere (99 224 for n = 158) saved as PLY."""
    path = os.path.join(tmp_dir, f"sphere_{n_rings}.ply")
    m = make_uv_sphere(n_rings, radius=1.0, center=(0.0, 1.0, 0.0))
    save_ply(path, m)
    desc = read_yaml(EXAMPLE)
    desc = _with_res(desc, res)
    desc["shapes"][0] = {"type": "mesh", "file": path, "material": "metal"}
    return desc, int(m.faces.shape[0])


# -------------------------------------------------------------------------------------------
# speed


def bench_jaxgfx(desc, *, spp, integrator, max_depth, repeat):
    """jaxgfx alone through the harness (warm median of ``max(repeat, 3)`` calls, new key per
    call, process CPU); the row of :func:`benchmarks._render_harness.interleave`."""
    r = H.JaxgfxRender(desc, spp=spp, integrator=integrator, max_depth=max_depth)
    return H.interleave({"jaxgfx": r}, repeats=max(repeat, 3))["jaxgfx"]


def _mitsuba(variant_pref):
    """Import mitsuba with the first working variant of ``variant_pref``; (mi, variant)."""
    return H.import_mitsuba(tuple(variant_pref))


def ratios(mi, *, repeats=3, quick=False):
    """Issue 22's table: samples/s of jaxgfx and Mitsuba 3 on the same descriptions, path
    tracing, ``max_depth`` 4, 16 spp, interleaved in this process: the two spheres of
    ``configs/scenes/inverse.yaml`` at 96x72 and 384x288, a 5 120-triangle blob (OBJ, Beckmann
    conductor, floor, point + area light; ``accel="auto"``) at 80x64 and 320x256."""
    rows = []
    sizes = {"two_spheres": ((96, 72),) if quick else ((96, 72), (384, 288)),
             "mesh_5k": ((80, 64),) if quick else ((80, 64), (320, 256))}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="jaxgfx_bench_ratios_") as tmp:
        for name, res in sizes.items():
            for w, h in res:
                if name == "two_spheres":
                    desc, extra = H.two_spheres_desc(w, h), {}
                else:
                    desc, n_tri = H.blob_mesh_desc(tmp, w, h)
                    extra = {"triangles": n_tri}
                row = {"scene": name, "width": w, "height": h, **extra}
                row.update(H.compare(desc, mi=mi, spp=16, max_depth=4, repeats=repeats))
                rows.append(row)
                _log(json.dumps(row))
    return rows


class _OnePassPerStep(H.JaxgfxRender):
    """The estimator's layout before issue 22 (one sample pass per scan step), same scene,
    same numbers per sample: the A of the ``passes`` section's A/B."""

    def __init__(self, desc, *, spp, integrator="path", max_depth=4):
        import equinox as eqx

        from jaxgfx.render.estimator import render_partial, resolve_integrator

        super().__init__(desc, spp=spp, integrator=integrator, max_depth=max_depth)
        integ = resolve_integrator(integrator, max_depth=max_depth)
        self._fn = eqx.filter_jit(
            lambda sc, k: render_partial(sc, k, integ, spp=spp, rays_per_step=None) / spp
        )

    def call(self, seed):
        return jax.block_until_ready(self._fn(self.scene, jax.random.key(seed)))


def passes_ab(mi, *, repeats=3, quick=False):
    """Interleaved A/B of the estimator's layout on the ratios scenes: one sample pass per scan
    step (before) against ``passes_per_step`` passes per step (now), with Mitsuba 3 in the same
    round-robin; also the largest |difference| of the two images for one key."""
    rows = []
    sizes = {"two_spheres": ((96, 72),) if quick else ((96, 72), (384, 288)),
             "mesh_5k": ((80, 64),) if quick else ((80, 64), (320, 256))}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="jaxgfx_bench_passes_") as tmp:
        for name, res in sizes.items():
            for w, h in res:
                if name == "two_spheres":
                    desc = H.two_spheres_desc(w, h)
                else:
                    desc, _ = H.blob_mesh_desc(tmp, w, h)
                renders = {
                    "one_pass_per_step": _OnePassPerStep(desc, spp=16, max_depth=4),
                    "grouped": H.JaxgfxRender(desc, spp=16, max_depth=4),
                    # the same without wavefront shading, which a batch of >= 2 chunks turns on
                    "grouped_no_wavefront": H.JaxgfxRender(
                        desc, spp=16, max_depth=None,
                        integrator=PathIntegrator(max_depth=4, chunk=None),
                    ),  # fmt: skip
                }
                if mi is not None:
                    renders["mitsuba"] = H.MitsubaRender(mi, desc, spp=16, max_depth=4)
                row = {"scene": name, "width": w, "height": h, "spp": 16, "max_depth": 4}
                row.update(H.interleave(renders, repeats=repeats))
                a = np.asarray(renders["one_pass_per_step"].call(7))
                b = np.asarray(renders["grouped"].call(7))
                row["max_abs_diff"] = float(np.abs(a - b).max())
                row["bit_identical"] = bool(np.array_equal(a, b))
                row["speedup"] = round(
                    row["grouped"]["samples_per_s"] / row["one_pass_per_step"]["samples_per_s"], 2
                )
                rows.append(row)
                _log(json.dumps(row))
    return rows


def mesh_profile(*, width=320, height=256, repeats=3):
    """Where a mesh render's time goes: the 5 120-triangle blob (path, depth 4, 16 spp,
    Embree) with the host side of every Embree ``pure_callback`` timed (closest-hit and
    shadow-ray queries counted and timed separately), against the render's wall time."""
    import collections

    from jaxgfx.render.geometry.accel import embree as E

    stats = collections.defaultdict(lambda: [0, 0.0, 0])
    orig = E._EmbreeScene.query

    def timed_query(self, o, d, tmin, tmax, any_hit):
        t = time.perf_counter()
        r = orig(self, o, d, tmin, tmax, any_hit)
        st = stats["shadow" if any_hit else "closest"]
        st[0] += 1
        st[1] += time.perf_counter() - t
        st[2] += int(np.prod(np.shape(o)[:-1]))
        return r

    E._EmbreeScene.query = timed_query
    try:
        with tempfile.TemporaryDirectory(prefix="jaxgfx_bench_meshprof_") as tmp:
            desc, n_tri = H.blob_mesh_desc(tmp, width, height)
            r = H.JaxgfxRender(desc, spp=16, max_depth=4)
            r.call(0)
            stats.clear()
            t, c = time.perf_counter(), time.process_time()
            for i in range(repeats):
                r.call(i + 1)
            wall = (time.perf_counter() - t) / repeats
            cpu = (time.process_time() - c) / repeats
    finally:
        E._EmbreeScene.query = orig
    out = {"triangles": n_tri, "width": width, "height": height, "accel": r.scene.accel,
           "render_wall_s": round(wall, 4), "render_cpu_s": round(cpu, 4)}  # fmt: skip
    for kind, (calls, sec, rays) in stats.items():
        out[kind] = {
            "callbacks_per_render": calls / repeats,
            "seconds_per_render": round(sec / repeats, 4),
            "fraction_of_wall": round(sec / repeats / wall, 3),
            "mrays_per_s_in_callback": round(rays / sec / 1e6, 2),
        }
    return out


# -------------------------------------------------------------------------------------------
# "model only what a scene needs": cost of each feature


def feature_costs(*, res, spp, repeat):
    """ns per direct-lighting sample as scene features are added one at a time: a scene that
    does not use refraction, point lights, an environment or a second material type must not
    pay for them (the integrators compile only what the scene contains)."""
    base = {
        "camera": {
            "origin": [0, 1.5, 5],
            "target": [0, 1, 0],
            "fov": 45,
            "width": res,
            "height": res,
        },
        "shapes": [
            {"type": "sphere", "center": [0, 1, 0], "radius": 1, "material": "floor"},
            {
                "type": "rectangle",
                "center": [0, 0, 0],
                "normal": [0, 1, 0],
                "size": [10, 10],
                "material": "floor",
            },
        ],
        "materials": {"floor": {"type": "diffuse", "reflectance": 0.5}},
        "emitters": [
            {
                "type": "area",
                "radiance": 10.0,
                "shape": {
                    "type": "rectangle",
                    "center": [0, 4, 0],
                    "normal": [0, -1, 0],
                    "size": [2, 2],
                },
            },
        ],
    }
    steps = []
    d = copy.deepcopy(base)
    steps.append(("diffuse + area light", copy.deepcopy(d)))
    d["materials"]["metal"] = {"type": "roughconductor", "alpha": 0.3}
    d["shapes"][0]["material"] = "metal"
    steps.append(("+ rough conductor", copy.deepcopy(d)))
    d["emitters"].append({"type": "point", "position": [2, 3, 1], "intensity": 50.0})
    steps.append(("+ point light", copy.deepcopy(d)))
    d["emitters"].append({"type": "constant", "radiance": 0.1})
    steps.append(("+ constant environment", copy.deepcopy(d)))
    d["materials"]["glass"] = {"type": "dielectric"}
    d["shapes"].append(
        {"type": "sphere", "center": [1.8, 0.5, 1.0], "radius": 0.5, "material": "glass"}
    )
    steps.append(("+ glass sphere (refraction)", copy.deepcopy(d)))
    rows = []
    for name, desc in steps:
        r = bench_jaxgfx(desc, spp=spp, integrator="direct", max_depth=2, repeat=repeat)
        rows.append(
            {
                "scene": name,
                "ns_per_sample": round(1e9 / r["samples_per_s"], 1),
                "compile_s": r["compile_s"],
            }
        )
        _log(json.dumps(rows[-1]))
    return rows


# -------------------------------------------------------------------------------------------
# equal-time error


def make_strategy_renderer(strategy, *, spp, max_depth):
    """``f(scene, key) -> (H, W, 3)``: mean of ``spp`` samples with one direct-light strategy
    (``render(..., strategy=...)``: "mis", "light" or "bsdf")."""

    def f(scene, key):
        return render(
            scene, key, spp=spp, integrator="path", max_depth=max_depth, strategy=strategy
        )

    return f


def equal_time(*, res, max_depth, ref_spp, spp_steps, base_spp, cache_dir):
    desc = _with_res(read_yaml(EXAMPLE), res)
    desc["emitters"] = [e for e in desc["emitters"] if e["type"] != "point"]
    scene = load_scene(desc)
    ref_path = os.path.join(cache_dir, f"jaxgfx_render_ref_{res}_{max_depth}_{ref_spp}.npy")
    if os.path.exists(ref_path):
        ref = np.load(ref_path)
        _log(f"reference from cache {ref_path}")
    else:
        chunk = make_strategy_renderer("mis", spp=64, max_depth=max_depth)
        n = max(ref_spp // 64, 1)
        t = time.perf_counter()
        acc = 0.0
        for i in range(n):
            acc = acc + np.asarray(chunk(scene, jax.random.key(10_000 + i)), np.float64)
        ref = acc / n
        _log(f"reference {n * 64} spp in {time.perf_counter() - t:.1f} s -> {ref_path}")
        os.makedirs(cache_dir, exist_ok=True)
        np.save(ref_path, ref)
    out = {"res": res, "max_depth": max_depth, "ref_spp": ref_spp, "strategies": {}}
    for strategy in ("light", "bsdf", "mis"):
        f = make_strategy_renderer(strategy, spp=base_spp, max_depth=max_depth)
        t = time.perf_counter()
        f(scene, jax.random.key(0)).block_until_ready()
        compile_s = time.perf_counter() - t
        t1 = median_time(lambda f=f: f(scene, jax.random.key(1)), 3)
        rows = []
        for m in spp_steps:
            # error of the mean of m independent calls; cost = m x the median call time
            acc = np.zeros(ref.shape)
            for i in range(m):
                acc += np.asarray(f(scene, jax.random.key(100 + i)), np.float64)
            rmse = float(np.sqrt(np.mean((acc / m - ref) ** 2)))
            rows.append({"spp": m * base_spp, "seconds": round(m * t1, 4), "rmse": rmse})
        out["strategies"][strategy] = {
            "compile_s": round(compile_s - t1, 3),
            "seconds_per_spp": round(t1 / base_spp, 5),
            "rows": rows,
        }
        _log(strategy, json.dumps(rows[-1]))
    return out


def plot(doc, out_dir):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    et = doc["equal_time"]
    fig, ax = plt.subplots(figsize=(5, 4))
    for name, s in et["strategies"].items():
        ax.loglog(
            [r["seconds"] for r in s["rows"]], [r["rmse"] for r in s["rows"]], "o-", label=name
        )
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("seconds (jaxgfx, CPU)")
    ax.set_ylabel(f"RMSE vs {et['ref_spp']}-spp reference")
    ax.set_title(f"example scene (no point light), {et['res']}², path depth {et['max_depth']}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, "speed_vs_error.png")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small spp, 1 repeat, 256-spp reference")
    ap.add_argument("--out", default=None, help="also write the JSON here")
    ap.add_argument("--plot", default=None, help="write speed_vs_error.png into this folder")
    ap.add_argument("--ref-cache", default=tempfile.gettempdir(), help="reference .npy folder")
    ap.add_argument("--no-mitsuba", action="store_true", help="jaxgfx only")
    ap.add_argument(
        "--mitsuba-variant", default=None, help="force a variant (default llvm_ad_rgb, else scalar)"
    )
    ap.add_argument(
        "--sections",
        default="ratios,speed,mesh,features,equal_time",
        help="subset of ratios,speed,mesh,features,equal_time; also passes, mesh_profile",
    )
    ap.add_argument("--max-load", type=float, default=1.0,
                    help="refuse to measure when the 1-min load average is above this")  # fmt: skip
    ap.add_argument("--allow-load", action="store_true",
                    help="measure above --max-load anyway (flagged loaded: true)")  # fmt: skip
    args = ap.parse_args(argv)
    sections = set(args.sections.split(","))
    gate = H.load_gate(args.max_load, refuse=not args.allow_load)

    quick = args.quick
    spp = 4 if quick else 16
    repeat = 3  # medians of at least 3 warm calls, also with --quick
    prefs = [args.mitsuba_variant] if args.mitsuba_variant else ["llvm_ad_rgb", "scalar_rgb"]
    mi, variant = (None, None) if args.no_mitsuba else _mitsuba(prefs)
    doc = {
        "benchmark": "render",
        "machine": machine(mitsuba=None if mi is None else mi.__version__, mitsuba_variant=variant),
        "spp": spp,
        "repeat": repeat,
        "load_gate": gate,
        "speed": [],
    }
    if "ratios" in sections:
        doc["ratios"] = ratios(mi, repeats=repeat, quick=quick)
    if "passes" in sections:  # not in the default sections
        doc["passes_ab"] = passes_ab(mi, repeats=5, quick=quick)
    if "mesh_profile" in sections:  # not in the default sections
        doc["mesh_profile"] = mesh_profile()
    base = read_yaml(EXAMPLE)
    cases = []
    for res in ((128,) if quick else (128, 256)) if "speed" in sections else ():
        for integ in ("direct", "path"):
            cases.append((f"example_{res}", _with_res(base, res), integ))
    with tempfile.TemporaryDirectory(prefix="jaxgfx_bench_render_") as tmp:
        if "mesh" in sections:
            mdesc, n_tri = mesh_scene(tmp, n_rings=40 if quick else 158)
            cases.append((f"mesh_{n_tri}_128", mdesc, "path"))
        for name, desc, integ in cases:
            # the BVH scene is ~100x slower per sample in jaxgfx (while_loop traversal): 4 spp
            spp = 4 if name.startswith("mesh") else doc["spp"]
            row = {
                "scene": name,
                "width": desc["camera"]["width"],
                "integrator": integ,
                "max_depth": 3 if integ == "path" else 2,
                "spp": spp,
            }
            # both systems through the harness, interleaved, new seed per call, synchronised
            row.update(
                H.compare(desc, mi=mi, spp=spp, integrator=integ, max_depth=3, repeats=repeat)
            )
            doc["speed"].append(row)
            _log(json.dumps(row))
    if "features" in sections:
        doc["feature_costs"] = feature_costs(res=128, spp=4 if quick else 16, repeat=repeat)
    if "equal_time" in sections:
        doc["equal_time"] = equal_time(
            res=32 if quick else 64,
            max_depth=3,
            ref_spp=256 if quick else 4096,
            spp_steps=(1, 2, 4) if quick else (1, 2, 4, 8, 16, 32),
            base_spp=4,
            cache_dir=args.ref_cache,
        )
        if args.plot:
            doc["plot"] = plot(doc, args.plot)
    emit(doc, args.out)


if __name__ == "__main__":
    main()
