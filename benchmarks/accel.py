"""Acceleration-structure benchmark: host build time and jitted trace throughput.

    python -m benchmarks.accel [--quick] [--max-exp 5] [--full] [--rays 4096] [--out FILE]

Scenes are random triangle soups (``make_triangle_soup``) of 1e2 ... 1e5 triangles (1e6 with
``--full``) whose triangle size shrinks like N^(-1/3) so the depth complexity stays similar.
For each structure: build seconds (NumPy, host), compile seconds (first call minus a warm call)
and trace time (best of 3 warm calls) -> rays/s. Brute force (JAX, and NumPy as the host peer)
runs up to 1e3 triangles. Prints one JSON document (progress rows go to stderr).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1e2..1e3 triangles, 1024 rays")
    ap.add_argument("--max-exp", type=int, default=5, help="largest size 10**max_exp")
    ap.add_argument("--full", action="store_true", help="include 1e6 triangles (slow build)")
    ap.add_argument("--rays", type=int, default=4096)
    ap.add_argument("--out", default=None, help="also write the JSON here")
    a = ap.parse_args(argv)
    max_exp = 3 if a.quick else (6 if a.full else a.max_exp)
    n_rays = 1024 if a.quick else a.rays
    sizes = [10**k for k in range(2, max_exp + 1)]
    res = run(sizes, n_rays)
    doc = dict(
        benchmark="accel",
        jax=jax.__version__,
        backend=jax.default_backend(),
        machine=platform.machine(),
        cpu_count=os.cpu_count(),
        load_avg=os.getloadavg(),
        n_rays=n_rays,
        results=res,
    )
    text = json.dumps(doc, indent=1)
    print(text)
    if a.out:
        with open(a.out, "w") as fh:
            fh.write(text)


if __name__ == "__main__":
    main()
