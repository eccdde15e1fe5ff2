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

A material key ``one_sided: true`` (reflection-only materials; default false) makes it black
from behind, as Mitsuba 3's ``diffuse`` etc. without ``twosided`` (:attr:`Scene.one_sided`).

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
:mod:`jaxgfx.render.bsdf.textured`); texels are leaves (``materials.floor.reflectance.image``,
``materials.floor.reflectance.color0``). SDF parameters: ``shapes.I.sdf.radius`` (``I`` indexes
``scene.shapes``). Details and measurements: docs/render_scenes.md.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from jaxgfx._checks import is_concrete
from jaxgfx.render.bsdf.textured import Textured
from jaxgfx.render.camera import MatrixCamera, PerspectiveCamera, ThinLensCamera
from jaxgfx.render.emitters import ConstantEnvironment, EnvironmentMap, PointLights
from jaxgfx.render.geometry import Rectangles, Spheres
from jaxgfx.render.parameters import get_path, parameter_paths, revalidate
from jaxgfx.render.sunsky import SunSky

__all__ = [
    "Scene",
    "Parameter",
    "parameter_names",
    "is_internal_name",
    "id_problem",
    "PARAMETER_BOUNDS",
]

PARAMETER_BOUNDS = {
    "fov": (0.0, 180.0),
    "aperture_radius": (0.0, float("inf")),
    "focus_distance": (0.0, float("inf")),
    "reflectance": (0.0, 1.0),
    "diffuse_reflectance": (0.0, 1.0),
    "specular_reflectance": (0.0, 1.0),
    "specular_transmittance": (0.0, 1.0),
    "kd": (0.0, 1.0),
    "ks": (0.0, 1.0),
    "color0": (0.0, 1.0),
    "color1": (0.0, 1.0),
    "alpha": (0.0, float("inf")),
    "alpha_u": (0.0, float("inf")),
    "alpha_v": (0.0, float("inf")),
    "exponent": (0.0, float("inf")),
    "eta": (0.0, float("inf")),
    "k": (0.0, float("inf")),
    "radii": (0.0, float("inf")),
    "radiance": (0.0, float("inf")),
    "intensities": (0.0, float("inf")),
    "scale": (0.0, float("inf")),
    "irradiance": (0.0, float("inf")),
    "intensity": (0.0, float("inf")),
    "cutoff_angle": (0.0, 180.0),
    "beam_width": (0.0, 180.0),
    "turbidity": (1.0, 10.0),
    "albedo": (0.0, 1.0),
    "sun_scale": (0.0, float("inf")),
    "sky_scale": (0.0, float("inf")),
    "rgb": (0.0, float("inf")),  # a measured BSDF's table (f cos θ times 4σ / D: may exceed 1)
}
"""``(lower, upper)`` of a parameter by its last field name (what the constructors accept;
reflectances at most 1 for energy conservation); others are unbounded."""


class Parameter(NamedTuple):
    """One differentiable leaf of a scene: ``path`` (for :meth:`Scene.get` / ``replace`` and
    ``jaxgfx fit``), ``shape``, ``dtype`` and ``bounds`` ``(lower, upper)``."""

    path: str
    shape: tuple
    dtype: object
    bounds: tuple


def is_internal_name(name: str) -> bool:
    """Whether ``name`` is one of the loader's own material names (``__default__`` for shapes
    without a material, ``__black__`` behind area lights): ``__NAME__``, refused in scene
    descriptions and never listed in hints."""
    return isinstance(name, str) and len(name) > 4 and name.startswith("__") and name.endswith("__")


def _index(path, text, n, what):
    """``int(text)`` when it indexes one of ``n`` objects (``what``: "an area light")."""
    if n == 0:
        raise ValueError(f"{path}: the scene has no {what.split(' ', 1)[1]}s")
    if not text.isdigit() or not int(text) < n:
        raise ValueError(f"{path}: expected {what} index in 0..{n - 1}, got {text!r}")
    return int(text)


