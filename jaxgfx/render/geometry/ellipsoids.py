# ruff: noqa: F722  (jaxtyping shape strings)
"""Ellipsoids: :class:`Ellipsoids` (Mitsuba 3's ``ellipsoids`` shape, the primitive of its
Gaussian-splatting scenes) as opaque surfaces, and the ellipsoid PLY file format
(:func:`read_ellipsoids_ply`, :func:`write_ellipsoids_ply`).

Conventions (Mitsuba 3's ``ellipsoids`` plugin, src/shapes/ellipsoids.{h,cpp}, and its 3.9.1
behaviour, measured in ``tests/render/test_ellipsoids.py``):

* ellipsoid ``i``: centre ``c``, scales ``s`` (its semi-axes before ``extent``) and a rotation
  quaternion ``q = (x, y, z, w)`` (Mitsuba's order; ``R(q)`` the usual matrix, ``x_world =
  c + R x_local``); the surface is ``{c + R (extent · s ⊙ u) : |u| = 1}``. ``extent`` (default
  3, as in Mitsuba: the support of a Gaussian of standard deviations ``s``) multiplies every
  scale.
* only the entering side is hit (Mitsuba culls back faces): a ray whose origin is inside an
  ellipsoid does not hit it; a ray hits at the NEAR root ``t_-`` of the quadratic below when
  ``tmin < t_- < tmax``.
* a scale of 0 (a flat ellipsoid) is never hit (as Mitsuba 3.9.1, whose ``1 / 0`` makes the
  quadratic NaN); negative scales act as their absolute values (the quadratic and the normal
  depend on ``s²``).
* quaternions must have unit length (checked at construction, ``| |q| - 1 | ≤ 1e-3``):
  Mitsuba builds ``R`` from ``q`` without normalising it (a non-unit ``q`` gives a non-rotation
  there); jaxgfx uses ``R(q / |q|)``, the same matrix for unit ``q``, so gradients w.r.t.
  ``q`` are those of the rotation (tangent to the unit sphere of quaternions).
* hit record: ``n = normalize(R (l / s²))`` with ``l = Rᵀ (p - c)`` (geometric = shading
  normal), ``uv = (0, 0)`` and no ``dp/du`` (Mitsuba defines neither; the shading frame's
  tangent is then the arbitrary one built around ``n``, in both renderers).
* no area sampling: Mitsuba's plugin returns zero positions and pdfs, so ellipsoids cannot be
  area emitters (refused by the scene loaders); no edge sampling of their silhouettes.

Intersection (exact, per ellipsoid): in the unit-sphere frame ``o' = S⁻¹ Rᵀ (o - c)``,
``d' = S⁻¹ Rᵀ d`` (``S = diag(extent · s)``), ``|o' + t d'|² = 1`` is ``A t² + 2 B t + C = 0``
with ``A = |d'|²``, ``B = o'·d'``, ``C = |o'|² - 1``. As jaxgfx's sphere (Haines et al., Ray
Tracing Gems ch. 7), the discriminant is taken cancellation-free as ``B² - A C = A (1 - |g|²)``
(``g = o' - (B / A) d'``, the point of the line nearest the centre) and the roots as
``q = -(B + sign(B) √disc)``, ``t = {q / A, C / q}``. A BVH over the ellipsoids' boxes
(``c ± (|R_r0| s_0, ...)`` row-wise: the exact axis-aligned box of a rotated ellipsoid, as
Mitsuba's) finds the nearest one; the hit record re-intersects it with live parameters, so
``t``, ``p`` and ``n`` are differentiable w.r.t. its centre, scales and quaternion (the
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
from jaxtyping import Array, Float, Int

from jaxgfx._math import safe_div, safe_normalize, safe_sqrt, sum_last
from jaxgfx.render.geometry.curves import _box_bvh, _bvh_trace
from jaxgfx.render.geometry.mesh_io import ply_header_and_body
from jaxgfx.render.geometry.ray import Hit, hit_record, prepare_rays

__all__ = [
    "Ellipsoids",
    "quaternion_matrix",
    "ellipsoid_entry",
    "read_ellipsoids_ply",
    "write_ellipsoids_ply",
    "PLY_FIELDS",
]

QUATERNION_TOL = 1e-3
"""Largest accepted ``| |q| - 1 |`` of a quaternion."""


def quaternion_matrix(q):
    """Rotation matrices ``(..., 3, 3)`` of quaternions ``q (..., 4)`` in Mitsuba's order
    ``(x, y, z, w)`` (normalised first; the zero quaternion gives the identity)."""
    q = safe_normalize(q)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    zero = (x == 0) & (y == 0) & (z == 0) & (w == 0)
    w = jnp.where(zero, 1.0, w)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, xw, yw, zw = x * y, x * z, y * z, x * w, y * w, z * w
    rows = [
        [1 - 2 * (yy + zz), 2 * (xy - zw), 2 * (xz + yw)],
        [2 * (xy + zw), 1 - 2 * (xx + zz), 2 * (yz - xw)],
        [2 * (xz - yw), 2 * (yz + xw), 1 - 2 * (xx + yy)],
    ]
    return jnp.stack([jnp.stack(r, -1) for r in rows], -2)


def _to_local(R, v):
    """``Rᵀ v`` for ``R (..., 3, 3)``, ``v (..., 3)`` (unrolled: fusion-friendly)."""
    return jnp.stack([sum_last(R[..., :, k] * v) for k in range(3)], -1)


def _to_world(R, v):
    """``R v``."""
    return jnp.stack([sum_last(R[..., k, :] * v) for k in range(3)], -1)


def ellipsoid_entry(c, s, q, o, d):
    """``(t, ok)``: the near root of rays ``o, d (..., 3)`` with ellipsoids of centre ``c``,
    semi-axes ``s`` (``(..., 3)``, ``extent`` already applied) and quaternion ``q (..., 4)``
    (broadcast), and where it exists (the line meets the ellipsoid and no semi-axis is 0).
    ``t`` may be negative (the ellipsoid behind the origin, or the origin inside); the caller
    applies ``tmin < t < tmax``. Finite values and gradients everywhere (module docstring)."""
    R = quaternion_matrix(q)
    flat = jnp.any(s == 0, axis=-1)
    inv = safe_div(jnp.ones_like(s), s)
    return _unit_sphere_entry(_to_local(R, o - c) * inv, _to_local(R, d) * inv, flat)


def _to_unit_frames(c, s, q):
    """``(W, flat)``: the maps ``W = S⁻¹ Rᵀ (N, 3, 3)`` into each ellipsoid's unit-sphere
    frame and which ellipsoids are flat (the BVH's leaves use them: no rotation per test)."""
    R = quaternion_matrix(q)
    inv = safe_div(jnp.ones_like(s), s)
    return jnp.swapaxes(R, -1, -2) * inv[..., :, None], jnp.any(s == 0, axis=-1)


def _unit_sphere_entry(ol, dl, flat):
    """``(t, ok)`` of :func:`ellipsoid_entry` from the ray ``ol + t dl`` in the unit-sphere
    frame (the robust quadratic of the module docstring)."""
    A = sum_last(dl * dl)
    B = sum_last(ol * dl)
    C = sum_last(ol * ol) - 1.0
    As = jnp.where(A > 0, A, 1.0)
    g = ol - (B / As)[..., None] * dl
    disc = A * (1.0 - sum_last(g * g))
    h = safe_sqrt(disc)
    qr = -(B + jnp.where(B >= 0, h, -h))
    t1 = qr / As
    t2 = safe_div(C, qr, fill=jnp.inf)
    t = jnp.minimum(t1, t2)
    ok = (disc >= 0) & (A > 0) & ~flat & jnp.isfinite(t)
    return jnp.where(ok, t, jnp.inf), ok


def _check_quaternions(q, name="quaternions"):
    if isinstance(q, jax.core.Tracer):
        return
    norm = np.linalg.norm(np.asarray(q, np.float64), axis=-1)
    bad = np.flatnonzero(~(np.abs(norm - 1.0) <= QUATERNION_TOL))
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"{name}: expected unit quaternions (x, y, z, w); row {i} has length "
                         f"{norm[i]:.6g} (Mitsuba 3 does not normalise them: normalise the "
                         "rows)")  # fmt: skip


