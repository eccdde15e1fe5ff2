# ruff: noqa: F722  (jaxtyping shape strings)
"""Linear curves (Mitsuba 3's ``linearcurve`` shape): :class:`LinearCurves`, tubes swept by a
sphere whose centre and radius vary linearly between consecutive control points, and the
curve text file format (:func:`read_curves`).

Conventions (Mitsuba 3's ``linearcurve`` plugin documentation and its 3.9.1 behaviour,
measured in ``tests/render/test_curves.py``):

* file: one control point per line, ``x y z radius``; an empty line starts a new curve; a curve
  needs at least two points; ``to_world`` moves the positions, the radii are left as they are.
* geometry: segment ``k`` joins control points ``a = P_i``, ``b = P_{i+1}`` of one curve; it
  is the convex hull of the balls ``(a, r_a)`` and ``(b, r_b)`` ("round cone": a cone tangent to
  both balls, closed by spherical caps), so consecutive segments meet in a round joint and the
  curve ends in a spherical end cap.
* only front faces are hit (Mitsuba culls the back faces of curves): a ray whose origin is
  inside a segment's solid does not hit that segment.
* hit record: with ``s ∈ [0, 1]`` the parameter of the swept sphere that touches the surface at
  ``p`` (``c(s) = a + s (b - a)``, ``r(s) = r_a + s (r_b - r_a)``; ``s`` is 0 or 1 on the caps),
  the normal is ``normalize(p - c(s))`` (geometric = shading normal), ``uv = (u, v)`` with ``u``
  around the curve, ``atan2(n·e_rot, n·e_rad) / 2π`` in ``[0, 1)`` (``e_rot`` the unit part of
  ``+z`` across the segment's axis ``e``, or ``+y`` for an axis along ``z``;
  ``e_rad = e_rot × e``) and ``v = (s + k) / K`` along the curves (``K`` segments in all);
  ``dp/du = 2π e × (p - c(s))``, ``dp/dv = K ((b - a) + (r_b - r_a) n)``
  (:meth:`LinearCurves.tangents`).

Intersection (exact, per segment): with ``q = x - a``, ``L² = |b - a|²``, ``Δr = r_b - r_a``,
the squared power ``F(x, s) = |q - s (b - a)|² - r(s)²`` is a convex quadratic in ``s`` when
``D = L² - Δr² > 0``; its minimum over ``s`` is at ``s*(x) = (q·(b - a) + r_a Δr) / D`` and the
round cone is ``{x : F(x, clamp(s*, 0, 1)) ≤ 0}``. Along a ray, ``D F(x, s*) = 0`` is a
quadratic in ``t`` (the cone's envelope); the segment's entry point is the nearest of the
envelope's entering roots with ``s* ∈ [0, 1]`` and the entering roots of the two balls (the
solid is convex, so that minimum is where the ray enters it). ``D ≤ 0`` (one ball inside the
other, or a zero-length segment) leaves the two balls. A BVH over the segments' boxes
(:func:`~jaxgfx.render.geometry.accel.build_bvh` on box proxies) finds the nearest segment; the
hit record re-intersects that segment with live parameters, so ``t``, ``p``, ``n`` and ``uv``
are differentiable w.r.t. control points and radii for the segment that was hit (the
visibility term of moving silhouettes is not: see docs/render_gradients.md).
"""

from __future__ import annotations

import math
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from jaxgfx._math import safe_atan2, safe_div, safe_normalize, safe_sqrt, sum_last
from jaxgfx.render.geometry._points import as_points
from jaxgfx.render.geometry.accel.bvh_sah import STACK_SIZE, build_bvh, next_node, safe_inv, slab
from jaxgfx.render.geometry.mesh import TriangleMesh
from jaxgfx.render.geometry.ray import Hit, hit_record, prepare_rays

__all__ = ["LinearCurves", "read_curves", "write_curves", "curve_lists", "round_cone_entry"]


