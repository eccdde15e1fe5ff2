# ruff: noqa: F722  (jaxtyping shape strings)
"""Signed distance functions (SDFs): primitives, CSG operators and normals.

An SDF is an ``eqx.Module`` whose ``__call__(p (..., 3)) -> (...)`` returns the signed
distance (negative inside) from ``p`` to the surface. Primitives are exact distances
(Quilez, "distance functions", 2008-2023); ``SDFIntersection``/``SDFSubtraction`` and the smooth
union give bounds rather than exact distances, which sphere tracing tolerates. Build trees from
plain dicts with :func:`sdf_from_dict`; intersect them by sphere tracing
(:mod:`jaxgfx.render.geometry.sphere_tracing`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jaxgfx._checks import check_choice, check_positive
from jaxgfx._math import max_last, safe_div, safe_norm, safe_normalize, sum_last

__all__ = [
    "SDF",
    "SDFSphere",
    "SDFBox",
    "SDFRoundBox",
    "SDFTorus",
    "SDFPlane",
    "SDFCapsule",
    "SDFUnion",
    "SDFIntersection",
    "SDFSubtraction",
    "SDFSmoothUnion",
    "SDF_OPS",
    "sdf_from_dict",
    "sdf_normal",
]


def _vec(x, name, n=3):
    a = jnp.asarray(x)
    if not jnp.issubdtype(a.dtype, jnp.floating):
        a = a.astype(jnp.float32)
    if a.shape != (n,):
        raise ValueError(f"{name}: expected shape ({n},), got {a.shape}")
    return a


def _scalar(x, name):
    a = jnp.asarray(x)
    if not jnp.issubdtype(a.dtype, jnp.floating):
        a = a.astype(jnp.float32)
    if a.shape != ():
        raise ValueError(f"{name}: expected a scalar, got shape {a.shape}")
    return a


class SDF(eqx.Module):
    """Abstract SDF: ``sdf(p)`` maps points ``(..., 3)`` to signed distances ``(...)``."""

    def __call__(self, p: Float[Array, "*b 3"]) -> Float[Array, "*b"]:
        raise NotImplementedError


class SDFSphere(SDF):
    """Sphere: ``|p - center| - radius``."""

    center: Float[Array, " 3"]
    radius: Float[Array, ""]

    def __init__(self, center, radius):
        self.center = _vec(center, "center")
        self.radius = check_positive(_scalar(radius, "radius"), "radius")

    def __call__(self, p):
        return safe_norm(p - self.center) - self.radius


def _box(q):
    outside = safe_norm(jnp.maximum(q, 0.0))
    inside = jnp.minimum(max_last(q), 0.0)
    return outside + inside


class SDFBox(SDF):
    """Axis-aligned box with half extents ``half_size (3,)`` (exact Euclidean distance)."""

    center: Float[Array, " 3"]
    half_size: Float[Array, " 3"]

    def __init__(self, center, half_size):
        self.center = _vec(center, "center")
        self.half_size = check_positive(_vec(half_size, "half_size"), "half_size")

    def __call__(self, p):
        return _box(jnp.abs(p - self.center) - self.half_size)


class SDFRoundBox(SDF):
    """Box of half extents ``half_size`` with edges rounded by ``radius`` (< min half size)."""

    center: Float[Array, " 3"]
    half_size: Float[Array, " 3"]
    radius: Float[Array, ""]

    def __init__(self, center, half_size, radius):
        self.center = _vec(center, "center")
        self.half_size = check_positive(_vec(half_size, "half_size"), "half_size")
        self.radius = check_positive(_scalar(radius, "radius"), "radius")

    def __call__(self, p):
        return _box(jnp.abs(p - self.center) - (self.half_size - self.radius)) - self.radius


class SDFTorus(SDF):
    """Torus around the y axis through ``center``: ring radius ``major``, tube ``minor``."""

    center: Float[Array, " 3"]
    major: Float[Array, ""]
    minor: Float[Array, ""]

    def __init__(self, center, major, minor):
        self.center = _vec(center, "center")
        self.major = check_positive(_scalar(major, "major"), "major")
        self.minor = check_positive(_scalar(minor, "minor"), "minor")

    def __call__(self, p):
        q = p - self.center
        ring = safe_norm(q[..., [0, 2]]) - self.major
        return safe_norm(jnp.stack([ring, q[..., 1]], -1)) - self.minor


class SDFPlane(SDF):
    """Half-space ``dot(p, n) <= offset`` (``n`` is normalised): ``dot(p, n) - offset``."""

    normal: Float[Array, " 3"]
    offset: Float[Array, ""]

    def __init__(self, normal, offset=0.0):
        self.normal = _vec(normal, "normal")
        self.offset = _scalar(offset, "offset")

    def __call__(self, p):
        return sum_last(p * safe_normalize(self.normal)) - self.offset


class SDFCapsule(SDF):
    """Capsule: points within ``radius`` of the segment ``a b``."""

    a: Float[Array, " 3"]
    b: Float[Array, " 3"]
    radius: Float[Array, ""]

    def __init__(self, a, b, radius):
        self.a = _vec(a, "a")
        self.b = _vec(b, "b")
        self.radius = check_positive(_scalar(radius, "radius"), "radius")

    def __call__(self, p):
        pa = p - self.a
        ba = self.b - self.a
        h = jnp.clip(safe_div(sum_last(pa * ba), jnp.sum(ba * ba)), 0.0, 1.0)
        return safe_norm(pa - h[..., None] * ba) - self.radius


class SDFUnion(SDF):
    """``min(a, b)``."""

    a: SDF
    b: SDF

    def __call__(self, p):
        return jnp.minimum(self.a(p), self.b(p))


class SDFIntersection(SDF):
    """``max(a, b)`` (a lower bound of the true distance outside)."""

    a: SDF
    b: SDF

    def __call__(self, p):
        return jnp.maximum(self.a(p), self.b(p))


class SDFSubtraction(SDF):
    """``a`` minus ``b``: ``max(a, -b)``."""

    a: SDF
    b: SDF

    def __call__(self, p):
        return jnp.maximum(self.a(p), -self.b(p))


class SDFSmoothUnion(SDF):
    """Polynomial smooth minimum with blend radius ``k > 0`` (Quilez 2013):
    ``h = clip(1/2 + (b - a) / 2k, 0, 1)``, ``d = mix(b, a, h) - k h (1 - h)``. Equals
    ``min(a, b)`` where ``|a - b| >= k``."""

    a: SDF
    b: SDF
    k: Float[Array, ""]

    def __init__(self, a, b, k):
        self.a, self.b = a, b
        self.k = check_positive(_scalar(k, "k"), "k")

    def __call__(self, p):
        da, db = self.a(p), self.b(p)
        h = jnp.clip(0.5 + 0.5 * safe_div(db - da, self.k), 0.0, 1.0)
        return db + h * (da - db) - self.k * h * (1.0 - h)


SDF_OPS = {
    "sphere": (SDFSphere, ("center", "radius"), ()),
    "box": (SDFBox, ("center", "half_size"), ()),
    "round_box": (SDFRoundBox, ("center", "half_size", "radius"), ()),
    "torus": (SDFTorus, ("center", "major", "minor"), ()),
    "plane": (SDFPlane, ("normal", "offset"), ()),
    "capsule": (SDFCapsule, ("a", "b", "radius"), ()),
    "union": (SDFUnion, (), ("a", "b")),
    "intersection": (SDFIntersection, (), ("a", "b")),
    "subtraction": (SDFSubtraction, (), ("a", "b")),
    "smooth_union": (SDFSmoothUnion, ("k",), ("a", "b")),
}
"""``op`` name → (class, numeric keys, child keys) for :func:`sdf_from_dict`."""


def sdf_from_dict(spec, *, path: str = "sdf") -> SDF:
    """Build an SDF tree from nested dicts, e.g.
    ``{"op": "smooth_union", "k": 0.2, "a": {"op": "sphere", "center": [0, 0, 0],
    "radius": 1}, "b": {"op": "box", "center": [1, 0, 0], "half_size": [.5, .5, .5]}}``.

    Every node needs ``op`` (a key of :data:`SDF_OPS`) and exactly that op's keys; errors raise
    ``ValueError`` naming the offending path (``sdf.a.b``) and op or key.
    """
    if not isinstance(spec, dict):
        raise ValueError(f"{path}: expected a dict with an 'op' key, got {type(spec).__name__}")
    op = check_choice(spec.get("op"), f"{path}.op", SDF_OPS)
    cls, nums, kids = SDF_OPS[op]
    keys = set(spec) - {"op"}
    need = set(nums) | set(kids)
    optional = {"offset"} if op == "plane" else set()
    if need - keys - optional:
        raise ValueError(f"{path}: op {op!r} is missing keys {sorted(need - keys - optional)}")
    if keys - need:
        raise ValueError(f"{path}: op {op!r} got unknown keys {sorted(keys - need)}")
    args = {k: sdf_from_dict(spec[k], path=f"{path}.{k}") for k in kids}
    for k in nums:
        if k in spec:
            try:
                args[k] = jnp.asarray(spec[k], jnp.float32)
            except (TypeError, ValueError):
                raise ValueError(f"{path}.{k}: expected numbers, got {spec[k]!r}") from None
    try:
        return cls(**args)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def sdf_normal(sdf: SDF, p: Float[Array, "*b 3"]) -> Float[Array, "*b 3"]:
    """Unit outward normal ``normalize(grad sdf(p))`` by automatic differentiation."""
    g = jax.grad(lambda q: jnp.sum(sdf(q)))(p)
    return safe_normalize(g)
