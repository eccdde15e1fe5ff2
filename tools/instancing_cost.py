"""Instancing against flattening: build time, memory and trace / render time
(docs/render_geometry.md, "Instancing").

Usage: ``JAX_PLATFORMS=cpu python tools/instancing_cost.py [--instances 100 1000] [--level 4]
[--no-render] [--backends jax embree]``.
``K`` instances of a ``20 * 4**level``-triangle blob (level 4: 5 120 triangles) on a grid, each
rotated and non-uniformly scaled, as :class:`~jaxgfx.render.geometry.Instances` over ONE
traversal structure, and as one flattened mesh of ``K`` times the triangles, per backend
(``jax`` BVH; ``embree`` when installed). Prints per backend and layout: build seconds,
memory (JAX BVH: bytes of its arrays, the mesh included; Embree: bytes of the float32
vertices and int32 faces handed to Embree, whose own BVH is native memory not measured
here), closest-hit time of ``R`` random camera rays (jitted, warm, best of 5, the two layouts'
calls alternating) and the time
of a 64x64, 4 spp ``direct`` render (warm, best of 2; ``--no-render`` skips it). Several
``--instances`` counts run one after the other.
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np
from scipy.spatial.transform import Rotation

from jaxgfx.render import render
from jaxgfx.render.geometry import Instances
from jaxgfx.render.geometry.accel import available_backends, build_traversal
from jaxgfx.render.geometry.mesh_io import make_blob
from jaxgfx.render.scene import load_scene


def _nbytes(tree):
    return sum(x.nbytes for x in jax.tree_util.tree_leaves(tree) if hasattr(x, "nbytes"))


def _mats(k):
    n = int(np.ceil(np.sqrt(k)))
    out = []
    for i in range(k):
        m = np.eye(4)
        s = np.array([1.0, 0.7, 1.3]) * (0.8 + 0.4 * ((i * 7) % 5) / 4)
        m[:3, :3] = Rotation.from_euler("xyz", [i * 17, i * 31, i * 43], degrees=True).as_matrix()
        m[:3, :3] = m[:3, :3] @ np.diag(s)
        m[:3, 3] = [3.0 * (i % n - n / 2), 0.0, 3.0 * (i // n - n / 2)]
        out.append(m)
    return np.array(out)


def _best(fn, reps):
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t0)
    return min(ts)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--instances", type=int, nargs="+", default=[100])
    ap.add_argument("--level", type=int, default=4)
    ap.add_argument("--rays", type=int, default=65536)
    ap.add_argument("--no-render", action="store_true")
    ap.add_argument("--backends", nargs="+", default=["jax", "embree"])
    a = ap.parse_args()
    for k in a.instances:
        run(k, a.level, a.rays, not a.no_render, a.backends)


def run(instances, level, rays, with_render, backends):
    mesh = make_blob(level, seed=3)
    mats = _mats(instances)
    inst0 = Instances(mesh, mats)
    flat = inst0.flatten()
    n = int(mesh.faces.shape[0])
    print(f"{instances} instances of {n} triangles (flattened: {int(flat.faces.shape[0])})")
    ext = float(np.abs(mats[:, :3, 3]).max()) + 2
    rng = np.random.default_rng(0)
    o = np.tile([[0.0, 3 * ext, 1.5 * ext]], (rays, 1))
    tgt = np.stack([rng.uniform(-ext, ext, rays), np.zeros(rays),
                    rng.uniform(-ext, ext, rays)], 1)  # fmt: skip
    d = tgt - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o, d = jnp.asarray(o, jnp.float32), jnp.asarray(d, jnp.float32)
    trace = jax.jit(lambda s, o, d: s.closest_t(o, d, tmin=0.0, tmax=jnp.inf)[0])
    cam = {"origin": [0.0, 3 * ext, 1.5 * ext], "target": [0, 0, 0], "fov": 50,
           "width": 64, "height": 64}  # fmt: skip
    for backend in [b for b in backends if b in available_backends()]:
        shapes, info = {}, {}
        for layout in ("instanced", "flattened"):
            t0 = time.perf_counter()
            if layout == "instanced":
                shape = Instances(build_traversal(mesh, backend), mats)
            else:
                shape = build_traversal(flat, backend)
            build = time.perf_counter() - t0
            # JAX BVH: its arrays (mesh included); Embree: the float32 vertices and int32
            # faces handed to it (its own BVH lives in native memory, not measured here)
            m_ = getattr(shape, "shape", shape).mesh
            geo = m_.vertices.shape[0] * 12 + m_.faces.shape[0] * 12
            mem = geo if backend == "embree" else _nbytes(shape)
            hits = int(jnp.isfinite(trace(shape, o, d)).sum())
            shapes[layout], info[layout] = shape, (build, mem, hits)
        # the two layouts' traces alternate (the machine's load drifts between runs)
        best = {k: np.inf for k in shapes}
        for _ in range(5):
            for k, shape in shapes.items():
                best[k] = min(best[k], _best(lambda shape=shape: trace(shape, o, d), 1))
        for layout in ("instanced", "flattened"):
            build, mem, hits = info[layout]
            t_trace = best[layout]
            first = t_render = float("nan")
            if with_render:
                src = mesh if layout == "instanced" else flat
                sd = {"type": "mesh", "vertices": np.asarray(src.vertices),
                      "faces": np.asarray(src.faces)}  # fmt: skip
                if layout == "instanced":
                    sd = {"type": "instances", "to_world": mats, "shapes": [sd]}
                scene = load_scene(
                    {
                        "camera": cam,
                        "shapes": [sd],
                        "emitters": [
                            {
                                "type": "directional",
                                "direction": [0, -1, -0.3],
                                "irradiance": [2, 2, 2],
                            }
                        ],
                    },  # fmt: skip
                    accel=backend,
                )
                key = jax.random.key(0)
                t0 = time.perf_counter()
                jax.block_until_ready(render(scene, key, spp=4, integrator="direct"))
                first = time.perf_counter() - t0
                t_render = _best(lambda s=scene, k=key: render(s, k, spp=4, integrator="direct"), 2)
            print(f"{backend:7s} {layout:10s} build {build:7.2f} s  memory {mem / 2**20:8.1f} MiB"
                  f"  trace {rays} rays {t_trace:7.3f} s ({hits} hits)"
                  f"  render first {first:6.1f} s, warm {t_render:6.2f} s")  # fmt: skip


if __name__ == "__main__":
    main()