def parameter_names(obj, *, aliases: bool = True) -> list[str]:
    """The parameter names a path may give after ``obj`` (for hints): its class's
    ``PARAMETER_ALIASES`` (``alpha``; a path resolves an alias only as its last name, so
    those of nested modules are not listed), its float array fields and, dotted, those of
    nested modules (``distribution.alpha_u``); a texture's own parameters as ``KEY.PARAM``
    (``reflectance.color0``). Integer arrays (mesh faces) and the arrays of a traversal
    structure (only its ``mesh.*`` is listed) are not parameters.

    >>> from jaxgfx.render.bsdf import RoughConductor
    >>> parameter_names(RoughConductor(0.3))
    ['alpha', 'alpha_u', 'alpha_v', 'distribution.alpha_u', 'distribution.alpha_v', 'reflectance']
    """
    if isinstance(obj, Textured):
        tex = [f"{k}.{p}" for k, t in obj.textures.items() for p in parameter_names(t)]
        rest = [n for n in parameter_names(obj.bsdf) if n.split(".")[0] not in obj.textures]
        return tex + rest
    from jaxgfx.render.geometry import TriangleMesh

    fields = vars(obj)
    mesh = fields.get("mesh")
    if isinstance(mesh, TriangleMesh) and not isinstance(obj, TriangleMesh):
        return [f"mesh.{n}" for n in parameter_names(mesh, aliases=False)]  # BVH, Embree, Warp
    out = list(getattr(type(obj), "PARAMETER_ALIASES", {})) if aliases else []
    for name, v in fields.items():
        if name.startswith("_"):
            continue
        if eqx.is_array(v) and jnp.issubdtype(v.dtype, jnp.inexact):
            out.append(name)
        elif isinstance(v, eqx.Module):
            out += [f"{name}.{n}" for n in parameter_names(v, aliases=False)]
    return list(dict.fromkeys(out))


def _listed_names(obj) -> list[str]:
    """The names :meth:`Scene.parameters` lists after ``obj``: each leaf once, by its field
    path; a textured material's texels, then the fields no texture overrides; a normal / bump
    map's nested material under ``bsdf.`` (textured or not), then its own map and ``scale``."""
    if isinstance(obj, Textured):  # texels, then the fields no texture overrides
        from jaxgfx.render.bsdf.textured import texturable_paths

        over = {".".join(p) for k in obj.textures for p in texturable_paths(obj.bsdf, k)}
        names = [f"{k}.{p}" for k, t in obj.textures.items() for p in parameter_names(t)]
        return names + [n for n in parameter_names(obj.bsdf, aliases=False) if n not in over]
    if getattr(obj, "needs_tangents", False):
        own = [n for n in parameter_names(obj, aliases=False) if n.split(".")[0] != "bsdf"]
        return [f"bsdf.{n}" for n in _listed_names(obj.bsdf)] + own
    return parameter_names(obj, aliases=False)


def _delta_kind(light) -> str:
    name = type(light).__name__
    return {"SpotLight": "spot", "ProjectorLight": "projector",
            "DirectionalAreaLight": "directionalarea"}.get(name, "directional")  # fmt: skip


EMITTER_KINDS = ("point", "area", "environment", "directional", "spot", "projector",
                 "directionalarea")  # fmt: skip
"""The words after ``emitters.`` that name emitters by kind (not usable as ids)."""


def id_problem(name) -> str | None:
    """Why ``name`` cannot name a shape or emitter in parameter paths, or ``None`` when it can:
    a non-empty string without ``.`` (the path separator), not all digits (``shapes.I``
    indexes), not an emitter kind (``emitters.area.I``) and not of the loader's ``__NAME__``
    form.

    >>> id_problem("ball") is None, id_problem("Plane.001"), id_problem("7")[:9]
    (True, "'Plane.001' contains '.', the parameter path separator", "'7' is a ")
    """
    if not isinstance(name, str) or not name:
        return f"expected a non-empty string, got {name!r}"
    if "." in name:
        return f"{name!r} contains '.', the parameter path separator"
    if name.isdigit():
        return f"{name!r} is a number (numbers index shapes.I / emitters.area.I)"
    if name in EMITTER_KINDS or is_internal_name(name):
        return f"{name!r} is reserved (emitters.{name}... / the loader's own names)"
    return None


