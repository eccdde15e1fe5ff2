"""``load_scene``: a scene description (mapping or YAML file) -> :class:`Scene`."""

from __future__ import annotations

import os
from collections.abc import Mapping

import jax
import jax.numpy as jnp

from jaxgfx._checks import check_choice
from jaxgfx.render.bsdf import make_bsdf
from jaxgfx.render.emitters import (
    AreaLight,
    ConstantEnvironment,
    DirectionalAreaLight,
    DirectionalLight,
    EnvironmentMap,
    PointLights,
    ProjectorLight,
    SpotLight,
)
from jaxgfx.render.film import make_filter
from jaxgfx.render.geometry import (
    BSplineCurves,
    Ellipsoids,
    Instances,
    LinearCurves,
    Rectangles,
    SDFGridShape,
    SDFShape,
    Spheres,
    area,
)
from jaxgfx.render.scene._lights import SPOT_TEXTURE_KEYS, projector_from_desc, spot_texture
from jaxgfx.render.scene._materials import (
    check_one_sided,
    emission_from_desc,
    material_from_desc,
)
from jaxgfx.render.scene._sunsky import sunsky_from_desc
from jaxgfx.render.scene.scene import Scene, id_problem, is_internal_name
from jaxgfx.render.scene.schema import (
    EMITTER_TYPES,
    FILM_KEYS,
    SCENE_KEYS,
    build_camera,
    envmap_image,
    envmap_rotation,
    expect_keys,
    num,
    rgb,
    shape_from_desc,
    vec,
)

__all__ = ["load_scene", "material_from_desc", "BVH_MIN_TRIANGLES"]

BVH_MIN_TRIANGLES = 64


def _concat(shapes):
    first = shapes[0]
    if isinstance(first, Spheres):
        frames = None
        if any(s.frames is not None for s in shapes):  # the others in world axes
            eye = jnp.eye(3, dtype=first.centers.dtype)
            frames = jnp.concatenate([
                s.frames if s.frames is not None
                else jnp.broadcast_to(eye, (s.radii.shape[0], 3, 3)) for s in shapes])  # fmt: skip
        return Spheres(
            jnp.concatenate([s.centers for s in shapes]),
            jnp.concatenate([s.radii for s in shapes]),
            frames,
        )
    return Rectangles(
        jnp.concatenate([s.centers for s in shapes]),
        jnp.concatenate([s.edge_u for s in shapes]),
        jnp.concatenate([s.edge_v for s in shapes]),
    )


