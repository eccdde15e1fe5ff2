# ruff: noqa: F722  (jaxtyping shape strings)
"""Bounding volume hierarchy: binned-SAH build on the host, stack traversal in JAX."""

from __future__ import annotations

import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from jaxgfx.render.accel._common import (
    STACK_SIZE,
    TriangleAccel,
    as_numpy_triangles,
    slab,
    tri_chunk,
)
from jaxgfx.render.shapes import TriangleMesh

__all__ = ["BVH", "build_bvh"]


def _half_area(lo, hi):
    e = np.maximum(hi - lo, 0.0)
    return e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0]


class BVH(TriangleAccel):
    """Flattened binary BVH over the triangles of ``mesh`` (build with :func:`build_bvh`).

    Nodes are stored depth-first: node ``i``'s left child is ``i + 1``. Fields:
    ``bounds (M, 2, 3)`` node boxes (min, max); ``offset (M,)``: right child index for inner
    nodes, first slot in ``prims`` for leaves; ``count (M,)``: 0 for inner nodes, the number of
    triangles for leaves (<= ``max_leaf``); ``prims (F,)`` face indices in leaf order.
    """

    mesh: TriangleMesh
    bounds: Float[Array, "M 2 3"]
    offset: Int[Array, " M"]
    count: Int[Array, " M"]
    prims: Int[Array, " F"]
    max_leaf: int = eqx.field(static=True)

    def _trace(self, tris, o, d, inv, tmin, tmax, any_hit):
        L = self.max_leaf
        bounds = self.bounds.astype(o.dtype)
        tn, tf, hit0 = slab(bounds[0, 0], bounds[0, 1], o, inv, tmin, tmax)
        stack_n = jnp.zeros(STACK_SIZE, jnp.int32)
        stack_t = jnp.zeros(STACK_SIZE, o.dtype)
        # state: node, its entry t, sp, stacks, best t, best prim, done
        init = (jnp.int32(0), tn, jnp.int32(0), stack_n, stack_t, tmax, jnp.int32(-1), ~hit0)
        ks = jnp.arange(L)

        def cond(s):
            return ~s[-1]

        def body(s):
            node, tnode, sp, sn, st, best, bprim, _ = s
            cnt = self.count[node]
            off = self.offset[node]
            is_leaf = cnt > 0
            skip = tnode >= best
            # leaf: test up to L triangles
            slots = off + ks
            idx = self.prims[jnp.minimum(slots, self.prims.shape[0] - 1)]
            tl, j = tri_chunk(tris, idx, ks < cnt, o, d, tmin, best)
            leaf_better = is_leaf & ~skip & (tl < best)
            best = jnp.where(leaf_better, tl, best)
            bprim = jnp.where(leaf_better, idx[j], bprim)
            # inner: test both children, descend into the nearer one, push the farther
            left, right = node + 1, off
            bl = bounds[jnp.stack([left, right])]
            ctn, _, chit = slab(bl[:, 0], bl[:, 1], o, inv, tmin, best)
            inner = ~is_leaf & ~skip
            hl, hr = inner & chit[0], inner & chit[1]
            l_first = ctn[0] <= ctn[1]
            near = jnp.where(hl & (~hr | l_first), left, right)
            tnear = jnp.where(near == left, ctn[0], ctn[1])
            far = jnp.where(near == left, right, left)
            tfar = jnp.where(near == left, ctn[1], ctn[0])
            both = hl & hr
            push = both & (sp < STACK_SIZE)
            sn = jnp.where(push, sn.at[sp].set(far), sn)
            st = jnp.where(push, st.at[sp].set(tfar), st)
            sp = sp + push.astype(jnp.int32)
            descend = hl | hr
            # otherwise pop
            empty = sp == 0
            top = jnp.maximum(sp - 1, 0)
            pop_node, pop_t = sn[top], st[top]
            node_new = jnp.where(descend, near, pop_node)
            t_new = jnp.where(descend, tnear, pop_t)
            sp = jnp.where(descend | empty, sp, sp - 1)
            done = (~descend & empty) | (any_hit & (bprim >= 0))
            return node_new, t_new, sp, sn, st, best, bprim, done

        out = jax.lax.while_loop(cond, body, init)
        return out[5], out[6]


