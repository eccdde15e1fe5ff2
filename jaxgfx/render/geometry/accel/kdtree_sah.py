# ruff: noqa: F722  (jaxtyping shape strings)
"""SAH kd-tree: host build, stack traversal in JAX (Havran 2000; pbrt-v3 §4.4)."""

from __future__ import annotations

import math
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from jaxgfx.render.geometry.accel._common import (
    STACK_SIZE,
    TriangleAccel,
    as_numpy_triangles,
    slab,
    tri_chunk,
)
from jaxgfx.render.geometry.mesh import TriangleMesh

__all__ = ["KDTree", "build_kdtree"]


class KDTree(TriangleAccel):
    """Axis-aligned kd-tree over the triangles of ``mesh`` (build with :func:`build_kdtree`).

    Depth-first node arrays: node ``i``'s lower (below-plane) child is ``i + 1``. ``axis (M,)``
    is 0, 1, 2 for inner nodes and 3 for leaves; ``split (M,)`` the plane position;
    ``offset (M,)`` the upper child (inner) or the first slot in ``prims`` (leaf); ``count
    (M,)`` the leaf size. Triangles straddling a plane are listed in both children.
    """

    mesh: TriangleMesh
    bounds: Float[Array, "2 3"]
    axis: Int[Array, " M"]
    split: Float[Array, " M"]
    offset: Int[Array, " M"]
    count: Int[Array, " M"]
    prims: Int[Array, " E"]
    chunk: int = eqx.field(static=True, default=4)

    def _trace(self, tris, o, d, inv, tmin, tmax, any_hit):
        K = self.chunk
        lo, hi = self.bounds[0].astype(o.dtype), self.bounds[1].astype(o.dtype)
        t0, t1, hit0 = slab(lo, hi, o, inv, tmin, tmax)
        split = self.split.astype(o.dtype)
        ks = jnp.arange(K)
        n_prims = self.prims.shape[0]
        sn = jnp.zeros(STACK_SIZE, jnp.int32)
        slo = jnp.zeros(STACK_SIZE, o.dtype)
        shi = jnp.zeros(STACK_SIZE, o.dtype)
        init = (jnp.int32(0), t0, t1, jnp.int32(0), jnp.int32(0), sn, slo, shi, tmax, jnp.int32(-1))
        init = (*init, ~hit0)

        def body(s):
            node, tlo, thi, k, sp, sn, slo, shi, best, bprim, _ = s
            ax = self.axis[node]
            is_leaf = ax == 3
            axc = jnp.minimum(ax, 2)
            culled = best <= tlo
            # leaf chunk
            start, cnt = self.offset[node], self.count[node]
            slots = start + k + ks
            idx = self.prims[jnp.minimum(slots, n_prims - 1)]
            mask = is_leaf & ~culled & (k + ks < cnt)
            tl, j = tri_chunk(tris, idx, mask, o, d, tmin, best)
            better = tl < best
            best = jnp.where(better, tl, best)
            bprim = jnp.where(better, idx[j], bprim)
            k = k + K
            leaf_done = is_leaf & ((k >= cnt) | culled)
            # inner node
            oa, da, pa = o[axc], d[axc], split[node]
            tplane = (pa - oa) * inv[axc]
            below_first = (oa < pa) | ((oa == pa) & (da <= 0))
            lower, upper = node + 1, self.offset[node]
            near = jnp.where(below_first, lower, upper)
            far = jnp.where(below_first, upper, lower)
            inner = ~is_leaf & ~culled
            near_only = (tplane > thi) | (tplane <= 0)
            far_only = ~near_only & (tplane < tlo)
            both = inner & ~near_only & ~far_only & (sp < STACK_SIZE)
            sn = jnp.where(both, sn.at[sp].set(far), sn)
            slo = jnp.where(both, slo.at[sp].set(tplane), slo)
            shi = jnp.where(both, shi.at[sp].set(thi), shi)
            sp = sp + both.astype(jnp.int32)
            go = inner
            go_node = jnp.where(far_only, far, near)
            go_lo = jnp.where(far_only, tplane, tlo)
            go_hi = jnp.where(near_only | far_only, thi, tplane)
            # after a finished leaf (or a culled node): stop if the best hit precedes thi
            fin = leaf_done | (~is_leaf & culled)
            stop = fin & (best <= thi)
            empty = sp == 0
            top = jnp.maximum(sp - 1, 0)
            pop = fin & ~stop & ~empty
            node = jnp.where(go, go_node, jnp.where(pop, sn[top], node))
            tlo = jnp.where(go, go_lo, jnp.where(pop, slo[top], tlo))
            thi = jnp.where(go, go_hi, jnp.where(pop, shi[top], thi))
            sp = jnp.where(pop, sp - 1, sp)
            k = jnp.where(go | fin, 0, k)
            done = stop | (fin & empty) | (any_hit & (bprim >= 0))
            return node, tlo, thi, k, sp, sn, slo, shi, best, bprim, done

        out = jax.lax.while_loop(lambda s: ~s[-1], body, init)
        return out[8], out[9]