def read_curves(path, *, min_points=2, kind="linear"):
    """``(points (N, 4) float64, starts)`` of a curve text file: ``x y z radius`` per line,
    curves separated by empty lines; ``starts`` is the index of each curve's first point.
    ``ValueError`` naming the file and line for unparsable or non-finite lines, curves with
    fewer than ``min_points`` points, negative radii and empty files."""
    path = os.fspath(path)
    with open(path) as f:
        lines = f.read().split("\n")
    pts, starts, new = [], [], True

    def finish(line_no):
        if not new and len(pts) - starts[-1] < min_points:
            raise ValueError(f"{path}:{line_no}: a {kind} curve needs at least {min_points} "
                             f"control points, this one has {len(pts) - starts[-1]}")  # fmt: skip

    for i, line in enumerate(lines, 1):
        s = line.strip()
        if not s:
            finish(i)
            new = True
            continue
        try:
            vals = [float(x) for x in s.split()]
        except ValueError:
            vals = []
        if len(vals) != 4 or not all(math.isfinite(v) for v in vals):
            raise ValueError(f"{path}:{i}: expected 4 finite numbers 'x y z radius', got {s!r}")
        if vals[3] < 0:
            raise ValueError(f"{path}:{i}: negative radius {vals[3]}")
        if new:
            starts.append(len(pts))
            new = False
        pts.append(vals)
    finish(len(lines))
    if not pts:
        raise ValueError(f"{path}: empty curve file (no control points)")
    return np.asarray(pts, np.float64), starts


def write_curves(path, curves) -> None:
    """Write ``curves`` (a list of ``(n_i, 4)`` arrays of ``x y z radius``) as a curve text
    file (:func:`read_curves`), curves separated by empty lines."""
    blocks = ["\n".join(" ".join(repr(float(x)) for x in row) for row in np.asarray(c))
              for c in curves]  # fmt: skip
    with open(path, "w") as f:
        f.write("\n\n".join(blocks) + "\n")


def curve_lists(shape) -> list:
    """The curves of a :class:`LinearCurves` as lists of ``[x, y, z, radius]`` rows (runs of
    consecutive segments are one curve)."""
    pts = np.asarray(shape.points, np.float64)
    out, prev = [], None
    for i in np.asarray(shape.segments).tolist():
        if prev is None or i != prev + 1:
            out.append([pts[i].tolist()])
        out[-1].append(pts[i + 1].tolist())
        prev = i
    return out


def round_cone_entry(a, ra, b, rb, o, d, start_cap=True):
    """``(t, s)``: where rays ``o, d (..., 3)`` enter the convex hull of the balls
    ``(a, ra)``, ``(b, rb)`` (broadcast), and the swept-sphere parameter ``s ∈ [0, 1]`` there.
    ``t = inf`` when the ray's line misses; ``t`` may be negative (entry behind the origin,
    or the origin inside). ``start_cap`` (bool, broadcast) False leaves out the ball at ``a``
    (a segment that continues a curve: the previous segment's end ball is the same ball). A
    zero-length segment (``a = b``) is never hit (as in Mitsuba 3.9.1 / Embree). Finite values
    and gradients everywhere (see the module docstring)."""
    ba = b - a
    dr = rb - ra
    L2 = sum_last(ba * ba)
    D = L2 - dr * dr
    cone = D > 1e-12 * jnp.maximum(L2, 1e-30)
    Ds = jnp.where(cone, D, 1.0)
    q0 = o - a
    # D F(o + t d, s*) = D (|q|² - ra²) - (q·ba + ra dr)² = A t² + 2 B t + C
    m = sum_last(q0 * ba) + ra * dr
    md = sum_last(d * ba)
    qq, qd = sum_last(q0 * q0), sum_last(q0 * d)
    A = Ds - md * md
    B = Ds * qd - m * md
    C = Ds * (qq - ra * ra) - m * m
    disc = B * B - A * C
    h = safe_sqrt(disc)
    qr = -(B + jnp.where(B >= 0, h, -h))
    t1 = safe_div(qr, A, fill=jnp.inf)
    t2 = safe_div(C, qr, fill=jnp.inf)
    inf = jnp.full_like(t1, jnp.inf)
    best, best_s = inf, jnp.zeros_like(t1)
    for t in (t1, t2):
        ok = cone & (disc >= 0) & jnp.isfinite(t) & (jnp.abs(A) > 0)
        tt = jnp.where(ok, t, 0.0)
        s = (m + tt * md) / Ds
        x = q0 + tt[..., None] * d
        n = x - s[..., None] * ba
        entering = sum_last(n * d) < 0
        ok = ok & (s >= 0) & (s <= 1) & entering
        better = ok & (tt < best)
        best = jnp.where(better, tt, best)
        best_s = jnp.where(better, s, best_s)
    for c, r, sv, on in ((a, ra, 0.0, start_cap), (b, rb, 1.0, True)):
        f = o - c
        bb = sum_last(f * d)
        g = f - bb[..., None] * d
        dd = r * r - sum_last(g * g)
        t = -bb - safe_sqrt(dd)
        better = on & (L2 > 0) & (dd >= 0) & (t < best)
        best = jnp.where(better, t, best)
        best_s = jnp.where(better, sv, best_s)
    return best, best_s