def build_bvh(mesh: TriangleMesh, *, max_leaf: int = 4, n_bins: int = 16) -> BVH:
    """Build a :class:`BVH` over ``mesh`` on the host with the binned surface-area heuristic.

    At each node the triangle centroids are binned into ``n_bins`` buckets per axis and the
    split minimising ``A_L N_L + A_R N_R`` (surface areas of child boxes times triangle counts;
    Wald 2007, "On fast construction of SAH-based BVHs") is taken; a node with at most
    ``max_leaf`` triangles becomes a leaf when splitting does not lower the SAH cost, and nodes
    with more are always split (median split when all centroids coincide). Build time is
    ``O(F log F)`` NumPy work plus Python overhead per node (~0.3 s per 1e4 triangles).
    """
    if not isinstance(max_leaf, int) or not 1 <= max_leaf <= 16:
        raise ValueError(f"max_leaf: expected an integer in [1, 16], got {max_leaf!r}")
    if not isinstance(n_bins, int) or not 2 <= n_bins <= 256:
        raise ValueError(f"n_bins: expected an integer in [2, 256], got {n_bins!r}")
    tri = as_numpy_triangles(mesh)
    lo_all, hi_all = tri.min(1), tri.max(1)
    cen = 0.5 * (lo_all + hi_all)
    bounds, offset, count, order = [], [], [], []
    B = n_bins

    def build(ids, depth):
        me = len(bounds)
        lo, hi = lo_all[ids].min(0), hi_all[ids].max(0)
        bounds.append(np.stack([lo, hi]))
        offset.append(0)
        count.append(0)
        n = len(ids)
        best = (np.inf, -1, -1)
        c = cen[ids]
        clo, chi = c.min(0), c.max(0)
        if n > 1:
            for ax in range(3):
                ext = chi[ax] - clo[ax]
                if ext <= 0:
                    continue
                if n <= B:
                    # few triangles: sweep every split between sorted centroids (exact SAH)
                    s = np.argsort(c[:, ax], kind="stable")
                    blo, bhi = lo_all[ids[s]], hi_all[ids[s]]
                    cnt = np.ones(n, np.int64)
                    key = c[s, ax]
                    valid_split = key[1:] > key[:-1]
                else:
                    b = np.minimum(((c[:, ax] - clo[ax]) / ext * B).astype(np.int64), B - 1)
                    s = np.argsort(b, kind="stable")
                    bs = b[s]
                    starts = np.flatnonzero(np.r_[True, bs[1:] != bs[:-1]])
                    blo = np.minimum.reduceat(lo_all[ids[s]], starts, axis=0)
                    bhi = np.maximum.reduceat(hi_all[ids[s]], starts, axis=0)
                    cnt = np.diff(np.r_[starts, n])
                    key = bs[starts]
                    valid_split = np.ones(len(starts) - 1, bool)
                llo = np.minimum.accumulate(blo, 0)[:-1]
                lhi = np.maximum.accumulate(bhi, 0)[:-1]
                rlo = np.minimum.accumulate(blo[::-1], 0)[::-1][1:]
                rhi = np.maximum.accumulate(bhi[::-1], 0)[::-1][1:]
                nl = np.cumsum(cnt)[:-1]
                nr = n - nl
                cost = np.where(
                    valid_split,
                    nl * _half_area(llo, lhi) + nr * _half_area(rlo, rhi),
                    np.inf,
                )
                if len(cost) == 0:
                    continue
                k = int(np.argmin(cost))
                if cost[k] < best[0]:
                    # split value: centroid key threshold (left = key <= split)
                    best = (cost[k], ax, (n <= B, key[k]))
        leaf_cost = n * _half_area(lo, hi)
        if n <= max_leaf and not best[0] < leaf_cost:
            offset[me] = len(order)
            count[me] = n
            order.extend(ids.tolist())
            return me
        if best[1] < 0 or depth > STACK_SIZE - 8:
            # no usable SAH split (coincident centroids) or too deep: median split
            ax = int(np.argmax(chi - clo))
            s = np.argsort(c[:, ax], kind="stable")
            left, right = ids[s[: n // 2]], ids[s[n // 2 :]]
        else:
            _, ax, (exact, thr) = best
            if exact:
                m = c[:, ax] <= thr
            else:
                ext = chi[ax] - clo[ax]
                m = np.minimum(((c[:, ax] - clo[ax]) / ext * B).astype(np.int64), B - 1) <= thr
            left, right = ids[m], ids[~m]
        build(left, depth + 1)
        offset[me] = build(right, depth + 1)
        return me

    lim = sys.getrecursionlimit()
    sys.setrecursionlimit(max(lim, 10_000))
    try:
        build(np.arange(tri.shape[0]), 0)
    finally:
        sys.setrecursionlimit(lim)
    return BVH(
        mesh=mesh,
        bounds=jnp.asarray(np.asarray(bounds), mesh.vertices.dtype),
        offset=jnp.asarray(offset, jnp.int32),
        count=jnp.asarray(count, jnp.int32),
        prims=jnp.asarray(order, jnp.int32),
        max_leaf=max_leaf,
    )
