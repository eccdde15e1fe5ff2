"""Acceleration-structure and traversal-backend benchmark.

    python -m benchmarks.accel [--quick] [--max-exp 5] [--full] [--rays 4096] [--out FILE]
                               [--sections structures,backends,scaling,wavefront] [--plot DIR]

``structures``: the pure-JAX BVH, grid and kd-tree. Scenes are random triangle soups
(``make_triangle_soup``) of 1e2 ... 1e5 triangles (1e6 with ``--full``) whose triangle size
shrinks like N^(-1/3) so the depth complexity stays similar.
For each structure: build seconds (NumPy, host), compile seconds (first call minus a warm call)
and trace time (best of 3 warm calls) -> rays/s. Brute force (JAX, and NumPy as the host peer)
runs up to 1e3 triangles.

``backends``: closest-hit rays/s of the traversal backends (``jaxgfx.render.traversal``) against
Mitsuba 3 ``ray_intersect_preliminary`` (``llvm_ad_rgb`` on one thread and on all threads;
``scalar_rgb`` if LLVM is missing) on UV spheres of 5 040 and 82 368 triangles, 65 536 primary
rays (256^2 pinhole) and 65 536 random rays. jaxgfx rows are end to end from jitted JAX code:
the backend's search plus the differentiable hit record (t, p, normals, uv) recomputed in JAX;
``embree_host`` is embreex alone on NumPy arrays. The JAX BVH traces 4 096 of the rays
(``--backends-jax-rays``). Also reports build seconds and the fraction of rays whose hit and
triangle id agree with Embree.

``scaling``: path-traced samples/s (depth 4, 128^2, 16 spp) of the example scene with its sphere
replaced by a UV-sphere mesh of 1k ... 1M triangles (``--quick``: up to 16k) for each backend and
Mitsuba 3 (same scene through ``to_mitsuba_dict``), with load/build and compile seconds, timed
by ``benchmarks/_render_harness.py`` (interleaved, warm, new seed per call, synchronised,
medians of 3, process CPU; Mitsuba's figure checked against its known throughput);
``--plot DIR`` writes ``samples_vs_triangles.png``. The run refuses to start above
``--max-load`` (default 1.0) unless ``--allow-load``.

``wavefront`` (issue 13, not run by default): closest-hit M rays/s of the JAX BVH traversal, a
2x2 ablation: per-ray ``while_loop`` under ``vmap`` (the traversal before issue 13) or the
wavefront pool, each with the step's leaf/child tests as fused elementwise code or as
reductions; UV spheres of 5 040 and 82 368 triangles, primary and random rays, 16 384 and
65 536 rays (``--wavefront-rays``); wall and process-CPU seconds, compile seconds, agreement of
triangle ids and t with the first variant.

Prints one JSON document (progress rows go to stderr).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks import _render_harness as H
from benchmarks._report import emit, machine
from jaxgfx.render import geometry as S
from jaxgfx.render.geometry import accel as A
from jaxgfx.render.geometry.mesh_io import make_triangle_soup


def _rays(n, seed=0):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-1.5, 1.5, (n, 3))
    d = rng.uniform(-1, 1, (n, 3)) - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return jnp.asarray(o, jnp.float32), jnp.asarray(d, jnp.float32)


@jax.jit
def _trace(acc, o, d):
    h = acc.intersect(o, d)
    return h.t, h.prim_id


@jax.jit
def _brute(mesh, o, d):
    h = S.intersect(mesh, o, d)
    return h.t, h.prim_id


def _numpy_brute(tri, o, d):
    """Vectorised Möller-Trumbore in NumPy (float32), the host peer."""
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    best = np.full(len(o), np.inf, np.float32)
    for i in range(0, len(o), 256):
        oo, dd = o[i : i + 256, None], d[i : i + 256, None]
        P = np.cross(dd, e2)
        det = np.sum(P * e1, -1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            T = oo - v0
            b1 = np.sum(P * T, -1) * inv
            Q = np.cross(T, e1)
            b2 = np.sum(Q * dd, -1) * inv
            t = np.sum(Q * e2, -1) * inv
        ok = (det != 0) & (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > 0)
        best[i : i + 256] = np.where(ok, t, np.inf).min(1)
    return best


def _max_abs(x):
    return float(np.max(np.abs(x), initial=0.0))


def _time_call(fn, *args, repeats=3):
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
    return first - best, best, out


def run(sizes, n_rays, brute_max=1000):
    o, d = _rays(n_rays)
    results = []
    for n in sizes:
        mesh = make_triangle_soup(n, size=0.5 * n ** (-1 / 3), seed=1)
        ref_t = None
        if n <= brute_max:
            compile_s, trace_s, (ref_t, _) = _time_call(_brute, mesh, o, d)
            results.append(dict(structure="brute_force_jax", n_tris=n, build_s=0.0,
                                compile_s=compile_s, trace_s=trace_s,
                                rays_per_s=n_rays / trace_s))  # fmt: skip
            tri = np.asarray(mesh.triangles, np.float32)
            t0 = time.perf_counter()
            np_t = _numpy_brute(tri, np.asarray(o), np.asarray(d))
            np_s = time.perf_counter() - t0
            ref_np = np.asarray(ref_t)
            both = np.isfinite(np_t) & np.isfinite(np.asarray(ref_t))
            same_hits = bool(np.array_equal(np.isfinite(np_t), np.isfinite(np.asarray(ref_t))))
            results.append(dict(structure="brute_force_numpy", n_tris=n, build_s=0.0,
                                compile_s=0.0, trace_s=np_s, rays_per_s=n_rays / np_s,
                                same_hits_as_jax=same_hits,
                                max_abs_dt_vs_jax=_max_abs(np_t[both] - ref_np[both])))  # fmt: skip
        for name, build in (
            ("bvh", A.build_bvh),
            ("grid", A.build_grid),
            ("kdtree", A.build_kdtree),
        ):
            t0 = time.perf_counter()
            acc = build(mesh)
            build_s = time.perf_counter() - t0
            compile_s, trace_s, (t, _) = _time_call(_trace, acc, o, d)
            row = dict(structure=name, n_tris=n, build_s=build_s, compile_s=compile_s,
                       trace_s=trace_s, rays_per_s=n_rays / trace_s,
                       hit_fraction=float(np.mean(np.isfinite(np.asarray(t)))))  # fmt: skip
            if name == "bvh":
                row["nodes"] = int(acc.bounds.shape[0])
            if name == "kdtree":
                row["nodes"] = int(acc.axis.shape[0])
                row["prim_refs"] = int(acc.prims.shape[0])
            if name == "grid":
                row["cells"] = int(np.prod(np.asarray(acc.res)))
                row["prim_refs"] = int(acc.cell_prims.shape[0])
            if ref_t is not None:
                row["matches_brute_force"] = bool(
                    np.allclose(np.asarray(t), np.asarray(ref_t), rtol=1e-5)
                )
            results.append(row)
            print(json.dumps(row), flush=True, file=sys.stderr)
    return results


# ---------------------------------------------------------------------------------------------
# traversal backends vs Mitsuba 3


def _primary_rays(n_side, eye=(0.0, 0.0, 3.0), half=0.45):
    y, x = np.meshgrid(np.linspace(-half, half, n_side), np.linspace(-half, half, n_side),
                       indexing="ij")  # fmt: skip
    d = np.stack([x, y, -np.ones_like(x)], -1).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(np.asarray(eye), d.shape)
    return np.ascontiguousarray(o, np.float32), d.astype(np.float32)


def _best_time(fn, repeats=3):
    best = np.inf
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


@jax.jit
def _e2e(acc, o, d):
    h = acc.intersect(o, d)
    return h.t, h.prim_id, h.p, h.ng, h.uv


def _mitsuba_setup():
    return H.import_mitsuba(("llvm_ad_rgb", "scalar_rgb"))


def _mitsuba_trace(mi, scene, o, d, threads):
    import drjit as dr

    ray = mi.Ray3f(o=mi.Point3f(*(o[:, k] for k in range(3))),
                   d=mi.Vector3f(*(d[:, k] for k in range(3))))  # fmt: skip
    prev = dr.thread_count()
    if threads:
        dr.set_thread_count(threads)
    try:

        def run():
            pi = scene.ray_intersect_preliminary(ray)
            t = np.array(pi.t)
            return t, np.array(pi.prim_index)

        run()  # JIT compilation of the kernel
        sec, (t, prim) = _best_time(run)
    finally:
        dr.set_thread_count(prev)
    prim = prim.astype(np.int64)
    return sec, np.where(np.isfinite(t) & (prim != 0xFFFFFFFF), prim, -1)


def run_backends(n_rings=(36, 144), n_side=256, jax_rays=4096):
    from jaxgfx.render.geometry import accel as T
    from jaxgfx.render.geometry.mesh_io import make_uv_sphere, save_ply

    mi, variant = _mitsuba_setup()
    rows = []
    rng = np.random.default_rng(0)
    n = n_side * n_side
    ro = rng.uniform(-1.5, 1.5, (n, 3))
    rd = rng.uniform(-1, 1, (n, 3)) - ro
    rd /= np.linalg.norm(rd, axis=1, keepdims=True)
    ray_sets = {"primary": _primary_rays(n_side), "random": (ro.astype(np.float32),
                                                              rd.astype(np.float32))}  # fmt: skip
    import tempfile

    for nr in n_rings:
        mesh = make_uv_sphere(nr)
        n_tris = int(mesh.faces.shape[0])
        accs, builds = {}, {}
        for name in T.available_backends():
            t0 = time.perf_counter()
            accs[name] = jax.block_until_ready(T.build_traversal(mesh, name))
            builds[name] = time.perf_counter() - t0
        msc = None
        if mi is not None:
            with tempfile.TemporaryDirectory() as tmp:
                path = os.path.join(tmp, "m.ply")
                save_ply(path, mesh)
                t0 = time.perf_counter()
                msc = mi.load_dict({"type": "scene", "m": {"type": "ply", "filename": path}})
                builds["mitsuba"] = time.perf_counter() - t0
        for rname, (o, d) in ray_sets.items():
            row = dict(n_tris=n_tris, rays=rname, n_rays=n, build_s=builds, mrays_per_s={},
                       compile_s={}, agree_with_embree={})  # fmt: skip
            ref = None
            if "embree" in accs:
                host = accs["embree"].keep.obj
                sec, (t_ref, ref) = _best_time(
                    lambda host=host, o=o, d=d: host.query(o, d, 0.0, np.inf, False)
                )
                row["mrays_per_s"]["embree_host"] = n / sec / 1e6
            for name, acc in accs.items():
                m = jax_rays if name == "jax" else n
                oj, dj = jnp.asarray(o[:m]), jnp.asarray(d[:m])
                t0 = time.perf_counter()
                jax.block_until_ready(_e2e(acc, oj, dj))
                first = time.perf_counter() - t0
                sec, out = _best_time(lambda acc=acc, oj=oj, dj=dj: jax.block_until_ready(
                    _e2e(acc, oj, dj)))  # fmt: skip
                row["mrays_per_s"][name] = m / sec / 1e6
                row["compile_s"][name] = max(first - sec, 0.0)
                prim = np.where(np.isfinite(np.asarray(out[0])), np.asarray(out[1]), -1)
                if ref is not None:
                    row["agree_with_embree"][name] = float(np.mean(prim == ref[:m]))
            if msc is not None:
                for threads in (1, None):
                    sec, prim = _mitsuba_trace(mi, msc, o, d, threads)
                    key = f"mitsuba_{variant}_" + ("1thread" if threads else "all_threads")
                    row["mrays_per_s"][key] = n / sec / 1e6
                    if ref is not None:
                        row["agree_with_embree"][key] = float(np.mean(prim == ref))
                m1 = row["mrays_per_s"][f"mitsuba_{variant}_1thread"]
                row["mitsuba_1thread_over"] = {
                    k: round(m1 / v, 2) for k, v in row["mrays_per_s"].items()
                    if not k.startswith("mitsuba")
                }  # fmt: skip
            rows.append(row)
            print(json.dumps(row), flush=True, file=sys.stderr)
    return dict(mitsuba_variant=variant, rows=rows)


# ---------------------------------------------------------------------------------------------
# the JAX BVH: wavefront traversal vs a per-ray while_loop under vmap (issue 13)


def _per_ray_bvh(bvh, o, d, tmin, tmax, materialize):
    """The traversal before issue 13: one ``lax.while_loop`` per ray under ``vmap`` (the batch
    iterates until its slowest ray is done), over the same step as the wavefront."""
    from jaxgfx.render.geometry.accel._common import STACK_SIZE, safe_inv, slab
    from jaxgfx.render.geometry.accel.bvh_sah import _step

    dt = o.dtype
    bounds = bvh.bounds.astype(dt)
    tris = bvh.mesh.vertices[bvh.mesh.faces].astype(dt)

    def one(o, d, a, b):
        inv = safe_inv(d)
        tn, _, hit0 = slab(bounds[0, 0], bounds[0, 1], o, inv, a, b)
        s = (jnp.int32(0), tn, jnp.int32(0), jnp.zeros(STACK_SIZE, jnp.int32),
             jnp.zeros(STACK_SIZE, dt), b, jnp.int32(-1), ~hit0)  # fmt: skip
        s = jax.lax.while_loop(
            lambda s: ~s[-1],
            lambda s: _step(bvh, tris, bounds, (o, d, inv, a), s, False, materialize),
            s,
        )
        return s[5], s[6]

    return jax.vmap(one)(o, d, tmin, tmax)


_BVH_VARIANTS = {
    # name: (wavefront?, materialised leaf/child tests?)
    "per_ray_fused": (False, False),  # the JAX BVH before issue 13
    "per_ray": (False, True),
    "wavefront_fused": (True, False),
    "wavefront": (True, True),  # the JAX BVH now
}


def _bvh_fn(wave, materialize, width):
    from jaxgfx.render.geometry.accel.bvh_sah import wavefront_trace

    @jax.jit
    def f(bvh, o, d):
        tmin, tmax = jnp.zeros(o.shape[0], o.dtype), jnp.full(o.shape[0], jnp.inf, o.dtype)
        if wave:
            return wavefront_trace(bvh, o, d, tmin, tmax, width=width, materialize=materialize)
        return _per_ray_bvh(bvh, o, d, tmin, tmax, materialize)

    return f


def run_wavefront(n_rings=(36, 144), n_rays=(16384, 65536), variants=tuple(_BVH_VARIANTS),
                  width=None, repeats=2):  # fmt: skip
    """Closest-hit M rays/s of the JAX BVH traversal variants on UV spheres (5 040 and 82 368
    triangles), primary and random rays; wall and process-CPU seconds, best of ``repeats``
    warm calls taken round-robin over the variants (the machine is shared: compare ratios
    within a row); compile seconds = first call minus the best warm call."""
    from jaxgfx.render.geometry.accel.bvh_sah import pool_width
    from jaxgfx.render.geometry.mesh_io import make_uv_sphere

    fns = {v: _bvh_fn(*_BVH_VARIANTS[v], width) for v in variants}
    rows = []
    for nr in n_rings:
        mesh = make_uv_sphere(nr)
        bvh = jax.block_until_ready(A.build_bvh(mesh))
        for n in n_rays:
            side = int(round(np.sqrt(n)))
            rng = np.random.default_rng(0)
            ro = rng.uniform(-1.5, 1.5, (n, 3))
            rd = rng.uniform(-1, 1, (n, 3)) - ro
            rd /= np.linalg.norm(rd, axis=1, keepdims=True)
            for rname, (o, d) in (("primary", _primary_rays(side)), ("random", (ro, rd))):
                o, d = jnp.asarray(o, jnp.float32), jnp.asarray(d, jnp.float32)
                row = dict(n_tris=int(mesh.faces.shape[0]), rays=rname, n_rays=int(o.shape[0]),
                           pool_width=width or pool_width(n), mrays_per_s={}, cpu_mrays_per_s={},
                           compile_s={}, compile_cpu_s={})  # fmt: skip
                outs, wall, cpu, first = {}, {}, {}, {}
                for v, f in fns.items():
                    t0, c0 = time.perf_counter(), time.process_time()
                    outs[v] = jax.block_until_ready(f(bvh, o, d))
                    first[v] = (time.perf_counter() - t0, time.process_time() - c0)
                    wall[v], cpu[v] = [], []
                for _ in range(repeats):
                    for v, f in fns.items():
                        t0, c0 = time.perf_counter(), time.process_time()
                        jax.block_until_ready(f(bvh, o, d))
                        wall[v].append(time.perf_counter() - t0)
                        cpu[v].append(time.process_time() - c0)
                for v in fns:
                    w, c = min(wall[v]), min(cpu[v])
                    row["mrays_per_s"][v] = o.shape[0] / w / 1e6
                    row["cpu_mrays_per_s"][v] = o.shape[0] / c / 1e6
                    row["compile_s"][v] = max(first[v][0] - w, 0.0)
                    row["compile_cpu_s"][v] = max(first[v][1] - c, 0.0)
                ref = variants[0]
                t_ref, p_ref = (np.asarray(x) for x in outs[ref])
                hit = p_ref >= 0
                row["hit_fraction"] = float(hit.mean())
                row[f"same_prim_as_{ref}"] = {
                    v: float(np.mean(np.asarray(outs[v][1]) == p_ref)) for v in fns
                }
                rel = {
                    v: np.abs(np.asarray(outs[v][0])[hit] - t_ref[hit]) / t_ref[hit] for v in fns
                }
                row[f"max_rel_dt_vs_{ref}"] = {
                    v: float(np.max(r, initial=0.0)) for v, r in rel.items()
                }
                row[f"speedup_over_{ref}"] = {
                    v: round(row["mrays_per_s"][v] / row["mrays_per_s"][ref], 2) for v in fns
                }
                rows.append(row)
                print(json.dumps(row), flush=True, file=sys.stderr)
    return dict(rows=rows)


# ---------------------------------------------------------------------------------------------
# samples/s against the triangle count, per backend and Mitsuba 3


def run_scaling(n_rings, *, res=128, spp=16, max_depth=4, jax_max_tris=70_000, repeats=3):
    """Path-traced samples/s against the triangle count: the example scene with its metal
    sphere replaced by a UV-sphere mesh (PLY), per traversal backend and Mitsuba 3, all timed by
    ``benchmarks/_render_harness.interleave`` in one round-robin per mesh (warm, new seed per
    call, synchronised, medians of ``repeats``, process CPU, other processes' CPU).

    Issue 22: this table used to be taken at 64^2 x 4 spp (16 k samples: Mitsuba's per-call
    overhead dominated), with one fixed seed, ``np.array`` as the only synchronisation and
    Mitsuba timed after all jaxgfx backends, at load 20: Mitsuba came out 16-25x too slow.
    Defaults now: 128^2, 16 spp, depth 4 (262 k samples per call)."""
    import copy
    import tempfile

    from benchmarks.render import EXAMPLE
    from jaxgfx.config import read_yaml
    from jaxgfx.render.geometry import accel as T
    from jaxgfx.render.geometry.mesh_io import make_uv_sphere, save_ply

    mi, variant = _mitsuba_setup()
    base = read_yaml(EXAMPLE)
    base["camera"]["width"] = base["camera"]["height"] = res
    rows = []
    with tempfile.TemporaryDirectory(prefix="jaxgfx_bench_accel_") as tmp:
        for nr in n_rings:
            m = make_uv_sphere(nr, radius=1.0, center=(0.0, 1.0, 0.0))
            path = os.path.join(tmp, f"sphere_{nr}.ply")
            save_ply(path, m)
            desc = copy.deepcopy(base)
            desc["shapes"][0] = {"type": "mesh", "file": path, "material": "metal"}
            n_tris = int(m.faces.shape[0])
            row = dict(n_tris=n_tris, res=res, spp=spp, integrator="path", max_depth=max_depth)
            renders = {}
            for name in T.available_backends():
                if name == "jax" and n_tris > jax_max_tris:
                    continue
                renders[name] = H.JaxgfxRender(desc, spp=spp, max_depth=max_depth, accel=name)
            if mi is not None:
                renders["mitsuba"] = H.MitsubaRender(mi, desc, spp=spp, max_depth=max_depth)
            row.update(H.interleave(renders, repeats=repeats))
            if mi is not None:
                row["mitsuba_suspect"] = H.mitsuba_suspect(row["mitsuba"])
                for name in T.ACCEL_BACKENDS:
                    if name in row:
                        row[f"mitsuba_over_{name}"] = round(
                            row["mitsuba"]["samples_per_s"] / row[name]["samples_per_s"], 2
                        )
            rows.append(row)
            print(json.dumps(row), flush=True, file=sys.stderr)
    return dict(mitsuba_variant=variant, rows=rows)


def plot_scaling(res, out_dir):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(out_dir, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, style in (("embree", "o-"), ("warp", "s-"), ("jax", "^-"), ("mitsuba", "k--")):
        pts = [(r["n_tris"], r[name]["samples_per_s"]) for r in res["rows"] if name in r]
        if pts:
            x, y = zip(*pts, strict=True)
            label = f"Mitsuba 3 ({res['mitsuba_variant']})" if name == "mitsuba" else name
            ax.loglog(x, y, style, label=label)
    ax.set_xlabel("triangles")
    ax.set_ylabel("path samples / s (depth 4, 128², 16 spp)")
    ax.set_title("Path tracing a mesh: samples/s per traversal backend")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    path = os.path.join(out_dir, "samples_vs_triangles.png")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1e2..1e3 triangles, 1024 rays")
    ap.add_argument("--max-exp", type=int, default=5, help="largest size 10**max_exp")
    ap.add_argument("--full", action="store_true", help="include 1e6 triangles (slow build)")
    ap.add_argument("--rays", type=int, default=4096)
    ap.add_argument("--out", default=None, help="also write the JSON here")
    ap.add_argument("--sections", default="structures,backends,scaling",
                    help="any of structures,backends,scaling,wavefront")  # fmt: skip
    ap.add_argument("--backends-jax-rays", type=int, default=4096,
                    help="rays traced by the JAX BVH in the backends section")  # fmt: skip
    ap.add_argument("--wavefront-rays", default="16384,65536",
                    help="ray counts of the wavefront section")  # fmt: skip
    ap.add_argument("--wavefront-width", type=int, default=None,
                    help="pool slots (default: bvh_sah.pool_width)")  # fmt: skip
    ap.add_argument(
        "--wavefront-variants",
        default=",".join(_BVH_VARIANTS),
        help=f"subset of {','.join(_BVH_VARIANTS)} (the first is the reference)",
    )
    ap.add_argument("--plot", default=None, help="write samples_vs_triangles.png here")
    ap.add_argument("--max-load", type=float, default=1.0,
                    help="refuse to measure when the 1-min load average is above this")  # fmt: skip
    ap.add_argument("--allow-load", action="store_true",
                    help="measure above --max-load anyway (flagged loaded: true)")  # fmt: skip
    a = ap.parse_args(argv)
    gate = H.load_gate(a.max_load, refuse=not a.allow_load)
    mach = machine()
    sections = set(a.sections.split(","))
    max_exp = 3 if a.quick else (6 if a.full else a.max_exp)
    n_rays = 1024 if a.quick else a.rays
    sizes = [10**k for k in range(2, max_exp + 1)]
    res = run(sizes, n_rays) if "structures" in sections else []
    extra = {}
    if "backends" in sections:
        extra["backends"] = run_backends(n_rings=(36,) if a.quick else (36, 144),
                                         n_side=64 if a.quick else 256,
                                         jax_rays=a.backends_jax_rays)  # fmt: skip
    if "wavefront" in sections:
        extra["wavefront"] = run_wavefront(
            n_rings=(36,) if a.quick else (36, 144),
            n_rays=(4096,) if a.quick else tuple(int(x) for x in a.wavefront_rays.split(",")),
            variants=tuple(a.wavefront_variants.split(",")),
            width=a.wavefront_width,
        )
    if "scaling" in sections:
        # 4n(n-1) triangles: 1 012, 4 032, 16 512, 65 280, 262 656, 1 001 000 (n = 501)
        rings = (17, 33, 65) if a.quick else (17, 33, 65, 129, 257, 501)
        extra["scaling"] = run_scaling(rings)
        if a.plot:
            extra["scaling"]["plot"] = plot_scaling(extra["scaling"], a.plot)
    doc = dict(benchmark="accel", machine=mach, load_gate=gate, n_rays=n_rays, results=res,
               **extra)
    emit(doc, a.out)


if __name__ == "__main__":
    main()