def load_scene(
    desc, *, base_dir: str | None = None, accel: str = "auto", dtype=None, **params
) -> Scene:
    """Build a :class:`Scene` from a description mapping, a YAML file path or a Mitsuba 3 XML
    file path (``.xml``; ``params`` replace its ``$name`` parameters, see
    :func:`jaxgfx.render.scene.mitsuba_xml.read_xml` and docs/render_scenes.md).

    ``dtype``: the float dtype of every scene array and of the render (``float32`` or
    ``float64``); ``None`` is JAX's default float (float64 when ``jax_enable_x64`` is on, else
    float32). Integer and float values in the description give the same dtype.

    ``accel`` selects the traversal backend of meshes with at least ``BVH_MIN_TRIANGLES``
    triangles (smaller ones are tested by brute force in JAX): ``"auto"`` (the fastest
    installed for JAX's device: Embree on CPU, Warp on GPU, else the JAX BVH), ``"embree"``,
    ``"warp"`` or ``"jax"``; see docs/render_backends.md. Images and gradients do not depend on
    it (the hit record is recomputed in JAX); change it later with :meth:`Scene.with_accel`.
    """
    from jaxgfx.render.geometry.accel import build_traversal, resolve_backend

    accel = resolve_backend(accel)  # ValueError / ImportError before any work
    dtype = _float_dtype(dtype)
    is_xml = isinstance(desc, (str, os.PathLike)) and os.fspath(desc).lower().endswith(".xml")
    if params and not is_xml:
        raise TypeError(f"load_scene: parameters {sorted(params)} are for .xml scenes only")
    if is_xml:  # Mitsuba 3 XML: translated into a description (absolute file paths)
        from jaxgfx.render.scene.mitsuba_xml import read_xml

        desc = read_xml(desc, **params).desc
    elif isinstance(desc, (str, os.PathLike)):
        from jaxgfx.config import read_yaml

        base_dir = base_dir or os.path.dirname(os.path.abspath(os.fspath(desc)))
        desc = read_yaml(desc)
    expect_keys(desc, "scene", *SCENE_KEYS)
    camera = build_camera(desc["camera"], base_dir=base_dir)
    film = desc.get("film", {}) or {}
    expect_keys(film, "film", (), FILM_KEYS)
    fopts = {k: v for k, v in film.items() if k != "filter"}
    rfilter = make_filter(film.get("filter", "box"), **fopts)

    mats_desc = desc.get("materials", {}) or {}
    if not isinstance(mats_desc, Mapping):
        raise ValueError("materials: expected a mapping from names to material descriptions")
    names, materials, one_sided = [], [], []
    for name, md in mats_desc.items():
        if is_internal_name(name):
            raise ValueError(
                f"materials.{name}: names of the form __NAME__ are the loader's own "
                "(__default__, __black__); rename the material"
            )
        sided = False
        if isinstance(md, Mapping) and "one_sided" in md:
            md = dict(md)
            sided = md.pop("one_sided")
        try:
            materials.append(material_from_desc(md, where="", base_dir=base_dir))
        except (ValueError, TypeError) as e:
            raise ValueError(f"materials.{name}: {e}") from None
        one_sided.append(check_one_sided(sided, materials[-1], f"materials.{name}.one_sided"))
        names.append(str(name))
    from jaxgfx.render.scene._mesh_attributes import attach_attributes, attribute_slots, with_slots

    slots = attribute_slots(materials)  # mesh_attribute textures: the attribute layout
    if slots:
        if any(getattr(m, "needs_tangents", False) for m in materials):
            raise ValueError("materials: normal / bump maps together with mesh_attribute "
                             "textures in one scene are not supported")  # fmt: skip
        materials = list(with_slots(materials, slots))

    def material_index(d, where):
        m = d.get("material")
        if m is None:
            if "__default__" not in names:
                names.append("__default__")
                materials.append(make_bsdf({"type": "diffuse", "reflectance": 0.5}))
            return names.index("__default__")
        if m not in names or is_internal_name(m):
            have = [n for n in names if not is_internal_name(n)]
            raise ValueError(f"{where}.material: unknown material {m!r}; have {have}")
        return names.index(m)

    shapes_desc = desc["shapes"]
    if not isinstance(shapes_desc, (list, tuple)):
        raise ValueError("shapes: expected a list")
    groups: dict[str, list] = {"sphere": [], "rectangle": []}
    group_mats: dict[str, list] = {"sphere": [], "rectangle": []}
    meshes, instanced = [], []
    seen_ids: dict = {}  # (namespace, id) -> where first given
    shape_ids = []  # (id, "sphere" / "rectangle" / "mesh", position in its list, material)
    for i, sd in enumerate(shapes_desc):
        where = f"shapes[{i}]"
        if isinstance(sd, Mapping) and sd.get("type") == "instances":  # shapegroup / instance
            from jaxgfx.render.scene._instances import instances_from_desc

            def build(m):
                return m if m.faces.shape[0] < BVH_MIN_TRIANGLES else build_traversal(m, accel)

            instanced += instances_from_desc(sd, where, base_dir, material_index, build)
            continue
        kind, shape = shape_from_desc(sd, where, base_dir)
        if slots and kind == "mesh":
            shape = attach_attributes(shape, sd, where, base_dir, slots)
        mi = material_index(sd, where)
        ident = _object_id(sd, where, "shapes", seen_ids)
        if ident is not None:
            pos = len(meshes) if kind in ("mesh", "sdf") else len(groups[kind])
            shape_ids.append((ident, "mesh" if kind in ("mesh", "sdf") else kind, pos, names[mi]))
        if kind in ("mesh", "sdf"):
            meshes.append((shape, mi))
        else:
            groups[kind].append(shape)
            group_mats[kind].append(mi)

    shapes, shape_mats = [], []
    first: dict = {}  # index in `shapes` of the sphere batch, the rectangle batch, the meshes
    for kind in ("sphere", "rectangle"):
        if groups[kind]:
            first[kind] = len(shapes)
            shapes.append(_concat(groups[kind]))
            shape_mats.append(jnp.asarray(group_mats[kind], jnp.int32))
    first["mesh"] = len(shapes)
    object_ids = [(ident, "shape", first[k] + (pos if k == "mesh" else 0),
                   None if k == "mesh" else pos, mat)
                  for ident, k, pos, mat in shape_ids]  # fmt: skip
    for m, mi in meshes:
        one_material = (SDFShape, SDFGridShape, Instances, LinearCurves, BSplineCurves,
                        Ellipsoids)  # fmt: skip
        if isinstance(m, one_material):
            shapes.append(m)
            shape_mats.append(jnp.full((1,), mi, jnp.int32))
            continue
        if m.faces.shape[0] >= BVH_MIN_TRIANGLES:
            shapes.append(build_traversal(m, accel))
        else:
            shapes.append(m)
        shape_mats.append(jnp.full((m.faces.shape[0],), mi, jnp.int32))
    for inst, table in instanced:
        shapes.append(inst)
        shape_mats.append(table)

    points_pos, points_int, area_lights, emitter_shapes, delta_lights = [], [], [], [], []
    environment = None
    em_desc = desc.get("emitters", []) or []
    if not isinstance(em_desc, (list, tuple)):
        raise ValueError("emitters: expected a list")
    for i, ed in enumerate(em_desc):
        where = f"emitters[{i}]"
        if not isinstance(ed, Mapping) or "type" not in ed:
            raise ValueError(f"{where}: expected a mapping with a 'type' key")
        kind = check_choice(ed["type"], f"{where}.type", EMITTER_TYPES)
        ident = _object_id(ed, where, "emitters", seen_ids) if isinstance(ed, Mapping) else None
        n_delta = sum(_delta_kind(e) == kind for e in delta_lights)
        if ident is not None:  # index of this emitter among its kind (row: point lights)
            ek = "environment" if kind in ("constant", "envmap", "sunsky") else kind
            index = {"point": 0, "area": len(area_lights), "environment": 0}.get(ek, n_delta)
            row = len(points_pos) if ek == "point" else None
            object_ids.append((ident, ek, index, row, None))
        if kind == "point":
            expect_keys(ed, where, ("type", "position", "intensity"), ("id",))
            points_pos.append(vec(ed["position"], f"{where}.position"))
            points_int.append(rgb(ed["intensity"], f"{where}.intensity"))
        elif kind == "directional":
            expect_keys(ed, where, ("type", "direction", "irradiance"), ("id",))
            delta_lights.append(
                _prefixed(
                    where,
                    DirectionalLight.create,
                    rgb(ed["irradiance"], f"{where}.irradiance"),
                    vec(ed["direction"], f"{where}.direction"),
                )
            )
        elif kind == "spot":
            expect_keys(
                ed,
                where,
                ("type", "position", "direction", "intensity"),
                ("cutoff_angle", "beam_width", "id", *SPOT_TEXTURE_KEYS),
            )
            texture, up = spot_texture(ed, where, base_dir)
            delta_lights.append(
                _prefixed(
                    where,
                    SpotLight.create,
                    vec(ed["position"], f"{where}.position"),
                    vec(ed["direction"], f"{where}.direction"),
                    rgb(ed["intensity"], f"{where}.intensity"),
                    num(ed.get("cutoff_angle", 20.0), f"{where}.cutoff_angle"),
                    None
                    if "beam_width" not in ed
                    else num(ed["beam_width"], f"{where}.beam_width"),
                    texture=texture,
                    up=up,
                )
            )
        elif kind == "projector":
            delta_lights.append(projector_from_desc(ed, where, base_dir))
        elif kind in ("area", "directionalarea"):
            expect_keys(ed, where, ("type", "shape", "radiance"), ("material", "id"))
            if isinstance(ed["shape"], Mapping) and ed["shape"].get("type") == "ellipsoids":
                raise ValueError(f"{where}.shape: ellipsoids cannot be area lights (Mitsuba's "
                                 "ellipsoids have no area sampling)")  # fmt: skip
            sk, shape = shape_from_desc(ed["shape"], f"{where}.shape", base_dir)
            shape_ident = _object_id(ed["shape"], f"{where}.shape", "shapes", seen_ids)
            if sk == "sdf":
                raise ValueError(f"{where}.shape: SDF shapes cannot be area lights (no area)")
            if "material" in ed["shape"]:
                raise ValueError(f"{where}.shape.material: put 'material' on the emitter")
            if ed.get("material"):
                mi = material_index(ed, where)
            else:
                mi = _black_material(names, materials)
            big = sk == "mesh" and shape.faces.shape[0] >= BVH_MIN_TRIANGLES
            shapes.append(build_traversal(shape, accel) if big else shape)  # traced like meshes
            if shape_ident is not None:
                row = 0 if sk in ("sphere", "rectangle") else None  # a batch of one
                object_ids.append((shape_ident, "shape", len(shapes) - 1, row, names[mi]))
            n_prims = shape.faces.shape[0] if sk == "mesh" else 1
            shape_mats.append(jnp.full((n_prims,), mi, jnp.int32))
            if kind == "directionalarea":  # a delta light: no emission towards the camera
                rad = rgb(ed["radiance"], f"{where}.radiance")
                delta_lights.append(
                    _prefixed(where, DirectionalAreaLight, rad, shape, len(shapes) - 1)
                )
                continue
            rad = emission_from_desc(
                ed["radiance"], f"{where}.radiance", base_dir=base_dir, rgb=rgb
            )
            area_lights.append(AreaLight(rad, len(shapes) - 1))
            emitter_shapes.append(shape)
        else:  # "constant" / "envmap" / "sunsky"
            if environment is not None:
                raise ValueError(f"{where}: only one environment emitter is supported")
            if kind == "sunsky":
                environment = sunsky_from_desc(ed, where)
            elif kind == "constant":
                expect_keys(ed, where, ("type", "radiance"), ("id",))
                environment = ConstantEnvironment(rgb(ed["radiance"], f"{where}.radiance"))
            else:
                environment = EnvironmentMap.create(
                    envmap_image(ed, where, base_dir),
                    ed.get("scale", 1.0),
                    envmap_rotation(ed, where),
                )
    if not shapes:
        raise ValueError("shapes: the scene has no geometry")
    point_lights = (
        PointLights.create(jnp.stack(points_pos), jnp.stack(points_int)) if points_pos else None
    )
    for i, sh in enumerate(emitter_shapes):
        if float(area(sh)) <= 0:
            raise ValueError(f"emitters: area light {i} has zero area")
    scene = Scene(
        camera=camera,
        shapes=tuple(shapes),
        shape_materials=tuple(shape_mats),
        materials=tuple(materials),
        point_lights=point_lights,
        area_lights=tuple(area_lights),
        emitter_shapes=tuple(emitter_shapes),
        environment=environment,
        material_names=tuple(names),
        rfilter=rfilter,
        delta_lights=tuple(delta_lights),
        object_ids=tuple(object_ids),
        # the loader's own materials (__default__, __black__) are two-sided
        one_sided=tuple(one_sided + [False] * (len(materials) - len(one_sided)))
        if any(one_sided)
        else (),
    )
    return cast_floats(scene, dtype)


