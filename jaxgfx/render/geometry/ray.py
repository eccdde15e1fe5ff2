# ruff: noqa: F722  (jaxtyping shape strings)
"""Rays, hit records and robust secondary-ray spawning.

Conventions (shared by every intersector in ``jaxgfx.render``):

* a ray is the pair of arrays ``o (..., 3)`` (origin) and ``d (..., 3)`` (unit direction) plus
  scalars or arrays ``tmin``, ``tmax`` broadcastable to ``(...)``; points are ``o + t d`` with
  ``tmin < t < tmax``;
* intersectors return a :class:`Hit` with batch shape ``(...)``. Where ``valid`` is False the
  record holds ``t = inf``, zero vectors, ``prim_id = shape_id = -1``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from jaxgfx._math import sum_last

__all__ = [
    "Hit",
    "hit_record",
    "empty_hit",
    "merge_hits",
    "prepare_rays",
    "offset_ray_origin",
    "spawn_ray",
]


class Hit(eqx.Module):
    """Closest-hit record (a pytree; all fields share the batch shape ``(...)``).

    Fields:
        t: ``(...)`` ray parameter of the hit, ``inf`` where there is none.
        valid: ``(...)`` bool, True where the ray hit something in ``(tmin, tmax)``.
        p: ``(..., 3)`` hit position (world units).
        ng: ``(..., 3)`` unit geometric normal. Triangles: ``normalize((v1-v0) x (v2-v0))``,
            i.e. it faces the viewer when the vertices are counter-clockwise as seen by him;
            spheres: outward; rectangles: ``normalize(edge_u x edge_v)``. It is NOT flipped
            towards the ray: use ``dot(ng, d) < 0`` to tell front from back faces.
        ns: ``(..., 3)`` unit shading normal (interpolated vertex normals for meshes that have
            them, otherwise ``ng``).
        uv: ``(..., 2)`` surface parametrisation: interpolated mesh UVs when present, else the
            barycentrics ``(b1, b2)`` of vertices 1 and 2; rectangle ``(s, t)`` in [0, 1]^2;
            sphere ``(phi / 2pi, theta / pi)``.
        prim_id: ``(...)`` int32 index of the primitive (triangle, sphere, ...), -1 if none.
        shape_id: ``(...)`` int32 index of the shape in a scene list, -1 if none.
    """

    t: Float[Array, "*b"]
    valid: Bool[Array, "*b"]
    p: Float[Array, "*b 3"]
    ng: Float[Array, "*b 3"]
    ns: Float[Array, "*b 3"]
    uv: Float[Array, "*b 2"]
    prim_id: Int[Array, "*b"]
    shape_id: Int[Array, "*b"]


def prepare_rays(o, d, tmin, tmax):
    """Rays at the Python boundary: ``o`` as a float array (float32 for integers), ``d`` in its
    dtype, both ``(..., 3)`` and broadcast together; ``tmin``, ``tmax`` as arrays of that dtype.
    ``ValueError`` naming ``o, d`` for other shapes."""
    o = jnp.asarray(o)
    if not jnp.issubdtype(o.dtype, jnp.floating):
        o = o.astype(jnp.float32)
    d = jnp.asarray(d, o.dtype)
    if o.shape[-1:] != (3,) or d.shape[-1:] != (3,):
        raise ValueError(f"o, d: expected shape (..., 3), got {o.shape} and {d.shape}")
    o, d = jnp.broadcast_arrays(o, d)
    return o, d, jnp.asarray(tmin, o.dtype), jnp.asarray(tmax, o.dtype)


def hit_record(valid, t, p, ng, ns, uv, prim_id, shape_id) -> Hit:
    """A :class:`Hit` from per-ray values, with the no-hit convention applied where ``valid`` is
    False (``t = inf``, zero vectors, ``prim_id = shape_id = -1``)."""
    v3 = valid[..., None]
    return Hit(
        t=jnp.where(valid, t, jnp.inf),
        valid=valid,
        p=jnp.where(v3, p, 0.0),
        ng=jnp.where(v3, ng, 0.0),
        ns=jnp.where(v3, ns, 0.0),
        uv=jnp.where(v3, uv, 0.0),
        prim_id=jnp.where(valid, prim_id, -1).astype(jnp.int32),
        shape_id=jnp.where(valid, shape_id, -1).astype(jnp.int32),
    )


def empty_hit(batch_shape, dtype=jnp.float32) -> Hit:
    """A :class:`Hit` of the given batch shape with no hits (``t = inf``, ``valid = False``)."""
    z3 = jnp.zeros((*batch_shape, 3), dtype)
    return Hit(
        t=jnp.full(batch_shape, jnp.inf, dtype),
        valid=jnp.zeros(batch_shape, bool),
        p=z3,
        ng=z3,
        ns=z3,
        uv=jnp.zeros((*batch_shape, 2), dtype),
        prim_id=jnp.full(batch_shape, -1, jnp.int32),
        shape_id=jnp.full(batch_shape, -1, jnp.int32),
    )


def merge_hits(a: Hit, b: Hit) -> Hit:
    """Elementwise closer of two hit records (``b`` wins only where strictly closer)."""
    take_b = b.valid & (~a.valid | (b.t < a.t))

    def pick(x, y):
        m = take_b.reshape(take_b.shape + (1,) * (x.ndim - take_b.ndim))
        return jnp.where(m, y, x)

    return jax.tree_util.tree_map(pick, a, b)


# Wächter & Binder 2019 ("A Fast and Robust Method for Avoiding Self-Intersection", Ray
# Tracing Gems ch. 6) constants, tuned for float32. For float64 the integer offset is scaled
# by 2**29 (the extra mantissa bits) so the relative offset is the same.
_ORIGIN = 1.0 / 32.0
_FLOAT_SCALE = 1.0 / 65536.0
_INT_SCALE = 256.0


def offset_ray_origin(p: Float[Array, "*b 3"], n: Float[Array, "*b 3"]) -> Float[Array, "*b 3"]:
    """Move ``p`` off its surface along ``n`` by a few ULPs (Wächter & Binder 2019).

    Each coordinate is offset by ``256 * n_i`` units in the last place of float32 (integer
    arithmetic on the bit pattern, so the offset scales with ``|p_i|``); coordinates within
    ``1/32`` of zero, where ULPs are tiny, get the absolute offset ``n_i / 65536`` instead.
    ``n`` should be a unit normal pointing to the side the new ray leaves to.

    The offset is a constant for differentiation (straight-through: ``d out / d p = I``).

    Example: ``offset_ray_origin([1., 0, 0], [1., 0, 0])`` → ``[1.0000305, 0, 0]``
    (``1 + 256 * 2**-23``).
    """
    p = jnp.asarray(p)
    n = jnp.asarray(n, p.dtype)
    if p.dtype == jnp.float64:
        itype, scale = jnp.int64, _INT_SCALE * 2.0**29
    else:
        itype, scale = jnp.int32, _INT_SCALE
    ps = jax.lax.stop_gradient(p)
    ns = jax.lax.stop_gradient(n)
    of_i = (scale * ns).astype(itype)
    bits = jax.lax.bitcast_convert_type(ps, itype)
    p_i = jax.lax.bitcast_convert_type(bits + jnp.where(ps < 0, -of_i, of_i), ps.dtype)
    p_f = ps + _FLOAT_SCALE * ns
    out = jnp.where(jnp.abs(ps) < _ORIGIN, p_f, p_i)
    return p + (out - ps)


def spawn_ray(
    p: Float[Array, "*b 3"], n: Float[Array, "*b 3"], d: Float[Array, "*b 3"]
) -> tuple[Float[Array, "*b 3"], Float[Array, "*b 3"]]:
    """Origin and direction of a secondary ray leaving surface point ``p`` in direction ``d``.

    The origin is ``p`` offset along ``±n`` (the side ``d`` points to) with
    :func:`offset_ray_origin`, so the new ray can be traced with ``tmin = 0`` without hitting
    the surface it starts on, even at grazing angles. Shapes: ``p, n, d (..., 3)``; ``n`` is the
    unit geometric normal (either orientation), ``d`` the unit direction (returned unchanged).
    Reference: Wächter & Binder 2019, Ray Tracing Gems ch. 6.
    """
    p = jnp.asarray(p)
    n = jnp.asarray(n, p.dtype)
    d = jnp.asarray(d, p.dtype)
    side = jnp.where(sum_last(n * d, keepdims=True) < 0, -1.0, 1.0).astype(p.dtype)
    return offset_ray_origin(p, side * n), d
