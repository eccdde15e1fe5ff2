"""Mitsuba 3 XML scenes -> jaxgfx scene descriptions (then the normal loader).

:func:`read_xml` parses a Mitsuba 3 scene file (``<scene version=...>``) into an
:class:`XMLScene`: the jaxgfx description dict (``desc``, what :func:`load_scene` builds a
:class:`Scene` from) plus the render options the file states (``spp``, ``integrator``,
``max_depth``, ``rr_depth``). ``load_scene("scene.xml", **params)`` calls it.

Supported: ``<default>`` and ``$name`` substitution (keyword arguments override defaults),
``<include>``, ``<path>``, ``id`` / ``<ref>``, nested ``to_world`` transforms (``translate``,
``rotate``, ``scale``, ``matrix``, ``lookat``), the plugins and parameters listed in
docs/render_scenes.md ("Mitsuba 3 XML scenes"). Everything else (an unknown plugin, tag,
attribute or parameter) raises one ``ValueError`` naming it, the object's ``id`` and
``file:line``, before anything is traced: a scene is never silently changed.

Conventions read from Mitsuba 3 (3.9.1; each checked by tests/render/test_mitsuba_xml*.py):

* transforms: column vectors, each element left-multiplies the matrix so far; ``rotate`` is
  right-handed about ``axis`` by ``angle`` degrees; ``matrix`` is row-major.
* sensor: ``to_world`` must be rigid (rotation + translation, det +1); camera looks along its
  local +z with +y up. ``fov_axis`` ``diagonal`` / ``smaller`` / ``larger`` are converted to an
  x- or y-fov; without ``fov``, ``focal_length`` (default ``50mm``) is the diagonal fov of a
  36 x 24 mm film. ``near_clip`` / ``far_clip`` are accepted only when no geometry lies where
  they would clip camera rays (checked on bounding boxes). ``thinlens``: the same, plus
  ``aperture_radius`` (required, >= 0) and ``focus_distance`` (default ``far_clip``, > 0):
  a :class:`~jaxgfx.render.camera.ThinLensCamera`. ``orthographic``: any invertible
  ``to_world`` (a scale sizes the sensor plane: the film width spans camera x in [-1, 1]),
  loaded as a :class:`~jaxgfx.render.camera.MatrixCamera` whose rays start on the near plane
  (:func:`~jaxgfx.render.scene.mitsuba_conventions.orthographic_view_proj_inverse`).
* ``disk`` and ``cylinder`` (open, no caps; ``p0``, ``p1``, ``radius``) are tessellated
  (256-triangle fan, 512-triangle tube with radial vertex normals) with Mitsuba's uvs
  (disk ``(r, φ/2π)``, cylinder ``(φ/2π, z)``, the cube mesh's per-face ``[0, 1]²``); rotated
  spheres keep their local frame (uv ``(φ/2π, θ/π)`` in it).
* OBJ texture coordinates are flipped (``v -> 1 - v``, Mitsuba's ``flip_tex_coords``); PLY's
  are not. Meshes without vertex normals get Mitsuba's angle-weighted smooth normals unless
  ``face_normals`` is true.
* spectra: ``<spectrum value="v">`` is the constant ``v``; wavelength lists
  ``"l1:v1, l2:v2, ..."`` are converted to linear sRGB as Mitsuba 3's RGB variants do
  (piecewise-linear spectrum, zero outside the listed range, against the CIE 1931 2 degree
  observer from colour-science, 1000 samples over 360-830 nm; reflectances weighted by D65 and
  normalised by its luminance, emission normalised by the CMFs' y integral).
* Mitsuba's one-sided BSDFs (``diffuse``, ``conductor``, ``roughconductor``, ``plastic``,
  ``roughplastic``, ``principled`` without ``spec_trans``; a ``normalmap`` / ``bumpmap`` around
  one; a shape's default ``diffuse``) not wrapped in ``twosided`` get ``one_sided: true`` (black
  from behind, :attr:`~jaxgfx.render.scene.Scene.one_sided`); inside ``twosided`` they are
  two-sided. ``blendbsdf`` and ``mask`` are loaded two-sided whatever their nested BSDFs
  (``twosided`` inside them is a pass-through); transmissive BSDFs scatter on both sides.
* ``directional``: the light travels along ``direction`` or ``to_world``'s +z (default +z);
  ``spot``: at ``to_world``'s origin, pointing along its +z, ``beam_width`` defaulting to 3/4 of
  ``cutoff_angle`` (20 degrees); the same falloff as :class:`jaxgfx.render.emitters.SpotLight`.
  A projected ``texture`` (bitmap) keeps to_world's +y as its ``up``. ``projector``: to_world's
  origin, +z and +y as ``position`` / ``direction`` / ``up``, ``irradiance`` (a colour or a
  bitmap), ``scale``, ``fov`` as the perspective sensor's over the texture's resolution
  (:class:`jaxgfx.render.emitters.ProjectorLight`).
* ``blendbsdf``: ``(1 - weight) bsdf_0 + weight bsdf_1``, the nested BSDFs in document order
  (unnamed) or ordered by name (named), as Mitsuba orders its nested objects.
* ``normalmap`` / ``bumpmap``: :class:`jaxgfx.render.bsdf.NormalMap` /
  :class:`jaxgfx.render.bsdf.BumpMap` around the nested BSDF (the normal map is read as
  written: give it ``raw`` true, as Mitsuba's documentation does); ``flip_invalid_normals``
  and ``use_shadowing_function`` (default true, as Mitsuba 3.9) are read.
* ``envmap``: same direction -> (u, v) map as jaxgfx (y up); Mitsuba places rows at
  ``v = j / (H - 1)``, jaxgfx at ``(j + 1/2) / H'``: the map is resampled to ``H' = 4 H`` rows
  with Mitsuba's linear interpolation along v (exact between Mitsuba's rows up to the
  interpolation of the resampled grid, see :func:`envmap_from_mitsuba`). ``to_world`` must be
  a rotation (its translation is ignored, as Mitsuba does for directions): it becomes the
  ``to_world`` of the envmap description; a scale or shear is refused.
* ``sunsky``: Mitsuba's parameters and defaults (:class:`jaxgfx.render.sunsky.SunSky`); the
  location / time parameters are kept in the description (the sun placed as Mitsuba places
  it), ``to_world`` must be a rotation, out-of-range values are refused with file and line.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import xml.parsers.expat

import numpy as np

from jaxgfx.render.scene.mitsuba_conventions import (
    CONDUCTOR_IOR,
    DEFAULTS,
    IOR_TABLE,
    ONE_SIDED_BSDFS,
    envmap_from_mitsuba,
    look_at_matrix,
    orthographic_view_proj_inverse,
    plugin_status,
    spectrum_to_rgb,
    swap_scalar_checkerboard,
)

__all__ = [
    "XMLScene",
    "read_xml",
    "IOR_TABLE",
    "spectrum_to_rgb",
    "envmap_from_mitsuba",
    "transform_matrix",
    "save_scene",
    "to_xml",
]

DISK_SEGMENTS = 256
CYLINDER_SEGMENTS = 256


@dataclasses.dataclass(frozen=True)
class XMLScene:
    """A translated Mitsuba scene: ``desc`` (the jaxgfx scene description; every file path in
    it is absolute), the sampler's ``spp`` (``None`` without a sensor sampler), the jaxgfx
    ``integrator`` name (``"path"``, ``"direct"``, ``"ptracer"`` or ``"aov"``), ``max_depth`` in the
    common convention (``None``: Mitsuba's ``-1``, unbounded; jaxgfx needs a number),
    ``rr_depth``, ``files`` (every XML file read, in order), ``hide_emitters`` (``ptracer``
    only: pass it to ``ParticleTracer(hide_emitters=...)``), and the ``PathIntegrator`` options
    ``adjoint`` (``"replay"`` for Mitsuba's ``prb`` / ``prb_basic``, else ``"ad"``) and
    ``strategy`` (``"bsdf"`` for ``prb_basic``, else ``"mis"``), the ``aov`` options ``aovs``
    and ``near_clip`` (the sensor's; Mitsuba measures depth from it), and ``visibility``
    (``"edge"`` for Mitsuba's ``direct_projective`` / ``prb_projective``, else ``None``: pass it
    to ``render(..., visibility=...)``); :attr:`integrator_spec` is the integrator options as
    the mapping ``render(..., integrator=...)`` takes."""

    desc: dict
    spp: int | None
    integrator: str
    max_depth: int | None
    rr_depth: int
    files: tuple
    hide_emitters: bool = False
    adjoint: str = "ad"
    strategy: str = "mis"
    aovs: tuple = ()
    near_clip: float = 0.0
    visibility: str | None = None

    @property
    def integrator_spec(self) -> dict:
        """``{type, max_depth, rr_depth, ...}`` for ``render(scene, key, integrator=...)``
        (``max_depth`` left out when unbounded: jaxgfx needs a number; ``hide_emitters``
        left out: pass it to ``ParticleTracer``)."""
        out = {"type": self.integrator}
        if self.max_depth is not None and self.integrator != "direct":
            out["max_depth"] = self.max_depth
        if self.integrator in ("path", "ptracer"):
            out["rr_depth"] = self.rr_depth
        if self.integrator == "path":
            out.update(strategy=self.strategy, adjoint=self.adjoint)
        if self.integrator == "aov":
            out.update(aovs=self.aovs, near_clip=self.near_clip)
        return out


# ------------------------------------------------------------------------------------------
# XML parsing with line numbers


@dataclasses.dataclass
class _Node:
    tag: str
    attrs: dict
    file: str
    line: int
    children: list = dataclasses.field(default_factory=list)

    @property
    def at(self) -> str:
        return f"{self.file}:{self.line}"


def _parse(path: str) -> _Node:
    parser = xml.parsers.expat.ParserCreate()
    stack: list[_Node] = []
    root: list[_Node] = []

    def start(tag, attrs):
        node = _Node(tag, dict(attrs), path, parser.CurrentLineNumber)
        (stack[-1].children if stack else root).append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        with open(path, "rb") as f:
            parser.ParseFile(f)
    except OSError as e:
        raise ValueError(f"{path}: cannot read the scene file: {e.strerror or e}") from None
    except xml.parsers.expat.ExpatError as e:
        msg = xml.parsers.expat.ErrorString(e.code)
        raise ValueError(f"{path}:{e.lineno}: XML syntax error: {msg}") from None
    return root[0]


# ------------------------------------------------------------------------------------------
# values


def _floats(text, where, n=None):
    parts = [p for p in re.split(r"[,\s]+", str(text).strip()) if p]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f"{where}: expected numbers, got {text!r}") from None
    if not vals or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"{where}: expected finite numbers, got {text!r}")
    if n is not None and len(vals) not in n:
        raise ValueError(f"{where}: expected {' or '.join(map(str, n))} numbers, got {text!r}")
    return vals


# a <rotate> axis within this of unit length is normalised (an axis written with a few digits,
# 0.577 0.577 0.577, differs from Mitsuba's unnormalised matrix by at most this, relatively);
# a longer or shorter one is refused (Mitsuba 3.9's ``dr::rotate`` uses it as given)
ROTATE_AXIS_TOL = 1e-3


def _rot(axis, angle_deg):
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    m = np.eye(4)
    m[:3, :3] = c * np.eye(3) + s * k + (1 - c) * np.outer(a, a)
    return m


def transform_matrix(ops) -> np.ndarray:
    """The 4x4 matrix of a list of ``(op, kwargs)`` transform elements, applied in order (each
    left-multiplies): ``("translate", {"v": (x, y, z)})``, ``("scale", {"v": (x, y, z)})``,
    ``("rotate", {"axis": a, "angle": deg})``, ``("matrix", {"m": 4x4})``,
    ``("lookat", {"origin", "target", "up"})``.

    Example: ``transform_matrix([("translate", {"v": (1, 2, 3)})])[:3, 3]`` is ``[1, 2, 3]``.
    """
    m = np.eye(4)
    for op, kw in ops:
        if op == "translate":
            t = np.eye(4)
            t[:3, 3] = kw["v"]
        elif op == "scale":
            t = np.diag([*kw["v"], 1.0])
        elif op == "rotate":
            t = _rot(kw["axis"], kw["angle"])
        elif op == "matrix":
            t = np.asarray(kw["m"], np.float64)
        elif op == "lookat":
            t = look_at_matrix(kw["origin"], kw["target"], kw["up"])
        else:  # pragma: no cover - the parser only produces the ops above
            raise ValueError(op)
        m = t @ m
    return m


# ------------------------------------------------------------------------------------------
# the document: substitution, includes, objects


_VALUE_TAGS = ("float", "integer", "boolean", "string", "rgb", "spectrum", "point", "vector")
_OBJECT_TAGS = ("bsdf", "texture", "shape", "emitter", "sensor", "film", "sampler", "rfilter",
                "integrator")  # fmt: skip
_UNSUPPORTED_TAGS = ("medium", "phase", "volume", "alias")


@dataclasses.dataclass
class _Prop:
    kind: str
    value: object
    node: _Node
    used: bool = False


@dataclasses.dataclass
class _Obj:
    tag: str
    type: str
    id: str | None
    node: _Node
    props: dict = dataclasses.field(default_factory=dict)
    children: list = dataclasses.field(default_factory=list)
    converted: object = None  # (material name, inside twosided) once converted

    @property
    def label(self) -> str:
        ident = f" id={self.id!r}" if self.id else ""
        return f"<{self.tag} type={self.type!r}{ident}>"

    @property
    def where(self) -> str:
        return f"{self.node.at}: {self.label}"


class _Doc:
    def __init__(self, path, params):
        self.params = {str(k): str(v).lower() if isinstance(v, bool) else str(v)
                       for k, v in params.items()}  # fmt: skip
        self.given = set(self.params)
        self.used: set[str] = set()
        self.ids: dict[str, _Obj] = {}
        self.files: list[str] = []
        self.search: list[str] = []
        self.stack: list[str] = []

    def sub(self, node: _Node) -> dict:
        """The node's attributes with ``$name`` replaced by the parameters."""
        out = {}
        for k, v in node.attrs.items():

            def rep(m, k=k, v=v):
                name = m.group(1)
                if name not in self.params:
                    raise ValueError(
                        f"{node.at}: <{node.tag}> attribute {k}={v!r}: undefined parameter "
                        f"${name} (give it as a keyword argument or a <default>)"
                    )
                self.used.add(name)
                return self.params[name]

            out[k] = re.sub(r"\$([A-Za-z_][A-Za-z0-9_]*)", rep, v)
        return out

    def resolve(self, name, node, label=None):
        label = label or f"<{node.tag}>"
        name = os.path.expanduser(name)
        if os.path.isabs(name):
            if os.path.isfile(name):
                return name
            raise ValueError(f"{node.at}: {label} filename {name!r}: no such file")
        for d in self.search:
            p = os.path.join(d, name)
            if os.path.isfile(p):
                return os.path.abspath(p)
        raise ValueError(
            f"{node.at}: {label} filename {name!r}: no such file (searched {self.search})"
        )


def _attrs(node, attrs, required=(), optional=(), what=None):
    unknown = sorted(set(attrs) - set(required) - set(optional))
    what = what or f"<{node.tag}>"
    if unknown:
        raise ValueError(f"{node.at}: {what}: unsupported attribute(s) {unknown}")
    missing = [a for a in required if a not in attrs]
    if missing:
        raise ValueError(f"{node.at}: {what}: missing attribute(s) {missing}")


def _xyz(attrs, node, default):
    if "value" in attrs:
        if any(k in attrs for k in "xyz"):
            raise ValueError(f"{node.at}: <{node.tag}>: give either value or x/y/z")
        v = _floats(attrs["value"], f"{node.at}: <{node.tag}> value", (1, 3))
        return v * 3 if len(v) == 1 else v
    return [_floats(attrs.get(k, str(default)), f"{node.at}: <{node.tag}> {k}", (1,))[0]
            for k in "xyz"]  # fmt: skip


def _transform(doc, node) -> np.ndarray:
    ops = []
    for c in node.children:
        a = doc.sub(c)
        at = f"{c.at}: <{c.tag}>"
        if c.tag == "translate":
            _attrs(c, a, (), ("x", "y", "z", "value"))
            ops.append(("translate", {"v": _xyz(a, c, 0.0)}))
        elif c.tag == "scale":
            _attrs(c, a, (), ("x", "y", "z", "value"))
            ops.append(("scale", {"v": _xyz(a, c, 1.0)}))
        elif c.tag == "rotate":
            _attrs(c, a, ("angle",), ("x", "y", "z", "value"))
            if "value" in a:
                axis = _floats(a["value"], f"{at} value", (3,))
            else:
                axis = _xyz(a, c, 0.0)
            if not np.linalg.norm(axis) > 0:
                raise ValueError(f"{at}: the rotation axis is zero")
            if abs(np.linalg.norm(axis) - 1.0) > ROTATE_AXIS_TOL:
                raise ValueError(
                    f"{at}: the rotation axis {tuple(float(v) for v in axis)} has length "
                    f"{np.linalg.norm(axis):.6g}, not 1: Mitsuba 3 does not normalise it (its "
                    "matrix is then not a rotation, and its normals use that matrix unchanged), "
                    "so the scene would render differently there; give a unit axis"
                )
            angle = _floats(a["angle"], f"{at} angle", (1,))[0]
            ops.append(("rotate", {"axis": axis, "angle": angle}))
        elif c.tag == "matrix":
            _attrs(c, a, ("value",))
            v = _floats(a["value"], f"{at} value", (9, 16))
            if len(v) == 9:
                m = np.eye(4)
                m[:3, :3] = np.reshape(v, (3, 3))
            else:
                m = np.reshape(v, (4, 4))
            ops.append(("matrix", {"m": m}))
        elif c.tag == "lookat":
            _attrs(c, a, ("origin", "target", "up"))
            kw = {k: _floats(a[k], f"{at} {k}", (3,)) for k in ("origin", "target", "up")}
            try:
                look_at_matrix(**kw)
            except ValueError as e:
                raise ValueError(f"{at}: {e}") from None
            ops.append(("lookat", kw))
        else:
            raise ValueError(f"{c.at}: <{c.tag}> inside <transform>: unsupported transform")
    m = transform_matrix(ops)
    if not np.all(np.isfinite(m)) or abs(np.linalg.det(m[:3, :3])) < 1e-300:
        raise ValueError(f"{node.at}: <transform>: the matrix is singular or not finite")
    return m


def _value(doc, node, a):
    """(kind, value) of a value element (attributes already substituted)."""
    tag, at = node.tag, f"{node.at}: <{node.tag} name={a.get('name')!r}>"
    if tag in ("float", "integer", "boolean", "string"):
        _attrs(node, a, ("name", "value"), what=at)
        v = a["value"]
        if tag == "float":
            return "float", _floats(v, at, (1,))[0]
        if tag == "integer":
            try:
                return "integer", int(v)
            except ValueError:
                raise ValueError(f"{at}: expected an integer, got {v!r}") from None
        if tag == "boolean":
            if v.lower() not in ("true", "false"):
                raise ValueError(f"{at}: expected true or false, got {v!r}")
            return "boolean", v.lower() == "true"
        return "string", v
    if tag == "rgb":
        _attrs(node, a, ("name", "value"), what=at)
        v = _floats(a["value"], at, (1, 3))
        return "rgb", np.asarray(v * 3 if len(v) == 1 else v, np.float64)
    if tag == "spectrum":
        _attrs(node, a, ("name",), ("value", "filename"), what=at)
        if "value" not in a:
            raise ValueError(f"{at}: spectra from files are not supported (give value=...)")
        text = a["value"].strip()
        if ":" not in text:
            v = _floats(text, at, (1,))[0]
            return "spectrum", ("const", v)
        wl, vals = [], []
        for item in [p for p in re.split(r"\s*,\s*|\s+", text) if p]:
            lv = item.split(":")
            if len(lv) != 2:
                raise ValueError(f"{at}: expected 'wavelength:value' pairs, got {item!r}")
            w, x = (_floats(t, at, (1,))[0] for t in lv)
            wl.append(w)
            vals.append(x)
        if len(wl) < 2 or any(b <= a_ for a_, b in zip(wl, wl[1:], strict=False)):
            raise ValueError(f"{at}: expected at least two increasing wavelengths")
        return "spectrum", ("list", wl, vals)
    if tag in ("point", "vector"):
        _attrs(node, a, ("name",), ("x", "y", "z", "value"), what=at)
        if "value" in a:
            return tag, _floats(a["value"], at, (3,))
        return tag, _xyz(a, node, 0.0)
    raise AssertionError(tag)  # pragma: no cover


def _object(doc, node) -> _Obj:
    """An object element (``<bsdf type=...>`` ...) with its properties and children."""
    a = doc.sub(node)
    _attrs(node, a, ("type",), ("id", "name"))
    obj = _Obj(node.tag, a["type"], a.get("id"), node)
    plugin_status(obj.tag, obj.type, obj.where)  # PLUGINS: refused / unknown plugins
    for c in node.children:
        ca = doc.sub(c)
        if c.tag in _VALUE_TAGS:
            kind, v = _value(doc, c, ca)
            _set(obj, ca["name"], _Prop(kind, v, c))
        elif c.tag == "transform":
            _attrs(c, ca, ("name",))
            try:
                m = _transform(doc, c)
            except ValueError as e:  # name the object too (e.g. a singular instance)
                raise ValueError(f"{e} ({obj.label}, parameter {ca['name']!r})") from None
            _set(obj, ca["name"], _Prop("transform", m, c))
        elif c.tag == "ref":
            _attrs(c, ca, ("id",), ("name",))
            if ca["id"] not in doc.ids:
                raise ValueError(
                    f"{c.at}: <ref id={ca['id']!r}>: unknown id (defined so far: {sorted(doc.ids)})"
                )
            target = doc.ids[ca["id"]]
            if "name" in ca:
                _set(obj, ca["name"], _Prop("object", target, c))
            else:
                obj.children.append(target)
        elif c.tag in _OBJECT_TAGS:
            child = _object(doc, c)
            if child.id:
                _register(doc, child)
            cname = doc.sub(c).get("name")
            if cname is not None:
                _set(obj, cname, _Prop("object", child, c))
            else:
                obj.children.append(child)
        else:
            raise ValueError(f"{c.at}: <{c.tag}> inside {obj.where}: unsupported element")
    return obj


def _set(obj, name, prop):
    if name in obj.props:
        raise ValueError(f"{prop.node.at}: {obj.where}: parameter {name!r} given twice")
    obj.props[name] = prop


def _register(doc, obj):
    if obj.id in doc.ids:
        raise ValueError(f"{obj.where}: id {obj.id!r} already defined at "
                         f"{doc.ids[obj.id].node.at}")  # fmt: skip
    doc.ids[obj.id] = obj


def _walk_scene(doc, node, out: list):
    """Top-level objects of ``node`` (a ``<scene>``) in order, with includes spliced in."""
    for c in node.children:
        if c.tag == "default":
            a = doc.sub(c)
            _attrs(c, a, ("name", "value"))
            doc.params.setdefault(a["name"], a["value"])
            if a["name"] in doc.given:
                doc.used.add(a["name"])
        elif c.tag == "path":
            a = doc.sub(c)
            _attrs(c, a, ("value",))
            p = os.path.expanduser(a["value"])
            p = p if os.path.isabs(p) else os.path.join(os.path.dirname(c.file), p)
            if not os.path.isdir(p):
                raise ValueError(f"{c.at}: <path value={a['value']!r}>: no such folder")
            doc.search.insert(0, os.path.abspath(p))
        elif c.tag == "include":
            a = doc.sub(c)
            _attrs(c, a, ("filename",))
            path = doc.resolve(a["filename"], c)
            if path in doc.stack:
                raise ValueError(f"{c.at}: <include filename={a['filename']!r}>: include cycle")
            _read_file(doc, path, out)
        elif c.tag in _OBJECT_TAGS:
            obj = _object(doc, c)
            if obj.id:
                _register(doc, obj)
            out.append(obj)
        elif c.tag in _UNSUPPORTED_TAGS:
            raise ValueError(f"{c.at}: <{c.tag}>: not supported (jaxgfx renders surfaces only)")
        else:
            raise ValueError(f"{c.at}: <{c.tag}>: unsupported element in <scene>")


def _read_file(doc, path, out):
    path = os.path.abspath(path)
    root = _parse(path)
    if root.tag != "scene":
        raise ValueError(f"{root.at}: expected a <scene> root element, got <{root.tag}>")
    a = doc.sub(root)
    _attrs(root, a, ("version",))
    try:
        major = int(a["version"].split(".")[0])
    except ValueError:
        raise ValueError(f"{root.at}: <scene version={a['version']!r}>: bad version") from None
    if major < 2:
        raise ValueError(
            f"{root.at}: <scene version={a['version']!r}>: Mitsuba 0.x scenes (camelCase "
            "names) are not supported; upgrade the file to version 2 or 3"
        )
    doc.files.append(path)
    if not doc.search:
        doc.search.append(os.path.dirname(path))
    doc.stack.append(path)
    _walk_scene(doc, root, out)
    doc.stack.pop()


# ------------------------------------------------------------------------------------------
# reading an object's parameters


class _Params:
    """Typed access to an object's parameters; :meth:`done` refuses the ones never read."""

    def __init__(self, obj: _Obj, doc: _Doc, *, no_textures: str | None = None):
        # no_textures: why texture-valued parameters are refused here (e.g. inside a blendbsdf)
        self.obj, self.doc, self.no_textures = obj, doc, no_textures

    def _get(self, name, kinds):
        p = self.obj.props.get(name)
        if p is None:
            return None
        p.used = True
        if p.kind not in kinds:
            raise ValueError(
                f"{p.node.at}: {self.obj.where}: parameter {name!r}: expected "
                f"{' or '.join(kinds)}, got <{p.node.tag}>"
            )
        return p

    def err(self, name, msg):
        p = self.obj.props.get(name)
        at = f"{p.node.at}: " if p is not None and p.node is not self.obj.node else ""
        return ValueError(f"{at}{self.obj.where}: parameter {name!r}: {msg}")

    def float(self, name, default=None, *, positive=False):
        p = self._get(name, ("float", "integer"))
        if p is None:
            return default
        if positive and not p.value > 0:
            raise self.err(name, f"expected a positive number, got {p.value}")
        return float(p.value)

    def int(self, name, default=None):
        p = self._get(name, ("integer",))
        return default if p is None else int(p.value)

    def bool(self, name, default=None):
        p = self._get(name, ("boolean",))
        return default if p is None else bool(p.value)

    def string(self, name, default=None, choices=None):
        p = self._get(name, ("string",))
        if p is None:
            return default
        if choices is not None and p.value not in choices:
            raise self.err(name, f"{p.value!r} is not supported; expected one of {choices}")
        return p.value

    def vec(self, name, default=None):
        p = self._get(name, ("point", "vector"))
        return default if p is None else [float(x) for x in p.value]

    def transform(self, name):
        p = self._get(name, ("transform",))
        return None if p is None else p.value

    def color(self, name, default=None, *, emission=False, texture=False):
        """RGB list, or a texture description (``texture=True``)."""
        kinds = ("float", "rgb", "spectrum") + (("object",) if texture else ())
        p = self.obj.props.get(name)
        if p is not None and p.kind == "object" and (not texture or self.no_textures):
            p.used = True
            raise self.err(name, self.no_textures or "textures are not supported for this "
                                                     "parameter")  # fmt: skip
        p = self._get(name, kinds)
        if p is None:
            return default
        if p.kind == "float":
            return [p.value] * 3
        if p.kind == "rgb":
            return [float(x) for x in p.value]
        if p.kind == "spectrum":
            if p.value[0] == "const":
                return [p.value[1]] * 3
            return [float(x) for x in spectrum_to_rgb(p.value[1], p.value[2], emission=emission)]
        if p.value.tag != "texture":
            raise self.err(name, f"expected a texture, got {p.value.where}")
        return _texture(p.value, self.doc)

    def scalar_or_texture(self, name, default=None):
        p = self.obj.props.get(name)
        if p is not None and p.kind == "object":  # Mitsuba's eval_1: see the swap's docstring
            return swap_scalar_checkerboard(self.color(name, texture=True))
        return self.float(name, default)

    def ior(self, name, default):
        p = self._get(name, ("float", "string"))
        if p is None:
            return IOR_TABLE[default]
        if p.kind == "float":
            if not p.value > 0:
                raise self.err(name, f"expected a positive number, got {p.value}")
            return float(p.value)
        key = p.value.lower()
        if key not in IOR_TABLE:
            raise self.err(name, f"unknown IOR name {p.value!r}; expected one of "
                                 f"{sorted(IOR_TABLE)}")  # fmt: skip
        return IOR_TABLE[key]

    def done(self, children_ok=0):
        for name, p in self.obj.props.items():
            if not p.used:
                raise ValueError(
                    f"{p.node.at}: {self.obj.where}: parameter {name!r} is not supported"
                )
        if len(self.obj.children) > children_ok:
            c = self.obj.children[children_ok]
            raise ValueError(
                f"{c.node.at}: {self.obj.where}: nested <{c.tag} type={c.type!r}> is not "
                "supported here"
            )


# ------------------------------------------------------------------------------------------
# textures and BSDFs


def _uv_scale(p: _Params, name="to_uv"):
    m = p.transform(name)
    if m is None:
        return None
    lin, off = m[:3, :3], m[:3, 3]
    if not (np.allclose(lin, np.diag(np.diag(lin))) and np.allclose(off, 0)
            and math.isclose(lin[0, 0], lin[1, 1])):  # fmt: skip
        raise p.err(name, "only a uniform scale of the texture coordinates is supported")
    return float(lin[0, 0])


def _texture(obj: _Obj, doc) -> dict:
    p = _Params(obj, doc)
    if obj.type == "bitmap":
        path = (
            doc.resolve(p.string("filename"), obj.props["filename"].node, obj.label)
            if "filename" in obj.props
            else None
        )
        if path is None:
            raise ValueError(f"{obj.where}: missing parameter 'filename'")
        d = {"type": "bitmap", "file": path}
        d["filter"] = p.string("filter_type", "bilinear", ("bilinear", "nearest"))
        d["wrap"] = p.string("wrap_mode", "repeat", ("repeat", "mirror", "clamp"))
        d["raw"] = p.bool("raw", False)
        p.string("format", "variant", ("variant", "uint8"))  # storage precision only
        m = p.transform("to_uv")
        if m is not None and not np.allclose(m, np.eye(4)):
            if not np.allclose(m[3], [0, 0, 0, 1]):
                raise p.err("to_uv", "expected an affine transform")
            # Mitsuba's 2-D uv map: the upper-left 2 x 2 block and the translation's x, y
            d["to_uv"] = [[float(m[0, 0]), float(m[0, 1]), float(m[0, 3])],
                          [float(m[1, 0]), float(m[1, 1]), float(m[1, 3])]]  # fmt: skip
        p.done()
        return d
    if obj.type == "checkerboard":
        d = {"type": "checkerboard", "color0": p.color("color0", [0.4] * 3),
             "color1": p.color("color1", [0.2] * 3)}  # fmt: skip
        s = _uv_scale(p)
        if s is not None:
            if not s > 0:
                raise p.err("to_uv", "expected a positive scale")
            d["scale"] = s
        p.done()
        return d
    if obj.type == "mesh_attribute":  # the values are read from the shapes' PLY files
        name = p.string("name")
        if name is None or not name.startswith(("vertex_", "face_")):
            raise ValueError(f"{obj.where}: parameter 'name': expected 'vertex_...' or "
                             f"'face_...', got {name!r}")  # fmt: skip
        d = {"type": "mesh_attribute", "name": name, "scale": p.float("scale", 1.0)}
        p.done()
        return d
    if obj.type == "rawconstant":  # a constant read as written (no colour conversion)
        q = obj.props.get("value")
        if q is None:
            raise ValueError(f"{obj.where}: missing parameter 'value'")
        if q.kind in ("float", "integer"):
            v = p.float("value")
        else:
            v = p.color("value") if q.kind == "rgb" else p.vec("value")
        p.done()
        return v
    raise ValueError(f"{obj.where}: texture plugin {obj.type!r} is not supported "
                     "(bitmap, checkerboard, rawconstant)")  # fmt: skip


def _distribution(p: _Params, aniso=False):
    """Distribution keys; ``aniso`` (roughconductor): ``alpha_u`` / ``alpha_v`` may differ
    (numbers or textures) -> ``alpha`` (= alpha_u) and ``alpha_v``."""
    dist = p.string("distribution", DEFAULTS["distribution"], ("beckmann", "ggx"))
    alpha = p.scalar_or_texture("alpha", None)
    au, av = p.scalar_or_texture("alpha_u"), p.scalar_or_texture("alpha_v")
    alpha_v = None
    if au is not None or av is not None:
        if alpha is not None:
            raise p.err("alpha", "give either alpha or alpha_u / alpha_v")
        if not aniso and (au is None or av is None or au != av or isinstance(au, dict)):
            raise p.err("alpha_u", "anisotropic roughness is not supported (the tangent "
                                   "frames of jaxgfx and Mitsuba differ)")  # fmt: skip
        if au is None or av is None:
            raise p.err("alpha_u" if au is None else "alpha_v", "give both alpha_u and alpha_v")
        alpha, alpha_v = au, (None if au == av and not isinstance(au, dict) else av)
    out = {"distribution": dist, "alpha": DEFAULTS["alpha"] if alpha is None else alpha,
           "sample_visible": p.bool("sample_visible", DEFAULTS["sample_visible"])}  # fmt: skip
    if alpha_v is not None:
        out["alpha_v"] = alpha_v
    return out


def _dpdu_frame(m: dict, obj: _Obj, nested, in_map, aniso=None) -> dict:
    """An anisotropic ``roughconductor`` (``alpha_v``) or ``principled`` / ``principledthin``
    (``anisotropic``) outside a normal map: wrapped in the identity normal map
    ``(0.5, 0.5, 1)`` (no flip, no shadowing factor), whose perturbed frame is the unperturbed
    one with the tangent ``dp/du``: Mitsuba's shading frame (jaxgfx's own plain frame has
    another tangent). Inside a normal map the nested BSDF already has that frame."""
    if aniso is None:
        aniso = "alpha_v" in m or "anisotropic" in m
    if not aniso or in_map:
        return m
    if nested:
        raise ValueError(f"{obj.where}: an anisotropic {obj.type} inside a blendbsdf or "
                         "mask is not supported (its dp/du tangent frame)")  # fmt: skip
    return {"type": "normalmap", "normalmap": [0.5, 0.5, 1.0], "bsdf": m,
            "flip_invalid_normals": False, "use_shadowing_function": False}  # fmt: skip


def _measured(obj: _Obj, p: _Params, doc, nested, in_map) -> dict:
    """``measured`` (an RGL ``.bsdf`` file, relative to the XML file's folder): read and
    checked now, for file / line errors; an anisotropic file (more than two ``phi_i`` nodes)
    shades in Mitsuba's ``dp/du`` frame (:func:`_dpdu_frame`)."""
    from jaxgfx.render.bsdf import read_measured

    fname = p.string("filename")
    if fname is None:
        raise ValueError(f"{obj.where}: missing parameter 'filename'")
    path = doc.resolve(fname, obj.props["filename"].node, obj.label)
    try:
        f = read_measured(path)
    except (OSError, ValueError) as e:
        raise p.err("filename", str(e)) from None
    m = {"type": "measured", "filename": os.path.abspath(path)}
    return _dpdu_frame(m, obj, nested, in_map, aniso=f["phi_i"].shape[0] > 2)


def _conductor(p: _Params) -> dict:
    material = p.string("material", DEFAULTS["conductor.material"])
    out = {"reflectance": p.color("specular_reflectance", [1.0] * 3, texture=True)}
    eta, k = p.color("eta"), p.color("k")
    if material != "none":
        if material not in CONDUCTOR_IOR:
            raise p.err("material", f"unknown conductor {material!r}; expected 'none' or one "
                                    f"of {sorted(CONDUCTOR_IOR)}")  # fmt: skip
        if eta is not None or k is not None:
            raise p.err("material", "give either a named material or eta / k, not both")
        e, kk = CONDUCTOR_IOR[material]
        out.update(fresnel="conductor", eta=list(e), k=list(kk))
    elif eta is None and k is None:
        out["fresnel"] = "none"
    else:
        out.update(fresnel="conductor", eta=eta or [0.0] * 3, k=k or [1.0] * 3)
    return out


def _principled(p: _Params) -> dict:
    """``principled``: Mitsuba's parameter names and defaults (jaxgfx's are the same); every
    weight may be a texture; ``spec_trans`` 0 (or absent) is omitted (no transmission lobe, as
    Mitsuba), as ``anisotropic`` 0 (or absent; else the caller puts the BSDF in the dp/du
    frame, :func:`_dpdu_frame`). Both ``specular`` and ``eta`` are refused."""
    d = DEFAULTS
    m = {"type": "principled",
         "base_color": p.color("base_color", [d["principled.base_color"]] * 3, texture=True),
         "roughness": p.scalar_or_texture("roughness", d["principled.roughness"])}  # fmt: skip
    for k in ("metallic", "spec_tint", "sheen", "sheen_tint", "flatness", "clearcoat",
              "clearcoat_gloss"):  # fmt: skip
        m[k] = p.scalar_or_texture(k, 0.0)
    _anisotropy(p, m)
    st = p.scalar_or_texture("spec_trans", 0.0)
    if st != 0.0:
        m["spec_trans"] = st
    eta, spec = p.float("eta", positive=True), p.float("specular")
    if eta is not None and spec is not None:
        raise p.err("eta", "give either eta or specular, not both (as Mitsuba)")
    if eta is not None:
        m["eta"] = eta
    else:
        m["specular"] = d["principled.specular"] if spec is None else spec
    for k in ("diffuse_reflectance_sampling_rate", "main_specular_sampling_rate",
              "clearcoat_sampling_rate"):  # fmt: skip
        m[k] = p.float(k, 1.0)
    return m


def _hair(p: _Params) -> dict:
    """``hair`` (Chiang et al. 2016): Mitsuba's names and defaults; ``sigma_a`` (an RGB or a
    number, no texture, times ``scale``) or the melanin concentrations, not both (as Mitsuba);
    ``eta = int_ior / ext_ior`` (amber / air); roughnesses in (0, 1]. Mitsuba reads ``scale``
    with the concentrations too and ignores it; so does this."""
    d = DEFAULTS
    m = {"type": "hair"}
    for k in ("longitudinal_roughness", "azimuthal_roughness"):
        m[k] = p.float(k, d["hair.roughness"])
        if not 0.0 < m[k] <= 1.0:
            raise p.err(k, f"expected a value in (0, 1], got {m[k]}")
    m["scale_tilt"] = p.float("scale_tilt", d["hair.scale_tilt"])
    m["eta"] = _ior_ratio(p, d["hair.int_ior"], d["hair.ext_ior"])
    if not m["eta"] > 1.0:
        raise p.err("int_ior", f"expected int_ior / ext_ior > 1, got {m['eta']}")
    sigma = p.color("sigma_a")
    eu, ph = p.float("eumelanin"), p.float("pheomelanin")
    scale = p.float("scale", 1.0)
    if sigma is not None and (eu is not None or ph is not None):
        raise p.err("sigma_a", "give either sigma_a or eumelanin / pheomelanin, not both "
                               "(as Mitsuba)")  # fmt: skip
    if sigma is not None:
        if min(sigma) < 0 or scale < 0:
            raise p.err("sigma_a", f"expected values >= 0, got {sigma} x {scale}")
        return {**m, "sigma_a": sigma, "scale": scale}
    eu = d["hair.eumelanin"] if eu is None else eu
    ph = d["hair.pheomelanin"] if ph is None else ph
    if eu < 0 or ph < 0:
        raise p.err("eumelanin" if eu < 0 else "pheomelanin", "expected a value >= 0")
    return {**m, "eumelanin": eu, "pheomelanin": ph}


def _pplastic(p: _Params) -> dict:
    """``pplastic`` (its unpolarised form): Mitsuba's names and defaults; ``eta`` (a number or
    a texture) or ``int_ior`` / ``ext_ior`` (polypropylene / air, which must differ), not
    both; ``alpha`` or ``alpha_u`` / ``alpha_v`` (anisotropic: in the dp/du frame)."""
    d = DEFAULTS
    if "eta" in p.obj.props:
        both = [k for k in ("int_ior", "ext_ior") if k in p.obj.props]
        if both:
            p.obj.props[both[0]].used = True
            raise p.err(both[0], "give either eta or int_ior / ext_ior, not both (as Mitsuba)")
        eta = p.scalar_or_texture("eta")
        if not isinstance(eta, dict) and not eta > 0:
            raise p.err("eta", f"expected a positive number, got {eta}")
    else:
        i, e = p.ior("int_ior", d["pplastic.int_ior"]), p.ior("ext_ior", d["pplastic.ext_ior"])
        if i == e:
            raise p.err("int_ior", f"the interior and exterior IORs must differ, got {i} "
                                   "(as Mitsuba)")  # fmt: skip
        eta = i / e
    return {"type": "pplastic", **_distribution(p, aniso=True), "eta": eta,
            "diffuse_reflectance": p.color("diffuse_reflectance",
                                           [d["pplastic.diffuse_reflectance"]] * 3, texture=True),
            "specular_reflectance": p.color("specular_reflectance", [1.0] * 3, texture=True)}


def _angle(p: _Params, name: str, default: float):
    """A ``polarizer`` / ``retarder`` angle (degrees): a number, a uniform RGB or a constant
    spectrum -> a float; any other value (a texture, per-channel angles) is read and dropped
    (``None``): angles only rotate polarisation states, which unpolarised rendering lacks."""
    q = p.obj.props.get(name)
    if q is None:
        return default
    if q.kind == "integer":
        return p.float(name)
    v = p.color(name, texture=True)
    return float(v[0]) if isinstance(v, list) and len(set(v)) == 1 else None


def _pass_through(p: _Params, t: str) -> dict:
    """``polarizer`` / ``circular`` / ``retarder`` in Mitsuba's RGB variants:
    ``transmittance`` (a colour or a texture, default 1) and the angles (kept when numbers; no
    effect on unpolarised light); ``polarizing`` (a polarizer's) and ``left_handed`` (a circular
    polarizer's; no effect either)."""
    m = {"type": t, "transmittance": p.color("transmittance", [1.0] * 3, texture=True)}
    if t == "circular":
        return {**m, "left_handed": p.bool("left_handed", False)}
    angles = (("theta", 0.0),) + ((("delta", 90.0),) if t == "retarder" else ())
    for name, default in angles:
        v = _angle(p, name, default)
        if v is not None:
            m[name] = v
    if t == "polarizer":
        m["polarizing"] = p.bool("polarizing", True)
    return m


def _anisotropy(p: _Params, m: dict) -> None:
    """``anisotropic`` (a number in [0, 1] or a texture) into ``m`` unless absent or 0
    (Mitsuba's ``get_flag``: the isotropic program)."""
    a = p.scalar_or_texture("anisotropic", 0.0)
    if not isinstance(a, dict) and not 0.0 <= a <= 1.0:
        raise p.err("anisotropic", f"expected a value in [0, 1], got {a}")
    if a != 0.0:
        m["anisotropic"] = a


def _principledthin(p: _Params) -> dict:
    """``principledthin``: Mitsuba's names and defaults (jaxgfx's are the same); weights and
    ``eta`` may be textures; ``spec_trans`` / ``diff_trans`` / ``anisotropic`` 0 (or absent)
    are omitted (``anisotropic`` as for ``principled``)."""
    d = DEFAULTS
    m = {"type": "principledthin",
         "base_color": p.color("base_color", [d["principled.base_color"]] * 3, texture=True),
         "roughness": p.scalar_or_texture("roughness", d["principled.roughness"]),
         "eta": p.scalar_or_texture("eta", d["principledthin.eta"])}  # fmt: skip
    for k in ("spec_tint", "sheen", "sheen_tint", "flatness"):
        m[k] = p.scalar_or_texture(k, 0.0)
    _anisotropy(p, m)
    for k in ("spec_trans", "diff_trans"):
        v = p.scalar_or_texture(k, 0.0)
        if v != 0.0:
            m[k] = v
    for k in ("diffuse_reflectance", "specular_reflectance", "specular_transmittance",
              "diffuse_transmittance"):  # fmt: skip
        m[f"{k}_sampling_rate"] = p.float(f"{k}_sampling_rate", 1.0)
    return m


def _twosided_child(obj: _Obj, doc) -> _Obj:
    p = _Params(obj, doc)
    if len(obj.children) != 1 or obj.children[0].tag != "bsdf":
        raise ValueError(f"{obj.where}: expected exactly one nested <bsdf> (different "
                         "front and back BSDFs are not supported)")  # fmt: skip
    p.done(children_ok=1)
    return obj.children[0]


def _ior_ratio(p: _Params, int_default, ext_default) -> float:
    return p.ior("int_ior", int_default) / p.ior("ext_ior", ext_default)


def _blend_children(obj: _Obj, p: _Params) -> list:
    """The two nested BSDFs of a ``blendbsdf`` in Mitsuba's order: unnamed ones (and ``<ref>``s)
    in document order, or named ones sorted by name (Mitsuba orders them by name, and names
    unnamed ones ``_arg_N``; a mix of both is refused rather than guessed)."""
    for c in obj.children:
        if c.tag != "bsdf":
            raise ValueError(
                f"{c.node.at}: {obj.where}: nested <{c.tag} type={c.type!r}> is "
                'not supported here (a texture weight needs name="weight")'
            )
    unnamed = list(obj.children)
    named = sorted((k, q) for k, q in obj.props.items()
                   if q.kind == "object" and q.value.tag == "bsdf")  # fmt: skip
    for _, q in named:
        q.used = True
    if unnamed and named:
        why = "would depend on Mitsuba's names for unnamed objects"
        raise p.err(named[0][0], f"give both nested BSDFs a name or neither (their order {why})")
    kids = unnamed or [q.value for _, q in named]
    if len(kids) != 2:
        raise ValueError(f"{obj.where}: expected exactly two nested <bsdf>, got {len(kids)}")
    return kids


def _bsdf_dict(obj: _Obj, doc, *, nested=False, in_map=False) -> dict:
    """The jaxgfx description of a BSDF object (``twosided`` unwrapped). ``nested``: a BSDF
    inside a ``blendbsdf``, whose parameters jaxgfx cannot texture."""
    while obj.type == "twosided":
        obj = _twosided_child(obj, doc)
    why = "textures are not supported in a BSDF nested in a blendbsdf or mask" if nested else None
    p = _Params(obj, doc, no_textures=why)
    t = obj.type
    children_ok = 0
    if t == "diffuse":
        rho = [DEFAULTS["diffuse.reflectance"]] * 3
        m = {"type": "diffuse", "reflectance": p.color("reflectance", rho, texture=True)}
    elif t == "conductor":
        m = {"type": "conductor", **_conductor(p)}
    elif t == "roughconductor":
        m = _dpdu_frame({"type": "roughconductor", **_distribution(p, aniso=True),
                         **_conductor(p)}, obj, nested, in_map)  # fmt: skip
    elif t in ("dielectric", "roughdielectric", "thindielectric"):
        eta = _ior_ratio(p, DEFAULTS["dielectric.int_ior"], DEFAULTS["dielectric.ext_ior"])
        m = {"type": t, **(_distribution(p) if t == "roughdielectric" else {}), "eta": eta,
             "specular_reflectance": p.color("specular_reflectance", [1.0] * 3, texture=True),
             "specular_transmittance": p.color("specular_transmittance", [1.0] * 3,
                                               texture=True)}  # fmt: skip
    elif t in ("plastic", "roughplastic"):
        m = {"type": t, **(_distribution(p) if t == "roughplastic" else {}),
             "eta": _ior_ratio(p, DEFAULTS["roughplastic.int_ior"],
                               DEFAULTS["roughplastic.ext_ior"]),
             "diffuse_reflectance": p.color("diffuse_reflectance",
                                             [DEFAULTS["roughplastic.diffuse_reflectance"]] * 3,
                                             texture=True),
             "specular_reflectance": p.color("specular_reflectance", [1.0] * 3, texture=True),
             "nonlinear": p.bool("nonlinear", False)}  # fmt: skip
    elif t == "blendbsdf":
        kids = _blend_children(obj, p)
        children_ok = len(obj.children)
        if nested and "weight" in obj.props and obj.props["weight"].kind == "object":
            obj.props["weight"].used = True
            raise p.err("weight", "a texture weight is supported for a top-level blendbsdf "
                                  "only, not one nested in another blendbsdf")  # fmt: skip
        w = p.scalar_or_texture("weight", DEFAULTS["blendbsdf.weight"])
        m = {"type": "blendbsdf", "weight": w,
             "bsdf0": _bsdf_dict(kids[0], doc, nested=True),
             "bsdf1": _bsdf_dict(kids[1], doc, nested=True)}  # fmt: skip
    elif t == "principled":
        m = _dpdu_frame(_principled(p), obj, nested, in_map)
    elif t == "principledthin":
        m = _dpdu_frame(_principledthin(p), obj, nested, in_map)
    elif t == "measured":
        m = _measured(obj, p, doc, nested, in_map)
    elif t == "hair":
        if nested or in_map:
            raise ValueError(f"{obj.where}: a hair BSDF nested in another BSDF is not supported "
                             "(it shades in the hit's dp/du frame)")  # fmt: skip
        m = _hair(p)
    elif t == "mask":
        if nested:
            raise ValueError(f"{obj.where}: a mask nested in a blendbsdf or mask is not supported")
        m = _mask_dict(obj, p, doc)
        children_ok = len(obj.children)
    elif t == "pplastic":
        m = _dpdu_frame(_pplastic(p), obj, nested, in_map)
    elif t in ("polarizer", "circular", "retarder"):
        if nested:
            raise ValueError(f"{obj.where}: a {t} nested in a blendbsdf or mask is not "
                             "supported (a pass-through, as the null BSDF)")  # fmt: skip
        m = _pass_through(p, t)
    elif t == "null":  # no parameters: Mask(Diffuse(0), opacity 0)
        if nested:
            raise ValueError(f"{obj.where}: a null BSDF nested in a blendbsdf or mask is not "
                             "supported (a mask's opacity does that)")  # fmt: skip
        m = {"type": "null"}
    elif t in ("normalmap", "bumpmap"):
        if nested:
            raise ValueError(f"{obj.where}: a {t} nested in a blendbsdf is not supported")
        m = _map_dict(obj, p, doc)
        children_ok = len(obj.children)
    else:
        raise ValueError(f"{obj.where}: BSDF plugin {t!r} is not supported")
    p.done(children_ok=children_ok)
    return m


def _map_dict(obj: _Obj, p: _Params, doc) -> dict:
    """``normalmap`` (a texture named ``normalmap`` and one nested BSDF) / ``bumpmap`` (one
    nested texture of any name, one nested BSDF and ``scale``), as Mitsuba 3 reads them."""
    t = obj.type
    kids = {"bsdf": [], "texture": []}
    for c in obj.children:
        if c.tag not in kids or (t == "normalmap" and c.tag == "texture"):
            hint = ' (the normal map needs name="normalmap")' if c.tag == "texture" else ""
            raise ValueError(f"{c.node.at}: {obj.where}: nested <{c.tag} type={c.type!r}> is "
                             f"not supported here{hint}")  # fmt: skip
        kids[c.tag].append(c)
    for k, q in obj.props.items():
        if q.kind == "object" and q.value.tag in kids and not (t == "normalmap" and k == t):
            q.used = True
            kids[q.value.tag].append(q.value)
    if len(kids["bsdf"]) != 1:
        raise ValueError(f"{obj.where}: expected exactly one nested <bsdf>, got "
                         f"{len(kids['bsdf'])}")  # fmt: skip
    m = {"type": t, "bsdf": _bsdf_dict(kids["bsdf"][0], doc, in_map=True)}
    if t == "normalmap":
        tex = p.color("normalmap", texture=True)
        if tex is None:
            raise ValueError(f"{obj.where}: missing the texture 'normalmap'")
        m["normalmap"] = tex
    else:
        if len(kids["texture"]) != 1:
            raise ValueError(f"{obj.where}: expected exactly one nested <texture> (the height "
                             f"map), got {len(kids['texture'])}")  # fmt: skip
        m["height"] = _texture(kids["texture"][0], doc)
        m["scale"] = p.float("scale", 1.0)
    for k in _MAP_FLAGS:  # Mitsuba 3's defaults: both on
        m[k] = p.bool(k, True)
    return m


_MAP_FLAGS = ("flip_invalid_normals", "use_shadowing_function")


def _mask_dict(obj: _Obj, p: _Params, doc) -> dict:
    """``mask``: one nested BSDF (untextured) and ``opacity`` (a number or a texture; Mitsuba's
    default 0.5) -> ``{type: mask, opacity, bsdf}``."""
    kids = []
    for c in obj.children:
        if c.tag != "bsdf":
            hint = 'an opacity texture needs name="opacity"'
            raise ValueError(f"{c.node.at}: {obj.where}: nested <{c.tag} type={c.type!r}> is "
                             f"not supported here ({hint})")  # fmt: skip
        kids.append(c)
    for q in obj.props.values():
        if q.kind == "object" and q.value.tag == "bsdf":
            q.used = True
            kids.append(q.value)
    if len(kids) != 1:
        raise ValueError(f"{obj.where}: expected exactly one nested <bsdf>, got {len(kids)}")
    opacity = p.scalar_or_texture("opacity", DEFAULTS["mask.opacity"])
    return {"type": "mask", "opacity": opacity, "bsdf": _bsdf_dict(kids[0], doc, nested=True)}


def _bsdf(obj: _Obj, doc, desc, *, name=None, twosided=False) -> str:
    """The material name of a BSDF object (converted once, shared by references): its ``id``,
    else ``name`` (the id of an enclosing ``twosided``), else ``bsdf_N``. A BSDF that Mitsuba
    shades on the front side only (:func:`_is_one_sided`) and that no ``twosided`` encloses
    gets ``one_sided: true``."""
    if obj.converted is not None and obj.converted[1] == twosided:
        return obj.converted[0]
    if obj.type == "twosided":
        name = _bsdf(_twosided_child(obj, doc), doc, desc, name=obj.id or name, twosided=True)
        obj.converted = (name, twosided)
        return name
    m = _bsdf_dict(obj, doc)
    if not twosided and _is_one_sided(obj, m):
        m["one_sided"] = True
    name = obj.id or name or f"bsdf_{len(desc['materials'])}"
    while name in desc["materials"]:
        name += "_"
    desc["materials"][name] = m
    obj.converted = (name, twosided)
    return name


def _is_one_sided(obj: _Obj, m: dict) -> bool:
    """Whether Mitsuba 3 shades the BSDF ``obj`` (jaxgfx description ``m``) on the front side
    only: one of :data:`ONE_SIDED_BSDFS` (a ``principled`` without ``spec_trans``), or a
    ``normalmap`` / ``bumpmap`` around one (not wrapped in ``twosided`` inside the map).
    ``mask`` and ``blendbsdf`` stay two-sided (as before; their nested BSDFs are not
    checked), transmissive BSDFs scatter on both sides anyway."""
    if obj.type in ("normalmap", "bumpmap"):
        kids = [c for c in obj.children if c.tag == "bsdf"]
        kids += [q.value for q in obj.props.values()
                 if q.kind == "object" and q.value.tag == "bsdf"]  # fmt: skip
        return len(kids) == 1 and _is_one_sided(kids[0], m["bsdf"])
    leaf = m
    while leaf.get("type") in ("normalmap", "bumpmap") and isinstance(leaf.get("bsdf"), dict):
        leaf = leaf["bsdf"]  # the dp/du-frame wrapper of an anisotropic BSDF (_dpdu_frame)
    return obj.type in ONE_SIDED_BSDFS and "spec_trans" not in leaf


# ------------------------------------------------------------------------------------------
# shapes


def _angle_weighted_normals(v, f):
    n = np.zeros_like(v)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    ln = np.linalg.norm(fn, axis=1, keepdims=True)
    fn = fn / np.where(ln > 0, ln, 1.0)
    for k in range(3):
        e1 = v[f[:, (k + 1) % 3]] - v[f[:, k]]
        e2 = v[f[:, (k + 2) % 3]] - v[f[:, k]]
        c = np.sum(e1 * e2, 1) / np.maximum(
            np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1), 1e-300
        )
        ang = np.arccos(np.clip(c, -1.0, 1.0))
        np.add.at(n, f[:, k], fn * ang[:, None])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(ln > 0, ln, 1.0)


def _cube():
    """Mitsuba's cube mesh (``src/shapes/cube.cpp``): ``[-1, 1]³``, 24 vertices (four per face,
    faces in the order -y, +y, +x, +z, -x, -z), 12 triangles ``(4s, 4s+1, 4s+2)``,
    ``(4s+3, 4s, 4s+2)`` counter-clockwise seen from outside, face normals, and each face's
    uvs ``(0, 1), (1, 1), (1, 0), (0, 0)`` for its vertices ``4s .. 4s+3``."""
    corner_of = [1, 5, 4, 0, 3, 2, 6, 7, 1, 3, 7, 5, 5, 7, 6, 4, 4, 6, 2, 0, 3, 1, 0, 2]
    normals = [(0, -1, 0), (0, 1, 0), (1, 0, 0), (0, 0, 1), (-1, 0, 0), (0, 0, -1)]
    v = np.array([[1.0 if c & 1 else -1.0, 1.0 if c & 2 else -1.0, 1.0 if c & 4 else -1.0]
                  for c in corner_of])  # fmt: skip
    n = np.repeat(np.asarray(normals, np.float64), 4, axis=0)
    uv = np.tile([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]], (6, 1))
    f = np.array([t for s in range(6) for t in ((4 * s, 4 * s + 1, 4 * s + 2),
                                                (4 * s + 3, 4 * s, 4 * s + 2))])  # fmt: skip
    return v, f, n, uv


def _disk(n_seg=DISK_SEGMENTS):
    """Mitsuba's unit disk (z = 0, normal +z) as a fan of ``n_seg`` triangles with its own
    three vertices each, and Mitsuba's uv ``(r, φ/2π)``, ``φ`` in ``[0, 2π)``: rim vertices
    ``(1, i/n)``, ``(1, (i+1)/n)`` and the centre ``(0, (i + 1/2)/n)``. Interpolated, ``u`` is
    ``r`` to ``1 - cos(π/n)`` (7.5e-5) and ``v`` is exact on the rim, off by up to ``1/2n``
    at the centre."""
    i = np.arange(n_seg)
    ang = 2 * np.pi * np.arange(n_seg + 1) / n_seg
    rim = np.stack([np.cos(ang), np.sin(ang), np.zeros(n_seg + 1)], 1)
    v = np.stack([np.zeros((n_seg, 3)), rim[i], rim[i + 1]], 1).reshape(-1, 3)
    uv = np.stack([np.stack([np.zeros(n_seg), (i + 0.5) / n_seg], 1),
                   np.stack([np.ones(n_seg), i / n_seg], 1),
                   np.stack([np.ones(n_seg), (i + 1) / n_seg], 1)], 1).reshape(-1, 2)  # fmt: skip
    f = np.arange(3 * n_seg).reshape(n_seg, 3)
    return v, f, np.tile([0.0, 0.0, 1.0], (3 * n_seg, 1)), uv


def _cylinder(n_seg=CYLINDER_SEGMENTS):
    """Mitsuba's unit cylinder (radius 1, axis z in [0, 1], no caps) as a strip of ``2 n_seg``
    triangles between two rings of ``n_seg + 1`` vertices (the seam's twice), faces
    counter-clockwise seen from outside (geometric normals outward, as Mitsuba's), vertex
    normals radial (the smooth cylinder's shading normals) and Mitsuba's uv ``(φ/2π, z)``."""
    ang = 2 * np.pi * np.arange(n_seg + 1) / n_seg
    ring = np.stack([np.cos(ang), np.sin(ang), np.zeros(n_seg + 1)], 1)
    ring[-1] = ring[0]
    v = np.concatenate([ring, ring + [0.0, 0.0, 1.0]])
    k = n_seg + 1
    i = np.arange(n_seg)
    j = i + 1
    f = np.concatenate([np.stack([i, j, k + j], 1), np.stack([i, k + j, k + i], 1)])
    u = np.arange(n_seg + 1) / n_seg
    uv = np.concatenate([np.stack([u, np.zeros(k)], 1), np.stack([u, np.ones(k)], 1)])
    return v, f, np.concatenate([ring, ring]), uv


def _frame_to_world(n):
    """Mitsuba's ``Frame3f(n)`` as a rotation (columns s, t, n): the tangents of Duff et al.,
    "Building an Orthonormal Basis, Revisited" (JCGT 6(1), 2017), which fix the cylinder's
    uv origin (``φ = 0`` along s)."""
    sign = 1.0 if n[2] >= 0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = np.array([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]])
    t = np.array([b, sign + n[1] * n[1] * a, -n[1]])
    return np.stack([s, t, np.asarray(n, np.float64)], 1)