def _object_id(d, where, namespace, seen):
    """The ``id`` of a shape / emitter description (``None`` when it has none), checked: a name
    :func:`~jaxgfx.render.scene.scene.id_problem` accepts, unique among the shapes (or the
    emitters) of the scene."""
    if not isinstance(d, Mapping) or "id" not in d:
        return None
    ident = d["id"]
    problem = id_problem(ident)
    if problem:
        raise ValueError(f"{where}.id: {problem}")
    if (namespace, ident) in seen:
        raise ValueError(f"{where}.id: duplicate id {ident!r} (first given at "
                         f"{seen[namespace, ident]})")  # fmt: skip
    seen[namespace, ident] = where
    return ident


def _delta_kind(light) -> str:
    if isinstance(light, ProjectorLight):
        return "projector"
    if isinstance(light, DirectionalAreaLight):
        return "directionalarea"
    return "spot" if isinstance(light, SpotLight) else "directional"


def _prefixed(where, build, *args, **kwargs):
    """``build(*args, **kwargs)`` with its ``ValueError`` prefixed by ``where``
    (``emitters[1].beam_width: ...``)."""
    try:
        return build(*args, **kwargs)
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None


def _float_dtype(dtype):
    if dtype is None:
        return jnp.asarray(1.0).dtype
    try:
        dt = jnp.dtype(dtype)
    except TypeError:
        dt = None
    if dt not in (jnp.dtype(jnp.float32), jnp.dtype(jnp.float64)):
        raise ValueError(f"dtype: expected float32 or float64 (or None), got {dtype!r}")
    if dt == jnp.float64 and not jax.config.jax_enable_x64:
        raise ValueError("dtype: float64 needs jax.config.update('jax_enable_x64', True) first")
    return dt


def cast_floats(tree, dtype):
    """``tree`` with every floating JAX array leaf cast to ``dtype`` (integer leaves, NumPy
    arrays held by traversal backends and static fields unchanged)."""

    def cast(x):
        if isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jnp.floating):
            return x.astype(dtype)
        return x

    return jax.tree_util.tree_map(cast, tree)


def _black_material(names, materials):
    if "__black__" not in names:
        names.append("__black__")
        materials.append(make_bsdf({"type": "diffuse", "reflectance": 0.0}))
    return names.index("__black__")
