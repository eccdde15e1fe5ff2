"""The scene description's schema: validators and the builders of cameras and shapes from their
description mappings (``ValueError`` naming the field, e.g. ``shapes[1].radius``).

Shared by :func:`jaxgfx.render.scene.load_scene` and the Mitsuba exporter, so both accept and
refuse exactly the same descriptions.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_choice, check_finite
from jaxgfx._math import safe_normalize
from jaxgfx.render.bsdf import rgb_param
from jaxgfx.render.camera import (
    BatchCamera,
    DistantSensor,
    IrradianceMeter,
    MatrixCamera,
    PerspectiveCamera,
    RadianceMeter,
    ThinLensCamera,
)
from jaxgfx.render.geometry import Rectangles, SDFShape, Spheres, TriangleMesh, sdf_from_dict
from jaxgfx.render.geometry.frame import host_basis

__all__ = [
    "SHAPE_TYPES",
    "EMITTER_TYPES",
    "SCENE_KEYS",
    "expect_keys",
    "vec",
    "num",
    "rgb",
    "envmap_image",
    "envmap_rotation",
    "build_camera",
    "rectangle_from_desc",
    "mesh_from_desc",
    "shape_from_desc",
    "MESH_SOURCES",
]

SHAPE_TYPES = ("sphere", "rectangle", "mesh", "sdf", "sdfgrid", "linearcurve",
               "bsplinecurve", "ellipsoids")  # fmt: skip
EMITTER_TYPES = ("area", "point", "constant", "envmap", "directional", "spot", "projector",
                 "directionalarea", "sunsky")  # fmt: skip
SCENE_KEYS = (("camera", "shapes"), ("materials", "emitters", "film"))
"""(required, optional) top-level keys of a scene description."""
FILM_KEYS = ("filter", "stddev", "radius", "B", "C", "lobes")
"""Optional keys of a scene's ``film`` (the filter's name and its options: ``radius`` for box
and tent, ``stddev`` and ``radius`` for gaussian, ``B``, ``C`` for mitchell, ``lobes`` for
lanczos; :func:`jaxgfx.render.film.make_filter` says which belong to which)."""


def envmap_image(ed, where, base_dir=None) -> np.ndarray:
    """The lat-long image of an ``envmap`` emitter description (``file`` relative to
    ``base_dir``, or an inline ``image``), validated to ``(H, W, >=3)``. (Its optional
    ``to_world``, a rotation, is read by :func:`envmap_rotation`.)"""
    expect_keys(ed, where, ("type",), ("file", "image", "scale", "to_world", "id"))
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


def envmap_rotation(ed, where):
    """The ``to_world`` of an ``envmap`` description as a 3x3 rotation (``None`` without one or
    for the identity): a 3x3 or 4x4 affine matrix whose linear part is orthogonal (its
    translation is ignored: the map is at infinity); a scale or shear is refused naming
    ``where.to_world``."""
    from jaxgfx.render.emitters import EnvironmentMap

    if "to_world" not in ed:
        return None
    return EnvironmentMap.check_to_world(ed["to_world"], f"{where}.to_world")


def expect_keys(d, where, required=(), optional=()):
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


def vec(x, where, n=3):
    a = as_float_array(x, where)
    check_finite(a, where)
    if a.shape != (n,):
        raise ValueError(f"{where}: expected {n} numbers, got shape {a.shape}")
    return a


def num(x, where, *, positive=False):
    a = as_float_array(x, where)
    check_finite(a, where)
    if a.shape != ():
        raise ValueError(f"{where}: expected a number, got shape {a.shape}")
    if positive and not float(a) > 0:
        raise ValueError(f"{where}: expected a positive number, got {float(a)}")
    return a


def rgb(x, where):
    a = rgb_param(x, where)
    if a.shape != (3,):
        raise ValueError(f"{where}: expected a number or an RGB triple, got shape {a.shape}")
    return a


def build_camera(d, where="camera", base_dir=None):
    """The camera of a ``camera`` description; the constructors' errors (``width: ...``) are
    prefixed with ``where`` (``camera.width: ...``). ``{type: radiancemeter, origin,
    direction}`` and ``{type: irradiancemeter, shape}`` give the 1 x 1 meters
    (:class:`~jaxgfx.render.camera.RadianceMeter`, :class:`~jaxgfx.render.camera.IrradianceMeter`;
    a mesh shape's file relative to ``base_dir``); ``{type: batch, cameras: [...]}`` a
    :class:`~jaxgfx.render.camera.BatchCamera` of image cameras of one size, side by side;
    ``{type: distant, direction, target, distance, radius?}`` a
    :class:`~jaxgfx.render.camera.DistantSensor` (``target`` a point or a shape)."""
    if not isinstance(d, Mapping):
        raise ValueError(f"{where}: expected a mapping, got {type(d).__name__}")
    try:
        return _build_camera(d, where, base_dir)
    except (ValueError, TypeError) as e:
        message = str(e)
        if message.startswith(f"{where}.") or message.startswith(f"{where}:"):
            raise
        raise type(e)(f"{where}.{message}") from None


def _build_camera(d, where, base_dir=None):
    kind = d.get("type")
    if kind == "batch":  # Mitsuba's batch sensor: image cameras side by side
        expect_keys(d, where, ("type", "cameras"))
        subs = d["cameras"]
        if not isinstance(subs, (list, tuple)) or not subs:
            raise ValueError(f"{where}.cameras: expected a non-empty list of cameras")
        cams = []
        for i, c in enumerate(subs):
            w = f"{where}.cameras.{i}"
            if not isinstance(c, Mapping):
                raise ValueError(f"{w}: expected a mapping, got {type(c).__name__}")
            if c.get("type") is not None:
                raise ValueError(f"{w}.type: a batch holds perspective, thin-lens and matrix "
                                 f"cameras, got {c.get('type')!r}")  # fmt: skip
            cams.append(build_camera(c, w))
        try:
            return BatchCamera.create(cams)
        except ValueError as e:
            raise ValueError(f"{where}.{e}") from None
    if kind == "distant":  # Mitsuba's distant sensor: a point, disk or shape target
        expect_keys(d, where, ("type", "direction", "target", "distance"), ("radius",))
        tgt, shape = d["target"], None
        if isinstance(tgt, Mapping):
            sk, shape = shape_from_desc(tgt, f"{where}.target", base_dir)
            if sk not in ("sphere", "rectangle", "mesh"):
                raise ValueError(f"{where}.target: a distant sensor's target shape is a "
                                 f"sphere, rectangle or mesh, got {sk!r}")  # fmt: skip
            tgt = None
        else:
            tgt = vec(tgt, f"{where}.target")
        radius = num(d.get("radius", 0.0), f"{where}.radius")
        return DistantSensor.create(vec(d["direction"], f"{where}.direction"), tgt,
                                    num(d["distance"], f"{where}.distance"), shape=shape,
                                    radius=radius)  # fmt: skip
    if kind is not None:  # the meters (Mitsuba's radiancemeter / irradiancemeter sensors)
        check_choice(kind, f"{where}.type",
                     ("radiancemeter", "irradiancemeter", "batch", "distant"))  # fmt: skip
        if kind == "radiancemeter":
            expect_keys(d, where, ("type", "origin", "direction"))
            return RadianceMeter.create(vec(d["origin"], f"{where}.origin"),
                                        vec(d["direction"], f"{where}.direction"))  # fmt: skip
        expect_keys(d, where, ("type", "shape"))
        sk, shape = shape_from_desc(d["shape"], f"{where}.shape", base_dir)
        if sk not in ("sphere", "rectangle", "mesh"):
            raise ValueError(f"{where}.shape: an irradiance meter needs a sphere, rectangle or "
                             f"mesh (a surface with an area), got {sk!r}")  # fmt: skip
        return IrradianceMeter(shape)
    if "view_proj_inverse" in d:
        expect_keys(d, where, ("view_proj_inverse", "width", "height"))
        return MatrixCamera.from_matrix(d["view_proj_inverse"], d["width"], d["height"])
    lens = ("aperture_radius", "focus_distance")
    if any(k in d for k in lens):  # a thin lens: both keys (ThinLensCamera)
        expect_keys(d, where, ("origin", "target", "fov", "width", "height", *lens),
                    ("up", "fov_axis"))  # fmt: skip
    else:
        expect_keys(d, where, ("origin", "target", "fov", "width", "height"), ("up", "fov_axis"))
    args = (
        vec(d["origin"], f"{where}.origin"),
        vec(d["target"], f"{where}.target"),
        vec(d.get("up", [0.0, 1.0, 0.0]), f"{where}.up"),
        num(d["fov"], f"{where}.fov"),
        d["width"],
        d["height"],
    )
    if "aperture_radius" in d:
        return ThinLensCamera.look_at(
            *args,
            aperture_radius=num(d["aperture_radius"], f"{where}.aperture_radius"),
            focus_distance=num(d["focus_distance"], f"{where}.focus_distance"),
            fov_axis=d.get("fov_axis", "x"),
        )
    return PerspectiveCamera.look_at(*args, fov_axis=d.get("fov_axis", "x"))


def rectangle_from_desc(d, where):
    # NumPy throughout: the description's constants need no compiled program
    if "edge_u" in d or "edge_v" in d:  # a parallelogram given by its full edge vectors
        eu, ev = vec(d.get("edge_u"), f"{where}.edge_u"), vec(d.get("edge_v"), f"{where}.edge_v")
        if not float(np.linalg.norm(np.cross(np.asarray(eu), np.asarray(ev)))) > 0:
            raise ValueError(f"{where}.edge_v: edge_u and edge_v must span a parallelogram")
        return Rectangles(*(_row(v) for v in (vec(d["center"], f"{where}.center"), eu, ev)))
    n = np.asarray(vec(d["normal"], f"{where}.normal"))
    nn = float(np.linalg.norm(n))
    if nn == 0:
        raise ValueError(f"{where}.normal: expected a non-zero vector")
    size = np.asarray(
        check_finite(as_float_array(d.get("size", [2.0, 2.0]), f"{where}.size"), f"{where}.size")
    )
    if size.shape != (2,) or bool(np.any(size <= 0)):
        raise ValueError(f"{where}.size: expected two positive numbers")
    s, t = host_basis(n / nn)  # float32 / float stays float32
    center = vec(d["center"], f"{where}.center")
    return Rectangles(_row(center), _row(s * size[0]), _row(t * size[1]))


def _row(a):
    """``a[None]`` as a JAX array, shaped on the host (no compiled reshape)."""
    return jax.device_put(np.asarray(a)[None])  # (jnp.asarray would compile a copy)


MESH_SOURCES = ("file", "vertices + faces", "generator")
"""The ways a ``{type: mesh}`` shape gives its triangles (exactly one per shape)."""


def _mesh_file(d, where, base_dir):
    from jaxgfx.render.geometry import mesh_io

    path = d["file"]
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"{where}.file: expected a path, got {path!r}")
    path = os.fspath(path)
    if not os.path.isabs(path) and base_dir:
        path = os.path.join(base_dir, path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".obj", ".ply"):
        raise ValueError(f"{where}.file: expected an .obj or .ply file, got {path!r}")
    if not os.path.isfile(path):
        what = "is a directory" if os.path.isdir(path) else "no such file"
        raise FileNotFoundError(2, f"{where}.file: {what}", path)
    try:
        return (mesh_io.load_obj if ext == ".obj" else mesh_io.load_ply)(path)
    except ValueError as e:  # name the shape as well as the file
        raise ValueError(f"{where}.file: {e}") from None


def _numbers(x, where):
    """``x`` as a float array; strings, booleans, ``None`` and ragged lists are one
    ``ValueError`` naming ``where``."""
    try:
        a = np.asarray(x)
    except (TypeError, ValueError):
        a = None
    if a is None or a.dtype.kind not in "iuf":
        raise ValueError(f"{where}: expected numbers, got {x!r}")
    return as_float_array(a, where)


def _vertex_rows(x, where):
    v = _numbers(x, where)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
        raise ValueError(f"{where}: expected rows of 3 coordinates (V, 3), got shape {v.shape}")
    return check_finite(v, where)


def _index_triples(x, where, n_vertices):
    """Faces ``(F, 3)`` int32 from a list of index triples (or an integer array), each index
    an integer in ``[0, n_vertices)``: a float (``1.5`` is not truncated), a string or a
    boolean is an error naming ``where[face]``."""
    if not isinstance(x, (list, tuple, np.ndarray)) and hasattr(x, "__array__"):
        x = np.asarray(x)  # a JAX array
    if isinstance(x, np.ndarray):  # vectorised (a list is checked entry by entry below)
        if x.dtype.kind not in "iu":
            raise ValueError(f"{where}: expected integer vertex indices, got {x.dtype} values")
        if x.ndim != 2 or x.shape[1] != 3 or x.shape[0] == 0:
            raise ValueError(f"{where}: expected index triples (F, 3), F >= 1, got {x.shape}")
        bad = np.argwhere((x < 0) | (x >= n_vertices))
        if bad.size:
            i, k = bad[0]
            raise _index_error(f"{where}[{i}]", x[i, k], n_vertices)
        return x.astype(np.int32)
    if isinstance(x, (list, tuple)):
        rows = x
    else:
        raise ValueError(f"{where}: expected a list of [i, j, k] vertex index triples, got {x!r}")
    if not rows:
        raise ValueError(f"{where}: expected at least one triangle, got none")
    for i, row in enumerate(rows):
        if not isinstance(row, (list, tuple, np.ndarray)) or len(row) != 3:
            raise ValueError(f"{where}[{i}]: expected 3 vertex indices [i, j, k], got {row!r}")
        for j in row:
            if isinstance(j, (bool, np.bool_)) or not isinstance(j, (int, np.integer)):
                raise ValueError(f"{where}[{i}]: expected integer vertex indices, got {j!r}")
            if not 0 <= j < n_vertices:
                raise _index_error(f"{where}[{i}]", j, n_vertices)
    return np.asarray(rows, np.int32)


def _index_error(where, j, n_vertices):
    return ValueError(
        f"{where}: vertex index {j} out of range [0, {n_vertices - 1}] "
        f"({n_vertices} vertices; indices are 0-based)"
    )


def _mesh_scale(x, where):
    s = _numbers(x, where)
    check_finite(s, where)
    if s.shape not in ((), (3,)) or not bool(jnp.all(s > 0)):
        got = s.tolist()
        raise ValueError(f"{where}: expected a positive number or 3 positive numbers, got {got}")
    return s


def mesh_from_desc(d, where, base_dir):
    """The :class:`TriangleMesh` of a ``{type: mesh}`` description: exactly one source of
    :data:`MESH_SOURCES`, then ``scale`` (positive: one number or one per axis) and
    ``translate``. Each bad entry is one ``ValueError`` naming ``where`` and the key."""
    from jaxgfx.render.geometry import mesh_io

    inline = "vertices" in d or "faces" in d
    given = [k for k in ("file", "vertices", "faces", "generator") if k in d]
    if ("file" in d) + ("generator" in d) + inline > 1:
        raise ValueError(
            f"{where}: expected one mesh source ('file', 'vertices' + 'faces' or 'generator'), "
            f"got {given}"
        )
    if "file" in d:
        m = _mesh_file(d, where, base_dir)
    elif inline:
        if "vertices" not in d or "faces" not in d:
            missing = "faces" if "vertices" in d else "vertices"
            raise ValueError(f"{where}: inline mesh without {missing!r} (give both)")
        v = _vertex_rows(d["vertices"], f"{where}.vertices")
        f = _index_triples(d["faces"], f"{where}.faces", v.shape[0])
        extra = {}
        for key, width in (("normals", 3), ("uvs", 2)):  # optional per-vertex attributes
            if key in d:
                a = check_finite(_numbers(d[key], f"{where}.{key}"), f"{where}.{key}")
                if a.shape != (v.shape[0], width):
                    raise ValueError(
                        f"{where}.{key}: expected shape ({v.shape[0]}, {width}), got {a.shape}"
                    )
                extra[key] = a
        m = TriangleMesh(v, jnp.asarray(f), extra.get("normals"), extra.get("uvs"))
    elif "generator" in d:  # procedural (jaxgfx.render.geometry.mesh_io.MESH_GENERATORS)
        m = mesh_io.mesh_from_generator(d["generator"], f"{where}.generator")
    else:
        raise ValueError(f"{where}: expected 'file', 'vertices' + 'faces' or 'generator'")
    if "translate" in d or "scale" in d:
        s = _mesh_scale(d.get("scale", 1.0), f"{where}.scale")
        t = vec(d.get("translate", [0.0, 0.0, 0.0]), f"{where}.translate")
        normals = m.normals
        if normals is not None:  # normals transform with the inverse transpose: n / s
            normals = safe_normalize(normals / s)
        m = TriangleMesh(m.vertices * s + t, m.faces, normals, m.uvs)
    if "to_world" in d:  # 4x4 affine matrix (column vectors), after translate / scale
        mat = check_finite(as_float_array(d["to_world"], f"{where}.to_world"), f"{where}.to_world")
        if mat.shape != (4, 4) or not np.allclose(np.asarray(mat[3]), [0, 0, 0, 1]):
            raise ValueError(f"{where}.to_world: expected a 4x4 affine matrix (last row 0 0 0 1)")
        lin = mat[:3, :3]
        if abs(float(jnp.linalg.det(lin))) == 0:
            raise ValueError(f"{where}.to_world: the matrix is singular")
        normals = m.normals
        if normals is not None:  # normals transform with the inverse transpose
            normals = safe_normalize(normals @ jnp.linalg.inv(lin))
        m = TriangleMesh(m.vertices @ lin.T + mat[:3, 3], m.faces, normals, m.uvs)
    return m


def shape_from_desc(d, where, base_dir):
    if not isinstance(d, Mapping) or "type" not in d:
        raise ValueError(f"{where}: expected a mapping with a 'type' key")
    if d["type"] == "instances":  # handled by load_scene at the top level of ``shapes``
        raise ValueError(
            f"{where}: 'instances' may appear only in the scene's shapes list "
            "(no nested instancing, no instanced emitters, as in Mitsuba 3)"
        )
    kind = check_choice(d["type"], f"{where}.type", SHAPE_TYPES)
    common = ("type", "material", "id")  # id: checked by load_scene
    if kind == "sphere":
        expect_keys(d, where, ("type", "center", "radius"), (*common, "frame"))
        r = num(d["radius"], f"{where}.radius", positive=True)
        frame = None
        if d.get("frame") is not None:  # local axes (columns) of a rotated sphere: its uv
            frame = np.asarray(d["frame"], np.float64)
            if frame.shape != (3, 3) or not np.allclose(frame.T @ frame, np.eye(3), atol=1e-6):
                raise ValueError(f"{where}.frame: expected an orthogonal 3x3 matrix (the "
                                 "sphere's local axes as columns)")  # fmt: skip
            frame = frame[None]
        return "sphere", Spheres(vec(d["center"], f"{where}.center")[None], r[None], frame)
    if kind == "rectangle":
        if "edge_u" in d or "edge_v" in d:
            expect_keys(d, where, ("type", "center", "edge_u", "edge_v"), common)
        else:
            expect_keys(d, where, ("type", "center", "normal"), (*common, "size"))
        return "rectangle", rectangle_from_desc(d, where)
    if kind == "mesh":
        expect_keys(
            d,
            where,
            ("type",),
            (
                *common,
                "file",
                "vertices",
                "faces",
                "normals",
                "uvs",
                "generator",
                "translate",
                "scale",
                "to_world",
                "attributes",
            ),
        )
        return "mesh", mesh_from_desc(d, where, base_dir)
    if kind == "sdfgrid":
        return "sdf", sdfgrid_from_desc(d, where, base_dir)
    if kind in ("linearcurve", "bsplinecurve"):
        return "sdf", linearcurve_from_desc(d, where, base_dir)
    if kind == "ellipsoids":  # jaxgfx/render/scene/_ellipsoids.py
        from jaxgfx.render.scene._ellipsoids import ellipsoids_from_desc

        return "sdf", ellipsoids_from_desc(d, where, base_dir, _read_shape_file)
    # "sdf"
    expect_keys(d, where, ("type", "expr"), (*common, "max_steps", "eps"))
    expr = d["expr"]
    sdf = sdf_from_dict(dict(expr) if isinstance(expr, Mapping) else expr, path=f"{where}.expr")
    try:
        return "sdf", SDFShape(sdf, d.get("max_steps", 128), d.get("eps", 1e-4))
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None


def sdfgrid_from_desc(d, where, base_dir):
    """``{type: sdfgrid, filename: grid.vol | values: (Z, Y, X) nested lists, normals: smooth |
    analytic, to_world: 4x4}``: an :class:`~jaxgfx.render.geometry.SDFGridShape` over the unit
    cube, placed by ``to_world`` as one :class:`~jaxgfx.render.geometry.Instances` (Mitsuba's
    ``sdfgrid``)."""
    from jaxgfx.render.geometry import Instances, SDFGrid, SDFGridShape, read_vol
    from jaxgfx.render.geometry.instance import check_instance_transforms

    expect_keys(d, where, ("type",), ("material", "id", "filename", "values", "normals",
                                      "to_world"))  # fmt: skip
    if ("filename" in d) == ("values" in d):
        raise ValueError(f"{where}: give exactly one of 'filename' and 'values'")
    if "filename" in d:
        values = _read_shape_file(d, where, base_dir, read_vol)
    else:
        values = as_float_array(d["values"], f"{where}.values")
    try:
        shape = SDFGridShape(SDFGrid(values), d.get("normals", "smooth"))
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None
    if "to_world" not in d:
        return shape
    m = check_instance_transforms(as_float_array(d["to_world"], f"{where}.to_world"),
                                  f"{where}.to_world")  # fmt: skip
    return Instances(shape, m)


def _read_shape_file(d, where, base_dir, read):
    """``read(path)`` of a file-backed shape's ``filename`` (a string, relative to
    ``base_dir``); a read error becomes one ``ValueError`` naming ``{where}.filename``."""
    path = d["filename"]
    if not isinstance(path, str):
        raise ValueError(f"{where}.filename: expected a path string, got {path!r}")
    path = path if os.path.isabs(path) else os.path.join(base_dir or ".", path)
    try:
        return read(path)
    except (OSError, ValueError) as e:
        raise ValueError(f"{where}.filename: {e}") from None


def linearcurve_points(d, where, base_dir):
    """``(points (N, 4), starts)`` of a ``linearcurve`` / ``bsplinecurve`` description:
    ``filename`` (Mitsuba's curve text file) or ``curves`` (a list of curves, each a list of
    ``[x, y, z, radius]``, at least two points for linear curves, four for B-splines),
    ``to_world`` applied to the positions (not the radii, as in Mitsuba)."""
    from jaxgfx.render.geometry import read_curves

    spline = d.get("type") == "bsplinecurve"
    need = 4 if spline else 2

    expect_keys(d, where, ("type",), ("material", "id", "filename", "curves", "to_world"))
    if ("filename" in d) == ("curves" in d):
        raise ValueError(f"{where}: give exactly one of 'filename' and 'curves'")
    if "filename" in d:
        kind = "B-spline" if spline else "linear"
        pts, starts = _read_shape_file(
            d, where, base_dir, lambda path: read_curves(path, min_points=need, kind=kind)
        )
    else:
        curves = d["curves"]
        if not isinstance(curves, (list, tuple)) or not curves:
            raise ValueError(f"{where}.curves: expected a non-empty list of curves")
        pts, starts = [], []
        for i, c in enumerate(curves):
            c = np.asarray(as_float_array(c, f"{where}.curves[{i}]"), np.float64)
            if c.ndim != 2 or c.shape[1] != 4 or c.shape[0] < need:
                raise ValueError(f"{where}.curves[{i}]: expected at least {need} [x, y, z, "
                                 f"radius] control points, got shape {c.shape}")  # fmt: skip
            if not np.all(np.isfinite(c)) or np.any(c[:, 3] < 0):
                raise ValueError(f"{where}.curves[{i}]: expected finite points and radii >= 0")
            starts.append(sum(len(p) for p in pts))
            pts.append(c)
        pts = np.concatenate(pts)
    if "to_world" in d:
        m = np.asarray(as_float_array(d["to_world"], f"{where}.to_world"), np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)) or not np.allclose(m[3], [0, 0, 0, 1]):
            raise ValueError(f"{where}.to_world: expected a finite 4x4 affine matrix")
        pts = np.concatenate([pts[:, :3] @ m[:3, :3].T + m[:3, 3], pts[:, 3:]], 1)
    return pts, starts


def linearcurve_from_desc(d, where, base_dir):
    """A :class:`~jaxgfx.render.geometry.LinearCurves` (or, for ``type: bsplinecurve``, a
    :class:`~jaxgfx.render.geometry.BSplineCurves`) from ``{type, filename | curves,
    to_world}`` (:func:`linearcurve_points`)."""
    from jaxgfx.render.geometry import BSplineCurves, LinearCurves

    pts, starts = linearcurve_points(d, where, base_dir)
    ends = [*starts[1:], len(pts)]
    spline = d.get("type") == "bsplinecurve"
    span = 3 if spline else 1
    segs = [i for s, e in zip(starts, ends, strict=True) for i in range(s, e - span)]
    return (BSplineCurves if spline else LinearCurves)(jnp.asarray(pts), segs)