def _as_rows(x, name, width, dtype=None):
    a = jnp.asarray(x) if dtype is None else jnp.asarray(x, dtype)
    if not jnp.issubdtype(a.dtype, jnp.floating):
        a = a.astype(jnp.float32)
    if a.ndim == 1 and a.shape[0] == width:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != width or a.shape[0] == 0:
        raise ValueError(f"{name}: expected shape (N, {width}) with N >= 1, got {a.shape}")
    if not isinstance(a, jax.core.Tracer) and not bool(jnp.all(jnp.isfinite(a))):
        raise ValueError(f"{name}: expected finite values")
    return a


def _boxes(c, s, q):
    """Axis-aligned boxes ``(lo, hi)`` of ellipsoids (NumPy float64; ``s`` with extent)."""
    q = q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-300)
    R = _np_quaternion_matrix(q)
    delta = np.sqrt(np.sum((R * s[:, None, :]) ** 2, axis=-1))
    # a float32 margin: the traversal's slab test and the leaf test round differently
    delta = delta * (1 + 1e-5) + 1e-6 * (1 + np.abs(c).max())
    return c - delta, c + delta


def _np_quaternion_matrix(q):
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], 1)  # fmt: skip


class Ellipsoids(eqx.Module):
    """``N`` ellipsoids as a shape of :func:`~jaxgfx.render.geometry.intersect_scene` (the
    custom-shape protocol ``closest_t`` / ``hit``), in world space: Mitsuba 3's
    ``ellipsoids`` (module docstring).

    ``centers (N, 3)``, ``scales (N, 3)``, ``quaternions (N, 4)`` (``x, y, z, w``, unit
    length): differentiable leaves; ``extent`` (static, default 3.0 as in Mitsuba) multiplies
    the scales. ``_bounds``, ``offset``, ``count``, ``prims``: a BVH over the ellipsoids' boxes
    built on the host by the constructor (re-create the shape after moving ellipsoids by more
    than an optimisation's gradient step; private, so ``Scene.parameters()`` lists only the
    three leaves).

    Example: ``Ellipsoids([[0, 0, 0]], [[1, .5, .25]], [[0, 0, 0, 1]], extent=1.0)`` and the
    ray from ``(0, 0, -5)`` along ``+z`` hit at ``t = 4.75`` with normal ``(0, 0, -1)``.
    """

    centers: Float[Array, "N 3"]
    scales: Float[Array, "N 3"]
    quaternions: Float[Array, "N 4"]
    _bounds: Float[Array, "M 2 3"]
    offset: Int[Array, " M"]
    count: Int[Array, " M"]
    prims: Int[Array, " N"]
    extent: float = eqx.field(static=True, default=3.0)
    max_leaf: int = eqx.field(static=True, default=4)

    def __init__(self, centers, scales, quaternions, *, extent=3.0, max_leaf=4):
        c = _as_rows(centers, "centers", 3)
        s = _as_rows(scales, "scales", 3, c.dtype)
        q = _as_rows(quaternions, "quaternions", 4, c.dtype)
        n = c.shape[0]
        for name, a in (("scales", s), ("quaternions", q)):
            if a.shape[0] != n:
                raise ValueError(f"{name}: expected {n} rows (one per center), got {a.shape[0]}")
        _check_quaternions(q)
        extent = float(extent)
        if not (math.isfinite(extent) and extent > 0):
            raise ValueError(f"extent: expected a positive number, got {extent}")
        self.centers, self.scales, self.quaternions = c, s, q
        self.extent, self.max_leaf = extent, max_leaf
        sg = jax.lax.stop_gradient
        cn = np.asarray(sg(c), np.float64)
        sn = np.abs(np.asarray(sg(s), np.float64)) * extent
        qn = np.asarray(sg(q), np.float64)
        lo, hi = _boxes(cn, sn, qn)
        self._bounds, self.offset, self.count, self.prims = _box_bvh(lo, hi, max_leaf, c.dtype)

    @property
    def primitive_count(self) -> int:
        return int(self.centers.shape[0])

    def _params(self, k, dtype, live=True):
        f = (lambda x: x) if live else jax.lax.stop_gradient
        c = f(self.centers).astype(dtype)[k]
        s = f(self.scales).astype(dtype)[k] * self.extent
        q = f(self.quaternions).astype(dtype)[k]
        return c, s, q

    @staticmethod
    def _leaf(c, W, flat, idx, o, d):
        ci, Wi = c[idx], W[idx]
        ol = sum_last(Wi * (o - ci)[..., None, :])
        dl = sum_last(Wi * d)
        return _unit_sphere_entry(ol, dl, flat[idx])[0]

    def closest_t(self, o, d, *, tmin=0.0, tmax=jnp.inf):
        """Nearest ``(t, primitive)`` per ray (``t = inf`` on misses); not differentiable."""
        sg = jax.lax.stop_gradient
        o, d, tmin, tmax = prepare_rays(sg(o), sg(d), sg(tmin), sg(tmax))
        batch = o.shape[:-1]
        flat = (o.reshape(-1, 3), d.reshape(-1, 3),
                jnp.broadcast_to(tmin, batch).reshape(-1),
                jnp.broadcast_to(tmax, batch).reshape(-1))  # fmt: skip
        c, s, q = self._params(slice(None), o.dtype, live=False)
        leaf = functools.partial(self._leaf, c, *_to_unit_frames(c, s, q))
        t, k = jax.vmap(lambda *r: _bvh_trace(self, leaf, *r))(*flat)
        t = jnp.where(k >= 0, t, jnp.inf)
        return t.reshape(batch), jnp.maximum(k, 0).reshape(batch)

    def occluded(self, o, d, tmax, *, tmin=0.0):
        """True where an ellipsoid is entered on the ray in ``(tmin, tmax)``."""
        return jnp.isfinite(self.closest_t(o, d, tmin=tmin, tmax=tmax)[0])

    def hit(self, prim_id, o, d, valid, t=None) -> Hit:
        """Differentiable record of ellipsoid ``prim_id`` (``t`` recomputed in closed form)."""
        o = jnp.asarray(o)
        d = jnp.asarray(d, o.dtype)
        o, d = jnp.broadcast_arrays(o, d)
        k = jnp.clip(prim_id, 0, self.primitive_count - 1)
        c, s, q = self._params(k, o.dtype)
        tt, ok = ellipsoid_entry(c, s, q, o, d)
        valid = valid & ok
        tt = jnp.where(valid, tt, 0.0)
        p = o + tt[..., None] * d
        R = quaternion_matrix(q)
        inv = safe_div(jnp.ones_like(s), s)
        n = safe_normalize(_to_world(R, _to_local(R, p - c) * inv * inv))
        uv = jnp.zeros(p.shape[:-1] + (2,), p.dtype)
        return hit_record(valid, tt, p, n, n, uv, prim_id, 0)

    def intersect(self, o, d, *, tmin=0.0, tmax=jnp.inf) -> Hit:
        """Closest hit of rays ``o, d (..., 3)`` (search, then :meth:`hit`)."""
        o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
        t, k = self.closest_t(o, d, tmin=tmin, tmax=tmax)
        return self.hit(k, o, d, jnp.isfinite(t), t=t)


