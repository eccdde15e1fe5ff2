"""Mesh attributes for ``mesh_attribute`` textures: the layout of the attributes a scene's
materials read, and the packing of each mesh's attribute values into that layout.

Every attribute name read by a :class:`~jaxgfx.render.bsdf.texture.MeshAttribute` of any
material gets a slot (sorted by name); each triangle mesh of the scene then carries
``vertex_attributes (V, 3 S)`` and ``face_attributes (F, 3 S)`` (``S`` slots; a one-channel
attribute is stored in all three columns of its slot; a mesh without an attribute holds 0 there),
and its hits carry the interpolated values in ``uv[..., 2:]``. Scenes whose materials read no
attribute are unchanged. Values come from the mesh description's ``attributes`` mapping
(``{vertex_color: (V, 3) rows, face_weight: (F,) or (F, 1), ...}``) or, for a ``.ply`` file,
from its extra vertex / face properties (Mitsuba 3's names, see
:func:`jaxgfx.render.geometry.mesh_io.ply_attributes`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import jax
import numpy as np

from jaxgfx.render.bsdf.texture import MeshAttribute
from jaxgfx.render.geometry import TriangleMesh

__all__ = ["attribute_slots", "with_slots", "attach_attributes"]


def _is_attr(x):
    return isinstance(x, MeshAttribute)


def attribute_slots(materials) -> dict:
    """``{attribute name: slot}`` for the mesh_attribute textures in ``materials``."""
    names = {x.name for x in jax.tree_util.tree_leaves(materials, is_leaf=_is_attr) if _is_attr(x)}
    return {n: i for i, n in enumerate(sorted(names))}


def with_slots(materials, slots):
    """``materials`` with each mesh_attribute texture's slot set."""

    def fix(x):
        return MeshAttribute(x.name, x.scale, slots[x.name]) if _is_attr(x) else x

    return jax.tree_util.tree_map(fix, materials, is_leaf=_is_attr)


def _source(sd, where, base_dir):
    given = sd.get("attributes")
    if given is not None:
        if not isinstance(given, Mapping):
            raise ValueError(f"{where}.attributes: expected a mapping name -> values")
        return dict(given), f"{where}.attributes"
    path = sd.get("file")
    if isinstance(path, (str, os.PathLike)) and os.fspath(path).lower().endswith(".ply"):
        from jaxgfx.render.geometry.mesh_io import load_ply

        path = os.fspath(path)
        if not os.path.isabs(path) and base_dir:
            path = os.path.join(base_dir, path)
        return load_ply(path, attributes=True)[1], f"{where}.file"
    return {}, where


def attach_attributes(mesh: TriangleMesh, sd, where, base_dir, slots) -> TriangleMesh:
    """``mesh`` with its attribute values packed into the scene's layout ``slots``."""
    attrs, src = _source(sd, where, base_dir)
    nv, nf = mesh.vertices.shape[0], mesh.faces.shape[0]
    for name in attrs:
        if not isinstance(name, str) or not name.startswith(("vertex_", "face_")):
            raise ValueError(f"{src}: attribute names start with 'vertex_' or 'face_', "
                             f"got {name!r}")  # fmt: skip
    va = np.zeros((nv, 3 * len(slots)))
    fa = np.zeros((nf, 3 * len(slots)))
    for name, s in slots.items():
        if name not in attrs:
            continue
        vals = np.asarray(attrs[name], np.float64)
        vals = vals[:, None] if vals.ndim == 1 else vals
        rows = nv if name.startswith("vertex_") else nf
        if vals.ndim != 2 or vals.shape[0] != rows or vals.shape[1] not in (1, 3):
            raise ValueError(f"{src}: attribute {name!r}: expected shape ({rows}, 1 or 3), got "
                             f"{vals.shape}")  # fmt: skip
        if not np.all(np.isfinite(vals)):
            raise ValueError(f"{src}: attribute {name!r} has non-finite values")
        (va if name.startswith("vertex_") else fa)[:, 3 * s : 3 * s + 3] = vals
    return TriangleMesh(mesh.vertices, mesh.faces, mesh.normals, mesh.uvs, va, fa)