class Scene(eqx.Module):
    """A renderable scene (pytree). Build with :func:`load_scene`.

    Fields: ``camera``; ``shapes`` (tuple of Spheres / Rectangles / TriangleMesh / SDFShape / a
    mesh traversal object: BVH, EmbreeMesh, WarpMesh, see :attr:`accel`);
    ``shape_materials`` (tuple of int32 arrays, material index per primitive of each shape);
    ``materials`` (tuple of BSDFs) named by the static ``material_names``; ``point_lights``
    (PointLights or None); ``area_lights`` (tuple of AreaLight); ``environment``
    (ConstantEnvironment / EnvironmentMap / SunSky / None); ``emitter_shapes`` (tuple: the raw
    shape of each area light, for sampling); ``rfilter`` (reconstruction filter, static);
    ``delta_lights`` (tuple of DirectionalLight / SpotLight / ProjectorLight).
    """

    camera: PerspectiveCamera | ThinLensCamera | MatrixCamera  # or a meter / BatchCamera
    shapes: tuple
    shape_materials: tuple
    materials: tuple
    point_lights: PointLights | None
    area_lights: tuple
    emitter_shapes: tuple
    environment: ConstantEnvironment | EnvironmentMap | SunSky | None
    material_names: tuple = eqx.field(static=True)
    rfilter: object = eqx.field(static=True)
    delta_lights: tuple = ()
    """Directional, spot and projector lights (``DirectionalLight`` / ``SpotLight`` /
    ``ProjectorLight``), in description order;
    empty for scenes without them (their programs are unchanged)."""
    object_ids: tuple = eqx.field(static=True, default=())
    """Named shapes and emitters (the description's / XML's ``id``): ``(id, kind, index, row,
    material)`` with ``kind`` ``"shape"`` (``index`` into :attr:`shapes`, ``row`` the sphere /
    rectangle of a batch or ``None``, ``material`` its material's name), ``"area"`` (into
    :attr:`area_lights`), ``"point"`` (``row`` of :attr:`point_lights`), ``"environment"``,
    ``"directional"`` / ``"spot"`` / ``"projector"`` (into :attr:`delta_lights`). Paths
    ``shapes.ID.FIELD`` and ``emitters.ID.FIELD`` name them (:meth:`parameters`)."""
    one_sided: tuple = eqx.field(static=True, default=())
    """Per material (aligned with :attr:`materials`): ``True`` where the material reflects
    from the front side only (black from behind, as Mitsuba 3's ``diffuse``, ``conductor``,
    ``plastic``, ... without ``twosided``; the description's ``one_sided: true``). Empty
    (the default) when no material is one-sided: every reflection-only material is then
    shaded on both sides and the programs are those of a scene without the field."""

    @property
    def width(self) -> int:
        return self.camera.width

    @property
    def height(self) -> int:
        return self.camera.height

    @property
    def dtype(self):
        """The scene's float dtype (float32, or float64 for a scene loaded with x64 on): the
        dtype the renderer computes in. :func:`load_scene` makes every float leaf this dtype."""
        leaves = [
            x
            for x in jax.tree_util.tree_leaves(self)
            if hasattr(x, "dtype") and jnp.issubdtype(x.dtype, jnp.floating)
        ]
        return jnp.result_type(*leaves) if leaves else jnp.dtype(jnp.float32)

    @property
    def accel(self) -> str | None:
        """Traversal backend of the scene's meshes (``"embree"``, ``"warp"``, ``"jax"``;
        ``None`` when no shape needs one); see docs/render_backends.md."""
        from jaxgfx.render.geometry.accel import accel_of

        names = {accel_of(s) for s in self.shapes} - {None}
        return names.pop() if len(names) == 1 else (None if not names else "mixed")

    def with_accel(self, accel: str = "auto") -> Scene:
        """Copy whose meshes are traced by backend ``accel`` (host build, cached per mesh; call
        outside ``jax.jit``). Images and gradients are unchanged up to ties."""
        from jaxgfx.render.geometry.accel import scene_with_accel

        return scene_with_accel(self, accel)

    @property
    def n_lights(self) -> int:
        n = len(self.area_lights) + (self.environment is not None) + len(self.delta_lights)
        return n + (self.point_lights.count if self.point_lights is not None else 0)

    # -- parameter access by name ------------------------------------------------------------
    def _locate(self, path: str):
        if not isinstance(path, str):
            raise TypeError(f"path: expected a dotted parameter path (str), got {path!r}")
        parts = path.split(".")
        head = parts[0]
        if head == "materials":
            if len(parts) < 2 or parts[1] not in self.material_names:
                have = [n for n in self.material_names if not is_internal_name(n)]
                raise ValueError(f"{path}: unknown material; have {have}")
            idx = self.material_names.index(parts[1])
            getter = lambda s: s.materials[idx]  # noqa: E731
            rest = parts[2:]
        elif (
            head == "camera"
            and len(parts) >= 3
            and parts[1] == "cameras"
            and hasattr(self.camera, "cameras")
        ):  # a BatchCamera's camera I: camera.cameras.I.FIELD
            i = _index(path, parts[2], len(self.camera.cameras), "a camera of the batch")
            getter = lambda s: s.camera.cameras[i]  # noqa: E731
            rest = parts[3:]
        elif head == "camera":
            getter = lambda s: s.camera  # noqa: E731
            rest = parts[1:]
        elif head == "emitters" and len(parts) >= 2 and parts[1] == "point":
            if self.point_lights is None:
                raise ValueError(f"{path}: the scene has no point lights")
            getter = lambda s: s.point_lights  # noqa: E731
            rest = parts[2:]
        elif head == "emitters" and len(parts) >= 3 and parts[1] == "area":
            i = _index(path, parts[2], len(self.area_lights), "an area light")
            getter = lambda s: s.area_lights[i]  # noqa: E731
            rest = parts[3:]
        elif head == "emitters" and len(parts) >= 2 and parts[1] == "environment":
            if self.environment is None:
                raise ValueError(f"{path}: the scene has no environment emitter")
            getter = lambda s: s.environment  # noqa: E731
            rest = parts[2:]
        elif (
            head == "emitters"
            and len(parts) >= 3
            and parts[1] in ("directional", "spot", "projector", "directionalarea")
        ):
            kinds = [i for i, e in enumerate(self.delta_lights) if _delta_kind(e) == parts[1]]
            i = kinds[_index(path, parts[2], len(kinds), f"a {parts[1]} light")]
            getter = lambda s: s.delta_lights[i]  # noqa: E731
            rest = parts[3:]
        elif head == "shapes" and len(parts) >= 2:
            i = _index(path, parts[1], len(self.shapes), "a shape")
            getter = lambda s: s.shapes[i]  # noqa: E731
            rest = parts[2:]
        else:
            raise ValueError(
                f"{path}: expected materials.NAME.FIELD, camera.FIELD, emitters.point.FIELD, "
                "emitters.area.I.FIELD, emitters.environment.FIELD, emitters.directional.I.FIELD, "
                "emitters.spot.I.FIELD, emitters.projector.I.FIELD, "
                "emitters.directionalarea.I.FIELD or shapes.I.FIELD"
            )
        if not rest:
            raise ValueError(f"{path}: expected a field name after the object")
        obj = getter(self)
        prefix = []
        if getattr(obj, "needs_tangents", False) and rest[0] == "bsdf" and len(rest) > 1:
            # a normal / bump map's nested material (which may be textured)
            prefix, obj, rest = ["bsdf"], obj.bsdf, rest[1:]
        if isinstance(obj, Textured):
            # textured parameter: materials.NAME.FIELD.image / .color0; others: the BSDF's
            if rest[0] in obj.textures:
                if len(rest) < 2:
                    raise ValueError(f"{path}: {rest[0]!r} is a texture; name its parameter")
                prefix = [*prefix, ("textures", rest[0])]
                obj, rest = obj.textures[rest[0]], rest[1:]
            else:
                prefix = [*prefix, "bsdf"]
                obj = obj.bsdf
        # aliases (e.g. isotropic `alpha` sets both microfacet alphas): the class's table
        aliases = getattr(type(obj), "PARAMETER_ALIASES", {})
        if len(rest) == 1 and rest[0] in aliases:
            rest_list = [list(p) for p in parameter_paths(obj, rest[0])]
        else:
            rest_list = [rest]
        getters = []
        for fields in rest_list:
            o = obj
            for field in fields:
                if not hasattr(o, field) or field.startswith("_"):
                    have = parameter_names(getter(self))
                    raise ValueError(f"{path}: no parameter {field!r}; have {have}")
                o = getattr(o, field)
            if not eqx.is_array(o):
                raise ValueError(f"{path}: {fields[-1]!r} is not an array parameter")

            def where(s, fields=(*prefix, *fields)):
                return get_path(getter(s), fields)

            getters.append(where)
        return getters, getter

    def parameters(self) -> list[Parameter]:
        """Every differentiable (float array) leaf with its path, shape, dtype and bounds,
        like Mitsuba's ``mi.traverse``: ``camera.*``, ``materials.NAME.*`` (named as in the
        description or by the XML ``id``; the loader's own ``__default__`` / ``__black__`` are
        not listed), ``emitters.point.*``, ``emitters.area.I.*``, ``emitters.environment.*``
        and ``shapes.I.*`` (``I`` indexes :attr:`shapes`; a mesh's ``mesh.vertices``). Each
        leaf once, by its field path (``distribution.alpha_u``, not the alias ``alpha``).
        Every path works with :meth:`get` and :meth:`replace`.

        >>> from jaxgfx.render.scene import load_scene
        >>> s = load_scene({"camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 40,
        ...     "width": 4, "height": 4}, "shapes": [{"type": "sphere", "center": [0, 0, 0],
        ...     "radius": 1, "material": "m"}], "materials": {"m": {"type": "diffuse"}}})
        >>> [p.path for p in s.parameters()][4:]
        ['materials.m.reflectance', 'shapes.0.centers', 'shapes.0.radii']
        >>> s.parameters()[-1]
        Parameter(path='shapes.0.radii', shape=(1,), dtype=dtype('float32'), bounds=(0.0, inf))
        """
        ids: dict = {}
        for ident, kind, index, row, _ in self.object_ids:
            ids.setdefault((kind, index), []).append((ident, row))

        def by_id(kind, index, head, index_prefix, obj, n_rows=None):
            """``(prefix, obj)`` of one object (or batch): each id, and the index path when
            the object (or some row of the batch) has none."""
            got = ids.get((kind, index), [])
            unnamed = not got if n_rows is None else len(got) < n_rows
            return [(f"{head}.{i}", obj) for i, _ in got] + (
                [(index_prefix, obj)] if unnamed else []
            )

        cams = getattr(self.camera, "cameras", None)  # a BatchCamera: each of its cameras
        objs = (
            [("camera", self.camera)]
            if cams is None
            else [(f"camera.cameras.{i}", c) for i, c in enumerate(cams)]
        )
        named = zip(self.material_names, self.materials, strict=True)
        objs += [(f"materials.{n}", m) for n, m in named if not is_internal_name(n)]
        if self.point_lights is not None:
            pl = self.point_lights
            objs += by_id("point", 0, "emitters", "emitters.point", pl, pl.positions.shape[0])
        for i, a in enumerate(self.area_lights):
            objs += by_id("area", i, "emitters", f"emitters.area.{i}", a)
        if self.environment is not None:
            objs += by_id("environment", 0, "emitters", "emitters.environment", self.environment)
        counts = {"directional": 0, "spot": 0, "projector": 0, "directionalarea": 0}
        for e in self.delta_lights:
            k = _delta_kind(e)
            objs += by_id(k, counts[k], "emitters", f"emitters.{k}.{counts[k]}", e)
            counts[k] += 1
        for i, s in enumerate(self.shapes):
            n = s.centers.shape[0] if isinstance(s, (Spheres, Rectangles)) else None
            objs += by_id("shape", i, "shapes", f"shapes.{i}", s, n)
        out = []
        for prefix, obj in objs:
            for name in _listed_names(obj):
                path = f"{prefix}.{name}"
                try:
                    v = self.get(path)
                except ValueError:  # not addressable (e.g. an SDF's internal constants)
                    continue
                parts = name.split(".")
                last = parts[-2] if parts[-1] == "image" and len(parts) > 1 else parts[-1]
                bounds = PARAMETER_BOUNDS.get(last, (-float("inf"), float("inf")))
                out.append(Parameter(path, tuple(v.shape), v.dtype, bounds))
        return out

    def _by_id(self, path):
        """``(index_path, row)``: a path naming a shape or emitter by its id
        (``shapes.ball.radii``, ``emitters.lamp.radiance``) as the path by index, with the row
        of a batch (spheres, rectangles, point lights; else ``None``); ``shapes.ID.bsdf.FIELD``
        is the shape's material (``materials.NAME.FIELD``). Other paths unchanged."""
        if not isinstance(path, str):
            return path, None
        parts = path.split(".")
        if len(parts) < 2 or parts[0] not in ("shapes", "emitters"):
            return path, None
        key = parts[1]
        if key.isdigit() or key in EMITTER_KINDS:
            return path, None
        kinds = ("shape",) if parts[0] == "shapes" else EMITTER_KINDS
        hit = [e for e in self.object_ids if e[0] == key and e[1] in kinds]
        if not hit:
            have = sorted(e[0] for e in self.object_ids if e[1] in kinds)
            if not have:  # no ids: the index path's own error
                return path, None
            what = "a shape index or id" if parts[0] == "shapes" else "an emitter kind or id"
            raise ValueError(f"{parts[0]}.{key}: unknown id {key!r}; expected {what} "
                             f"(ids: {have})")  # fmt: skip
        _, kind, index, row, material = hit[0]
        rest = parts[2:]
        if kind == "shape" and rest[:1] == ["bsdf"]:
            if material is None or is_internal_name(material):
                raise ValueError(f"{path}: shape {key!r} has no named material")
            return ".".join(["materials", material, *rest[1:]]), None
        head = {"shape": f"shapes.{index}", "point": "emitters.point",
                "environment": "emitters.environment"}.get(
                    kind, f"emitters.{kind}.{index}")  # fmt: skip
        return ".".join([head, *rest]), row

    def get(self, path: str):
        """The array at a dotted parameter path (see :meth:`replace`)."""
        index_path, row = self._by_id(path)
        v = self._locate(index_path)[0][0](self)
        return v if row is None else v[row : row + 1]

    def replace(self, path: str, value):
        """Copy of the scene with the parameter at ``path`` set to ``value`` (same shape).

        The changed object is checked as its constructor checks it (``__check_init__``), so a
        concrete value the loader would refuse raises the same ``ValueError`` here (e.g.
        ``materials.metal.alpha`` = 0); traced values (inside ``jit`` / ``grad``) pass.
        """
        index_path, row = self._by_id(path)
        wheres, owner = self._locate(index_path)
        out = self
        for where in wheres:
            old = where(out)
            if row is None:
                new = jnp.broadcast_to(jnp.asarray(value, old.dtype), old.shape)
            else:  # one sphere / rectangle / point light of a batch
                part = old[row : row + 1]
                new = old.at[row : row + 1].set(jnp.broadcast_to(jnp.asarray(value, old.dtype),
                                                                 part.shape))  # fmt: skip
            out = eqx.tree_at(where, out, new)
        if is_concrete(value):
            try:
                revalidate(owner(out))
            except (ValueError, TypeError) as e:
                raise type(e)(f"{path}: {e}") from None
        return out
