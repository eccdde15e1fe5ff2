# ruff: noqa: F722  (jaxtyping shape strings)
"""Top-level acceleration for instancing: a BVH over the instances' world-space boxes.

:func:`build_tlas` builds it on the host with the triangle BVH's binned-SAH builder
(:func:`.bvh_sah.build_bvh`, each box handed to it as a degenerate triangle whose bounds are the
box; one instance per leaf). Two traversals use it:

* :func:`two_level_trace` (JAX): ONE wavefront stack traversal through both levels, the
  pattern of :func:`.bvh_sah.wavefront_trace` with an instance index in each ray's state and on
  its stack. A top-level leaf switches the ray into the instance's space
  (``o' = A⁻¹(o − b)``, ``d' = A⁻¹ d``, NOT normalised, so a local ``t`` is the world ``t`` and
  the best hit, the stack's entry distances and ``tmin`` / ``tmax`` need no rescaling) and
  continues at the bottom-level root; popping a top-level node switches back. Each ray visits
  only the instances whose boxes it reaches before its best hit, nearest child first.
* :func:`tlas_candidates` (NumPy, for host engines such as Embree): all ``(ray, instance)``
  pairs whose box the ray meets in ``[tmin, tmax]``, by a vectorised breadth-first descent.

References: Wald 2007 (binned SAH, via :func:`.bvh_sah.build_bvh`); the two-level traversal
of instanced BVHs as in pbrt-v4 §7.1.4 ("Object instancing") and Embree's instance geometry
(Wald et al. 2014).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from jaxgfx.render.geometry.accel._common import STACK_SIZE, safe_inv, slab, tri_chunk
from jaxgfx.render.geometry.accel.bvh_sah import (
    _min_slot,
    _slab_reduced,
    build_bvh,
    near_far,
    next_node,
    pool_width,
)
from jaxgfx.render.geometry.mesh import TriangleMesh

__all__ = ["TopLevel", "build_tlas", "inv3", "tlas_candidates", "tlas_collect", "two_level_trace"]

# Two levels share one stack: room for a top-level path and a bottom-level one.
TWO_LEVEL_STACK = 2 * STACK_SIZE


class TopLevel(eqx.Module):
    """A BVH over ``K`` instance boxes (build with :func:`build_tlas`). Nodes depth-first as in
    :class:`.bvh_sah.BVH`: ``bounds (M, 2, 3)``; ``offset (M,)`` the right child of an inner
    node, the instance index of a leaf; ``leaf (M,)`` True for leaves (one instance each)."""

    bounds: Float[Array, "M 2 3"]
    offset: Int[Array, " M"]
    leaf: Array


def build_tlas(boxes) -> TopLevel:
    """Top-level BVH over world boxes ``(K, 2, 3)`` (min, max), built on the host with the
    binned-SAH builder, one instance per leaf."""
    bx = np.asarray(boxes, np.float64)
    if bx.ndim != 3 or bx.shape[1:] != (2, 3) or bx.shape[0] == 0:
        raise ValueError(f"boxes: expected shape (K, 2, 3) with K >= 1, got {bx.shape}")
    K = bx.shape[0]
    # box k as the degenerate triangle (lo, hi, hi): its bounds are the box, its centroid
    # (as the builder takes it, the bounds' centre) the box centre
    v = np.stack([bx[:, 0], bx[:, 1], bx[:, 1]], 1).reshape(-1, 3)
    f = np.arange(3 * K, dtype=np.int32).reshape(K, 3)
    b = build_bvh(TriangleMesh(jnp.asarray(v, jnp.float32), jnp.asarray(f)), max_leaf=1)
    count = np.asarray(b.count)
    off = np.asarray(b.offset)
    prims = np.asarray(b.prims)
    inst = np.where(count > 0, prims[np.minimum(off, K - 1)], off)
    # node boxes from the float64 boxes, rounded outwards to float32
    bounds = np.asarray(b.bounds, np.float64)
    lo = np.nextafter(bounds[:, 0].astype(np.float32), np.float32(-np.inf))
    hi = np.nextafter(bounds[:, 1].astype(np.float32), np.float32(np.inf))
    return TopLevel(
        bounds=jnp.asarray(np.stack([lo, hi], 1)),
        offset=jnp.asarray(inst, jnp.int32),
        leaf=jnp.asarray(count > 0),
    )


def tlas_candidates(bounds, offset, leaf, o, d, tmin, tmax):
    """Host (NumPy): every ``(ray, instance, entry t)`` whose instance box ray ``o + t d``
    (``o, d (N, 3)``, ``tmin, tmax (N,)``) meets for some ``t`` in ``[tmin, tmax]``; three
    arrays, in no particular order. Breadth-first over the top level, all rays at once."""
    bounds = np.asarray(bounds, np.float64)
    offset = np.asarray(offset)
    leaf = np.asarray(leaf)
    with np.errstate(divide="ignore"):
        inv = 1.0 / np.where(d == 0, np.where(np.signbit(d), -1e-30, 1e-30), d)

    def hit(nodes, rays):
        ta = (bounds[nodes, 0] - o[rays]) * inv[rays]
        tb = (bounds[nodes, 1] - o[rays]) * inv[rays]
        tn = np.maximum(np.minimum(ta, tb).max(1), tmin[rays])
        tf = np.minimum(np.maximum(ta, tb).min(1) * (1 + 1e-6), tmax[rays])
        return tn, tn <= tf

    rays = np.arange(o.shape[0])
    nodes = np.zeros_like(rays)
    tn, ok = hit(nodes, rays)
    rays, nodes, tn = rays[ok], nodes[ok], tn[ok]
    out_r, out_k, out_t = [], [], []
    while rays.size:
        lf = leaf[nodes]
        out_r.append(rays[lf])
        out_k.append(offset[nodes[lf]])
        out_t.append(tn[lf])
        rays, nodes = rays[~lf], nodes[~lf]
        rays = np.concatenate([rays, rays])
        nodes = np.concatenate([nodes + 1, offset[nodes]])
        tn, ok = hit(nodes, rays)
        rays, nodes, tn = rays[ok], nodes[ok], tn[ok]
    if not out_r:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(out_r), np.concatenate(out_k), np.concatenate(out_t)


def inv3(a):
    """Inverse of ``(..., 3, 3)`` matrices in closed form: the columns of ``A⁻¹`` are
    ``(a₁×a₂, a₂×a₀, a₀×a₁) / det A`` for the rows ``aᵢ`` of ``A`` (elementwise, differentiable).

    Used instead of ``jnp.linalg.inv``: on XLA CPU that is a LAPACK ``getrf`` custom call whose
    batch loop (``ParallelBatchMap``) waits on tasks it schedules on the intra-op thread pool;
    two such calls running at once on a 2-thread pool each held one thread and waited forever
    for the other's (the hang of the instanced Mitsuba comparison, issue 24; stacks in
    docs/render_geometry.md). Callers guarantee ``det A != 0`` (``Instances`` checks it)."""
    r0, r1, r2 = a[..., 0, :], a[..., 1, :], a[..., 2, :]
    c0, c1, c2 = jnp.cross(r1, r2), jnp.cross(r2, r0), jnp.cross(r0, r1)
    det = jnp.sum(r0 * c0, -1)
    return jnp.stack([c0, c1, c2], -1) / det[..., None, None]


def _step(top, blas, bounds, tris, inv_lin, shift, n, ray, s, any_hit):
    """One step of ONE ray through the two levels (see :func:`two_level_trace`). Nodes
    ``< nt`` are the top level's, ``nt + j`` the bottom level's node ``j``; ``inst`` is the
    instance whose space the current node lives in (``-1``: world, the top level)."""
    o, d, tmin = ray
    node, inst, tnode, sp, sn, si, st, best, bprim, done = s
    nt = top.bounds.shape[0]
    in_top = node < nt
    tn_ = jnp.minimum(node, nt - 1)
    bn_ = jnp.clip(node - nt, 0, blas.count.shape[0] - 1)
    k = jnp.maximum(inst, 0)
    # the ray in the current node's space (world at the top level)
    a = inv_lin[k]
    local = inst >= 0
    ol = jnp.where(local, a @ (o - shift[k]), o)
    dl = jnp.where(local, a @ d, d)
    inv = safe_inv(dl)
    skip = (tnode >= best) | done
    # bottom-level leaf: its max_leaf triangles
    L = blas.max_leaf
    ks = jnp.arange(L)
    cnt = jnp.where(in_top, 0, blas.count[bn_])
    off = blas.offset[bn_]
    b_leaf = cnt > 0
    idx = blas.prims[jnp.minimum(off + ks, blas.prims.shape[0] - 1)]
    tl, j = _min_slot(tri_chunk(tris, idx, ks < cnt, ol, dl, tmin, best, reduce=False))
    better = b_leaf & ~skip & (tl < best)
    best = jnp.where(better, tl, best)
    bprim = jnp.where(better, k * n + idx[jnp.minimum(j, L - 1)], bprim)
    # top-level leaf: enter the instance (its box was tested by the parent)
    t_leaf = in_top & top.leaf[tn_]
    enter = t_leaf & ~skip
    # inner node of either level: both children's boxes
    left = node + 1
    right = jnp.where(in_top, top.offset[tn_], nt + off)
    inner = ~skip & ~t_leaf & ~b_leaf
    bl = bounds[jnp.stack([left, jnp.minimum(right, bounds.shape[0] - 1)])]
    ctn, chit = _slab_reduced(bl[:, 0], bl[:, 1], ol, inv, tmin, best)
    hl, hr = inner & chit[0], inner & chit[1]
    near, tnear, far, tfar = near_far(hl, hr, ctn, left, right)
    push = hl & hr & (sp < TWO_LEVEL_STACK)
    sn = sn.at[sp].set(far, mode="drop")
    si = si.at[sp].set(inst, mode="drop")
    st = st.at[sp].set(tfar, mode="drop")
    sp = sp + push.astype(jnp.int32)
    descend = hl | hr
    empty = sp == 0
    top_ = jnp.maximum(sp - 1, 0)
    go = descend | enter
    node_new = jnp.where(done, node, jnp.where(enter, nt, jnp.where(descend, near, sn[top_])))
    inst_new = jnp.where(
        done, inst, jnp.where(enter, top.offset[tn_], jnp.where(descend, inst, si[top_]))
    )
    t_new = jnp.where(enter, tnode, jnp.where(descend, tnear, st[top_]))
    sp = jnp.where(go | empty | done, sp, sp - 1)
    done = done | (~go & empty) | (any_hit & (bprim >= 0))
    return node_new, inst_new, t_new, sp, sn, si, st, best, bprim, done


def _wavefront(o, d, tmin, tmax, root, width, slot0, load, step, out0, write):
    """The wavefront loop of :func:`.bvh_sah.wavefront_trace`, generic in the per-slot state.

    Rays ``o, d (N, 3)`` whose interval ``(tmin, tmax)`` meets the ``root (2, 3)`` box queue (in
    input order) for a pool of ``width`` slots. ``slot0``: the initial slot state (a tuple of
    ``(W, ...)`` arrays whose last entry is ``done``; all slots start done and empty);
    ``load(take, (o, d, tmin, t_entry, tmax), state)`` resets the slots ``take`` for the rays
    given; ``step((o, d, tmin), state)`` advances ONE slot (it is vmapped);
    ``write(out, dst, state)`` scatters the finished slots' results to rays ``dst`` (``N``:
    dropped). Returns ``out`` (``out0`` for the rays never queued)."""
    N = o.shape[0]
    W = pool_width(N) if width is None else max(1, min(width, N))
    tn, _, hit0 = slab(root[0], root[1], o, safe_inv(d), tmin, tmax)
    nq = jnp.sum(hit0, dtype=jnp.int32)
    pos = jnp.where(
        hit0,
        jnp.cumsum(hit0, dtype=jnp.int32) - 1,
        nq + jnp.cumsum(~hit0, dtype=jnp.int32) - 1,
    )
    perm = jnp.zeros(N, jnp.int32).at[pos].set(jnp.arange(N, dtype=jnp.int32))
    queue = tuple(x[perm] for x in (o, d, tmin, tn, tmax))
    vstep = jax.vmap(step)

    def body(c):
        ray, o, d, a, s, nxt, out = c
        done = s[-1]
        out = write(out, jnp.where(done & (ray >= 0), ray, N), s)
        rank = jnp.cumsum(done, dtype=jnp.int32) - 1
        new = nxt + rank
        take = done & (new < nq)
        g = jnp.minimum(new, N - 1)
        q = tuple(x[g] for x in queue)
        t3 = take[:, None]
        o, d = jnp.where(t3, q[0], o), jnp.where(t3, q[1], d)
        a = jnp.where(take, q[2], a)
        ray = jnp.where(take, perm[g], jnp.where(done, -1, ray))
        s = load(take, q, s)
        s = (*s[:-1], s[-1] & ~take)
        nxt = jnp.minimum(nxt + rank[-1] + 1, nq)
        s = vstep((o, d, a), s)
        return ray, o, d, a, s, nxt, out

    def cond(c):
        return (c[5] < nq) | jnp.any(c[0] >= 0)

    dt = o.dtype
    zi, zf, z3 = jnp.zeros(W, jnp.int32), jnp.zeros(W, dt), jnp.zeros((W, 3), dt)
    c = jax.lax.while_loop(cond, body, (zi - 1, z3, z3, zf, slot0, jnp.int32(0), out0))
    return c[-1]


def two_level_trace(top, blas, to_world, o, d, tmin, tmax, *, any_hit=False, width=None):
    """Closest (or, ``any_hit``, some) hit ``(t, prim)`` of world rays ``o, d (N, 3)`` in
    ``(tmin, tmax) (N,)`` against the instances ``to_world (K, 4, 4)`` of the triangle BVH
    ``blas`` (:class:`.bvh_sah.BVH`, local space) under the top level ``top``
    (:func:`build_tlas` over the instances' world boxes). ``prim = k · n + j`` (instance ``k``,
    triangle ``j`` of ``n``); ``-1`` and ``t = tmax`` where nothing is hit.

    The wavefront of :func:`.bvh_sah.wavefront_trace` (:func:`_wavefront`: a pool of ray
    slots refilled from the queue of rays that meet the top-level root box), stepping each slot
    through :func:`_step`: a top-level leaf moves the ray into its instance's space and on to
    the bottom-level root; pushed nodes remember their instance, so a pop returns to the right
    space. Not differentiable (the hit record is recomputed from ``prim``)."""
    N = o.shape[0]
    if N == 0:
        return tmax, jnp.zeros(0, jnp.int32)
    dt = o.dtype
    sg = jax.lax.stop_gradient
    m = sg(to_world).astype(dt)
    inv_lin = inv3(m[:, :3, :3])
    shift = m[:, :3, 3]
    n = blas.mesh.faces.shape[0]
    bounds = jnp.concatenate([sg(top.bounds).astype(dt), sg(blas.bounds).astype(dt)])
    tris = sg(blas.mesh.vertices)[blas.mesh.faces].astype(dt)
    W = pool_width(N) if width is None else max(1, min(width, N))
    zi, zf = jnp.zeros(W, jnp.int32), jnp.zeros(W, dt)
    S = TWO_LEVEL_STACK
    stacks = (jnp.zeros((W, S), jnp.int32), jnp.zeros((W, S), jnp.int32), jnp.zeros((W, S), dt))
    s0 = (zi, zi - 1, zf, zi, *stacks, zf, zi - 1, jnp.ones(W, bool))

    def load(take, q, s):
        node, inst, tnode, sp, sn, si, st, best, bprim, done = s
        node = jnp.where(take, 0, node)
        inst = jnp.where(take, -1, inst)
        tnode = jnp.where(take, q[3], tnode)
        sp = jnp.where(take, 0, sp)
        best = jnp.where(take, q[4], best)
        bprim = jnp.where(take, -1, bprim)
        return node, inst, tnode, sp, sn, si, st, best, bprim, done

    def step(ray, s):
        return _step(top, blas, bounds, tris, inv_lin, shift, n, ray, s, any_hit)

    def write(out, dst, s):
        return out[0].at[dst].set(s[7], mode="drop"), out[1].at[dst].set(s[8], mode="drop")

    out0 = (tmax, jnp.full(N, -1, jnp.int32))
    root = bounds[0]
    return _wavefront(o, d, tmin, tmax, root, W, s0, load, step, out0, write)


def _collect_step(top, bounds, C, ray, s):
    """One step of ONE ray of :func:`tlas_collect`: a leaf inserts its (instance, entry t)
    into the sorted list of the ``C`` nearest, an inner node descends into the nearer hit
    child and pushes the other; the stack is popped when there is nothing to descend into."""
    o, d, tmin = ray
    node, tnode, tmax, sp, sn, st, ck, ct, cnt, done = s
    inv = safe_inv(d)
    cs = jnp.arange(C)
    leaf = top.leaf[node] & ~done
    pos = jnp.sum(ct <= tnode)
    prev_k = jnp.concatenate([ck[:1], ck[:-1]])
    prev_t = jnp.concatenate([ct[:1], ct[:-1]])
    ins_k = jnp.where(cs < pos, ck, jnp.where(cs == pos, top.offset[node], prev_k))
    ins_t = jnp.where(cs < pos, ct, jnp.where(cs == pos, tnode, prev_t))
    ck = jnp.where(leaf, ins_k, ck)
    ct = jnp.where(leaf, ins_t, ct)
    cnt = cnt + leaf.astype(jnp.int32)
    left, right = node + 1, top.offset[node]
    bl = bounds[jnp.stack([left, jnp.minimum(right, bounds.shape[0] - 1)])]
    ctn, chit = _slab_reduced(bl[:, 0], bl[:, 1], o, inv, tmin, tmax)
    inner = ~top.leaf[node] & ~done
    hl, hr = inner & chit[0], inner & chit[1]
    node, tnode, sp, sn, st, finished = next_node(node, hl, hr, ctn, left, right, sp, sn, st,
                                                  done)  # fmt: skip
    done = done | finished
    return node, tnode, tmax, sp, sn, st, ck, ct, cnt, done


def tlas_collect(top, o, d, tmin, tmax, *, slots=8, width=None):
    """The instances whose boxes rays ``o, d (N, 3)`` meet in ``[tmin, tmax] (N,)``, nearest
    box entry first: ``(inst (N, slots) int32, entry t (N, slots), count (N,) int32)``.

    A stack traversal of the top level per ray (the wavefront :func:`_wavefront`, steps
    :func:`_collect_step`) that keeps the ``slots`` nearest entries in a sorted list
    (``inst = -1`` and ``t = inf`` in unused slots). ``count`` is the number of boxes met,
    which exceeds ``slots`` where entries were dropped: the caller completes those rays
    (:func:`tlas_candidates` on the host)."""
    N = o.shape[0]
    dt = o.dtype
    C = slots
    if N == 0:
        return jnp.zeros((0, C), jnp.int32), jnp.zeros((0, C), dt), jnp.zeros(0, jnp.int32)
    bounds = jax.lax.stop_gradient(top.bounds).astype(dt)
    W = pool_width(N) if width is None else max(1, min(width, N))
    zi, zf = jnp.zeros(W, jnp.int32), jnp.zeros(W, dt)
    s0 = (zi, zf, zf, zi, jnp.zeros((W, STACK_SIZE), jnp.int32), jnp.zeros((W, STACK_SIZE), dt),
          jnp.full((W, C), -1, jnp.int32), jnp.full((W, C), jnp.inf, dt), zi,
          jnp.ones(W, bool))  # fmt: skip

    def load(take, q, s):
        node, tnode, tmax, sp, sn, st, ck, ct, cnt, done = s
        t2 = take[:, None]
        return (jnp.where(take, 0, node), jnp.where(take, q[3], tnode),
                jnp.where(take, q[4], tmax), jnp.where(take, 0, sp), sn, st,
                jnp.where(t2, -1, ck), jnp.where(t2, jnp.inf, ct), jnp.where(take, 0, cnt),
                done)  # fmt: skip

    def step(ray, s):
        return _collect_step(top, bounds, C, ray, s)

    def write(out, dst, s):
        return tuple(x.at[dst].set(v, mode="drop") for x, v in zip(out, s[6:9], strict=True))

    out0 = (jnp.full((N, C), -1, jnp.int32), jnp.full((N, C), jnp.inf, dt),
            jnp.zeros(N, jnp.int32))  # fmt: skip
    return _wavefront(o, d, tmin, tmax, bounds[0], W, s0, load, step, out0, write)
