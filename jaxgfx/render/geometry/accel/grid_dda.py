# ruff: noqa: F722  (jaxtyping shape strings)
"""Uniform grid: host build into CSR cell lists, 3-D DDA traversal (Amanatides & Woo 1987)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from jaxgfx.render.geometry.accel._common import TriangleAccel, as_numpy_triangles, slab, tri_chunk
from jaxgfx.render.geometry.mesh import TriangleMesh

__all__ = ["UniformGrid", "build_grid", "grid_resolution"]


class UniformGrid(TriangleAccel):
    """Uniform grid over the triangles of ``mesh`` (build with :func:`build_grid`).

    Fields: ``bounds (2, 3)`` grid box; ``res (3,)`` cells per axis; ``cell_start (C + 1,)`` and
    ``cell_prims (E,)`` the CSR lists of face indices overlapping each cell (cell index
    ``(ix * ry + iy) * rz + iz``); ``chunk`` triangles are tested per loop iteration.
    """

    mesh: TriangleMesh
    bounds: Float[Array, "2 3"]
    res: Int[Array, " 3"]
    cell_start: Int[Array, " C1"]
    cell_prims: Int[Array, " E"]
    chunk: int = eqx.field(static=True, default=4)

    def _trace(self, tris, o, d, inv, tmin, tmax, any_hit):
        K = self.chunk
        lo, hi = self.bounds[0].astype(o.dtype), self.bounds[1].astype(o.dtype)
        res = self.res
        size = (hi - lo) / res
        t0, t1, hit0 = slab(lo, hi, o, inv, tmin, tmax)
        p = o + t0 * d
        cell = jnp.clip(jnp.floor((p - lo) / size).astype(jnp.int32), 0, res - 1)
        step = jnp.where(d > 0, 1, -1).astype(jnp.int32)
        nxt = lo + (cell + (d > 0)) * size
        tnext = jnp.where(d != 0, (nxt - o) * inv, jnp.inf)
        tdelta = jnp.where(d != 0, size * jnp.abs(inv), jnp.inf)
        ks = jnp.arange(K)
        n_prims = self.cell_prims.shape[0]

        def cid(c):
            return (c[0] * res[1] + c[1]) * res[2] + c[2]

        init = (cell, tnext, jnp.int32(0), tmax, jnp.int32(-1), ~hit0)

        def body(s):
            cell, tnext, k, best, bprim, _ = s
            c = cid(cell)
            start, end = self.cell_start[c], self.cell_start[c + 1]
            slots = start + k + ks
            idx = self.cell_prims[jnp.minimum(slots, n_prims - 1)]
            tl, j = tri_chunk(tris, idx, slots < end, o, d, tmin, best)
            better = tl < best
            best = jnp.where(better, tl, best)
            bprim = jnp.where(better, idx[j], bprim)
            k = k + K
            cell_done = start + k >= end
            texit = jnp.min(tnext)
            ax = jnp.argmin(tnext)
            finished = cell_done & ((best <= texit) | (texit > t1))
            adv = cell_done & ~finished
            onehot = jnp.arange(3) == ax
            cell = jnp.where(adv & onehot, cell + step, cell)
            tnext = jnp.where(adv & onehot, tnext + tdelta, tnext)
            out = jnp.any((cell < 0) | (cell >= res))
            k = jnp.where(cell_done, 0, k)
            done = finished | (adv & out) | (any_hit & (bprim >= 0))
            return jnp.clip(cell, 0, res - 1), tnext, k, best, bprim, done

        out = jax.lax.while_loop(lambda s: ~s[-1], body, init)
        return out[3], out[4]


def grid_resolution(bounds, n_tris: int, *, density: float = 3.0, max_res: int = 256):
    """Cells per axis ``~ extent_i * (density * N / V)^(1/3)`` (about ``density * N`` cells
    of roughly cubic shape; Cleary & Wyvill 1988, pbrt-v1 ``GridAccel`` heuristic), clipped to
    ``[1, max_res]``."""
    ext = np.maximum(np.asarray(bounds[1]) - np.asarray(bounds[0]), 0.0)
    emax = ext.max()
    ext = np.maximum(ext, 1e-3 * emax) if emax > 0 else np.ones(3)
    k = (density * n_tris / np.prod(ext)) ** (1.0 / 3.0)
    return np.clip(np.round(ext * k), 1, max_res).astype(np.int64)


def build_grid(mesh: TriangleMesh, *, density: float = 3.0, max_res: int = 256, chunk: int = 4):
    """Build a :class:`UniformGrid` on the host.

    Each triangle is listed in every cell overlapped by its bounding box (conservative: a
    triangle-box SAT test would prune some entries); the lists are stored as CSR arrays.
    Resolution from :func:`grid_resolution`.
    """
    if not np.isfinite(density) or density <= 0:
        raise ValueError(f"density: expected a finite value > 0, got {density!r}")
    tri = as_numpy_triangles(mesh)
    tlo, thi = tri.min(1), tri.max(1)
    lo, hi = tlo.min(0), thi.max(0)
    pad = 1e-4 * max(float((hi - lo).max()), 1e-6)
    lo, hi = lo - pad, hi + pad
    res = grid_resolution((lo, hi), tri.shape[0], density=density, max_res=max_res)
    size = (hi - lo) / res
    c0 = np.clip(np.floor((tlo - lo) / size).astype(np.int64), 0, res - 1)
    c1 = np.clip(np.floor((thi - lo) / size).astype(np.int64), 0, res - 1)
    span = c1 - c0 + 1
    per = span.prod(1)
    tid = np.repeat(np.arange(len(tri)), per)
    first = np.repeat(np.cumsum(per) - per, per)
    j = np.arange(per.sum()) - first
    sp = span[tid]
    iz = j % sp[:, 2]
    iy = (j // sp[:, 2]) % sp[:, 1]
    ix = j // (sp[:, 2] * sp[:, 1])
    cells = ((c0[tid, 0] + ix) * res[1] + (c0[tid, 1] + iy)) * res[2] + (c0[tid, 2] + iz)
    order = np.argsort(cells, kind="stable")
    counts = np.bincount(cells, minlength=int(res.prod()))
    start = np.concatenate([[0], np.cumsum(counts)])
    return UniformGrid(
        mesh=mesh,
        bounds=jnp.asarray(np.stack([lo, hi]), mesh.vertices.dtype),
        res=jnp.asarray(res, jnp.int32),
        cell_start=jnp.asarray(start, jnp.int32),
        cell_prims=jnp.asarray(tid[order], jnp.int32),
        chunk=chunk,
    )
