# ruff: noqa: F722  (jaxtyping shape strings)
"""Bounding volume hierarchy: binned-SAH build on the host, wavefront stack traversal in JAX."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from jaxgfx.render.geometry.accel._common import (
    _GROW,
    STACK_SIZE,
    TriangleAccel,
    as_numpy_triangles,
    flat_rays,
    safe_inv,
    slab,
    tri_chunk,
)
from jaxgfx.render.geometry.mesh import TriangleMesh

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
    Queries run the wavefront traversal :func:`wavefront_trace`.
    """

    mesh: TriangleMesh
    bounds: Float[Array, "M 2 3"]
    offset: Int[Array, " M"]
    count: Int[Array, " M"]
    prims: Int[Array, " F"]
    max_leaf: int = eqx.field(static=True)

    def _run(self, o, d, tmin, tmax, any_hit):
        o, d, batch, (O, D, TMIN, TMAX) = flat_rays(o, d, tmin, tmax)
        t, prim = wavefront_trace(self, O, D, TMIN, TMAX, any_hit=any_hit)
        return o, d, t.reshape(batch), prim.reshape(batch)


# Most slots of the wavefront pool (see :func:`pool_width`).
WAVEFRONT_WIDTH = 1024


def _min_slot(t):
    """``(min, first argmin)`` over the last axis of ``t`` as ONE variadic reduction.

    XLA CPU fuses an elementwise chain into each of its consumers: with an unrolled minimum,
    the Möller-Trumbore test that feeds the step's eight outputs was recomputed in six fused
    kernels. A reduction's result is materialised once."""
    k = jnp.arange(t.shape[-1], dtype=jnp.int32)

    def pick(a, b):
        first = (a[0] < b[0]) | ((a[0] == b[0]) & (a[1] < b[1]))
        return jnp.where(first, a[0], b[0]), jnp.where(first, a[1], b[1])

    init = (jnp.array(jnp.inf, t.dtype), jnp.int32(t.shape[-1]))
    return jax.lax.reduce((t, k), init, pick, (t.ndim - 1,))


def near_far(hl, hr, ctn, left, right):
    """Which child to visit first: ``(near, tnear, far, tfar)`` from the two children's hit
    flags ``hl``, ``hr`` and entry distances ``ctn (2, ...)`` (the left one on ties)."""
    l_first = ctn[0] <= ctn[1]
    near = jnp.where(hl & (~hr | l_first), left, right)
    tnear = jnp.where(near == left, ctn[0], ctn[1])
    far = jnp.where(near == left, right, left)
    tfar = jnp.where(near == left, ctn[1], ctn[0])
    return near, tnear, far, tfar


def next_node(node, hl, hr, ctn, left, right, sp, sn, st, done):
    """One stack step of a BVH traversal: descend into the nearer hit child (pushing the
    other when both are hit) or pop the stack. Returns ``(node, t_node, sp, sn, st,
    finished)``; ``finished``: nothing hit and the stack empty."""
    near, tnear, far, tfar = near_far(hl, hr, ctn, left, right)
    push = hl & hr & (sp < STACK_SIZE)
    # The slot above the top is free: write it unconditionally (an index past the end is
    # dropped), an in-place update of the loop carry.
    sn = sn.at[sp].set(far, mode="drop")
    st = st.at[sp].set(tfar, mode="drop")
    sp = sp + push.astype(jnp.int32)
    descend = hl | hr
    empty = sp == 0
    top = jnp.maximum(sp - 1, 0)
    node_new = jnp.where(done, node, jnp.where(descend, near, sn[top]))
    t_new = jnp.where(descend, tnear, st[top])
    sp = jnp.where(descend | empty | done, sp, sp - 1)
    return node_new, t_new, sp, sn, st, ~descend & empty