def _is_textured(desc, name):
    """Whether material ``name`` reads the hit's uv: a texture parameter or a normal / bump map,
    also inside nested BSDFs (``bsdf``, ``bsdf0``, ``bsdf1``: descriptions, not textures)."""
    from jaxgfx.render.bsdf.textured import is_texture_desc

    def reads_uv(m):
        if m.get("type") in ("normalmap", "bumpmap"):
            return True
        return any(reads_uv(v) if k in ("bsdf", "bsdf0", "bsdf1") else is_texture_desc(v)
                   for k, v in m.items())  # fmt: skip

    return reads_uv(desc["materials"].get(name, {}))


def _shape(obj: _Obj, doc, desc, ctx):
    """Append the shape (or area light) of ``obj`` to ``desc``."""
    p = _Params(obj, doc)
    m = p.transform("to_world")
    m = np.eye(4) if m is None else m
    # a named nested BSDF / emitter (``<ref name="bsdf" id=...>``, matpreview.xml): Mitsuba
    # takes a shape's child objects whatever their name
    named = [q for q in obj.props.values()
             if q.kind == "object" and q.value.tag in ("bsdf", "emitter")]  # fmt: skip
    for q in named:
        q.used = True
    kids = obj.children + [q.value for q in named]
    bsdfs = [c for c in kids if c.tag == "bsdf"]
    emitters = [c for c in kids if c.tag == "emitter"]
    meters = [c for c in obj.children if c.tag == "sensor" and c.type == "irradiancemeter"]
    other = [c for c in obj.children if c.tag not in ("bsdf", "emitter") and c not in meters]
    if other:
        c = other[0]
        raise ValueError(f"{c.node.at}: {obj.where}: nested <{c.tag} type={c.type!r}> is not "
                         "supported in a shape")  # fmt: skip
    if len(bsdfs) > 1 or len(emitters) > 1:
        raise ValueError(f"{obj.where}: expected at most one <bsdf> and one <emitter>")
    if p.bool("flip_normals", False):
        raise p.err("flip_normals", "flipped normals are not supported")
    if bsdfs:
        mat = _bsdf(bsdfs[0], doc, desc)
    elif emitters:  # Mitsuba's default BSDF of an emitting shape: a black (one-sided) diffuse
        mat = "mitsuba_default_emitter"
        rho = [0.0, 0.0, 0.0]
        desc["materials"].setdefault(
            mat, {"type": "diffuse", "reflectance": rho, "one_sided": True}
        )
    else:  # Mitsuba's default BSDF: a (one-sided) diffuse
        mat = "mitsuba_default"
        rho = [DEFAULTS["diffuse.reflectance"]] * 3
        desc["materials"].setdefault(
            mat, {"type": "diffuse", "reflectance": rho, "one_sided": True}
        )
    lin, det = m[:3, :3], float(np.linalg.det(m[:3, :3]))
    t = obj.type
    if t == "sphere":
        center = np.asarray(p.vec("center", [0.0, 0.0, 0.0]))
        radius = p.float("radius", 1.0, positive=True)
        mm = m @ np.diag([radius, radius, radius, 1.0])
        mm[:3, 3] = m[:3, :3] @ center + m[:3, 3]
        ml = mm[:3, :3]
        s = float(np.linalg.norm(ml[:, 0]))
        if not np.allclose(ml.T @ ml, s * s * np.eye(3), rtol=1e-6, atol=1e-9 * s * s):
            raise p.err("to_world", "a sphere's to_world must be a rotation, uniform scale "
                                    "and translation (no ellipsoids)")  # fmt: skip
        sd = {"type": "sphere", "center": mm[:3, 3].tolist(), "radius": float(s)}
        if not np.allclose(ml / s, np.eye(3), atol=1e-9):  # rotated: uv in its local frame
            sd["frame"] = (ml / s).tolist()
        bbox = np.stack([mm[:3, 3] - s, mm[:3, 3] + s])
    elif t == "rectangle":
        if emitters and det < 0:
            raise p.err("to_world", "a mirroring to_world (det < 0) on an emitting rectangle "
                                    "flips its emitting side; not supported")  # fmt: skip
        sd = {"type": "rectangle", "center": m[:3, 3].tolist(),
              "edge_u": (2 * lin[:, 0]).tolist(), "edge_v": (2 * lin[:, 1]).tolist()}  # fmt: skip
        corners = np.array([[x, y, 0, 1] for x in (-1, 1) for y in (-1, 1)]) @ m.T
        bbox = np.stack([corners[:, :3].min(0), corners[:, :3].max(0)])
    elif t in ("obj", "ply", "serialized", "cube", "disk", "cylinder"):
        from jaxgfx.render.geometry import mesh_io

        uvs = normals = None
        attrs: dict = {}
        if t in ("obj", "ply", "serialized"):
            fname = p.string("filename")
            if fname is None:
                raise ValueError(f"{obj.where}: missing parameter 'filename'")
            path = doc.resolve(fname, obj.props["filename"].node, obj.label)
            try:
                if t == "serialized":
                    from jaxgfx.render.geometry.serialized import read_serialized

                    # vertex colours are ignored, as Mitsuba does unless a texture reads them
                    mesh = read_serialized(path, p.int("shape_index", 0))
                elif t == "ply":  # with its vertex_* / face_* attributes (mesh_attribute)
                    mesh, attrs = mesh_io.load_ply(path, attributes=True)
                else:
                    mesh = mesh_io.load_obj(path)
            except ValueError as e:
                raise p.err("filename", str(e)) from None
            v = np.asarray(mesh.vertices, np.float64)
            f = np.asarray(mesh.faces)
            if mesh.uvs is not None:
                uvs = np.asarray(mesh.uvs, np.float64)
                if t == "obj" and p.bool("flip_tex_coords", True):
                    uvs = np.stack([uvs[:, 0], 1.0 - uvs[:, 1]], 1)
            if p.bool("face_normals", False):
                normals = None
            elif mesh.normals is not None:
                normals = np.asarray(mesh.normals, np.float64)
            else:
                normals = _angle_weighted_normals(v, f)
        elif t == "cube":
            v, f, _, uvs = _cube()
        elif t == "cylinder":
            p0 = np.asarray(p.vec("p0", [0.0, 0.0, 0.0]), np.float64)
            p1 = np.asarray(p.vec("p1", [0.0, 0.0, 1.0]), np.float64)
            radius = p.float("radius", 1.0, positive=True)
            length = float(np.linalg.norm(p1 - p0))
            if not length > 0:
                raise p.err("p1", "p0 and p1 coincide (a cylinder of length 0)")
            local = np.eye(4)  # Mitsuba: to_world . translate(p0) . to_frame(d) . scale(r, r, l)
            local[:3, :3] = _frame_to_world((p1 - p0) / length) @ np.diag([radius, radius, length])
            local[:3, 3] = p0
            m = m @ local
            lin, det = m[:3, :3], float(np.linalg.det(m[:3, :3]))
            cx, cy, cz = lin[:, 0], lin[:, 1], lin[:, 2]
            r2 = float(cx @ cx)
            if not (abs(float(cy @ cy) - r2) <= 1e-6 * r2
                    and max(abs(float(cx @ cy)), abs(float(cx @ cz)), abs(float(cy @ cz)))
                    <= 1e-6 * max(r2, float(cz @ cz))):  # fmt: skip
                raise p.err("to_world", "a cylinder's to_world must keep its cross-section a "
                                        "circle (no non-uniform scale across the axis, no "
                                        "shear)")  # fmt: skip
            v, f, normals, uvs = _cylinder()
        else:
            v, f, normals, uvs = _disk()
        if emitters and det < 0:
            raise p.err("to_world", "a mirroring to_world (det < 0) on an emitting mesh "
                                    "flips its emitting side; not supported")  # fmt: skip
        sd = {"type": "mesh", "vertices": v.tolist(), "faces": np.asarray(f).tolist()}
        if normals is not None:
            sd["normals"] = normals.tolist()
        if uvs is not None:
            sd["uvs"] = uvs.tolist()
        if t == "ply" and attrs:
            sd["attributes"] = {k: a.tolist() for k, a in attrs.items()}
        if not np.allclose(m, np.eye(4)):
            sd["to_world"] = m.tolist()
        vw = v @ lin.T + m[:3, 3]
        bbox = np.stack([vw.min(0), vw.max(0)])
        ctx.setdefault("triangles", {})[id(obj)] = vw[np.asarray(f)]  # _check_clip
    elif t == "sdfgrid":  # the unit cube's grid, read now for file/line errors
        from jaxgfx.render.geometry import read_vol

        if emitters:
            raise ValueError(f"{obj.where}: an sdfgrid cannot be an area emitter (as in Mitsuba)")
        fname = p.string("filename")
        if fname is None:
            raise ValueError(f"{obj.where}: missing parameter 'filename'")
        path = doc.resolve(fname, obj.props["filename"].node, obj.label)
        try:
            read_vol(path)
        except (OSError, ValueError) as e:
            raise p.err("filename", str(e)) from None
        sd = {"type": "sdfgrid", "filename": os.path.abspath(path),
              "normals": p.string("normals", "smooth", ("smooth", "analytic"))}  # fmt: skip
        if not np.allclose(m, np.eye(4)):
            sd["to_world"] = m.tolist()
        c = np.array([[x, y, z, 1.0] for x in (0, 1) for y in (0, 1) for z in (0, 1)]) @ m.T
        bbox = np.stack([c[:, :3].min(0), c[:, :3].max(0)])
    elif t in ("linearcurve", "bsplinecurve"):  # control points read now for file/line errors
        from jaxgfx.render.geometry import read_curves

        if emitters:
            raise ValueError(f"{obj.where}: a {t} cannot be an area emitter (Mitsuba's "
                             "curves have no area sampling)")  # fmt: skip
        fname = p.string("filename")
        if fname is None:
            raise ValueError(f"{obj.where}: missing parameter 'filename'")
        path = doc.resolve(fname, obj.props["filename"].node, obj.label)
        try:
            spline = t == "bsplinecurve"
            pts, _ = read_curves(path, min_points=4 if spline else 2,
                                 kind="B-spline" if spline else "linear")  # fmt: skip
        except (OSError, ValueError) as e:
            raise p.err("filename", str(e)) from None
        sd = {"type": t, "filename": os.path.abspath(path)}
        if not np.allclose(m, np.eye(4)):
            sd["to_world"] = m.tolist()
        c = pts[:, :3] @ m[:3, :3].T + m[:3, 3]
        bbox = np.stack([(c - pts[:, 3:]).min(0), (c + pts[:, 3:]).max(0)])
    elif t == "ellipsoids":  # jaxgfx/render/scene/_ellipsoids.py; the PLY read now for errors
        from jaxgfx.render.scene._ellipsoids import ellipsoids_xml

        sd, bbox = ellipsoids_xml(p, obj, doc, m, emitters)
    else:
        raise ValueError(f"{obj.where}: shape plugin {t!r} is not supported "
                         "(obj, ply, serialized, sphere, rectangle, cube, disk, "
                         "cylinder, sdfgrid, linearcurve, bsplinecurve, ellipsoids)")  # fmt: skip
    p.done(children_ok=len(obj.children))
    ctx["bboxes"].append((bbox, obj))
    if meters:  # the irradiance meter's shape (read_xml puts it into the camera)
        if sd["type"] not in ("sphere", "rectangle", "mesh"):
            raise ValueError(f"{meters[0].where}: an irradiancemeter on a {t} is not "
                             "supported (sphere, rectangle or a mesh)")  # fmt: skip
        ctx["meter_shape"] = {k: v for k, v in sd.items() if k != "id"}
    if emitters:
        e = emitters[0]
        ep = _Params(e, doc)
        if e.type not in ("area", "directionalarea"):
            raise ValueError(f"{e.where}: only 'area' and 'directionalarea' emitters can be "
                             "attached to a shape")  # fmt: skip
        # directionalarea: an RGB radiance only (jaxgfx's DirectionalAreaLight)
        rad = ep.color("radiance", [1.0] * 3, emission=True, texture=e.type == "area")
        ep.done()
        ed = {"type": e.type, "shape": sd, "radiance": rad, "material": mat}
        _name_by_id(ed, e.id or obj.id)  # an unnamed area emitter goes by its shape's id
        _name_by_id(sd, obj.id)
        desc["emitters"].append(ed)
    else:
        sd["material"] = mat
        _name_by_id(sd, obj.id)
        desc["shapes"].append(sd)


