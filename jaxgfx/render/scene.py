"""Scenes: a pytree of camera, shapes, materials and emitters, built from a dict or YAML file.

``load_scene(desc)`` accepts a mapping or a path to a YAML file with the sections ``camera``,
``shapes``, ``materials``, ``emitters`` (and optional ``film``), e.g.::

    camera: {origin: [0, 1.5, 5], target: [0, 1, 0], fov: 45, width: 128, height: 128}
    shapes:
      - {type: sphere, center: [0, 1, 0], radius: 1, material: metal}
      - {type: rectangle, center: [0, 0, 0], normal: [0, 1, 0], size: [10, 10], material: floor}
      - {type: mesh, file: bunny.obj, material: floor}
      - {type: sdf, expr: {op: sphere, center: [2, 1, 0], radius: 0.5}, material: floor,
         max_steps: 128, eps: 1e-4}                    # sphere traced (SDFShape)
    materials:
      metal: {type: roughconductor, distribution: ggx, alpha: 0.3}
      floor: {type: diffuse, reflectance: {type: checkerboard, color0: 0.8, color1: 0.2, scale: 8}}
    emitters:
      - {type: area, shape: {type: rectangle, center: [0, 4, 0], normal: [0, -1, 0], size: [2, 2]},
         radiance: [10, 10, 10]}
      - {type: point, position: [2, 3, 1], intensity: [50, 50, 50]}
      - {type: constant, radiance: [1, 1, 1]}          # or {type: envmap, file: sky.exr}

Every float is a differentiable leaf. Unknown keys, missing materials, NaN parameters raise
``ValueError`` naming the field (``shapes[1].radius``). Only what a scene uses is built: no
acceleration structure without meshes, no environment without an environment emitter, and the
integrators evaluate only the material types present.

``scene.replace("materials.metal.alpha", 0.2)`` returns a copy with one parameter changed
(also ``camera.fov``, ``emitters.point.intensities``, ``emitters.area.0.radiance``, nested
fields such as ``materials.metal.distribution.alpha_u``; ``alpha`` of a microfacet material
sets both ``alpha_u`` and ``alpha_v``).
``scene.get(path)`` reads one. Any RGB / float material parameter may be a texture
(``{type: bitmap, file|image, wrap, filter, raw}`` or ``{type: checkerboard, ...}``, see
:mod:`jaxgfx.render.textured`); texels are leaves (``materials.floor.reflectance.image``,
``materials.floor.reflectance.color0``). SDF parameters: ``shapes.I.sdf.radius`` (``I`` indexes
``scene.shapes``). Details and measurements: docs/render_scenes.md.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_finite
from jaxgfx._math import safe_normalize
from jaxgfx.render.bsdf import make_bsdf
from jaxgfx.render.bsdf._base import rgb_param
from jaxgfx.render.camera import MatrixCamera, PerspectiveCamera
from jaxgfx.render.emitters import AreaLight, ConstantEnvironment, EnvironmentMap, PointLights
from jaxgfx.render.film import make_filter
from jaxgfx.render.frame import frame_from_normal
from jaxgfx.render.sdf import sdf_from_dict
from jaxgfx.render.sdf_shape import SDFShape
from jaxgfx.render.shapes import Rectangles, Spheres, TriangleMesh, area
from jaxgfx.render.textured import Textured, make_textured

__all__ = ["Scene", "load_scene", "SHAPE_TYPES", "EMITTER_TYPES"]

SHAPE_TYPES = ("sphere", "rectangle", "mesh", "sdf")
EMITTER_TYPES = ("area", "point", "constant", "envmap")
BVH_MIN_TRIANGLES = 64


class Scene(eqx.Module):
    """A renderable scene (pytree). Build with :func:`load_scene`.

    Fields: ``camera``; ``shapes`` (tuple of Spheres / Rectangles / TriangleMesh / BVH);
    ``shape_materials`` (tuple of int32 arrays, material index per primitive of each shape);
    ``materials`` (tuple of BSDFs) named by the static ``material_names``; ``point_lights``
    (PointLights or None); ``area_lights`` (tuple of AreaLight); ``environment``
    (ConstantEnvironment / EnvironmentMap / None); ``emitter_shapes`` (tuple: the raw shape of each
    area light, for sampling); ``rfilter`` (reconstruction filter, static).
    """

    camera: PerspectiveCamera | MatrixCamera
    shapes: tuple
    shape_materials: tuple
    materials: tuple
    point_lights: PointLights | None
    area_lights: tuple
    emitter_shapes: tuple
    environment: ConstantEnvironment | EnvironmentMap | None
    material_names: tuple = eqx.field(static=True)
    rfilter: object = eqx.field(static=True)

    @property
    def width(self) -> int:
        return self.camera.width

    @property
    def height(self) -> int:
        return self.camera.height

    @property
    def n_lights(self) -> int:
        n = len(self.area_lights) + (self.environment is not None)
        return n + (self.point_lights.count if self.point_lights is not None else 0)

    # -- parameter access by name ------------------------------------------------------------
    def _locate(self, path: str):
        parts = path.split(".")
        head = parts[0]
        if head == "materials":
            if len(parts) < 2 or parts[1] not in self.material_names:
                raise ValueError(f"{path}: unknown material; have {list(self.material_names)}")
            idx = self.material_names.index(parts[1])
            getter = lambda s: s.materials[idx]  # noqa: E731
            rest = parts[2:]
        elif head == "camera":
            getter = lambda s: s.camera  # noqa: E731
            rest = parts[1:]
        elif head == "emitters" and len(parts) >= 2 and parts[1] == "point":
            if self.point_lights is None:
                raise ValueError(f"{path}: the scene has no point lights")
            getter = lambda s: s.point_lights  # noqa: E731
            rest = parts[2:]
        elif head == "emitters" and len(parts) >= 3 and parts[1] == "area":
            i = int(parts[2])
            if not 0 <= i < len(self.area_lights):
                raise ValueError(f"{path}: area light index out of range")
            getter = lambda s: s.area_lights[i]  # noqa: E731
            rest = parts[3:]
        elif head == "emitters" and len(parts) >= 2 and parts[1] == "environment":
            if self.environment is None:
                raise ValueError(f"{path}: the scene has no environment emitter")
            getter = lambda s: s.environment  # noqa: E731
            rest = parts[2:]
        elif head == "shapes" and len(parts) >= 2:
            i = int(parts[1])
            getter = lambda s: s.shapes[i]  # noqa: E731
            rest = parts[2:]
        else:
            raise ValueError(
                f"{path}: expected materials.NAME.FIELD, camera.FIELD, emitters.point.FIELD, "
                "emitters.area.I.FIELD, emitters.environment.FIELD or shapes.I.FIELD"
            )
        if not rest:
            raise ValueError(f"{path}: expected a field name after the object")
        obj = getter(self)
        prefix = []
        if isinstance(obj, Textured):
            # textured parameter: materials.NAME.FIELD.image / .color0; others: the BSDF's
            if rest[0] in obj.textures:
                if len(rest) < 2:
                    raise ValueError(f"{path}: {rest[0]!r} is a texture; name its parameter")
                prefix = [("textures", rest[0])]
                obj, rest = obj.textures[rest[0]], rest[1:]
            else:
                prefix = ["bsdf"]
                obj = obj.bsdf
        # aliases: isotropic roughness `alpha` sets both microfacet alphas
        if rest == ["alpha"] and hasattr(obj, "distribution") and not hasattr(obj, "alpha"):
            rest_list = [["distribution", "alpha_u"], ["distribution", "alpha_v"]]
        else:
            rest_list = [rest]
        getters = []
        for fields in rest_list:
            o = obj
            for field in fields:
                if not hasattr(o, field):
                    names = [
                        n
                        for n, v in vars(o).items()
                        if eqx.is_array(v) or isinstance(v, eqx.Module)
                    ]
                    raise ValueError(f"{path}: no parameter {field!r}; have {names}")
                o = getattr(o, field)
            if not eqx.is_array(o):
                raise ValueError(f"{path}: {fields[-1]!r} is not an array parameter")

            def where(s, fields=(*prefix, *fields)):
                o = getter(s)
                for f in fields:
                    o = getattr(o, f[0])[f[1]] if isinstance(f, tuple) else getattr(o, f)
                return o

            getters.append(where)
        return getters

    def get(self, path: str):
        """The array at a dotted parameter path (see :meth:`replace`)."""
        return self._locate(path)[0](self)

    def replace(self, path: str, value):
        """Copy of the scene with the parameter at ``path`` set to ``value`` (same shape)."""
        out = self
        for where in self._locate(path):
            old = where(out)
            new = jnp.broadcast_to(jnp.asarray(value, old.dtype), old.shape)
            out = eqx.tree_at(where, out, new)
        return out


# -------------------------------------------------------------------------------------------
# loading


def envmap_image(ed, where, base_dir=None) -> np.ndarray:
    """The lat-long image of an ``envmap`` emitter description (``file`` relative to
    ``base_dir``, or an inline ``image``), validated to ``(H, W, >=3)``."""
    _expect_keys(ed, where, ("type",), ("file", "image", "scale"))
    if "file" in ed:
        from jaxgfx import io

        path = os.fspath(ed["file"])
        if not os.path.isabs(path) and base_dir:
            path = os.path.join(base_dir, path)
        img = io.read_any(path)
    elif "image" in ed:
        img = np.asarray(ed["image"], np.float32)
    else:
        raise ValueError(f"{where}: expected 'file' or 'image'")
    if img.ndim != 3 or img.shape[-1] < 3:
        raise ValueError(f"{where}.image: expected (H, W, 3), got shape {img.shape}")
    return img


def _expect_keys(d, where, required=(), optional=()):
    if not isinstance(d, Mapping):
        raise ValueError(f"{where}: expected a mapping, got {type(d).__name__}")
    unknown = sorted(set(d) - set(required) - set(optional))
    if unknown:
        raise ValueError(
            f"{where}: unknown key(s) {unknown}; expected {sorted(set(required) | set(optional))}"
        )
    missing = [k for k in required if k not in d]
    if missing:
        raise ValueError(f"{where}: missing key(s) {missing}")


def _vec(x, where, n=3):
    a = as_float_array(x, where)
    check_finite(a, where)
    if a.shape != (n,):
        raise ValueError(f"{where}: expected {n} numbers, got shape {a.shape}")
    return a


def _num(x, where, *, positive=False):
    a = as_float_array(x, where)
    check_finite(a, where)
    if a.shape != ():
        raise ValueError(f"{where}: expected a number, got shape {a.shape}")
    if positive and not float(a) > 0:
        raise ValueError(f"{where}: expected a positive number, got {float(a)}")
    return a


def _rgb(x, where):
    a = rgb_param(x, where)
    if a.shape != (3,):
        raise ValueError(f"{where}: expected a number or an RGB triple, got shape {a.shape}")
    return a


def _build_camera(d, where="camera"):
    if "view_proj_inverse" in d:
        _expect_keys(d, where, ("view_proj_inverse", "width", "height"))
        return MatrixCamera.from_matrix(d["view_proj_inverse"], d["width"], d["height"])
    _expect_keys(d, where, ("origin", "target", "fov", "width", "height"), ("up", "fov_axis"))
    return PerspectiveCamera.look_at(
        _vec(d["origin"], f"{where}.origin"),
        _vec(d["target"], f"{where}.target"),
        _vec(d.get("up", [0.0, 1.0, 0.0]), f"{where}.up"),
        _num(d["fov"], f"{where}.fov"),
        d["width"],
        d["height"],
        fov_axis=d.get("fov_axis", "x"),
    )


def _rectangle(d, where):
    n = _vec(d["normal"], f"{where}.normal")
    nn = float(jnp.linalg.norm(n))
    if nn == 0:
        raise ValueError(f"{where}.normal: expected a non-zero vector")
    size = as_float_array(d.get("size", [2.0, 2.0]), f"{where}.size")
    if size.shape != (2,) or bool(jnp.any(size <= 0)):
        raise ValueError(f"{where}.size: expected two positive numbers")
    fr = frame_from_normal(n / nn)
    return Rectangles(
        _vec(d["center"], f"{where}.center")[None], (fr.s * size[0])[None], (fr.t * size[1])[None]
    )


def _mesh(d, where, base_dir):
    from jaxgfx.render import mesh as mesh_io

    if "file" in d:
        path = d["file"]
        if not os.path.isabs(path) and base_dir:
            path = os.path.join(base_dir, path)
        ext = os.path.splitext(path)[1].lower()
        if ext not in (".obj", ".ply"):
            raise ValueError(f"{where}.file: expected an .obj or .ply file, got {path!r}")
        try:
            m = (mesh_io.load_obj if ext == ".obj" else mesh_io.load_ply)(path)
        except ValueError as e:  # name the shape as well as the file
            raise ValueError(f"{where}.file: {e}") from None
    elif "vertices" in d and "faces" in d:
        v = check_finite(as_float_array(d["vertices"], f"{where}.vertices"), f"{where}.vertices")
        f = np.asarray(d["faces"])
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"{where}: expected vertices (V, 3) and faces (F, 3)")
        if f.min() < 0 or f.max() >= v.shape[0]:
            raise ValueError(f"{where}.faces: vertex index out of range")
        m = TriangleMesh(v, jnp.asarray(f, jnp.int32))
    else:
        raise ValueError(f"{where}: expected 'file' or 'vertices' + 'faces'")
    if "translate" in d or "scale" in d:
        s = as_float_array(d.get("scale", 1.0), f"{where}.scale")
        t = _vec(d.get("translate", [0.0, 0.0, 0.0]), f"{where}.translate")
        normals = m.normals
        if normals is not None:  # normals transform with the inverse transpose: n / s
            normals = safe_normalize(normals / s)
        m = TriangleMesh(m.vertices * s + t, m.faces, normals, m.uvs)
    return m


def _shape_from_desc(d, where, base_dir):
    if not isinstance(d, Mapping) or "type" not in d:
        raise ValueError(f"{where}: expected a mapping with a 'type' key")
    kind = d["type"]
    common = ("type", "material")
    if kind == "sphere":
        _expect_keys(d, where, ("type", "center", "radius"), common)
        r = _num(d["radius"], f"{where}.radius", positive=True)
        return "sphere", Spheres(_vec(d["center"], f"{where}.center")[None], r[None])
    if kind == "rectangle":
        _expect_keys(d, where, ("type", "center", "normal"), (*common, "size"))
        return "rectangle", _rectangle(d, where)
    if kind == "mesh":
        _expect_keys(
            d, where, ("type",), (*common, "file", "vertices", "faces", "translate", "scale")
        )
        return "mesh", _mesh(d, where, base_dir)
    if kind == "sdf":
        _expect_keys(d, where, ("type", "expr"), (*common, "max_steps", "eps"))
        expr = d["expr"]
        sdf = sdf_from_dict(dict(expr) if isinstance(expr, Mapping) else expr, path=f"{where}.expr")
        try:
            return "sdf", SDFShape(sdf, d.get("max_steps", 128), d.get("eps", 1e-4))
        except ValueError as e:
            raise ValueError(f"{where}.{e}") from None
    raise ValueError(f"{where}.type: expected one of {SHAPE_TYPES}, got {kind!r}")


def _concat(shapes):
    first = shapes[0]
    if isinstance(first, Spheres):
        return Spheres(
            jnp.concatenate([s.centers for s in shapes]), jnp.concatenate([s.radii for s in shapes])
        )
    return Rectangles(
        jnp.concatenate([s.centers for s in shapes]),
        jnp.concatenate([s.edge_u for s in shapes]),
        jnp.concatenate([s.edge_v for s in shapes]),
    )


def load_scene(desc, *, base_dir: str | None = None) -> Scene:
    """Build a :class:`Scene` from a description mapping or a YAML file path."""
    if isinstance(desc, (str, os.PathLike)):
        from jaxgfx.config import read_yaml

        base_dir = base_dir or os.path.dirname(os.path.abspath(os.fspath(desc)))
        desc = read_yaml(desc)
    _expect_keys(desc, "scene", ("camera", "shapes"), ("materials", "emitters", "film"))
    camera = _build_camera(desc["camera"])
    film = desc.get("film", {}) or {}
    _expect_keys(film, "film", (), ("filter", "stddev", "radius"))
    fopts = {k: v for k, v in film.items() if k != "filter"}
    rfilter = make_filter(film.get("filter", "box"), **fopts)

    mats_desc = desc.get("materials", {}) or {}
    if not isinstance(mats_desc, Mapping):
        raise ValueError("materials: expected a mapping from names to material descriptions")
    names, materials = [], []
    for name, md in mats_desc.items():
        try:
            materials.append(make_textured(dict(md), make_bsdf, where="", base_dir=base_dir))
        except (ValueError, TypeError) as e:
            raise ValueError(f"materials.{name}: {e}") from None
        names.append(str(name))

    def material_index(d, where):
        m = d.get("material")
        if m is None:
            if "__default__" not in names:
                names.append("__default__")
                materials.append(make_bsdf({"type": "diffuse", "reflectance": 0.5}))
            return names.index("__default__")
        if m not in names:
            raise ValueError(f"{where}.material: unknown material {m!r}; have {names}")
        return names.index(m)

    shapes_desc = desc["shapes"]
    if not isinstance(shapes_desc, (list, tuple)):
        raise ValueError("shapes: expected a list")
    groups: dict[str, list] = {"sphere": [], "rectangle": []}
    group_mats: dict[str, list] = {"sphere": [], "rectangle": []}
    meshes = []
    for i, sd in enumerate(shapes_desc):
        where = f"shapes[{i}]"
        kind, shape = _shape_from_desc(sd, where, base_dir)
        mi = material_index(sd, where)
        if kind in ("mesh", "sdf"):
            meshes.append((shape, mi))
        else:
            groups[kind].append(shape)
            group_mats[kind].append(mi)

    shapes, shape_mats = [], []
    for kind in ("sphere", "rectangle"):
        if groups[kind]:
            shapes.append(_concat(groups[kind]))
            shape_mats.append(jnp.asarray(group_mats[kind], jnp.int32))
    for m, mi in meshes:
        if isinstance(m, SDFShape):
            shapes.append(m)
            shape_mats.append(jnp.full((1,), mi, jnp.int32))
            continue
        if m.faces.shape[0] >= BVH_MIN_TRIANGLES:
            from jaxgfx.render.accel.bvh import build_bvh

            shapes.append(build_bvh(m))
        else:
            shapes.append(m)
        shape_mats.append(jnp.full((m.faces.shape[0],), mi, jnp.int32))

    points_pos, points_int, area_lights, emitter_shapes = [], [], [], []
    environment = None
    em_desc = desc.get("emitters", []) or []
    if not isinstance(em_desc, (list, tuple)):
        raise ValueError("emitters: expected a list")
    for i, ed in enumerate(em_desc):
        where = f"emitters[{i}]"
        if not isinstance(ed, Mapping) or "type" not in ed:
            raise ValueError(f"{where}: expected a mapping with a 'type' key")
        kind = ed["type"]
        if kind == "point":
            _expect_keys(ed, where, ("type", "position", "intensity"))
            points_pos.append(_vec(ed["position"], f"{where}.position"))
            points_int.append(_rgb(ed["intensity"], f"{where}.intensity"))
        elif kind == "area":
            _expect_keys(ed, where, ("type", "shape", "radiance"), ("material",))
            sk, shape = _shape_from_desc(ed["shape"], f"{where}.shape", base_dir)
            if sk == "sdf":
                raise ValueError(f"{where}.shape: SDF shapes cannot be area lights (no area)")
            if "material" in ed["shape"]:
                raise ValueError(f"{where}.shape.material: put 'material' on the emitter")
            if ed.get("material"):
                mi = material_index(ed, where)
            else:
                mi = _black_material(names, materials)
            shapes.append(shape)
            n_prims = shape.faces.shape[0] if sk == "mesh" else 1
            shape_mats.append(jnp.full((n_prims,), mi, jnp.int32))
            area_lights.append(
                AreaLight(_rgb(ed["radiance"], f"{where}.radiance"), len(shapes) - 1)
            )
            emitter_shapes.append(shape)
        elif kind in ("constant", "envmap"):
            if environment is not None:
                raise ValueError(f"{where}: only one environment emitter is supported")
            if kind == "constant":
                _expect_keys(ed, where, ("type", "radiance"))
                environment = ConstantEnvironment(_rgb(ed["radiance"], f"{where}.radiance"))
            else:
                environment = EnvironmentMap.create(
                    envmap_image(ed, where, base_dir), ed.get("scale", 1.0)
                )
        else:
            raise ValueError(f"{where}.type: expected one of {EMITTER_TYPES}, got {kind!r}")
    if not shapes:
        raise ValueError("shapes: the scene has no geometry")
    point_lights = (
        PointLights.create(jnp.stack(points_pos), jnp.stack(points_int)) if points_pos else None
    )
    for i, sh in enumerate(emitter_shapes):
        if float(area(sh)) <= 0:
            raise ValueError(f"emitters: area light {i} has zero area")
    return Scene(
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
    )


def _black_material(names, materials):
    if "__black__" not in names:
        names.append("__black__")
        materials.append(make_bsdf({"type": "diffuse", "reflectance": 0.0}))
    return names.index("__black__")