def _slab_reduced(bmin, bmax, o, inv, t0, t1):
    """:func:`slab`'s ``(tn, hit)`` with the per-axis max and min as one reduction (materialised,
    like :func:`_min_slot`)."""
    ta = (bmin - o) * inv
    tb = (bmax - o) * inv
    lo, hi = jax.lax.reduce(
        (jnp.minimum(ta, tb), jnp.maximum(ta, tb)),
        (jnp.array(-jnp.inf, o.dtype), jnp.array(jnp.inf, o.dtype)),
        lambda a, b: (jnp.maximum(a[0], b[0]), jnp.minimum(a[1], b[1])),
        (ta.ndim - 1,),
    )
    tn = jnp.maximum(lo, t0)
    tf = jnp.minimum(hi * _GROW[jnp.dtype(o.dtype)], t1)
    return tn, tn <= tf


def _step(bvh, tris, bounds, ray, s, any_hit, materialize=True):
    """One traversal step of ONE ray ``ray = (o, d, 1/d, tmin)`` with state ``s = (node, its
    entry t, stack pointer, node stack, t stack, best t, best prim, done)``; a no-op for a
    finished ray. An inner node tests both child boxes, descends into the nearer hit child and
    pushes the farther one; a leaf tests its ``max_leaf`` slots; a node entered beyond the best
    hit is skipped; the stack is popped when there is nothing to descend into.
    ``materialize=False``: the leaf and child tests as unrolled elementwise code (the
    traversal before issue 13; kept for the ablation in benchmarks/accel.py)."""
    o, d, inv, tmin = ray
    node, tnode, sp, sn, st, best, bprim, done = s
    L = bvh.max_leaf
    ks = jnp.arange(L)
    cnt = bvh.count[node]
    off = bvh.offset[node]
    is_leaf = cnt > 0
    skip = (tnode >= best) | done
    idx = bvh.prims[jnp.minimum(off + ks, bvh.prims.shape[0] - 1)]
    if materialize:
        tl, j = _min_slot(tri_chunk(tris, idx, ks < cnt, o, d, tmin, best, reduce=False))
    else:
        tl, j = tri_chunk(tris, idx, ks < cnt, o, d, tmin, best)
    leaf_better = is_leaf & ~skip & (tl < best)
    best = jnp.where(leaf_better, tl, best)
    bprim = jnp.where(leaf_better, idx[jnp.minimum(j, L - 1)], bprim)
    left, right = node + 1, off
    bl = bounds[jnp.stack([left, right])]
    if materialize:
        ctn, chit = _slab_reduced(bl[:, 0], bl[:, 1], o, inv, tmin, best)
    else:
        ctn, _, chit = slab(bl[:, 0], bl[:, 1], o, inv, tmin, best)
    inner = ~is_leaf & ~skip
    hl, hr = inner & chit[0], inner & chit[1]
    node_new, t_new, sp, sn, st, finished = next_node(node, hl, hr, ctn, left, right, sp, sn,
                                                      st, done)  # fmt: skip
    done = done | finished | (any_hit & (bprim >= 0))
    return node_new, t_new, sp, sn, st, best, bprim, done