def _name_by_id(d, ident):
    """Give description ``d`` the XML ``id`` as its name in parameter paths (``shapes.ID``,
    ``emitters.ID``) when the id can be one (``id_problem``: no ``.``, not a number or an
    emitter kind); such an object keeps its index name. Duplicate ids are refused by
    ``_register`` (file and line)."""
    from jaxgfx.render.scene.scene import id_problem

    if ident and id_problem(ident) is None:
        d["id"] = ident


def _shapegroup(obj: _Obj, doc, desc, ctx):
    """Translate a ``shapegroup``'s shapes (group space); they appear only when instanced.
    Mitsuba 3 refuses nested groups, nested instances and emitters in a group: so does this."""
    if not obj.id:
        raise ValueError(f"{obj.where}: a shapegroup needs an id (instances refer to it)")
    groups = ctx.setdefault("groups", {})
    if obj.id in groups:
        return groups[obj.id]
    _Params(obj, doc).done(children_ok=len(obj.children))  # a group has no parameters
    sub = {"materials": desc["materials"], "shapes": [], "emitters": []}
    sctx: dict = {"bboxes": []}
    for c in obj.children:
        if c.tag != "shape":
            raise ValueError(f"{c.node.at}: <{c.tag}> inside {obj.where}: a shapegroup holds "
                             "shapes only")  # fmt: skip
        if c.type in ("shapegroup", "instance"):
            raise ValueError(f"{c.node.at}: {c.where} inside {obj.where}: nested instancing is "
                             "not permitted (as in Mitsuba 3)")  # fmt: skip
        if any(g.tag == "emitter" for g in c.children):
            raise ValueError(f"{c.node.at}: {c.where} inside {obj.where}: instancing of "
                             "emitters is not supported (as in Mitsuba 3)")  # fmt: skip
        _shape(c, doc, sub, sctx)
    groups[obj.id] = g = {"shapes": sub["shapes"], "bboxes": sctx["bboxes"], "entry": None}
    return g