def _segment_frame(axis):
    """Mitsuba's consistent frame ``(e_rot, e_rad)`` around a unit segment axis."""
    z = jnp.zeros_like(axis).at[..., 2].set(1.0)
    v = z - axis * sum_last(axis * z)[..., None]
    singular = jnp.abs(axis[..., 2]) >= 1.0
    y = jnp.zeros_like(axis).at[..., 1].set(1.0)
    e_rot = jnp.where(singular[..., None], y, safe_normalize(v))
    return e_rot, jnp.cross(e_rot, axis)


class LinearCurves(eqx.Module):
    """Linear curves as a shape of :func:`~jaxgfx.render.geometry.intersect_scene` (the
    custom-shape protocol ``closest_t`` / ``hit``), in world space.

    ``points (N, 4)``: control points ``x, y, z, radius`` of all curves (differentiable
    leaves); ``segments (K,)``: index of each segment's first point (the segment joins points
    ``i`` and ``i + 1``); ``bvh``: a BVH over the segments' boxes, built on the host by the
    constructor (its boxes are those of the points given; re-create the shape after moving
    points by more than the gradient step of an optimisation). See the module docstring.

    Example: ``LinearCurves([[-1, 0, 0, .1], [1, 0, 0, .1]])`` (one curve) and the ray from
    ``(0, 0, -1)`` along ``+z`` hits at ``t = 0.9`` with ``uv = (0.75, 0.5)``.
    """

    points: Float[Array, "N 4"]
    segments: Int[Array, " K"]
    start_cap: Bool[Array, " K"]
    bounds: Float[Array, "M 2 3"]
    offset: Int[Array, " M"]
    count: Int[Array, " M"]
    prims: Int[Array, " K"]
    max_leaf: int = eqx.field(static=True, default=4)

    def __init__(self, points, segments=None, *, max_leaf=4):
        p = as_points(jnp.asarray(points), "points", 4)
        if not isinstance(p, jax.core.Tracer) and bool(jnp.any(p[:, 3] < 0)):
            raise ValueError("points: radii (the 4th column) must be >= 0")
        n = p.shape[0]
        if segments is None:
            segments = np.arange(n - 1)
        seg = np.asarray(segments, np.int64).reshape(-1)
        if seg.size == 0 or n < 2:
            raise ValueError("points: a curve needs at least two control points (one segment)")
        if seg.min() < 0 or seg.max() > n - 2:
            raise ValueError(f"segments: indices must lie in [0, {n - 2}] (a segment joins "
                             "points i and i + 1)")  # fmt: skip
        self.points = p
        self.segments = jnp.asarray(seg, jnp.int32)
        # Embree's rule (Mitsuba's backend): a segment draws its start ball only when no
        # segment ends where it starts (it begins a curve)
        self.start_cap = jnp.asarray(~np.isin(seg - 1, seg))
        pn = np.asarray(jax.lax.stop_gradient(p), np.float64)
        a, b = pn[seg], pn[seg + 1]
        lo = np.minimum(a[:, :3] - a[:, 3:], b[:, :3] - b[:, 3:])
        hi = np.maximum(a[:, :3] + a[:, 3:], b[:, :3] + b[:, 3:])
        proxy = TriangleMesh(  # one triangle per box: its vertices' bounds are the box
            np.stack([lo, hi, hi], 1).reshape(-1, 3),
            np.arange(3 * seg.size).reshape(-1, 3),
        )
        bvh = build_bvh(proxy, max_leaf=max_leaf)
        self.bounds = bvh.bounds.astype(p.dtype)
        self.offset, self.count, self.prims = bvh.offset, bvh.count, bvh.prims
        self.max_leaf = max_leaf

    @property
    def segment_count(self) -> int:
        return int(self.segments.shape[0])

    def _ends(self, pts, k):
        i = self.segments[k]
        c0, c1 = pts[i], pts[i + 1]
        return c0[..., :3], c0[..., 3], c1[..., :3], c1[..., 3], self.start_cap[k]

    def _trace_one(self, pts, o, d, tmin, tmax):
        """Nearest ``(t, segment)`` of ONE ray (stack traversal of the segments' BVH)."""
        inv = safe_inv(d)
        L = self.max_leaf
        ks = jnp.arange(L)
        zero_i = jnp.int32(0)
        _, _, hit0 = slab(self.bounds[0, 0], self.bounds[0, 1], o, inv, tmin, tmax)
        sn = jnp.zeros(STACK_SIZE, jnp.int32)
        st = jnp.zeros(STACK_SIZE, o.dtype)
        s0 = (zero_i, tmin, zero_i, sn, st, tmax, jnp.int32(-1), ~hit0)

        def body(s):
            node, tnode, sp, sn, st, best, bprim, done = s
            cnt, off = self.count[node], self.offset[node]
            is_leaf = cnt > 0
            skip = (tnode >= best) | done
            idx = self.prims[jnp.minimum(off + ks, self.prims.shape[0] - 1)]
            a, ra, b, rb, cap = self._ends(pts, idx)
            t, _ = round_cone_entry(a, ra, b, rb, o, d, cap)
            t = jnp.where((ks < cnt) & (t > tmin) & (t < best), t, jnp.inf)
            j = jnp.argmin(t)
            leaf_better = is_leaf & ~skip & (t[j] < best)
            best = jnp.where(leaf_better, t[j], best)
            bprim = jnp.where(leaf_better, idx[j], bprim)
            left, right = node + 1, off
            bl = self.bounds[jnp.stack([left, right])]
            ctn, _, chit = slab(bl[:, 0], bl[:, 1], o, inv, tmin, best)
            inner = ~is_leaf & ~skip
            hl, hr = inner & chit[0], inner & chit[1]
            node, tnode, sp, sn, st, fin = next_node(node, hl, hr, ctn, left, right, sp, sn,
                                                     st, done)  # fmt: skip
            return node, tnode, sp, sn, st, best, bprim, done | fin

        out = jax.lax.while_loop(lambda s: ~s[-1], body, s0)
        return out[5], out[6]

    def closest_t(self, o, d, *, tmin=0.0, tmax=jnp.inf):
        """Nearest ``(t, segment)`` per ray (``t = inf`` on misses); not differentiable."""
        sg = jax.lax.stop_gradient
        o, d, tmin, tmax = prepare_rays(sg(o), sg(d), sg(tmin), sg(tmax))
        batch = o.shape[:-1]
        pts = sg(self.points).astype(o.dtype)
        flat = (o.reshape(-1, 3), d.reshape(-1, 3),
                jnp.broadcast_to(tmin, batch).reshape(-1),
                jnp.broadcast_to(tmax, batch).reshape(-1))  # fmt: skip
        t, k = jax.vmap(lambda *r: self._trace_one(pts, *r))(*flat)
        t = jnp.where(k >= 0, t, jnp.inf)
        return t.reshape(batch), jnp.maximum(k, 0).reshape(batch)

    def occluded(self, o, d, tmax, *, tmin=0.0):
        """True where a segment lies on the ray in ``(tmin, tmax)``."""
        return jnp.isfinite(self.closest_t(o, d, tmin=tmin, tmax=tmax)[0])

    def _local(self, prim_id, o, d, valid):
        """Live ``(valid, t, p, n, s, axis, a, b, ra, rb)`` at segment ``prim_id``."""
        pts = self.points.astype(o.dtype)
        k = jnp.clip(prim_id, 0, self.segment_count - 1)
        a, ra, b, rb, cap = self._ends(pts, k)
        t, s = round_cone_entry(a, ra, b, rb, o, d, cap)
        valid = valid & jnp.isfinite(t)
        t = jnp.where(valid, t, 0.0)
        p = o + t[..., None] * d
        c = a + s[..., None] * (b - a)
        n = safe_normalize(p - c)
        return valid, t, p, n, s, k, a, b, ra, rb

    def hit(self, prim_id, o, d, valid, t=None) -> Hit:
        """Differentiable record of segment ``prim_id`` (``t`` recomputed in closed form)."""
        o = jnp.asarray(o)
        d = jnp.asarray(d, o.dtype)
        o, d = jnp.broadcast_arrays(o, d)
        valid, t, p, n, s, k, a, b, _, _ = self._local(prim_id, o, d, valid)
        e_rot, e_rad = _segment_frame(safe_normalize(b - a))
        u = safe_atan2(sum_last(n * e_rot), sum_last(n * e_rad))
        u = jnp.where(u < 0, u + 2 * math.pi, u) / (2 * math.pi)
        v = (s + k) / self.segment_count
        uv = jnp.stack([u, v], -1)
        return hit_record(valid, t, p, n, n, uv, prim_id, 0)

    def tangents(self, prim_id, p, ng):
        """Mitsuba's ``(dp/du, dp/dv)`` at points ``p`` with normals ``ng`` on segments
        ``prim_id`` (module docstring)."""
        pts = self.points.astype(p.dtype)
        k = jnp.clip(prim_id, 0, self.segment_count - 1)
        a, ra, b, rb, _ = self._ends(pts, k)
        ba = b - a
        # the contact sphere: s* of p (module docstring), its radius r(s*)
        dr = rb - ra
        D = sum_last(ba * ba) - dr * dr
        cone = D > 0
        s = safe_div(sum_last((p - a) * ba) + ra * dr, jnp.where(cone, D, 1.0))
        s = jnp.where(cone, jnp.clip(s, 0.0, 1.0), jnp.where(ra >= rb, 0.0, 1.0))
        r = ra + s * dr
        c = p - r[..., None] * ng
        axis = safe_normalize(ba)
        dpdu = 2 * math.pi * jnp.cross(axis, p - c)
        dpdv = self.segment_count * (ba + (rb - ra)[..., None] * ng)
        return dpdu, dpdv

    def intersect(self, o, d, *, tmin=0.0, tmax=jnp.inf) -> Hit:
        """Closest hit of rays ``o, d (..., 3)`` (search, then :meth:`hit`)."""
        o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
        t, k = self.closest_t(o, d, tmin=tmin, tmax=tmax)
        return self.hit(k, o, d, jnp.isfinite(t), t=t)
