# ruff: noqa: F722  (jaxtyping shape strings)
"""Indexed triangle meshes: :class:`TriangleMesh`, the brute-force triangle tests selectable by
name, and the differentiable hit record (interpolated shading normals and UVs)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from jaxgfx._checks import as_float_array
from jaxgfx._math import safe_div, safe_normalize, sum_last, vdot
from jaxgfx.render.geometry._points import as_points
from jaxgfx.render.geometry.ray import Hit, hit_record
from jaxgfx.render.geometry.triangle_moller_trumbore import moller_trumbore_all
from jaxgfx.render.geometry.triangle_unit import unit_triangle_all

__all__ = ["TriangleMesh", "TRIANGLE_INTERSECTORS", "mesh_hit"]


class TriangleMesh(eqx.Module):
    """Indexed triangle mesh.

    Fields: ``vertices (V, 3)`` float, ``faces (F, 3)`` int32 (counter-clockwise as seen from
    the side the geometric normal points to), optional ``normals (V, 3)`` (per-vertex shading
    normals) and ``uvs (V, 2)``. Zero-area faces are allowed: they are never hit.
    Optional mesh attributes (Mitsuba's ``vertex_*`` / ``face_*``, read by ``mesh_attribute``
    textures): ``vertex_attributes (V, C)`` (interpolated with the barycentrics) and
    ``face_attributes (F, C)`` (constant per face), same ``C``; a hit's ``uv`` then carries
    ``C`` more columns: ``uv[..., 2:]`` = interpolated vertex value + face value.
    Differentiate w.r.t. ``vertices`` with ``eqx.filter_grad`` or by rebuilding the mesh inside
    the differentiated function (``faces`` is an integer leaf).
    """

    vertices: Float[Array, "V 3"]
    faces: Int[Array, "F 3"]
    normals: Float[Array, "V 3"] | None = None
    uvs: Float[Array, "V 2"] | None = None
    vertex_attributes: Float[Array, "V C"] | None = None
    face_attributes: Float[Array, "F C"] | None = None

    def __init__(
        self, vertices, faces, normals=None, uvs=None, vertex_attributes=None, face_attributes=None
    ):
        v = as_points(_numeric(vertices, "vertices", "fiu"), "vertices", 3)
        f = _numeric(faces, "faces", "iu")
        if f.ndim != 2 or f.shape[-1] != 3:
            raise ValueError(
                f"faces: expected an integer array of shape (F, 3), got {f.dtype}{f.shape}"
            )
        if f.shape[0] == 0:
            raise ValueError("faces: expected at least one triangle, got 0")
        if not isinstance(f, jax.core.Tracer):
            fn = np.asarray(f)  # checked before the int32 cast (2**40 must not wrap around)
            if fn.min() < 0 or fn.max() >= v.shape[0]:
                raise ValueError(
                    f"faces: indices must lie in [0, {v.shape[0] - 1}], "
                    f"got range [{fn.min()}, {fn.max()}]"
                )
        self.vertices = v
        self.faces = jnp.asarray(f).astype(jnp.int32)
        if normals is not None:
            normals = as_points(normals, "normals", 3).astype(v.dtype)
            if normals.shape[0] != v.shape[0]:
                raise ValueError(f"normals: expected shape {v.shape}, got {normals.shape}")
        if uvs is not None:
            uvs = as_points(uvs, "uvs", 2).astype(v.dtype)
            if uvs.shape[0] != v.shape[0]:
                raise ValueError(f"uvs: expected shape ({v.shape[0]}, 2), got {uvs.shape}")
        self.normals, self.uvs = normals, uvs
        va, fa = vertex_attributes, face_attributes
        if (va is None) != (fa is None):
            raise ValueError("vertex_attributes, face_attributes: give both or neither")
        if va is not None:
            va = as_float_array(va, "vertex_attributes").astype(v.dtype)
            fa = as_float_array(fa, "face_attributes").astype(v.dtype)
            if va.ndim != 2 or va.shape[0] != v.shape[0]:
                raise ValueError(
                    f"vertex_attributes: expected shape ({v.shape[0]}, C), got {va.shape}"
                )
            if fa.shape != (f.shape[0], va.shape[1]):
                raise ValueError(
                    f"face_attributes: expected shape ({f.shape[0]}, {va.shape[1]}), got {fa.shape}"
                )
        self.vertex_attributes, self.face_attributes = va, fa

    @property
    def triangles(self) -> Float[Array, "F 3 3"]:
        """Corner positions ``(F, 3, 3)`` (face, corner, xyz)."""
        return self.vertices[self.faces]


def _numeric(x, name, kinds):
    """``x`` as an array whose dtype kind is in ``kinds`` (``"f"`` float, ``"i"``/``"u"``
    integer); ``ValueError`` naming ``name`` for strings, booleans, ragged lists, ``None``.
    JAX arrays (and tracers) are returned as they are when their dtype fits."""
    if not isinstance(x, (jax.Array, np.ndarray)):
        try:
            x = np.asarray(x)
        except (TypeError, ValueError):
            raise ValueError(
                f"{name}: expected an array of numbers, got a ragged or non-numeric sequence"
            ) from None
    if x.dtype.kind not in kinds:
        what = "an integer" if kinds == "iu" else "a numeric"
        raise ValueError(f"{name}: expected {what} array, got dtype {x.dtype}")
    return x


TRIANGLE_INTERSECTORS = {
    "MollerTrumbore1997": moller_trumbore_all,
    "affine": unit_triangle_all,
}
"""Brute-force triangle intersectors selectable by ``method=`` in :func:`intersect`."""


def mesh_hit(shape: TriangleMesh, pid, o, d, valid, prim_id, sid) -> Hit:
    """Differentiable hit record of rays ``o, d`` against triangle ``pid`` (Möller–Trumbore
    barycentrics; interpolated shading normals and UVs when the mesh has them)."""
    f = shape.faces[pid]
    v0, v1, v2 = (shape.vertices[f[..., k]] for k in range(3))
    e1, e2 = v1 - v0, v2 - v0
    P = jnp.cross(d, e2)
    det = vdot(P, e1)
    T = o - v0
    Q = jnp.cross(T, e1)
    valid = valid & (det != 0)
    t = safe_div(vdot(Q, e2), det)
    b1 = safe_div(vdot(P, T), det)
    b2 = safe_div(vdot(Q, d), det)
    b0 = 1.0 - b1 - b2
    p = b0[..., None] * v0 + b1[..., None] * v1 + b2[..., None] * v2
    ng = safe_normalize(jnp.cross(e1, e2))
    if shape.normals is not None:
        nv = shape.normals
        ns = safe_normalize(
            b0[..., None] * nv[f[..., 0]]
            + b1[..., None] * nv[f[..., 1]]
            + b2[..., None] * nv[f[..., 2]]
        )
        ns = jnp.where(sum_last(ns * ns, keepdims=True) > 0, ns, ng)
    else:
        ns = ng
    if shape.uvs is not None:
        tv = shape.uvs
        uv = (
            b0[..., None] * tv[f[..., 0]]
            + b1[..., None] * tv[f[..., 1]]
            + b2[..., None] * tv[f[..., 2]]
        )
    else:
        uv = jnp.stack([b1, b2], axis=-1)
    if shape.vertex_attributes is not None:  # mesh_attribute textures read uv[..., 2:]
        va = shape.vertex_attributes
        a = (
            b0[..., None] * va[f[..., 0]]
            + b1[..., None] * va[f[..., 1]]
            + b2[..., None] * va[f[..., 2]]
            + shape.face_attributes[pid]
        )
        uv = jnp.concatenate([uv, a.astype(uv.dtype)], axis=-1)
    return hit_record(valid, t, p, ng, ns, uv, prim_id, sid)