def _instance(obj: _Obj, doc, desc, ctx):
    """One ``instance``: its ``to_world`` joins the ``{type: instances}`` entry of its group
    (one entry per group, at the place of the group's first instance)."""
    p = _Params(obj, doc)
    m = p.transform("to_world")
    m = np.eye(4) if m is None else m
    refs = [c for c in obj.children if c.tag == "shape" and c.type == "shapegroup"]
    if len(obj.children) != 1 or len(refs) != 1:
        raise ValueError(f"{obj.where}: an instance needs exactly one shapegroup (a <ref> to "
                         f"its id), got {len(obj.children)} nested objects")  # fmt: skip
    lin = m[:3, :3]
    if not abs(np.linalg.det(lin)) > 1e-12 * np.linalg.norm(lin) ** 3:
        raise p.err("to_world", "the transform is singular (det = 0); an instance must be "
                                "an invertible affine map")  # fmt: skip
    p.done(children_ok=1)
    g = _shapegroup(refs[0], doc, desc, ctx)
    if g["entry"] is None:
        g["entry"] = {"type": "instances", "shapes": g["shapes"], "to_world": []}
        desc["shapes"].append(g["entry"])
    g["entry"]["to_world"].append(m.tolist())
    for (lo, hi), _ in g["bboxes"]:  # world boxes of the instanced shapes (clip checks)
        c = np.array([[x[0], y[1], z[2], 1.0] for x in (lo, hi) for y in (lo, hi)
                      for z in (lo, hi)])  # fmt: skip
        w = (c @ m.T)[:, :3]
        ctx["bboxes"].append((np.stack([w.min(0), w.max(0)]), obj))