def build_kdtree(
    mesh: TriangleMesh,
    *,
    n_bins: int = 32,
    max_leaf: int = 4,
    max_depth: int | None = None,
    traversal_cost: float = 1.0,
    intersect_cost: float = 4.0,
    empty_bonus: float = 0.5,
    chunk: int = 4,
) -> KDTree:
    """Build a :class:`KDTree` on the host with the surface-area heuristic.

    Candidate planes at each node: ``n_bins - 1`` uniform positions per axis plus, for nodes
    with at most 64 triangles, every triangle-box edge inside the node (exact SAH there). The
    cost of a split is ``C_t + C_i (1 - b_e) (A_L N_L + A_R N_R) / A`` (``b_e`` only when one
    side is empty); a node becomes a leaf when that is not below ``C_i N``, when ``N <=
    max_leaf`` or at depth ``8 + 1.3 log2 N`` (pbrt-v3 §4.4 rule; here ``C_t = 1``, ``C_i = 4``).
    Triangles are bounded by their boxes clipped to the node.
    """
    if not isinstance(n_bins, int) or not 2 <= n_bins <= 1024:
        raise ValueError(f"n_bins: expected an integer in [2, 1024], got {n_bins!r}")
    tri = as_numpy_triangles(mesh)
    n_tri = tri.shape[0]
    tlo, thi = tri.min(1), tri.max(1)
    lo, hi = tlo.min(0), thi.max(0)
    pad = 1e-5 * max(float((hi - lo).max()), 1e-6)
    lo, hi = lo - pad, hi + pad
    if max_depth is None:
        max_depth = int(round(8 + 1.3 * math.log2(max(n_tri, 1))))
    max_depth = min(max_depth, STACK_SIZE - 2)
    axis_l, split_l, off_l, cnt_l, prims = [], [], [], [], []

    def area(a, b):
        e = np.maximum(b - a, 0.0)
        return e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0]

    def leaf(ids):
        axis_l.append(3)
        split_l.append(0.0)
        off_l.append(len(prims))
        cnt_l.append(len(ids))
        prims.extend(ids.tolist())

    def build(ids, nlo, nhi, depth):
        n = len(ids)
        if n <= max_leaf or depth >= max_depth:
            leaf(ids)
            return
        blo = np.maximum(tlo[ids], nlo)
        bhi = np.minimum(thi[ids], nhi)
        total = area(nlo, nhi)
        best = (intersect_cost * n, -1, 0.0)
        for ax in range(3):
            if nhi[ax] <= nlo[ax]:
                continue
            cand = nlo[ax] + (nhi[ax] - nlo[ax]) * np.arange(1, n_bins) / n_bins
            if n <= 64:
                e = np.concatenate([blo[:, ax], bhi[:, ax]])
                cand = np.concatenate([cand, e[(e > nlo[ax]) & (e < nhi[ax])]])
            smin, smax = np.sort(blo[:, ax]), np.sort(bhi[:, ax])
            nl = np.searchsorted(smin, cand, "left")
            nr = n - np.searchsorted(smax, cand, "right")
            llo, lhi = nlo.copy(), nhi.copy()
            ext = nhi - nlo
            # child areas as functions of the plane position (linear in it)
            other = [a for a in range(3) if a != ax]
            cap = ext[other[0]] * ext[other[1]]
            per = ext[other[0]] + ext[other[1]]
            al = cap + per * (cand - nlo[ax])
            ar = cap + per * (nhi[ax] - cand)
            bonus = np.where((nl == 0) | (nr == 0), empty_bonus, 0.0)
            cost = traversal_cost + intersect_cost * (1 - bonus) * (al * nl + ar * nr) / total
            del llo, lhi
            k = int(np.argmin(cost))
            if cost[k] < best[0]:
                best = (float(cost[k]), ax, float(cand[k]))
        _, ax, p = best
        if ax < 0:
            leaf(ids)
            return
        go_l = (blo[:, ax] < p) | ((blo[:, ax] == p) & (bhi[:, ax] == p))
        go_r = bhi[:, ax] > p
        me = len(axis_l)
        axis_l.append(ax)
        split_l.append(p)
        off_l.append(0)
        cnt_l.append(0)
        lhi = nhi.copy()
        lhi[ax] = p
        rlo = nlo.copy()
        rlo[ax] = p
        build(ids[go_l], nlo, lhi, depth + 1)
        off_l[me] = len(axis_l)
        build(ids[go_r], rlo, nhi, depth + 1)

    lim = sys.getrecursionlimit()
    sys.setrecursionlimit(max(lim, 10_000))
    try:
        build(np.arange(n_tri), lo, hi, 0)
    finally:
        sys.setrecursionlimit(lim)
    dt = mesh.vertices.dtype
    return KDTree(
        mesh=mesh,
        bounds=jnp.asarray(np.stack([lo, hi]), dt),
        axis=jnp.asarray(axis_l, jnp.int32),
        split=jnp.asarray(split_l, dt),
        offset=jnp.asarray(off_l, jnp.int32),
        count=jnp.asarray(cnt_l, jnp.int32),
        prims=jnp.asarray(prims if prims else [0], jnp.int32),
        chunk=chunk,
    )