def pool_width(n_rays: int) -> int:
    """Slots of the wavefront pool for ``n_rays`` rays: 1/16 of the rays, within [256, 1024]
    (and at most ``n_rays``). Measured on XLA CPU (benchmarks/accel.py, docs/performance.md):
    wider pools step more finished slots in the tail, narrower ones pay the per-iteration
    overhead more often; extra narrower pools for the tail gained under 10 % and cost one more
    compiled step each."""
    return max(1, min(n_rays, WAVEFRONT_WIDTH, max(n_rays // 16, 256)))


def wavefront_trace(bvh, o, d, tmin, tmax, *, any_hit=False, width=None, materialize=True):
    """Closest (or, ``any_hit``, some) hit ``(t, prim)`` of rays ``o, d (N, 3)`` in
    ``(tmin, tmax) (N,)`` against ``bvh`` (``prim = -1``, ``t = tmax`` where nothing is hit).

    A wavefront traversal that only steps active rays. Rays that miss the root box are
    answered at once; the others queue for a pool of ``width`` slots (default
    :func:`pool_width`). Each loop iteration writes out the results of the finished slots,
    refills them with the next queued rays (a prefix sum over the free slots ranks them) and
    advances every slot by one :func:`_step`. The loop runs ~sum(steps) / width + max(steps)
    iterations of ``width`` rays, where a per-ray ``while_loop`` under ``vmap`` runs max(steps)
    iterations of all N rays. Each ray visits the nodes in the order of :func:`_step`'s stack
    traversal, so hits do not depend on the pool. Not differentiable (the hit record is
    recomputed from ``prim``)."""
    N = o.shape[0]
    if N == 0:
        return tmax, jnp.zeros(0, jnp.int32)
    W = pool_width(N) if width is None else max(1, min(width, N))
    dt = o.dtype
    sg = jax.lax.stop_gradient
    bounds = sg(bvh.bounds).astype(dt)
    tris = sg(bvh.mesh.vertices)[bvh.mesh.faces].astype(dt)
    inv = safe_inv(d)
    tn, _, hit0 = slab(bounds[0, 0], bounds[0, 1], o, inv, tmin, tmax)
    # the queue: the rays that hit the root box, in input order (a stable partition by two
    # prefix sums; XLA's CPU argsort of the same boolean key cost ~4 % of a trace)
    nq = jnp.sum(hit0, dtype=jnp.int32)
    pos = jnp.where(
        hit0,
        jnp.cumsum(hit0, dtype=jnp.int32) - 1,
        nq + jnp.cumsum(~hit0, dtype=jnp.int32) - 1,
    )
    perm = jnp.zeros(N, jnp.int32).at[pos].set(jnp.arange(N, dtype=jnp.int32))
    queue = tuple(x[perm] for x in (o, d, inv, tmin, tn, tmax))
    step = jax.vmap(lambda ray, s: _step(bvh, tris, bounds, ray, s, any_hit, materialize))

    def writeout(ray, best, bprim, done, out):
        dst = jnp.where(done & (ray >= 0), ray, N)
        return out[0].at[dst].set(best, mode="drop"), out[1].at[dst].set(bprim, mode="drop")

    def body(c):
        ray, o, d, inv, a, s, nxt, out = c
        node, tnode, sp, sn, st, best, bprim, done = s
        out = writeout(ray, best, bprim, done, out)
        rank = jnp.cumsum(done, dtype=jnp.int32) - 1
        new = nxt + rank
        take = done & (new < nq)
        g = jnp.minimum(new, N - 1)
        o_q, d_q, inv_q, a_q, tn_q, b_q = (q[g] for q in queue)
        t3 = take[:, None]
        o, d, inv = jnp.where(t3, o_q, o), jnp.where(t3, d_q, d), jnp.where(t3, inv_q, inv)
        a = jnp.where(take, a_q, a)
        ray = jnp.where(take, perm[g], jnp.where(done, -1, ray))
        node = jnp.where(take, 0, node)
        tnode = jnp.where(take, tn_q, tnode)
        sp = jnp.where(take, 0, sp)
        best = jnp.where(take, b_q, best)
        bprim = jnp.where(take, -1, bprim)
        done = done & ~take
        nxt = jnp.minimum(nxt + rank[-1] + 1, nq)
        s = step((o, d, inv, a), (node, tnode, sp, sn, st, best, bprim, done))
        return ray, o, d, inv, a, s, nxt, out

    def cond(c):
        return (c[6] < nq) | jnp.any(c[0] >= 0)

    zi, zf, z3 = jnp.zeros(W, jnp.int32), jnp.zeros(W, dt), jnp.zeros((W, 3), dt)
    stacks = jnp.zeros((W, STACK_SIZE), jnp.int32), jnp.zeros((W, STACK_SIZE), dt)
    s0 = (zi, zf, zi, *stacks, zf, zi - 1, jnp.ones(W, bool))
    out = (tmax, jnp.full(N, -1, jnp.int32))
    c = jax.lax.while_loop(cond, body, (zi - 1, z3, z3, z3, zf, s0, jnp.int32(0), out))
    return c[-1]


def _seg_reduce(ufunc, x, offsets):
    return ufunc.reduceat(x, offsets, axis=0)


def build_bvh(mesh: TriangleMesh, *, max_leaf: int = 4, n_bins: int = 16) -> BVH:
    """Build a :class:`BVH` over ``mesh`` on the host with the binned surface-area heuristic.

    At each node the triangle centroids are binned into ``n_bins`` buckets per axis and the
    split minimising ``A_L N_L + A_R N_R`` (surface areas of child boxes times triangle counts;
    Wald 2007, "On fast construction of SAH-based BVHs") is taken. A node with at most
    ``max_leaf`` triangles is always a leaf (traversal tests all ``max_leaf`` slots of a leaf
    in one loop iteration, so smaller leaves only add iterations: at 1e4 triangles this was
    1.7x faster than SAH-terminated 1-triangle leaves); nodes with more are always split
    (median split along the widest centroid extent when no binned split separates them, or
    beyond depth 56 to bound the traversal stack). The build is level-synchronous and
    vectorised in NumPy (all nodes of one depth at once); nodes are then renumbered
    depth-first.
    """
    if not isinstance(max_leaf, int) or not 1 <= max_leaf <= 16:
        raise ValueError(f"max_leaf: expected an integer in [1, 16], got {max_leaf!r}")
    if not isinstance(n_bins, int) or not 2 <= n_bins <= 256:
        raise ValueError(f"n_bins: expected an integer in [2, 256], got {n_bins!r}")
    tri = as_numpy_triangles(mesh)
    F = tri.shape[0]
    lo_all, hi_all = tri.min(1), tri.max(1)
    cen = 0.5 * (lo_all + hi_all)
    B = n_bins
    perm = np.arange(F)
    # BFS node records
    n_lo, n_hi, n_left, n_right, n_first, n_count = [], [], [], [], [], []
    seg_start = np.array([0])
    seg_end = np.array([F])
    seg_node = np.array([0])
    n_nodes = 1
    depth = 0
    rec = {}
    while len(seg_start):
        S = len(seg_start)
        sizes = seg_end - seg_start
        offs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        total = int(sizes.sum())
        seg = np.repeat(np.arange(S), sizes)
        pos = np.repeat(seg_start - offs, sizes) + np.arange(total)
        idx = perm[pos]
        lo, hi, c = lo_all[idx], hi_all[idx], cen[idx]
        blo = _seg_reduce(np.minimum, lo, offs)
        bhi = _seg_reduce(np.maximum, hi, offs)
        clo = _seg_reduce(np.minimum, c, offs)
        chi = _seg_reduce(np.maximum, c, offs)
        cext = chi - clo
        safe_ext = np.where(cext > 0, cext, 1.0)
        bins = np.minimum(((c - clo[seg]) / safe_ext[seg] * B).astype(np.int64), B - 1)
        costs = np.full((S, 3, B - 1), np.inf)
        for ax in range(3):
            key = seg * B + bins[:, ax]
            order = np.argsort(key, kind="stable")
            ks = key[order]
            starts = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
            u = ks[starts]
            dlo = np.full((S * B, 3), np.inf)
            dhi = np.full((S * B, 3), -np.inf)
            dlo[u] = np.minimum.reduceat(lo[order], starts, axis=0)
            dhi[u] = np.maximum.reduceat(hi[order], starts, axis=0)
            cnt = np.bincount(key, minlength=S * B).reshape(S, B)
            dlo, dhi = dlo.reshape(S, B, 3), dhi.reshape(S, B, 3)
            llo = np.minimum.accumulate(dlo, 1)[:, :-1]
            lhi = np.maximum.accumulate(dhi, 1)[:, :-1]
            rlo = np.minimum.accumulate(dlo[:, ::-1], 1)[:, ::-1][:, 1:]
            rhi = np.maximum.accumulate(dhi[:, ::-1], 1)[:, ::-1][:, 1:]
            nl = np.cumsum(cnt, 1)[:, :-1]
            nr = sizes[:, None] - nl
            with np.errstate(invalid="ignore"):
                cst = nl * _half_area(llo, lhi) + nr * _half_area(rlo, rhi)
            costs[:, ax] = np.where((nl > 0) & (nr > 0) & (cext[:, ax : ax + 1] > 0), cst, np.inf)
        flat = costs.reshape(S, -1)
        best = flat.argmin(1)
        best_cost = flat[np.arange(S), best]
        best_ax, best_k = best // (B - 1), best % (B - 1)
        # a leaf costs one loop iteration whatever its size (max_leaf slots are always tested),
        # so nodes that fit are never split
        is_leaf = sizes <= max_leaf
        median = ~is_leaf & (~np.isfinite(best_cost) | (depth > STACK_SIZE - 8))
        side = bins[np.arange(total), best_ax[seg]] > best_k[seg]
        if median.any():
            max_ax = np.argmax(cext, 1)
            val = c[np.arange(total), max_ax[seg]]
            o2 = np.lexsort((val, seg))
            rank = np.empty(total, np.int64)
            rank[o2] = np.arange(total) - offs[seg[o2]]
            med_side = rank >= (sizes[seg] // 2)
            side = np.where(median[seg], med_side, side)
        # stable partition inside each segment: left (side 0) first
        order = np.argsort(seg * 2 + side, kind="stable")
        perm[pos] = idx[order]
        n_left_seg = np.bincount(seg, weights=~side, minlength=S).astype(np.int64)
        split = ~is_leaf
        n_split = int(split.sum())
        left_ids = n_nodes + 2 * np.arange(n_split)
        for arr, vals in (
            (n_lo, blo),
            (n_hi, bhi),
            (n_first, seg_start),
            (n_count, np.where(is_leaf, sizes, 0)),
        ):
            arr.append(vals)
        lid = np.full(S, -1)
        lid[split] = left_ids
        n_left.append(lid)
        n_right.append(np.where(split, lid + 1, -1))
        rec.setdefault("node", []).append(seg_node)
        n_nodes += 2 * n_split
        ss, se, sl = seg_start[split], seg_end[split], n_left_seg[split]
        seg_start = np.stack([ss, ss + sl], 1).reshape(-1)
        seg_end = np.stack([ss + sl, se], 1).reshape(-1)
        seg_node = np.stack([left_ids, left_ids + 1], 1).reshape(-1)
        depth += 1
    node_ids = np.concatenate(rec["node"])
    M = n_nodes
    lo_b, hi_b = np.empty((M, 3)), np.empty((M, 3))
    left, first, count = np.empty(M, np.int64), np.empty(M, np.int64), np.empty(M, np.int64)
    lo_b[node_ids] = np.concatenate(n_lo)
    hi_b[node_ids] = np.concatenate(n_hi)
    left[node_ids] = np.concatenate(n_left)
    first[node_ids] = np.concatenate(n_first)
    count[node_ids] = np.concatenate(n_count)
    # depth-first renumbering: left child directly after its parent
    dfs = np.empty(M, np.int64)
    new_of = np.empty(M, np.int64)
    stack = [0]
    k = 0
    left_l = left.tolist()
    while stack:
        i = stack.pop()
        dfs[k] = i
        new_of[i] = k
        k += 1
        if left_l[i] >= 0:
            stack.append(left_l[i] + 1)
            stack.append(left_l[i])
    offset = np.where(count[dfs] > 0, first[dfs], new_of[np.maximum(left[dfs] + 1, 0)])
    return BVH(
        mesh=mesh,
        bounds=jnp.asarray(np.stack([lo_b[dfs], hi_b[dfs]], 1), mesh.vertices.dtype),
        offset=jnp.asarray(offset, jnp.int32),
        count=jnp.asarray(count[dfs], jnp.int32),
        prims=jnp.asarray(perm, jnp.int32),
        max_leaf=max_leaf,
    )