# ------------------------------------------------------------------------------------------
# emitters, sensor, integrator


def _emitter(obj: _Obj, doc, desc):
    p = _Params(obj, doc)
    t = obj.type
    if t == "point":
        pos = p.vec("position")
        m = p.transform("to_world")
        if m is not None:
            if pos is not None:
                raise p.err("position", "give either position or to_world")
            pos = m[:3, 3].tolist()
        d = {"type": "point", "position": pos or [0.0, 0.0, 0.0],
             "intensity": p.color("intensity", [1.0] * 3, emission=True)}  # fmt: skip
    elif t == "constant":
        d = {"type": "constant", "radiance": p.color("radiance", [1.0] * 3, emission=True)}
    elif t == "envmap":
        from jaxgfx import io

        path = (
            doc.resolve(p.string("filename"), obj.props["filename"].node, obj.label)
            if "filename" in obj.props
            else None
        )
        if path is None:
            raise ValueError(f"{obj.where}: missing parameter 'filename'")
        m = p.transform("to_world")  # a rotation (Mitsuba looks up to_world^-1 d)
        if m is not None and not np.allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-6):
            raise p.err("to_world", "an environment map's to_world must be a rotation (no "
                                    "scale or shear)")  # fmt: skip
        p.string("filter_type", "bilinear", ("bilinear",))
        try:
            img = io.read_any(path)
        except (ValueError, OSError) as e:
            raise p.err("filename", f"cannot read {path!r}: {e}") from None
        if img.ndim != 3 or img.shape[-1] < 3 or min(img.shape[:2]) < 2:
            raise p.err("filename", f"expected an RGB image of at least 2x2, got {img.shape}")
        d = {"type": "envmap", "image": envmap_from_mitsuba(img),
             "scale": p.float("scale", 1.0)}  # fmt: skip
        if m is not None and not np.allclose(m[:3, :3], np.eye(3), rtol=0, atol=1e-12):
            d["to_world"] = m[:3, :3].tolist()
    elif t == "directional":
        direction = p.vec("direction")
        m = p.transform("to_world")
        if m is not None:
            if direction is not None:
                raise p.err("direction", "give either direction or to_world (Mitsuba refuses "
                                         "both)")  # fmt: skip
            # Mitsuba uses to_world's image of +z as is (not normalised): a unit one only
            z = m[:3, 2]
            if not abs(float(np.linalg.norm(z)) - 1.0) < 1e-6:
                raise p.err("to_world", "a to_world that scales the light's +z axis is not "
                                        "supported (Mitsuba does not normalise it)")  # fmt: skip
            direction = z.tolist()
        direction = direction or list(DEFAULTS["directional.direction"])
        if not np.linalg.norm(direction) > 0:
            raise p.err("direction", "expected a nonzero vector")
        d = {"type": "directional", "direction": _unit(direction),
             "irradiance": p.color("irradiance", [1.0] * 3, emission=True)}  # fmt: skip
    elif t == "spot":
        m = p.transform("to_world")
        m = np.eye(4) if m is None else m
        lin = m[:3, :3]
        s2 = float(np.mean(np.sum(lin * lin, 0)))
        if not np.allclose(lin.T @ lin, s2 * np.eye(3), rtol=1e-6, atol=1e-9 * s2):
            raise p.err("to_world", "a spot light's to_world must be a rotation, uniform scale "
                                    "and translation (the cone would not be circular)")  # fmt: skip
        tex = _light_texture(p, "texture", lin) if "texture" in obj.props else None
        cutoff = p.float("cutoff_angle", DEFAULTS["spot.cutoff_angle"])
        beam = p.float("beam_width", cutoff * DEFAULTS["spot.beam_width_fraction"])
        if not 0 < cutoff <= 180:
            raise p.err("cutoff_angle", f"expected degrees in (0, 180], got {cutoff}")
        if not 0 <= beam <= cutoff:
            raise p.err("beam_width", f"expected degrees in [0, cutoff_angle], got {beam}")
        d = {"type": "spot", "position": m[:3, 3].tolist(), "direction": _unit(lin[:, 2]),
             "intensity": p.color("intensity", [1.0] * 3, emission=True),
             "cutoff_angle": cutoff, "beam_width": beam}  # fmt: skip
        if tex is not None:  # the texture's orientation: to_world's +y (Mitsuba's look_at up)
            d.update(texture=tex, up=_unit(lin[:, 1]))
    elif t == "projector":
        d = _projector(p)
    elif t == "sunsky":
        d = _sunsky(p)
    else:
        raise ValueError(f"{obj.where}: emitter plugin {t!r} is not supported "
                         "(area, point, constant, envmap, directional, spot, "
                         "projector, sunsky)")  # fmt: skip
    p.done()
    _name_by_id(d, obj.id)
    desc["emitters"].append(d)


