# ruff: noqa: F722  (jaxtyping shape strings)
"""Curves: :class:`LinearCurves` (Mitsuba 3's ``linearcurve`` shape), tubes swept by a sphere
whose centre and radius vary linearly between consecutive control points,
:class:`BSplineCurves` (``bsplinecurve``; its own docstring), and the curve text file format
(:func:`read_curves`).

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

import functools
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

__all__ = [
    "LinearCurves",
    "BSplineCurves",
    "read_curves",
    "write_curves",
    "curve_lists",
    "round_cone_entry",
]


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
    """The curves of a :class:`LinearCurves` or :class:`BSplineCurves` as lists of
    ``[x, y, z, radius]`` rows (runs of consecutive segments are one curve)."""
    pts = np.asarray(shape.points, np.float64)
    span = 3 if isinstance(shape, BSplineCurves) else 1
    out, prev = [], None
    for i in np.asarray(shape.segments).tolist():
        if prev is None or i != prev + 1:
            out.append([pts[j].tolist() for j in range(i, i + span)])
        out[-1].append(pts[i + span].tolist())
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


def _box_bvh(lo, hi, max_leaf, dtype):
    """``(bounds, offset, count, prims)`` of a BVH over boxes ``lo, hi (P, 3)``: the SAH
    builder of :func:`~jaxgfx.render.geometry.accel.build_bvh` on one proxy triangle per box
    (its vertices' bounds are the box)."""
    proxy = TriangleMesh(
        np.stack([lo, hi, hi], 1).reshape(-1, 3), np.arange(3 * lo.shape[0]).reshape(-1, 3)
    )
    bvh = build_bvh(proxy, max_leaf=max_leaf)
    return bvh.bounds.astype(dtype), bvh.offset, bvh.count, bvh.prims


def _bvh_trace(acc, leaf, o, d, tmin, tmax):
    """Nearest ``(t, primitive)`` of ONE ray: a stack traversal of the BVH ``acc._bounds``,
    ``offset``, ``count``, ``prims`` (:func:`_box_bvh`) whose leaves test their
    ``acc.max_leaf`` primitive slots with ``leaf(idx, o, d) -> t (max_leaf,)``."""
    inv = safe_inv(d)
    ks = jnp.arange(acc.max_leaf)
    zero_i = jnp.int32(0)
    _, _, hit0 = slab(acc._bounds[0, 0], acc._bounds[0, 1], o, inv, tmin, tmax)
    sn = jnp.zeros(STACK_SIZE, jnp.int32)
    st = jnp.zeros(STACK_SIZE, o.dtype)
    s0 = (zero_i, tmin, zero_i, sn, st, tmax, jnp.int32(-1), ~hit0)

    def body(s):
        node, tnode, sp, sn, st, best, bprim, done = s
        cnt, off = acc.count[node], acc.offset[node]
        is_leaf = cnt > 0
        skip = (tnode >= best) | done
        idx = acc.prims[jnp.minimum(off + ks, acc.prims.shape[0] - 1)]
        t = leaf(idx, o, d)
        t = jnp.where((ks < cnt) & (t > tmin) & (t < best), t, jnp.inf)
        j = jnp.argmin(t)
        leaf_better = is_leaf & ~skip & (t[j] < best)
        best = jnp.where(leaf_better, t[j], best)
        bprim = jnp.where(leaf_better, idx[j], bprim)
        left, right = node + 1, off
        bl = acc._bounds[jnp.stack([left, right])]
        ctn, _, chit = slab(bl[:, 0], bl[:, 1], o, inv, tmin, best)
        inner = ~is_leaf & ~skip
        hl, hr = inner & chit[0], inner & chit[1]
        node, tnode, sp, sn, st, fin = next_node(node, hl, hr, ctn, left, right, sp, sn, st,
                                                 done)  # fmt: skip
        return node, tnode, sp, sn, st, best, bprim, done | fin

    out = jax.lax.while_loop(lambda s: ~s[-1], body, s0)
    return out[5], out[6]


def _segment_frame(axis):
    """Mitsuba's consistent frame ``(e_rot, e_rad)`` around a unit segment axis."""
    z = jnp.zeros_like(axis).at[..., 2].set(1.0)
    v = z - axis * sum_last(axis * z)[..., None]
    singular = jnp.abs(axis[..., 2]) >= 1.0
    y = jnp.zeros_like(axis).at[..., 1].set(1.0)
    e_rot = jnp.where(singular[..., None], y, safe_normalize(v))
    return e_rot, jnp.cross(e_rot, axis)


def _points_and_segments(points, segments, span, too_few, segment_rule):
    """The checked ``(points (N, 4), segment starts (K,) int64)`` of a curve shape whose
    segments each use ``span`` consecutive points (2 linear, 4 B-spline); ``segments`` ``None``:
    every start. ``too_few`` / ``segment_rule``: the kind's wording of the two errors."""
    p = as_points(jnp.asarray(points), "points", 4)
    if not isinstance(p, jax.core.Tracer) and bool(jnp.any(p[:, 3] < 0)):
        raise ValueError("points: radii (the 4th column) must be >= 0")
    n = p.shape[0]
    last = n - span  # the largest segment start
    seg = np.asarray(np.arange(last + 1) if segments is None else segments, np.int64).reshape(-1)
    if seg.size == 0 or n < span:
        raise ValueError(f"points: {too_few}")
    if seg.min() < 0 or seg.max() > last:
        raise ValueError(f"segments: indices must lie in [0, {last}] ({segment_rule})")
    return p, seg


class _CurveQueries(eqx.Module):
    """The BVH queries of both curve kinds; a subclass gives ``_leaf(pts, idx, o, d)``, the hit
    distance of primitive ``idx`` (``inf`` on a miss)."""

    def closest_t(self, o, d, *, tmin=0.0, tmax=jnp.inf):
        """Nearest ``(t, primitive)`` per ray (``t = inf`` on misses); not differentiable."""
        sg = jax.lax.stop_gradient
        o, d, tmin, tmax = prepare_rays(sg(o), sg(d), sg(tmin), sg(tmax))
        batch = o.shape[:-1]
        pts = sg(self.points).astype(o.dtype)
        flat = (o.reshape(-1, 3), d.reshape(-1, 3),
                jnp.broadcast_to(tmin, batch).reshape(-1),
                jnp.broadcast_to(tmax, batch).reshape(-1))  # fmt: skip
        leaf = functools.partial(self._leaf, pts)
        t, k = jax.vmap(lambda *r: _bvh_trace(self, leaf, *r))(*flat)
        t = jnp.where(k >= 0, t, jnp.inf)
        return t.reshape(batch), jnp.maximum(k, 0).reshape(batch)

    def occluded(self, o, d, tmax, *, tmin=0.0):
        """True where a curve lies on the ray in ``(tmin, tmax)``."""
        return jnp.isfinite(self.closest_t(o, d, tmin=tmin, tmax=tmax)[0])


class LinearCurves(_CurveQueries):
    """Linear curves as a shape of :func:`~jaxgfx.render.geometry.intersect_scene` (the
    custom-shape protocol ``closest_t`` / ``hit``), in world space.

    ``points (N, 4)``: control points ``x, y, z, radius`` of all curves (differentiable
    leaves); ``segments (K,)``: index of each segment's first point (the segment joins points
    ``i`` and ``i + 1``); ``_bounds``, ``offset``, ``count``, ``prims``: a BVH over the
    segments' boxes, built on the host by the constructor (its boxes are those of the points
    given; re-create the shape after moving points by more than the gradient step of an
    optimisation; private, so ``Scene.parameters()`` lists only ``points``). See the module
    docstring.

    Example: ``LinearCurves([[-1, 0, 0, .1], [1, 0, 0, .1]])`` (one curve) and the ray from
    ``(0, 0, -1)`` along ``+z`` hits at ``t = 0.9`` with ``uv = (0.75, 0.5)``.
    """

    points: Float[Array, "N 4"]
    segments: Int[Array, " K"]
    start_cap: Bool[Array, " K"]
    _bounds: Float[Array, "M 2 3"]
    offset: Int[Array, " M"]
    count: Int[Array, " M"]
    prims: Int[Array, " K"]
    max_leaf: int = eqx.field(static=True, default=4)

    def __init__(self, points, segments=None, *, max_leaf=4):
        p, seg = _points_and_segments(
            points, segments, 2, "a curve needs at least two control points (one segment)",
            "a segment joins points i and i + 1",
        )  # fmt: skip
        self.points = p
        self.segments = jnp.asarray(seg, jnp.int32)
        # Embree's rule (Mitsuba's backend): a segment draws its start ball only when no
        # segment ends where it starts (it begins a curve)
        self.start_cap = jnp.asarray(~np.isin(seg - 1, seg))
        pn = np.asarray(jax.lax.stop_gradient(p), np.float64)
        a, b = pn[seg], pn[seg + 1]
        lo = np.minimum(a[:, :3] - a[:, 3:], b[:, :3] - b[:, 3:])
        hi = np.maximum(a[:, :3] + a[:, 3:], b[:, :3] + b[:, 3:])
        self._bounds, self.offset, self.count, self.prims = _box_bvh(lo, hi, max_leaf, p.dtype)
        self.max_leaf = max_leaf

    @property
    def segment_count(self) -> int:
        return int(self.segments.shape[0])

    def _ends(self, pts, k):
        i = self.segments[k]
        c0, c1 = pts[i], pts[i + 1]
        return c0[..., :3], c0[..., 3], c1[..., :3], c1[..., 3], self.start_cap[k]

    @property
    def primitive_count(self) -> int:
        return self.segment_count

    def _leaf(self, pts, idx, o, d):
        a, ra, b, rb, cap = self._ends(pts, idx)
        return round_cone_entry(a, ra, b, rb, o, d, cap)[0]

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


# ---------------------------------------------------------------------------------------------
# cubic B-spline curves


def _bspline(P, v):
    """Uniform cubic B-spline of control values ``P (..., 4, C)`` at ``v (...)``: value, first
    and second derivative, each ``(..., C)``."""
    v = v[..., None]
    w = 1 - v
    b0, b1 = w**3, 3 * v**3 - 6 * v**2 + 4
    b2, b3 = -3 * v**3 + 3 * v**2 + 3 * v + 1, v**3
    d0, d1 = -3 * w**2, 9 * v**2 - 12 * v
    d2, d3 = -9 * v**2 + 6 * v + 3, 3 * v**2
    e0, e1, e2, e3 = 6 * w, 18 * v - 12, -18 * v + 6, 6 * v

    def comb(a, b, c, e):
        return (a * P[..., 0, :] + b * P[..., 1, :] + c * P[..., 2, :] + e * P[..., 3, :]) / 6

    return comb(b0, b1, b2, b3), comb(d0, d1, d2, d3), comb(e0, e1, e2, e3)


def _tube_residual(P, o, d, t, v):
    """``(G, J)``: the conditions ``(x - c)·c' = 0`` and ``|x - c|² - r² = 0`` of the ray point
    ``x = o + t d`` on the circle of the segment at ``v`` (module docstring), and their
    Jacobian w.r.t. ``(t, v)`` (``(..., 2)``, ``(..., 2, 2)``)."""
    c4, dc4, ddc4 = _bspline(P, v)
    c, dc, ddc = c4[..., :3], dc4[..., :3], ddc4[..., :3]
    r, dr = c4[..., 3], dc4[..., 3]
    q = o + t[..., None] * d - c
    g1 = sum_last(q * dc)
    g2 = sum_last(q * q) - r * r
    j11 = sum_last(d * dc)
    j12 = sum_last(q * ddc) - sum_last(dc * dc)
    j21 = 2 * sum_last(q * d)
    j22 = -2 * sum_last(q * dc) - 2 * r * dr
    G = jnp.stack([g1, g2], -1)
    J = jnp.stack([jnp.stack([j11, j12], -1), jnp.stack([j21, j22], -1)], -2)
    return G, J


def _newton_step(G, J):
    """``J⁻¹ G`` of 2×2 systems (zero where ``J`` is singular)."""
    det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    ok = jnp.abs(det) > 0
    inv = jnp.where(ok, 1.0 / jnp.where(ok, det, 1.0), 0.0)
    dt = (J[..., 1, 1] * G[..., 0] - J[..., 0, 1] * G[..., 1]) * inv
    dv = (-J[..., 1, 0] * G[..., 0] + J[..., 0, 0] * G[..., 1]) * inv
    return dt, dv


class BSplineCurves(_CurveQueries):
    """Cubic B-spline curves (Mitsuba 3's ``bsplinecurve``) as a shape of
    :func:`~jaxgfx.render.geometry.intersect_scene`, in world space.

    Segment ``k`` uses the control points ``i .. i + 3`` (``i = segments[k]``; a curve of
    ``n`` points has ``n - 3`` segments) and is the uniform cubic B-spline ``c(v)``,
    ``r(v)`` (the radius interpolated like the position), ``v ∈ [0, 1]``. The surface is the
    sweep of the circle of radius ``r(v)`` around ``c(v)`` in the plane perpendicular to
    ``c'(v)`` (Embree's round curves, which Mitsuba uses: not the sweep of a sphere), open at
    the ends of a curve; only front faces are hit.

    Intersection: each segment is split into ``pieces`` chords whose round cones
    (:func:`round_cone_entry`), inflated by ``δ`` (on the host: 1.5 × the largest distance of
    the curve from its chord plus the largest radius deviation from the chord's linear radius,
    sampled at 33 points per piece), contain every circle of the piece; a BVH over the pieces
    finds candidates, and from the inflated cone's entry ``newton_steps`` Newton iterations
    solve the two conditions ``(x - c(v))·c'(v) = 0``, ``|x - c(v)|² = r(v)²`` for ``(t, v)``.
    A root counts when its residuals are below ``1e-4`` (relative to ``r |c'|`` and ``r²``),
    its ``v`` lies in the piece and the surface faces the ray. The hit record repeats one Newton
    step with live parameters (the implicit-function derivative of ``t`` and ``v``); the
    normal is the sweep surface's, ``normalize((|c'|² - (p - c)·c'') (p - c) - r r' c')``, the
    uv as :class:`LinearCurves` with ``v = (v_local + k) / K``.
    """

    points: Float[Array, "N 4"]
    segments: Int[Array, " K"]
    _inflate: Float[Array, " P"]
    _bounds: Float[Array, "M 2 3"]
    offset: Int[Array, " M"]
    count: Int[Array, " M"]
    prims: Int[Array, " P"]
    pieces: int = eqx.field(static=True, default=8)
    newton_steps: int = eqx.field(static=True, default=12)
    max_leaf: int = eqx.field(static=True, default=4)

    def __init__(self, points, segments=None, *, pieces=8, newton_steps=12, max_leaf=4):
        p, seg = _points_and_segments(
            points, segments, 4, "a B-spline curve needs at least four control points",
            "a segment uses points i .. i + 3",
        )  # fmt: skip
        self.points, self.segments = p, jnp.asarray(seg, jnp.int32)
        self.pieces, self.newton_steps, self.max_leaf = pieces, newton_steps, max_leaf
        pn = np.asarray(jax.lax.stop_gradient(p), np.float64)
        P = pn[seg[:, None] + np.arange(4)]  # (K, 4, 4)
        f = np.linspace(0, 1, 33)
        v = (np.arange(pieces)[:, None] + f) / pieces  # (pieces, 33)
        cv = np.asarray(_bspline(P[:, None, None], v[None]), np.float64)[0]  # (K, pcs, 33, 4)
        lin = cv[:, :, :1] * (1 - f[:, None]) + cv[:, :, -1:] * f[:, None]
        dev = np.linalg.norm(cv[..., :3] - lin[..., :3], axis=-1) + np.abs(cv[..., 3] - lin[..., 3])
        delta = 1.5 * dev.max(-1) + 1e-6 * (1 + np.abs(pn[:, :3]).max())
        self._inflate = jnp.asarray(delta.reshape(-1), p.dtype)
        a, b = cv[:, :, 0], cv[:, :, -1]
        ra, rb = (a[..., 3] + delta)[..., None], (b[..., 3] + delta)[..., None]
        lo = np.minimum(a[..., :3] - ra, b[..., :3] - rb).reshape(-1, 3)
        hi = np.maximum(a[..., :3] + ra, b[..., :3] + rb).reshape(-1, 3)
        self._bounds, self.offset, self.count, self.prims = _box_bvh(lo, hi, max_leaf, p.dtype)

    @property
    def segment_count(self) -> int:
        return int(self.segments.shape[0])

    @property
    def primitive_count(self) -> int:
        """Pieces (``segment_count × pieces``): the ``prim_id`` of hits."""
        return self.segment_count * self.pieces

    def _control(self, pts, piece):
        k = piece // self.pieces
        return pts[self.segments[k][..., None] + jnp.arange(4)], k

    def _solve(self, pts, piece, o, d):
        """Converged ``(t, v, ok)`` of rays ``o, d`` in pieces ``piece`` (not differentiable)."""
        P, _ = self._control(pts, piece)
        j = (piece % self.pieces).astype(o.dtype)
        v0, v1 = j / self.pieces, (j + 1) / self.pieces
        ca, cb = _bspline(P, v0)[0], _bspline(P, v1)[0]
        delta = self._inflate[piece]
        t0, s0 = round_cone_entry(ca[..., :3], ca[..., 3] + delta, cb[..., :3], cb[..., 3] + delta,
                                  o, d)  # fmt: skip
        cand = jnp.isfinite(t0)
        t = jnp.where(cand, jnp.maximum(t0, 0.0), 0.0)
        v = v0 + s0 * (v1 - v0)

        def step(_, tv):
            t, v = tv
            G, J = _tube_residual(P, o, d, t, v)
            dt, dv = _newton_step(G, J)
            return t - dt, jnp.clip(v - dv, v0 - 0.5 / self.pieces, v1 + 0.5 / self.pieces)

        t, v = jax.lax.fori_loop(0, self.newton_steps, step, (t, v))
        G, _ = _tube_residual(P, o, d, t, v)
        c4, dc4, ddc4 = _bspline(P, v)
        r, dcn = c4[..., 3], jnp.sqrt(sum_last(dc4[..., :3] ** 2))
        scale = jnp.maximum(r, 1e-12)
        conv = (jnp.abs(G[..., 0]) <= 1e-4 * scale * jnp.maximum(dcn, 1e-12)) & (
            jnp.abs(G[..., 1]) <= 1e-4 * scale * scale
        )
        n = self._normal(o + t[..., None] * d, c4, dc4, ddc4)
        front = sum_last(n * d) < 0
        ok = cand & conv & (v >= v0) & (v <= v1) & front & jnp.isfinite(t)
        return t, v, ok

    @staticmethod
    def _normal(p, c4, dc4, ddc4):
        q = p - c4[..., :3]
        dc = dc4[..., :3]
        corr = sum_last(dc * dc) - sum_last(q * ddc4[..., :3])
        return safe_normalize(corr[..., None] * q - (c4[..., 3] * dc4[..., 3])[..., None] * dc)

    def _leaf(self, pts, idx, o, d):
        t, _, ok = self._solve(pts, idx, o, d)
        return jnp.where(ok, t, jnp.inf)

    def _local(self, prim_id, o, d, valid):
        sg = jax.lax.stop_gradient
        pts = self.points.astype(o.dtype)
        piece = jnp.clip(prim_id, 0, self.primitive_count - 1)
        t, v, ok = self._solve(sg(pts), piece, sg(o), sg(d))
        valid = valid & ok
        t, v = jnp.where(valid, t, 0.0), jnp.where(valid, v, 0.5)
        P, k = self._control(pts, piece)
        G, J = _tube_residual(P, o, d, t, v)  # live: one Newton step carries the derivative
        dt, dv = _newton_step(G, sg(J))
        t, v = t - dt, v - dv
        c4, dc4, ddc4 = _bspline(P, v)
        p = o + t[..., None] * d
        return valid, t, v, k, p, c4, dc4, ddc4

    def hit(self, prim_id, o, d, valid, t=None) -> Hit:
        """Differentiable record of piece ``prim_id`` (``t`` re-solved; see the class doc)."""
        o = jnp.asarray(o)
        d = jnp.asarray(d, o.dtype)
        o, d = jnp.broadcast_arrays(o, d)
        valid, t, v, k, p, c4, dc4, ddc4 = self._local(prim_id, o, d, valid)
        n = self._normal(p, c4, dc4, ddc4)
        w = safe_normalize(p - c4[..., :3])
        e_rot, e_rad = _segment_frame(safe_normalize(dc4[..., :3]))
        u = safe_atan2(sum_last(w * e_rot), sum_last(w * e_rad))
        u = jnp.where(u < 0, u + 2 * math.pi, u) / (2 * math.pi)
        uv = jnp.stack([u, (v + k) / self.segment_count], -1)
        return hit_record(valid, t, p, n, n, uv, prim_id, 0)

    def tangents(self, prim_id, p, ng):
        """Mitsuba 3.9.1's ``(dp/du, dp/dv)`` at hits of pieces ``prim_id``. The circle's ``v``
        is re-derived from ``p`` (Newton on ``(p - c(v))·c'(v) = 0`` from the piece's
        middle); with ``w`` the unit radial direction, ``dp/du = 2π r e × w`` and
        ``dp/dv = K (c' + r' w + r ∂w/∂v)``, ``∂w/∂v`` taken in the Frenet frame ``(T, N, B)``
        (curvature ``κ``, torsion ``τ``; both 0 where the frame degenerates) at fixed
        ``w·N``, ``w·B``, as Mitsuba's ``partials``: ``|c'| ((w·N) (-κ T + τ B) - (w·B) τ N)``.
        """
        pts = self.points.astype(p.dtype)
        piece = jnp.clip(prim_id, 0, self.primitive_count - 1)
        P, _ = self._control(pts, piece)
        j = (piece % self.pieces).astype(p.dtype)
        v = (j + 0.5) / self.pieces

        def step(_, v):
            c4, dc4, ddc4 = _bspline(P, v)
            q = p - c4[..., :3]
            g = sum_last(q * dc4[..., :3])
            dg = sum_last(q * ddc4[..., :3]) - sum_last(dc4[..., :3] ** 2)
            return v - safe_div(g, dg)

        v = jax.lax.fori_loop(0, self.newton_steps, step, v)
        c4, dc4, ddc4 = _bspline(P, v)
        dc, ddc, r, dr = dc4[..., :3], ddc4[..., :3], c4[..., 3:4], dc4[..., 3:4]
        dddc = -P[..., 0, :3] + 3 * P[..., 1, :3] - 3 * P[..., 2, :3] + P[..., 3, :3]
        w = safe_normalize(p - c4[..., :3])
        speed = jnp.sqrt(sum_last(dc * dc))[..., None]
        e = safe_normalize(dc)
        x = jnp.cross(dc, ddc)
        xn = jnp.sqrt(sum_last(x * x))[..., None]
        kappa = safe_div(xn, speed**3)
        tau = safe_div(sum_last(dddc * x)[..., None], xn * xn)
        small = (xn < 1e-6) | (jnp.sqrt(sum_last(dddc * dddc))[..., None] < 1e-6)
        tau = jnp.where(small, 0.0, tau)
        fn = safe_normalize(jnp.cross(x, dc))
        fb = safe_normalize(jnp.cross(e, fn))
        degenerate = kappa < np.finfo(np.float32).eps
        kappa, tau = jnp.where(degenerate, 0.0, kappa), jnp.where(degenerate, 0.0, tau)
        cos_u, sin_u = sum_last(fn * w)[..., None], sum_last(fb * w)[..., None]
        radv = speed * cos_u * (-kappa * e + tau * fb) - speed * sin_u * tau * fn
        dpdu = 2 * math.pi * r * jnp.cross(e, w)
        dpdv = self.segment_count * (dc + dr * w + r * radv)
        return dpdu, dpdv

    def intersect(self, o, d, *, tmin=0.0, tmax=jnp.inf) -> Hit:
        """Closest hit of rays ``o, d (..., 3)`` (search, then :meth:`hit`)."""
        o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
        t, k = self.closest_t(o, d, tmin=tmin, tmax=tmax)
        return self.hit(k, o, d, jnp.isfinite(t), t=t)