# ---------------------------------------------------------------------------------------------
# the PLY file format of Mitsuba's ellipsoids

PLY_FIELDS = ("x", "y", "z", "nx", "ny", "nz", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1",
              "rot_2", "rot_3")  # fmt: skip
"""The ``vertex`` properties of an ellipsoid PLY file without attributes, in Mitsuba's order
(``scale_k`` = ln of the scale, ``rot_0..3`` = the quaternion's ``w, x, y, z``)."""

_PLY_FLOAT = {"float": "f4", "float32": "f4"}


def read_ellipsoids_ply(path, *, scale_factor=1.0, to_world=None):
    """``(centers (N, 3), scales (N, 3), quaternions (N, 4) x y z w)`` (float32 NumPy) of an
    ellipsoid PLY file as Mitsuba 3's ``ellipsoids`` reads it: one ``vertex`` element of
    float properties ``x y z nx ny nz``, then any attributes, then ``scale_0..2`` (logarithms:
    the scale is ``max(exp(scale_k), 1e-6) · scale_factor``) and ``rot_0..3`` (``w x y z``,
    normalised). ``to_world`` (4x4 affine; no mirroring) moves the centres, rotates the
    quaternions by the rotation of its polar decomposition ``Q S`` and multiplies the scales by
    the mean of ``diag(S)`` (Mitsuba's approximation for non-uniform scales).

    ``ValueError`` naming the file for anything else; attributes (extra properties such as
    3D Gaussian splatting's ``f_dc_*``, ``f_rest_*``, ``opacity``) are refused: they serve
    Mitsuba's volumetric primitive integrators, which a surface renderer cannot honour."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as e:
        raise ValueError(f"{path}: {e.strerror or e}") from None
    header, body = ply_header_and_body(path, data)
    fmt, elements = None, []
    for lineno, line in enumerate(header[1:], 2):
        s = line.split()
        if not s or s[0] in ("comment", "obj_info"):
            continue
        if s[0] == "format" and len(s) >= 2:
            fmt = s[1]
        elif s[0] == "element" and len(s) == 3 and s[2].isdigit():
            elements.append((s[1], int(s[2]), []))
        elif s[0] == "property" and elements and len(s) == 3:
            if s[1] not in _PLY_FLOAT:
                raise ValueError(f"{path}:{lineno}: property {s[2]!r} has type {s[1]!r}; "
                                 "ellipsoid PLY files hold float properties only")  # fmt: skip
            elements[-1][2].append(s[2])
        else:
            raise ValueError(f"{path}:{lineno}: bad PLY header line {line!r}")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise ValueError(f"{path}: unsupported PLY format {fmt!r}")
    if not elements or elements[0][0] != "vertex":
        raise ValueError(f"{path}: expected a 'vertex' element first")
    _, n, names = elements[0]
    if len(elements) > 1:
        raise ValueError(f"{path}: expected one element ('vertex'), got "
                         f"{[e[0] for e in elements]}")  # fmt: skip
    if len(names) < 13 or tuple(names[:6]) != PLY_FIELDS[:6] or \
            tuple(names[-7:]) != PLY_FIELDS[6:]:  # fmt: skip
        raise ValueError(f"{path}: expected the vertex properties {list(PLY_FIELDS[:6])}, "
                         f"[attributes], {list(PLY_FIELDS[6:])}; got {names}")  # fmt: skip
    if len(names) > 13:
        raise ValueError(f"{path}: per-ellipsoid attributes {names[6:-7]} are not supported: "
                         "they serve Mitsuba's volumetric primitive integrators (opacity, "
                         "spherical harmonics), which a surface renderer cannot "
                         "honour")  # fmt: skip
    if n == 0:
        raise ValueError(f"{path}: no ellipsoids (vertex count 0)")
    width = len(names)
    if fmt == "ascii":
        try:
            vals = np.array(body.decode("ascii").split()[: n * width], np.float64)
        except (UnicodeDecodeError, ValueError):
            raise ValueError(f"{path}: unparsable ASCII PLY body") from None
        if vals.size != n * width:
            raise ValueError(f"{path}: expected {n * width} numbers, got {vals.size}")
        rows = vals.reshape(n, width).astype(np.float32)
    else:
        dt = np.dtype("<f4" if fmt == "binary_little_endian" else ">f4")
        if len(body) < n * width * 4:
            raise ValueError(f"{path}: truncated PLY body ({len(body)} bytes for {n} "
                             f"ellipsoids of {width} floats)")  # fmt: skip
        rows = np.frombuffer(body, dt, n * width).reshape(n, width).astype(np.float32)
    if not np.all(np.isfinite(rows)):
        i = int(np.flatnonzero(~np.all(np.isfinite(rows), 1))[0])
        raise ValueError(f"{path}: ellipsoid {i} has non-finite values")
    centers = rows[:, :3].astype(np.float64)
    scales = np.maximum(np.exp(rows[:, 6:9]), np.float32(1e-6)) * np.float32(scale_factor)
    quats = rows[:, [10, 11, 12, 9]].astype(np.float64)  # (w x y z) -> (x y z w)
    if to_world is not None:
        m = np.asarray(to_world, np.float64)
        lin = m[:3, :3]
        u, sig, vt = np.linalg.svd(lin)
        if np.linalg.det(lin) <= 0:
            raise ValueError("to_world: a mirroring or singular transform (det <= 0) cannot "
                             "place ellipsoids")  # fmt: skip
        Q = u @ vt  # polar decomposition lin = Q S, S = V Σ Vᵀ: mean(diag S) = mean(Σ)
        centers = centers @ lin.T + m[:3, 3]
        scales = scales * np.float32(sig.mean())
        quats = _quat_mul(_matrix_quat(Q), quats)
    norm = np.linalg.norm(quats, axis=-1, keepdims=True)
    if np.any(norm == 0):
        raise ValueError(f"{path}: ellipsoid {int(np.flatnonzero(norm == 0)[0])} has a zero "
                         "quaternion")  # fmt: skip
    quats = quats / norm
    return centers.astype(np.float32), scales.astype(np.float32), quats.astype(np.float32)


def _quat_mul(a, b):
    """Hamilton products of quaternions ``(x, y, z, w)``: ``R(a b) = R(a) R(b)``."""
    ax, ay, az, aw = np.moveaxis(np.broadcast_to(a, np.broadcast_shapes(a.shape, b.shape)), -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], -1)  # fmt: skip


def _matrix_quat(R):
    """A unit quaternion ``(x, y, z, w)`` of the rotation matrix ``R`` (Shepperd's method)."""
    t = np.trace(R)
    m = [t, R[0, 0], R[1, 1], R[2, 2]]
    k = int(np.argmax(m))
    if k == 0:
        w = 0.5 * math.sqrt(1 + t)
        x, y, z = (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), \
            (R[1, 0] - R[0, 1]) / (4 * w)  # fmt: skip
    elif k == 1:
        x = 0.5 * math.sqrt(1 + 2 * R[0, 0] - t)
        w, y, z = (R[2, 1] - R[1, 2]) / (4 * x), (R[0, 1] + R[1, 0]) / (4 * x), \
            (R[0, 2] + R[2, 0]) / (4 * x)  # fmt: skip
    elif k == 2:
        y = 0.5 * math.sqrt(1 + 2 * R[1, 1] - t)
        w, x, z = (R[0, 2] - R[2, 0]) / (4 * y), (R[0, 1] + R[1, 0]) / (4 * y), \
            (R[1, 2] + R[2, 1]) / (4 * y)  # fmt: skip
    else:
        z = 0.5 * math.sqrt(1 + 2 * R[2, 2] - t)
        w, x, y = (R[1, 0] - R[0, 1]) / (4 * z), (R[0, 2] + R[2, 0]) / (4 * z), \
            (R[1, 2] + R[2, 1]) / (4 * z)  # fmt: skip
    return np.array([x, y, z, w])


def write_ellipsoids_ply(path, centers, scales, quaternions) -> None:
    """Write ellipsoids as a binary little-endian PLY file Mitsuba 3's ``ellipsoids`` reads
    (:data:`PLY_FIELDS`: zero normals, ``ln |scale|``, the quaternion as ``w x y z``).
    ``ValueError`` for a scale of 0 (its logarithm does not exist; Mitsuba's reader would
    clamp it to 1e-6)."""
    c = np.asarray(centers, np.float64).reshape(-1, 3)
    s = np.abs(np.asarray(scales, np.float64).reshape(-1, 3))
    q = np.asarray(quaternions, np.float64).reshape(-1, 4)
    if np.any(s == 0):
        raise ValueError("scales: a scale of 0 cannot be written to a PLY file (ln 0)")
    rows = np.concatenate([c, np.zeros_like(c), np.log(s), q[:, [3, 0, 1, 2]]], 1)
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {len(c)}"]
    head += [f"property float {f}" for f in PLY_FIELDS] + ["end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(head) + "\n").encode("ascii"))
        f.write(rows.astype("<f4").tobytes())