def _sunsky(p: _Params) -> dict:
    """A ``sunsky``: Mitsuba's parameters and defaults (``sun_direction`` or the location /
    time ones, not both), each checked here so that a bad value names its line; ``to_world``
    a rotation (its translation ignored); ``albedo`` a number or colour, not a texture."""
    from jaxgfx.render.scene._sunsky import check_time
    from jaxgfx.render.sunsky import SUNSKY_DEFAULTS as D
    from jaxgfx.render.sunsky import TIME_KEYS

    d = {"type": "sunsky"}
    m = p.transform("to_world")
    if m is not None:
        if not np.allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-6):
            raise p.err("to_world", "a sunsky's to_world must be a rotation (no scale or "
                                    "shear)")  # fmt: skip
        if not np.allclose(m[:3, :3], np.eye(3), rtol=0, atol=1e-12):
            d["to_world"] = m[:3, :3].tolist()
    sun = p.vec("sun_direction")
    when = {k: (p.int(k) if k in ("year", "month", "day") else p.float(k)) for k in TIME_KEYS
            if k in p.obj.props}  # fmt: skip
    if sun is not None:
        if when:
            raise p.err("sun_direction", f"give either sun_direction or the location / time "
                                         f"parameters {sorted(when)}, not both (Mitsuba "
                                         "refuses both)")  # fmt: skip
        if not (np.all(np.isfinite(sun)) and np.linalg.norm(sun) > 0):
            raise p.err("sun_direction", f"expected a finite nonzero vector, got {sun}")
        d["sun_direction"] = sun
    else:
        d.update(check_time(when, p.err))
    for k, lo, hi in (("turbidity", 1.0, 10.0), ("sun_scale", 0.0, math.inf),
                      ("sky_scale", 0.0, math.inf)):  # fmt: skip
        v = p.float(k, D[k])
        if not lo <= v <= hi:
            raise p.err(k, f"expected a number in [{lo}, {hi}], got {v}")
        d[k] = v
    ap = p.float("sun_aperture", D["sun_aperture"])
    if not 0.0 < ap < 180.0:
        raise p.err("sun_aperture", f"expected degrees in (0, 180), got {ap}")
    alb = p.color("albedo", [D["albedo"]] * 3)
    if not all(0.0 <= a <= 1.0 for a in alb):
        raise p.err("albedo", f"expected values in [0, 1], got {alb}")
    d.update(sun_aperture=ap, albedo=alb, complex_sun=p.bool("complex_sun", D["complex_sun"]))
    return d


def _light_texture(p: _Params, name, lin) -> dict:
    """The bitmap description of a spot light's projected ``texture`` (Mitsuba refuses a
    constant one); ``to_world`` must keep the image unmirrored (``det > 0``)."""
    tex = p.color(name, texture=True)
    if not isinstance(tex, dict) or tex.get("type") != "bitmap":
        raise p.err(name, "expected a bitmap texture (Mitsuba refuses a constant one)")
    if not np.linalg.det(lin) > 0:
        raise p.err("to_world", "a mirroring to_world (det < 0) is not supported with a "
                                "projected texture")  # fmt: skip
    return tex


def _projector(p: _Params) -> dict:
    """A ``projector``: rotation and translation of ``to_world`` as ``position`` /
    ``direction`` / ``up`` (a uniform scale ``s`` of it multiplies Mitsuba's emitted light by
    ``s``, folded into ``scale``); ``fov`` / ``focal_length`` / ``fov_axis`` as the perspective
    sensor's, with the texture's resolution as the image (a constant: 1 x 1)."""
    m = p.transform("to_world")
    m = np.eye(4) if m is None else m
    if not np.allclose(m[3], [0, 0, 0, 1]):
        raise p.err("to_world", "expected an affine transform")
    lin = m[:3, :3]
    s2 = float(np.mean(np.sum(lin * lin, 0)))
    if not (s2 > 0 and np.allclose(lin.T @ lin, s2 * np.eye(3), rtol=1e-6, atol=1e-9 * s2)):
        raise p.err("to_world", "a projector's to_world must be a rotation, uniform scale and "
                                "translation")  # fmt: skip
    if not np.linalg.det(lin) > 0:
        raise p.err("to_world", "a mirroring to_world (det < 0) is not supported")
    irr = p.color("irradiance", [1.0] * 3, emission=True, texture=True)
    width = height = 1
    if isinstance(irr, dict):
        if irr.get("type") != "bitmap":
            raise p.err("irradiance", f"expected a bitmap texture or a colour, got "
                                      f"{irr.get('type')!r}")  # fmt: skip
        from jaxgfx import io

        try:
            height, width = io.read_any(irr["file"]).shape[:2]
        except (ValueError, OSError) as e:
            raise p.err("irradiance", f"cannot read {irr['file']!r}: {e}") from None
    fov, axis = _fov_x_or_y(p, width, height)
    return {"type": "projector", "position": m[:3, 3].tolist(), "direction": _unit(lin[:, 2]),
            "up": _unit(lin[:, 1]), "fov": fov, "fov_axis": axis, "irradiance": irr,
            "scale": p.float("scale", 1.0) * math.sqrt(s2)}  # fmt: skip


def _unit(v) -> list:
    v = np.asarray(v, np.float64)
    return (v / np.linalg.norm(v)).tolist()


def _fov_x_or_y(p: _Params, width, height):
    aspect = width / height
    fov = p.float("fov")
    if fov is None:
        fl = p.string("focal_length", "50mm")
        mt = re.fullmatch(r"\s*([0-9.]+)\s*(mm)?\s*", fl)
        if mt is None or not float(mt.group(1)) > 0:
            raise p.err("focal_length", f"expected e.g. '50mm', got {fl!r}")
        fov = 2 * math.degrees(math.atan(math.hypot(36.0, 24.0) / (2 * float(mt.group(1)))))
        axis = "diagonal"
    else:
        axis = p.string("fov_axis", "x", ("x", "y", "diagonal", "smaller", "larger"))
    if not 0 < fov < 180:
        raise p.err("fov", f"expected 0 < fov < 180, got {fov}")
    if axis == "smaller":
        axis = "y" if aspect > 1 else "x"
    elif axis == "larger":
        axis = "x" if aspect > 1 else "y"
    if axis == "diagonal":
        w = 2 * math.tan(math.radians(fov) / 2) / math.sqrt(1 + 1 / aspect**2)
        return 2 * math.degrees(math.atan(w / 2)), "x"
    return fov, axis


