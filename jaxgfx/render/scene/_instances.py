"""``{type: instances}`` shape descriptions (Mitsuba's ``shapegroup`` / ``instance``).

``{type: instances, shapes: [shape descriptions in group space], to_world: [4x4, ...]}``:
every member shape is placed once per matrix. Each member becomes ONE
:class:`~jaxgfx.render.geometry.instance.Instances` whose shape (for meshes of at least
``BVH_MIN_TRIANGLES`` triangles: its traversal structure) is built once and shared by all
instances. As in Mitsuba 3, groups do not nest and hold no emitters; an empty group or an
empty matrix list adds nothing. SDF shapes (``sdf``, ``sdfgrid``) may be members: they are
intersected in the instance's space.
"""

from __future__ import annotations

from collections.abc import Mapping

import jax.numpy as jnp
import numpy as np

from jaxgfx.render.geometry.instance import Instances, check_instance_transforms
from jaxgfx.render.scene.schema import expect_keys, shape_from_desc

__all__ = ["instances_from_desc"]


def instances_from_desc(d, where, base_dir, material_index, build_mesh):
    """``[(Instances, material table (K·n,) int32), ...]`` for one ``instances`` entry.

    ``material_index(desc, where)`` resolves a member's ``material``; ``build_mesh(mesh)``
    returns the mesh itself or its traversal structure."""
    expect_keys(d, where, ("type", "shapes", "to_world"))
    members = d["shapes"]
    if not isinstance(members, (list, tuple)):
        raise ValueError(f"{where}.shapes: expected a list of shape descriptions")
    mats = d["to_world"]
    if isinstance(mats, (list, tuple)) and len(mats) == 0:
        return []
    to_world = check_instance_transforms(mats, f"{where}.to_world")
    out = []
    for j, sd in enumerate(members):
        w = f"{where}.shapes[{j}]"
        if isinstance(sd, Mapping) and sd.get("type") == "instances":
            raise ValueError(f"{w}: nested instancing is not supported (as in Mitsuba 3)")
        if isinstance(sd, Mapping) and sd.get("type") in ("linearcurve", "bsplinecurve"):
            raise ValueError(f"{w}: instanced curves are not supported (place the curves "
                             "with their own to_world)")  # fmt: skip
        if isinstance(sd, Mapping) and sd.get("type") == "ellipsoids":
            raise ValueError(f"{w}: instanced ellipsoids are not supported (list them in one "
                             "ellipsoids shape)")  # fmt: skip
        kind, shape = shape_from_desc(sd, w, base_dir)
        m = to_world
        if isinstance(shape, Instances):  # an sdfgrid with its own to_world: compose
            m = to_world @ np.asarray(shape.to_world[0], np.float64)
            shape = shape.shape
        mi = material_index(sd, w)
        if kind == "mesh":
            shape = build_mesh(shape)
        inst = Instances(shape, m)
        out.append((inst, jnp.full((inst.count * inst.n_prims,), mi, jnp.int32)))
    return out