def _sensor(obj: _Obj, doc, ctx, size=None) -> dict:
    """``(camera description, film, spp)`` of a ``<sensor>``. ``size``: ``(width, height)``
    of a sub-sensor of a ``batch`` (which sets its film's size, as Mitsuba's batch does; its
    own film, sampler and filter are read and ignored)."""
    p = _Params(obj, doc)
    ok = ("perspective", "thinlens", "orthographic", "radiancemeter", "irradiancemeter", "batch",
          "distant")  # fmt: skip
    if obj.type not in ok or (size is not None and obj.type not in ok[:3]):
        ok = ok if size is None else ok[:3]
        raise ValueError(f"{obj.where}: sensor plugin {obj.type!r} is not supported"
                         f"{' in a batch' if size else ''} ({', '.join(ok)})")  # fmt: skip
    films = [c for c in obj.children if c.tag == "film"]
    samplers = [c for c in obj.children if c.tag == "sampler"]
    for c in obj.children:
        if c.tag not in ("film", "sampler") and not (obj.type == "batch" and c.tag == "sensor"):
            raise ValueError(f"{c.node.at}: {obj.where}: nested <{c.tag}> is not supported")
    width, height, film = DEFAULTS["film.width"], DEFAULTS["film.height"], {}
    if films:
        fo = films[0]
        fp = _Params(fo, doc)
        if fo.type != "hdrfilm":
            raise ValueError(f"{fo.where}: film plugin {fo.type!r} is not supported (hdrfilm)")
        width, height = fp.int("width", 768), fp.int("height", 576)
        if width < 1 or height < 1:
            raise fp.err("width", f"expected positive width and height, got {width}x{height}")
        fp.string("pixel_format", "rgb", ("rgb", "rgba", "luminance", "luminance_alpha"))
        fp.string("component_format", "float16", ("float16", "float32", "uint32"))
        fp.string("file_format", "openexr", ("openexr", "exr", "rgbe", "pfm"))
        fp.bool("sample_border")  # jaxgfx always samples the border (see the filter notes)
        rfs = [c for c in fo.children if c.tag == "rfilter"]
        rf = rfs[0] if rfs else None
        if rf is None or rf.type == "gaussian":
            stddev = 0.5
            if rf is not None:
                rp = _Params(rf, doc)
                stddev = rp.float("stddev", 0.5, positive=True)
                rp.done()
            film = {"filter": "gaussian", "stddev": stddev, "radius": 4 * stddev}
        elif rf.type == "box":
            _Params(rf, doc).done()
            film = {"filter": "box"}
        elif rf.type == "tent":
            rp = _Params(rf, doc)
            film = {"filter": "tent", "radius": rp.float("radius", DEFAULTS["tent.radius"],
                                                         positive=True)}  # fmt: skip
            rp.done()
        elif rf.type == "mitchell":
            rp = _Params(rf, doc)
            film = {"filter": "mitchell", "B": rp.float("B", DEFAULTS["mitchell.B"]),
                    "C": rp.float("C", DEFAULTS["mitchell.C"])}  # fmt: skip
            rp.done()
        elif rf.type == "catmullrom":
            _Params(rf, doc).done()
            film = {"filter": "catmullrom"}
        elif rf.type == "lanczos":
            rp = _Params(rf, doc)
            lobes = rp.int("lobes", DEFAULTS["lanczos.lobes"])
            if lobes < 1:
                raise rp.err("lobes", f"expected a positive integer, got {lobes}")
            film = {"filter": "lanczos", "lobes": lobes}
            rp.done()
        else:
            raise ValueError(f"{rf.where}: reconstruction filter {rf.type!r} is not supported "
                             "(box, gaussian, tent, mitchell, catmullrom, lanczos)")  # fmt: skip
        fp.done(children_ok=len(rfs))
        if len(rfs) > 1:
            raise ValueError(f"{fo.where}: expected at most one <rfilter>")
    spp = None
    if samplers:
        so = samplers[0]
        sp = _Params(so, doc)
        ok = ("independent", "stratified", "multijitter", "orthogonal", "ldsampler")
        if so.type not in ok:
            raise ValueError(f"{so.where}: sampler plugin {so.type!r} is not supported {ok}")
        spp = sp.int("sample_count", 4)
        sp.int("seed")
        if so.type in ("stratified", "multijitter", "orthogonal"):
            sp.bool("jitter")
        sp.done()
        if spp < 1:
            raise sp.err("sample_count", f"expected a positive integer, got {spp}")
    if obj.type == "batch":
        return _batch(p, obj, doc, ctx, films, samplers, width, height, film, spp)
    if size is not None:
        width, height = size
    if obj.type in ("radiancemeter", "irradiancemeter"):
        return _meter(p, obj, films, samplers, width, height, film, spp)
    if obj.type == "distant":
        return _distant(p, obj, doc, ctx, films, samplers, width, height, film, spp)
    if obj.type == "orthographic":
        return _orthographic(p, obj, ctx, films, samplers, width, height, film, spp)
    fov, axis = _fov_x_or_y(p, width, height)
    m = p.transform("to_world")
    m = np.eye(4) if m is None else m
    r = m[:3, :3]
    if not (np.allclose(r.T @ r, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0):
        raise p.err("to_world", "the camera's to_world must be a rotation and translation "
                                "(no scale, shear or mirroring)")  # fmt: skip
    near, far = _clip_planes(p)
    lens = None
    if obj.type == "thinlens":  # Mitsuba's thinlens has no principal point offset
        lens = _thin_lens(p, far)
    else:
        for name in ("principal_point_offset_x", "principal_point_offset_y"):
            if p.float(name, 0.0) != 0.0:
                raise p.err(name, "an off-centre principal point is not supported")
    if len(films) > 1 or len(samplers) > 1:
        raise ValueError(f"{obj.where}: expected at most one <film> and one <sampler>")
    p.done(children_ok=len(obj.children))
    o = m[:3, 3]
    cam = {"origin": o.tolist(), "target": (o + r[:, 2]).tolist(), "up": r[:, 1].tolist(),
           "fov": fov, "fov_axis": axis, "width": width, "height": height}  # fmt: skip
    tx = math.tan(math.radians(fov) / 2)
    tx, ty = (tx, tx * height / width) if axis == "x" else (tx * width / height, tx)
    # how far from `o` a camera ray may be while in front of the near plane (z < near_clip in
    # camera space, where Mitsuba clips): near k on a pinhole ray; a lens ray from the lens
    # point a (|a| <= A) towards the focus point is a (1 - z/f) + z (s_x, s_y) off the axis at
    # depth z, so at most A max(1, |1 - near/f|) further
    reach = near * math.sqrt(1 + tx * tx + ty * ty)
    if lens is not None:
        cam["aperture_radius"], cam["focus_distance"] = lens
        reach += lens[0] * max(1.0, abs(1.0 - near / lens[1]))
    ctx.setdefault("clip", []).append((o, near, far, reach, obj))
    return cam, film, spp


def _batch(p: _Params, obj: _Obj, doc, ctx, films, samplers, width, height, film, spp):
    """Mitsuba's ``batch`` sensor -> ``{type: batch, cameras: [...]}``: its nested perspective,
    thin-lens and orthographic sensors in document order, each ``width / N`` x ``height`` (the
    batch's film; a width that ``N`` does not divide is refused, as Mitsuba refuses it), with
    the batch's film, filter and sampler."""
    # the nested sensors in document order: unnamed ones are children, named ones properties
    pos = {id(n): i for i, n in enumerate(obj.node.children)}
    found = [(c.node, c) for c in obj.children if c.tag == "sensor"]
    for q in obj.props.values():
        if q.kind == "object" and q.value.tag == "sensor":
            q.used = True
            found.append((q.node, q.value))
    subs = [c for _, c in sorted(found, key=lambda nc: pos.get(id(nc[0]), len(pos)))]
    if not subs:
        raise ValueError(f"{obj.where}: a batch sensor needs at least one nested <sensor>")
    if width % len(subs):
        raise ValueError(f"{(films[0] if films else obj).where}: a batch of {len(subs)} sensors "
                         f"needs a film width divisible by {len(subs)}, got {width}")  # fmt: skip
    if len(films) > 1 or len(samplers) > 1:
        raise ValueError(f"{obj.where}: expected at most one <film> and one <sampler>")
    cams = [_sensor(c, doc, ctx, size=(width // len(subs), height))[0] for c in subs]
    p.done(children_ok=len(obj.children))
    return {"type": "batch", "cameras": cams}, film, spp


def _one_pixel_film(obj, films, samplers, width, height, what):
    """Refuse a film other than 1 x 1 for ``what`` (a meter, a distant sensor) and more than
    one film or sampler, naming the film's (or the sensor's) file and line."""
    if (width, height) != (1, 1):
        raise ValueError(f"{(films[0] if films else obj).where}: {what} needs a 1 x 1 "
                         f"film, got {width} x {height}")  # fmt: skip
    if len(films) > 1 or len(samplers) > 1:
        raise ValueError(f"{obj.where}: expected at most one <film> and one <sampler>")


def _unit_z(p: _Params, m, what):
    """The +z axis of the sensor's ``to_world`` ``m`` (a list), which must be a unit vector
    (Mitsuba does not normalise it; ``what`` names the sensor in the error)."""
    z = m[:3, 2]
    if not abs(float(np.linalg.norm(z)) - 1.0) < 1e-6:
        raise p.err("to_world", f"a to_world that scales the {what}'s +z axis is not "
                                "supported (Mitsuba does not normalise it)")  # fmt: skip
    return z.tolist()


def _meter(p: _Params, obj, films, samplers, width, height, film, spp):
    """Mitsuba's ``radiancemeter`` (``origin`` + ``direction``, or ``to_world``: its origin
    and +z, which must be a unit vector) and ``irradiancemeter`` (nested in a shape, which
    :func:`_shape` gives it) -> ``{type: radiancemeter | irradiancemeter, ...}``; a 1 x 1 film
    (Mitsuba refuses others for the radiance meter)."""
    _one_pixel_film(obj, films, samplers, width, height, f"a {obj.type}")
    if obj.type == "irradiancemeter":
        if "to_world" in obj.props:
            raise p.err("to_world", "an irradiancemeter takes its shape's transform (as in "
                                    "Mitsuba)")  # fmt: skip
        p.done(children_ok=len(obj.children))
        return {"type": "irradiancemeter"}, film, spp
    m = p.transform("to_world")
    origin, direction = p.vec("origin"), p.vec("direction")
    if m is not None:  # to_world wins over origin / direction (as in Mitsuba)
        origin, direction = m[:3, 3].tolist(), _unit_z(p, m, "meter")
    elif (origin is None) != (direction is None):
        raise p.err("origin" if origin is None else "direction",
                    "give both origin and direction (or to_world)")  # fmt: skip
    origin = [0.0, 0.0, 0.0] if origin is None else list(origin)
    direction = [0.0, 0.0, 1.0] if direction is None else list(direction)
    if not np.linalg.norm(direction) > 0:
        raise p.err("direction", "expected a nonzero vector")
    p.done(children_ok=len(obj.children))
    return {"type": "radiancemeter", "origin": origin, "direction": _unit(direction)}, film, spp


def _distant(p: _Params, obj: _Obj, doc, ctx, films, samplers, width, height, film, spp):
    """Mitsuba's ``distant`` sensor -> ``{type: distant, direction, target, distance,
    radius?}``: ``direction`` (normalised) or ``to_world`` (its +z, which must be a unit
    vector; both refused, as in Mitsuba; neither: +z); ``target`` a ``<point>``, a nested
    shape (sphere, rectangle or mesh: only sampled, not scene geometry, as in Mitsuba) or none
    (the disk across the scene's bounding sphere). The ray origins' ``distance`` (twice the
    bounding sphere's radius, as Mitsuba's) and the disk are set by :func:`read_xml` once
    every shape is read (:func:`_distant_bounds`). A 1 x 1 film."""
    _one_pixel_film(obj, films, samplers, width, height, "a distant sensor")
    m, direction = p.transform("to_world"), p.vec("direction")
    if m is not None and direction is not None:
        raise p.err("direction", "give direction or to_world, not both (as Mitsuba)")
    if m is not None:
        direction = _unit_z(p, m, "sensor")
    direction = [0.0, 0.0, 1.0] if direction is None else list(direction)
    if not np.linalg.norm(direction) > 0:
        raise p.err("direction", "expected a nonzero vector")
    cam = {"type": "distant", "direction": _unit(direction)}
    tp = obj.props.get("target")
    if tp is not None and tp.kind == "object":
        tp.used = True
        if tp.value.tag != "shape":
            raise p.err("target", f"expected a point or a shape, got {tp.value.where}")
        scratch: dict = {"materials": {}, "shapes": [], "emitters": []}
        _shape(tp.value, doc, scratch, {"bboxes": []})
        sd = scratch["shapes"][0] if scratch["shapes"] else None
        if sd is None or sd["type"] not in ("sphere", "rectangle", "mesh") or scratch["emitters"]:
            raise ValueError(f"{tp.value.where}: a distant sensor's target is a sphere, "
                             "rectangle or mesh without an emitter")  # fmt: skip
        cam["target"] = {k: v for k, v in sd.items() if k not in ("id", "material")}
    elif tp is not None:
        cam["target"] = p.vec("target")
    p.done(children_ok=len(obj.children))
    ctx["distant"] = cam
    return cam, film, spp


def _distant_bounds(ctx):
    """Complete the distant sensor's description from the scene's bounding sphere (Mitsuba's
    ``scene.bbox().bounding_sphere()``, its radius enlarged by 1e-4 relative): rays start
    ``2 R`` back from a point or shape target; without a target they start on the disk of
    radius ``R`` about the centre, ``R`` back (so they cross the whole sphere)."""
    cam = ctx["distant"]
    lo = np.min([b[0] for b, _ in ctx["bboxes"]], axis=0)
    hi = np.max([b[1] for b, _ in ctx["bboxes"]], axis=0)
    r = max(0.5 * float(np.linalg.norm(hi - lo)) * (1 + 1e-4), 1e-4)
    if "target" in cam:
        cam["distance"] = 2 * r
    else:
        cam.update(target=(0.5 * (lo + hi)).tolist(), distance=r, radius=r)


def _thin_lens(p: _Params, far):
    """``(aperture_radius, focus_distance)`` of Mitsuba's ``thinlens`` sensor: the radius is
    required (as in Mitsuba) and must be >= 0; the focus distance defaults to ``far_clip`` (as
    in Mitsuba) and must be > 0 (Mitsuba accepts any; jaxgfx refuses what is not a thin lens)."""
    a = p.float("aperture_radius")
    if a is None:
        raise ValueError(f"{p.obj.where}: parameter 'aperture_radius' is required "
                         "(the lens radius in world units)")  # fmt: skip
    if not (math.isfinite(a) and a >= 0):
        raise p.err("aperture_radius", f"expected a finite number >= 0, got {a}")
    f = p.float("focus_distance", far)
    if not (math.isfinite(f) and f > 0):
        raise p.err("focus_distance", f"expected a finite number > 0, got {f}")
    return a, f


def _clip_planes(p: _Params):
    near = p.float("near_clip", DEFAULTS["near_clip"], positive=True)
    far = p.float("far_clip", DEFAULTS["far_clip"])
    if not far > near:
        raise p.err("far_clip", f"expected far_clip > near_clip, got {far} <= {near}")
    return near, far


def _orthographic(p: _Params, obj: _Obj, ctx, films, samplers, width, height, film, spp):
    """Mitsuba's ``orthographic`` sensor -> a :class:`MatrixCamera` description
    (:func:`orthographic_view_proj_inverse`): rays start on the near plane, as Mitsuba's, so
    ``near_clip`` is reproduced exactly; ``far_clip`` is checked like the perspective one's."""
    m = p.transform("to_world")
    m = np.eye(4) if m is None else m
    a = m[:3, :3]
    if not abs(np.linalg.det(a)) > 1e-12 * max(float(np.abs(a).max()), 1e-100) ** 3:
        raise p.err("to_world", "the orthographic sensor's to_world must be invertible "
                                "(a degenerate sensor plane or direction)")  # fmt: skip
    near, far = _clip_planes(p)
    if len(films) > 1 or len(samplers) > 1:
        raise ValueError(f"{obj.where}: expected at most one <film> and one <sampler>")
    p.done(children_ok=len(obj.children))
    vpi = orthographic_view_proj_inverse(m, near, width, height)
    ctx.setdefault("clip_ortho", []).append((m, near, far, obj))
    return {"view_proj_inverse": vpi.tolist(), "width": width, "height": height}, film, spp


def _check_clip_ortho(ctx):
    """Refuse geometry beyond Mitsuba's orthographic ``far_clip``: its rays start at the near
    plane point and end after ``far_clip - near_clip`` along the unit direction; each bounding
    box corner's distance along the ray through it (an affine function of the point, so the
    corners bound it) must not exceed that."""
    for m, near, far, sensor in ctx["clip_ortho"]:  # one per sensor (several in a batch)
        a = m[:3, :3]
        d = a[:, 2] / np.linalg.norm(a[:, 2])
        basis = np.stack([a[:, 0], a[:, 1], d], 1)
        o = a @ np.array([0.0, 0.0, near]) + m[:3, 3]
        for (lo, hi), obj in ctx["bboxes"]:
            corners = np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1)
            t = np.linalg.solve(basis, corners - o[:, None])[2]
            if float(t.max()) > far - near:
                raise ValueError(
                    f"{sensor.where}: far_clip={far}: {obj.where} reaches beyond it (Mitsuba "
                    "clips it, jaxgfx does not)"
                )


def _aov(p: _Params, obj):
    """Mitsuba's ``aov`` with ``aovs="name:type,..."`` of the types jaxgfx's
    :class:`~jaxgfx.render.integrators.AOVIntegrator` computes (``albedo``, ``depth``,
    ``position``, ``geo_normal``, ``sh_normal``), channels in the given order; nested
    integrators (Mitsuba's image channels before the AOVs) are refused."""
    from jaxgfx.render.integrators.aov import AOV_TYPES

    if obj.children:
        raise ValueError(f"{obj.children[0].node.at}: {obj.where}: a nested integrator inside "
                         "'aov' is not supported (AOVs only)")  # fmt: skip
    spec = p.string("aovs", "")
    types = []
    for item in [x.strip() for x in spec.split(",") if x.strip()]:
        name, _, kind = item.partition(":")
        if not name or kind not in AOV_TYPES:
            raise p.err("aovs", f"{item!r}: expected name:type with a type jaxgfx computes "
                                f"({', '.join(AOV_TYPES)})")  # fmt: skip
        types.append(kind)
    if not types:
        raise p.err("aovs", "expected at least one name:type")
    p.done()
    return "aov", None, 5, False, {"aovs": tuple(types)}


_PROJECTIVE = ("direct_projective", "prb_projective")


def _projective(p: _Params, obj):
    """Mitsuba's projective-sampling integrators as jaxgfx's ``direct`` / ``path`` with edge
    sampling (``visibility="edge"``, reverse mode ``adjoint="ad"``): the same images, and
    boundary (visibility) terms in the derivatives. ``max_depth`` / ``rr_depth`` as Mitsuba's
    ``ADIntegrator`` reads them (``prb_projective``: default 6 and 5; ``direct_projective``
    reads and then ignores them: depth 2); ``sppc`` / ``sppp`` / ``sppi`` (integers >= 0),
    ``guiding`` (none, grid, octree), ``guiding_proj``, ``guiding_rounds`` (>= 1) and
    ``project_seed`` (both, bsdf, emitter) are checked and have no jaxgfx meaning: edge
    sampling draws the silhouettes it knows directly (no guiding), with the render's ``spp``
    passes of boundary samples (no separate counts)."""
    hide = p.bool("hide_emitters", False)
    if hide:
        raise p.err("hide_emitters", "hidden emitters are supported by 'ptracer' only")
    depth = p.int("max_depth", 6)
    rr = p.int("rr_depth", 5)
    low = 0 if obj.type == "direct_projective" else 1  # Mitsuba ignores that one's max_depth
    if not (depth == -1 or depth >= low) or rr < 1:
        raise p.err("max_depth", f"expected max_depth -1 or >= {low} and rr_depth >= 1, got "
                                 f"{depth}, {rr}")  # fmt: skip
    for name in ("sppc", "sppp", "sppi"):
        v = p.int(name)
        if v is not None and v < 0:
            raise p.err(name, f"expected a sample count >= 0, got {v}")
    p.string("guiding", "octree", ("none", "grid", "octree"))
    p.bool("guiding_proj", True)
    rounds = p.int("guiding_rounds", 1)
    if rounds < 1:
        raise p.err("guiding_rounds", f"expected a positive integer, got {rounds}")
    p.string("project_seed", "both", ("both", "bsdf", "emitter"))
    p.done()
    opts = {"visibility": "edge"}
    if obj.type == "direct_projective":  # Mitsuba overrides both: a path of depth 2
        return "direct", 2, 5, False, opts
    return "path", (None if depth == -1 else depth), rr, False, opts


def _check_projective(integ: _Obj, sensor: _Obj, desc: dict, ctx: dict) -> None:
    """What jaxgfx's edge sampling needs of a scene rendered by a projective integrator: a
    perspective sensor (Mitsuba's projective integrators refuse the others too), the box
    rfilter (edge sampling's pixel integral; Mitsuba's default is gaussian) and no curves
    (their silhouettes are not edge-sampled; Mitsuba projects them)."""
    if sensor.type != "perspective":
        raise ValueError(f"{sensor.where}: {integ.type} needs a perspective sensor (as in "
                         f"Mitsuba), got {sensor.type!r}")  # fmt: skip
    rf = (desc.get("film") or {}).get("filter", "gaussian")
    if rf != "box":
        raise ValueError(f"{integ.where}: {integ.type} needs <rfilter type=\"box\"/> in the "
                         f"film (jaxgfx's edge sampling integrates box pixels), got {rf!r}")
    for _, o in ctx["bboxes"]:
        if o.type in ("linearcurve", "bsplinecurve"):
            raise ValueError(f"{o.where}: {integ.where}: {integ.type} with a {o.type} is not "
                             "supported (jaxgfx's edge sampling does not sample curve "
                             "silhouettes; use prb / path for material gradients)")  # fmt: skip


def _integrator(obj: _Obj, doc):
    p = _Params(obj, doc)
    if obj.type == "moment":  # its first channels are the nested integrator's image
        if len(obj.children) != 1 or obj.children[0].tag != "integrator":
            raise ValueError(f"{obj.where}: expected exactly one nested <integrator>")
        p.done(children_ok=1)
        return _integrator(obj.children[0], doc)
    if obj.type == "aov":
        return _aov(p, obj)
    if obj.type in _PROJECTIVE:
        return _projective(p, obj)
    if obj.type not in ("path", "direct", "ptracer", "prb", "prb_basic"):
        raise ValueError(f"{obj.where}: integrator plugin {obj.type!r} is not supported "
                         "(path, direct, ptracer, prb, prb_basic, direct_projective, "
                         "prb_projective, moment, aov)")  # fmt: skip
    hide = p.bool("hide_emitters", False)
    if hide and obj.type != "ptracer":
        raise p.err("hide_emitters", "hidden emitters are supported by 'ptracer' only")
    opts = {}
    if obj.type in ("path", "ptracer", "prb", "prb_basic"):
        # Mitsuba's differentiable integrators default to max_depth 6, path / ptracer to -1
        depth = p.int("max_depth", 6 if obj.type.startswith("prb") else -1)
        rr = p.int("rr_depth", 5)
        if depth == 0 or depth < -1 or rr < 1:
            raise p.err("max_depth", f"expected max_depth -1 or >= 1 and rr_depth >= 1, got "
                                     f"{depth}, {rr}")  # fmt: skip
        if obj.type == "ptracer":
            p.int("samples_per_pass", -1)  # a work split: the same image
        p.done()
        depth = None if depth == -1 else depth
        if obj.type.startswith("prb"):  # path replay backpropagation: jaxgfx's replay adjoint
            opts["adjoint"] = "replay"
            if obj.type == "prb_basic":  # BSDF sampling only, no Russian roulette
                opts["strategy"] = "bsdf"
                rr = depth if depth is not None else rr
        return ("ptracer" if obj.type == "ptracer" else "path"), depth, rr, hide, opts
    for name in ("emitter_samples", "bsdf_samples"):
        if p.int(name, 1) != 1:
            raise p.err(name, "only 1 sample per strategy is supported (jaxgfx direct MIS)")
    p.done()
    return "direct", 2, 5, False, opts


def _point_triangles_distance(o, tri) -> float:
    """Smallest distance from the point ``o`` to the triangles ``tri`` (F, 3, 3)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    ok = nn > 0
    # the foot of the perpendicular, when inside the triangle (barycentric signs)
    t = np.where(ok, np.einsum("ij,ij->i", o - a, n) / np.where(ok, nn, 1.0), 0.0)
    q = o - t[:, None] * n
    inside = ok.copy()
    for p0, p1 in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(p1 - p0, q - p0), n) >= 0
    d = np.where(inside, np.abs(t) * np.sqrt(nn), np.inf)
    for p0, p1 in ((a, b), (b, c), (c, a)):  # else the nearest point of an edge
        e = p1 - p0
        ee = np.einsum("ij,ij->i", e, e)
        s = np.clip(np.einsum("ij,ij->i", o - p0, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
        d = np.minimum(d, np.linalg.norm(o - (p0 + s[:, None] * e), axis=1))
    return float(d.min())


def _check_clip(ctx):
    if "clip_ortho" in ctx:
        _check_clip_ortho(ctx)
    if "clip" not in ctx:
        return
    for clip in ctx["clip"]:  # one per sensor (several in a batch)
        _check_clip_one(ctx, *clip)


def _check_clip_one(ctx, o, near, far, reach, sensor):
    for bbox, obj in ctx["bboxes"]:
        lo, hi = bbox
        dmin = float(np.linalg.norm(np.maximum(0.0, np.maximum(lo - o, o - hi))))
        dmax = float(np.linalg.norm(np.maximum(np.abs(lo - o), np.abs(hi - o))))
        if dmin < reach and id(obj) in ctx.get("triangles", {}):  # a mesh: its own distance
            dmin = _point_triangles_distance(o, ctx["triangles"][id(obj)])
        if dmin < reach:
            raise ValueError(
                f"{sensor.where}: near_clip={near}: {obj.where} comes closer than "
                f"{reach:.4g} to the camera, where Mitsuba may clip it (jaxgfx does not clip)"
            )
        if dmax > far:
            raise ValueError(
                f"{sensor.where}: far_clip={far}: {obj.where} reaches beyond it (Mitsuba clips "
                "it, jaxgfx does not)"
            )


def read_xml(path, **params) -> XMLScene:
    """Translate a Mitsuba 3 XML scene file into a jaxgfx :class:`XMLScene`.

    ``params`` replace ``$name`` in attribute values and override ``<default name value>``
    (like ``mitsuba.load_file(path, name=value)``); a parameter that no ``<default>`` declares
    and no attribute uses is an error. Relative file names are resolved as Mitsuba does: the
    ``<path>`` folders (relative to the XML file that names them, latest first), then the
    folder of the top-level file. Raises ``ValueError`` naming ``file:line`` and the object
    for anything the translation cannot reproduce.

    Example: ``read_xml("cbox.xml", spp=16).desc["camera"]["fov"]``.
    """
    path = os.fspath(path)
    doc = _Doc(path, params)
    objs: list[_Obj] = []
    _read_file(doc, path, objs)
    unused = sorted(doc.given - doc.used)
    if unused:
        raise ValueError(f"{path}: parameter(s) {unused} are neither declared by a <default> "
                         "nor used as $name in the scene")  # fmt: skip
    desc: dict = {"materials": {}, "shapes": [], "emitters": []}
    ctx: dict = {"bboxes": []}
    sensors = [o for o in objs if o.tag == "sensor"]
    sensors += [c for o in objs if o.tag == "shape" for c in o.children if c.tag == "sensor"]
    integ = [o for o in objs if o.tag == "integrator"]
    if not sensors:
        raise ValueError(f"{path}: the scene has no <sensor> (jaxgfx needs a camera)")
    if len(sensors) > 1:
        raise ValueError(f"{sensors[1].where}: only one sensor is supported")
    if len(integ) > 1:
        raise ValueError(f"{integ[1].where}: only one integrator is supported")
    cam, film, spp = _sensor(sensors[0], doc, ctx)
    desc["camera"] = cam
    if film:
        desc["film"] = film
    integrator, depth, rr, hide, opts = (_integrator(integ[0], doc) if integ else
                                         ("path", None, 5, False, {}))  # fmt: skip
    for o in objs:
        if o.tag == "shape" and o.type == "shapegroup":
            _shapegroup(o, doc, desc, ctx)
        elif o.tag == "shape" and o.type == "instance":
            _instance(o, doc, desc, ctx)
        elif o.tag == "shape":
            _shape(o, doc, desc, ctx)
        elif o.tag == "emitter":
            _emitter(o, doc, desc)
        elif o.tag == "bsdf":
            if not o.id:
                raise ValueError(f"{o.where}: a top-level <bsdf> needs an id")
            _bsdf(o, doc, desc)
        elif o.tag == "texture":
            if not o.id:
                raise ValueError(f"{o.where}: a top-level <texture> needs an id")
            _texture(o, doc)  # validated; used where referenced
        elif o.tag in ("sensor", "integrator"):
            continue
        else:
            raise ValueError(f"{o.where}: a top-level <{o.tag}> is not supported")
    if not desc["shapes"] and not any(e["type"] == "area" for e in desc["emitters"]):
        raise ValueError(f"{path}: the scene has no shapes")
    if cam.get("type") == "irradiancemeter":
        cam["shape"] = ctx["meter_shape"]
    if cam.get("type") == "distant":
        _distant_bounds(ctx)
    _check_clip(ctx)
    if not desc["emitters"]:
        del desc["emitters"]
    if opts.get("visibility"):
        _check_projective(integ[0], sensors[0], desc, ctx)
    if integrator == "aov" and "clip" in ctx:  # Mitsuba's depth: from the near plane
        nears = {float(c[1]) for c in ctx["clip"]}
        if len(nears) > 1:
            raise ValueError(f"{sensors[0].where}: an aov integrator needs one near_clip for "
                             f"every sensor of the batch, got {sorted(nears)}")  # fmt: skip
        opts["near_clip"] = nears.pop()
    return XMLScene(desc, spp, integrator, depth, rr, tuple(doc.files), hide, **opts)


# ------------------------------------------------------------------------------------------
# writing: jaxgfx description -> Mitsuba 3 XML


def _xml_attr(x) -> str:
    from xml.sax.saxutils import quoteattr

    return quoteattr(str(x))


def _num(x) -> str:
    """Shortest text that reads back to ``x`` (to its float32 value when it is one)."""
    x = float(x)
    x32 = np.float32(x)
    return str(x32) if float(x32) == x and np.isfinite(x32) else repr(x)


def _xml_object(tag, d, indent, name=None, ident=None) -> list[str]:
    from jaxgfx.render.scene.mitsuba_conventions import PLUGINS

    pad = "    " * indent
    attrs = f" type={_xml_attr(d['type'])}"
    ident = d.get("id", ident)  # a nested object's own id (an area light's <emitter>)
    if ident is not None:
        attrs += f" id={_xml_attr(ident)}"
    if name is not None:
        attrs += f" name={_xml_attr(name)}"
    body = []
    for k, v in d.items():
        if k in ("type", "id"):
            continue
        q = "    " * (indent + 1)
        if isinstance(v, dict) and v.get("type") == "rgb":
            body.append(f'{q}<rgb name={_xml_attr(k)} value="{", ".join(map(_num, v["value"]))}"/>')
        elif isinstance(v, dict) and v.get("type") == "ref":
            body.append(f"{q}<ref id={_xml_attr(v['id'])}/>")
        elif isinstance(v, dict):
            tags = [t for (t, ty) in PLUGINS if ty == v["type"]]
            if not tags:  # pragma: no cover - the exporter writes known plugins only
                raise ValueError(f"{k}: plugin {v['type']!r} has no XML tag")
            # a texture and a distant sensor's target shape are named parameters
            nested_name = k if tags[0] == "texture" or k == "target" else None
            body += _xml_object(tags[0], v, indent + 1, name=nested_name)
        elif isinstance(v, bool):
            body.append(f'{q}<boolean name={_xml_attr(k)} value="{str(v).lower()}"/>')
        elif isinstance(v, (int, np.integer)):
            body.append(f'{q}<integer name={_xml_attr(k)} value="{int(v)}"/>')
        elif isinstance(v, (float, np.floating)):
            body.append(f'{q}<float name={_xml_attr(k)} value="{_num(v)}"/>')
        elif isinstance(v, str):
            body.append(f"{q}<string name={_xml_attr(k)} value={_xml_attr(v)}/>")
        elif k in ("to_world", "to_uv"):
            m = np.asarray(v, np.float64).reshape(-1)
            body.append(f'{q}<transform name={_xml_attr(k)}><matrix value="'
                        f'{" ".join(map(_num, m))}"/></transform>')  # fmt: skip
        elif np.shape(v) == (3,):
            tag3 = "vector" if k in ("direction", "sun_direction") else "point"  # a <vector>
            body.append(f'{q}<{tag3} name={_xml_attr(k)} value="{", ".join(map(_num, v))}"/>')
        else:  # pragma: no cover - the exporter writes the kinds above only
            raise ValueError(f"{k}: cannot write {v!r} as Mitsuba XML")
    if not body:
        return [f"{pad}<{tag}{attrs}/>"]
    return [f"{pad}<{tag}{attrs}>", *body, f"{pad}</{tag}>"]


def to_xml(mitsuba_dict: dict, *, anonymous=()) -> str:
    """Mitsuba 3 XML text of a ``load_dict`` dictionary as :func:`to_mitsuba_dict` builds it
    (transforms as nested lists, ``mi=None``): each top-level entry becomes an object whose
    ``id`` is its key; ``{"type": "rgb"}`` values become ``<rgb>``, ``{"type": "ref"}``
    ``<ref>``, 4x4 ``to_world`` a ``<matrix>``, 3-vectors ``<point>``.

    Example: ``to_xml({"type": "scene", "s": {"type": "sphere", "radius": 1.0}})`` contains
    ``<shape type="sphere" id="s">``.
    """
    from jaxgfx.render.scene.mitsuba_conventions import PLUGINS

    if mitsuba_dict.get("type") != "scene":
        raise ValueError("mitsuba_dict: expected a {'type': 'scene', ...} dictionary")
    lines = ['<scene version="3.0.0">']
    for key, v in mitsuba_dict.items():
        if key == "type":
            continue
        tag = next(t for (t, ty) in PLUGINS if ty == v["type"])
        lines += _xml_object(tag, v, 1, ident=None if key in anonymous else key)
    lines.append("</scene>")
    return "\n".join(lines) + "\n"


def save_scene(
    scene,
    path,
    *,
    spp: int = 16,
    integrator: str = "path",
    max_depth: int | None = None,
    rr_depth: int = 5,
    base_dir=None,
    hide_emitters: bool = False,
) -> str:
    """Write a jaxgfx scene as a Mitsuba 3 XML file that Mitsuba loads to the same image.

    ``scene``: a description mapping or YAML path (as :func:`load_scene` takes), or a
    :class:`Scene` (converted by :func:`jaxgfx.render.scene.mitsuba.scene_to_desc`). The
    conventions are :func:`jaxgfx.render.scene.mitsuba.to_mitsuba_dict`'s (one table,
    :mod:`jaxgfx.render.scene.mitsuba_conventions`); materials become top-level ``<bsdf>``
    objects whose ``id`` is the material name (so :func:`read_xml` gives the same names back).
    Files Mitsuba needs that the description does not provide (PLYs of inline or generated
    meshes, the re-gridded environment map) are written into ``<stem>_files/`` next to
    ``path`` and referenced relatively; mesh files the description names are referenced by
    absolute path. ``spp`` -> the ``independent`` sampler, ``integrator`` / ``max_depth``
    (``None``: Mitsuba's ``-1``, unbounded) / ``rr_depth`` / ``hide_emitters`` (``ptracer``
    only) as :func:`jaxgfx.render.scene.mitsuba.mitsuba_integrator`. Returns ``path``.
    Features Mitsuba lacks raise ``NotImplementedError`` naming the field (as
    ``to_mitsuba_dict``).

    Example: ``save_scene("configs/scenes/example.yaml", "/tmp/example.xml", spp=64)``.
    """
    from jaxgfx.render.scene import mitsuba as M
    from jaxgfx.render.scene.scene import Scene

    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        raise ValueError(f"spp: expected a positive integer, got {spp!r}")
    if max_depth is None:
        integ = M.mitsuba_integrator(
            integrator, max_depth=1, rr_depth=rr_depth, hide_emitters=hide_emitters
        )
        integ["max_depth"] = 2 if integrator in ("direct", "direct_projective") else -1
    else:
        integ = M.mitsuba_integrator(
            integrator, max_depth=max_depth, rr_depth=rr_depth, hide_emitters=hide_emitters
        )
    if isinstance(scene, Scene):
        scene = M.scene_to_desc(scene)
    elif isinstance(scene, (str, os.PathLike)):
        from jaxgfx.config import read_yaml

        base_dir = base_dir or os.path.dirname(os.path.abspath(os.fspath(scene)))
        scene = read_yaml(scene)
    path = os.path.abspath(os.fspath(path))
    if not path.lower().endswith(".xml"):
        raise ValueError(f"path: expected a .xml file name, got {path!r}")
    folder = os.path.dirname(path)
    files = os.path.splitext(path)[0] + "_files"
    d = M.to_mitsuba_dict(scene, base_dir=base_dir, work_dir=files, refs=True)
    M.sensor_dict(d)["sampler"]["sample_count"] = int(spp)
    d["integrator"] = integ

    def relative(x):
        if isinstance(x, dict):
            return {k: (os.path.relpath(v, folder) if k == "filename" and
                        os.path.dirname(v) == files else relative(v))
                    for k, v in x.items()}  # fmt: skip
        return x

    # shapes and emitters without an id in the description are written without one (their
    # dictionary keys are the exporter's own), so that read_xml names them by index again
    objs = [*scene["shapes"], *(scene.get("emitters") or [])]
    named = {x.get("id") for x in objs} | {x["shape"].get("id") for x in objs if "shape" in x}
    anonymous = {k for k in d if re.fullmatch(r"(shape|emitter)_\d+_*", k) and k not in named}
    text = to_xml(relative(d), anonymous=anonymous)
    os.makedirs(folder, exist_ok=True)
    with open(path, "w") as f:
        f.write(text)
    return path
