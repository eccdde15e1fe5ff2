"""Host-side mesh I/O (Wavefront OBJ, PLY) and procedural meshes for tests and benchmarks.

Everything here runs in NumPy on the host and returns a
:class:`jaxgfx.render.geometry.TriangleMesh`. Malformed files raise ``ValueError`` naming the
file and line.
"""

from __future__ import annotations

import os

import numpy as np

from jaxgfx._checks import check_choice
from jaxgfx.render.geometry.mesh import TriangleMesh

__all__ = [
    "load_obj",
    "load_ply",
    "save_obj",
    "save_ply",
    "make_uv_sphere",
    "make_icosphere",
    "make_triangle_soup",
    "make_blob",
    "vertex_normals",
    "MESH_GENERATORS",
    "mesh_from_generator",
]


def _mesh(v, f, n=None, uv=None):
    return TriangleMesh(
        np.asarray(v, np.float32),
        np.asarray(f, np.int32),
        None if n is None else np.asarray(n, np.float32),
        None if uv is None else np.asarray(uv, np.float32),
    )


def _fix_index(i, n, path, lineno):
    i = int(i)
    j = i - 1 if i > 0 else n + i
    if i == 0 or not 0 <= j < n:
        raise ValueError(f"{path}:{lineno}: index {i} out of range (1..{n} or -{n}..-1)")
    return j


def _check_finite_vertices(path, v: np.ndarray) -> None:
    bad = np.flatnonzero(~np.all(np.isfinite(v), axis=-1))
    if bad.size:
        raise ValueError(
            f"{path}: {bad.size} vertices have NaN/Inf coordinates (first: vertex {bad[0]} "
            f"= {v[bad[0]].tolist()}, 0-based)"
        )


def load_obj(path) -> TriangleMesh:
    """Read a Wavefront OBJ file: ``v``, ``vt``, ``vn`` and ``f`` records.

    Faces may be ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``, with 1-based or negative
    (relative) indices; polygons are fan-triangulated. Since a :class:`TriangleMesh` has one
    index per corner, corners with distinct ``(v, vt, vn)`` triples become distinct vertices.
    Normals/UVs are kept only if every corner has them. Other records (``o``, ``g``, ``s``,
    ``usemtl``, ``mtllib``, ``l``, ``p``) are ignored.
    """
    path = os.fspath(path)
    vs, vts, vns = [], [], []
    corners: dict[tuple[int, int, int], int] = {}
    out_v, out_t, out_n, faces = [], [], [], []
    try:
        with open(path, encoding="utf-8", errors="strict") as fh:
            lines = fh.readlines()
    except UnicodeDecodeError as e:
        raise ValueError(f"{path}: not a text OBJ file ({e})") from None
    for lineno, line in enumerate(lines, 1):
        s = line.split("#", 1)[0].split()
        if not s:
            continue
        tag, args = s[0], s[1:]
        try:
            if tag == "v":
                if len(args) < 3:
                    raise ValueError("expected 3 coordinates")
                vs.append([float(x) for x in args[:3]])
            elif tag == "vt":
                if len(args) < 2:
                    raise ValueError("expected 2 texture coordinates")
                vts.append([float(x) for x in args[:2]])
            elif tag == "vn":
                if len(args) != 3:
                    raise ValueError("expected 3 normal components")
                vns.append([float(x) for x in args])
            elif tag == "f":
                if len(args) < 3:
                    raise ValueError("a face needs at least 3 vertices")
                idx = []
                for a in args:
                    parts = a.split("/")
                    if len(parts) > 3 or parts[0] == "":
                        raise ValueError(f"bad face corner {a!r}")
                    vi = _fix_index(parts[0], len(vs), path, lineno)
                    ti = (
                        _fix_index(parts[1], len(vts), path, lineno)
                        if len(parts) > 1 and parts[1]
                        else -1
                    )
                    ni = (
                        _fix_index(parts[2], len(vns), path, lineno)
                        if len(parts) > 2 and parts[2]
                        else -1
                    )
                    key = (vi, ti, ni)
                    if key not in corners:
                        corners[key] = len(out_v)
                        out_v.append(vi)
                        out_t.append(ti)
                        out_n.append(ni)
                    idx.append(corners[key])
                for k in range(1, len(idx) - 1):
                    faces.append([idx[0], idx[k], idx[k + 1]])
        except ValueError as e:
            if str(e).startswith(path):
                raise
            raise ValueError(f"{path}:{lineno}: malformed {tag!r} record: {e}") from None
    if not faces:
        raise ValueError(f"{path}: no faces found")
    V = np.asarray(vs, np.float64)[out_v]
    _check_finite_vertices(path, np.asarray(vs, np.float64))
    out_t, out_n = np.asarray(out_t), np.asarray(out_n)
    uv = np.asarray(vts)[out_t] if vts and np.all(out_t >= 0) else None
    nn = np.asarray(vns)[out_n] if vns and np.all(out_n >= 0) else None
    return _mesh(V, faces, nn, uv)


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


def ply_header_and_body(path, data: bytes) -> tuple[list[str], bytes]:
    """A PLY file's header lines (up to ``end_header``, ASCII) and the bytes after it;
    ``ValueError`` naming ``path`` when ``data`` is not a PLY file."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise ValueError(f"{path}: not a PLY file (missing 'ply' magic or 'end_header')")
    nl = data.find(b"\n", end)
    body = data[nl + 1 :] if nl >= 0 else b""
    try:
        return data[:end].decode("ascii").splitlines(), body
    except UnicodeDecodeError:
        raise ValueError(f"{path}: PLY header is not ASCII") from None


def load_ply(path, *, attributes: bool = False):
    """Read a PLY file (``ascii`` or ``binary_little_endian`` 1.0).

    Uses the ``vertex`` element (``x y z``, optional ``nx ny nz`` and ``u v`` / ``s t``) and the
    ``face`` element's ``vertex_indices`` (or ``vertex_index``) list, fan-triangulating
    polygons. Other elements are skipped; other vertex / face properties too, unless
    ``attributes``: then returns ``(mesh, attrs)`` with ``attrs`` the mesh attributes as
    Mitsuba 3 names them (:func:`ply_attributes`): ``{"vertex_color": (V, 3), "face_weight":
    (F, 1), ...}`` (face values repeated for each triangle of a polygon).
    """
    path = os.fspath(path)
    with open(path, "rb") as fh:
        data = fh.read()
    header, body = ply_header_and_body(path, data)
    fmt = None
    elements: list[tuple[str, int, list]] = []
    for line in header[1:]:
        s = line.split()
        if not s or s[0] in ("comment", "obj_info"):
            continue
        if s[0] == "format":
            fmt = s[1] if len(s) > 1 else None
        elif s[0] == "element" and len(s) == 3:
            elements.append((s[1], int(s[2]), []))
        elif s[0] == "property" and elements:
            if s[1] == "list" and len(s) == 5 and s[2] in _PLY_TYPES and s[3] in _PLY_TYPES:
                elements[-1][2].append((s[4], "list", _PLY_TYPES[s[2]], _PLY_TYPES[s[3]]))
            elif len(s) == 3 and s[1] in _PLY_TYPES:
                elements[-1][2].append((s[2], _PLY_TYPES[s[1]]))
            else:
                raise ValueError(f"{path}: bad PLY property line {line!r}")
        else:
            raise ValueError(f"{path}: bad PLY header line {line!r}")
    if fmt not in ("ascii", "binary_little_endian"):
        raise ValueError(f"{path}: unsupported PLY format {fmt!r} (ascii, binary_little_endian)")
    values: dict[str, dict[str, np.ndarray]] = {}
    if fmt == "ascii":
        tokens = body.split()
        pos = 0
        try:
            for name, count, props in elements:
                cols: dict[str, list] = {p[0]: [] for p in props}
                for _ in range(count):
                    for p in props:
                        if p[1] == "list":
                            k = int(tokens[pos])
                            cols[p[0]].append(
                                [int(float(x)) for x in tokens[pos + 1 : pos + 1 + k]]
                            )
                            if len(cols[p[0]][-1]) != k:
                                raise IndexError
                            pos += 1 + k
                        else:
                            cols[p[0]].append(float(tokens[pos]))
                            pos += 1
                values[name] = cols
        except (IndexError, ValueError):
            raise ValueError(f"{path}: truncated or malformed ASCII PLY body") from None
    else:
        pos = 0
        for name, count, props in elements:
            if all(p[1] != "list" for p in props):
                dt = np.dtype([(p[0], "<" + p[1]) for p in props])
                if pos + dt.itemsize * count > len(body):
                    raise ValueError(f"{path}: truncated binary PLY element {name!r}")
                arr = np.frombuffer(body, dt, count, pos)
                pos += dt.itemsize * count
                values[name] = {p[0]: arr[p[0]] for p in props}
                continue
            cols = {p[0]: [] for p in props}
            for _ in range(count):
                for p in props:
                    if p[1] == "list":
                        ct, it = np.dtype("<" + p[2]), np.dtype("<" + p[3])
                        if pos + ct.itemsize > len(body):
                            raise ValueError(f"{path}: truncated binary PLY element {name!r}")
                        k = int(np.frombuffer(body, ct, 1, pos)[0])
                        pos += ct.itemsize
                        if pos + it.itemsize * k > len(body):
                            raise ValueError(f"{path}: truncated binary PLY element {name!r}")
                        cols[p[0]].append(np.frombuffer(body, it, k, pos).tolist())
                        pos += it.itemsize * k
                    else:
                        dt = np.dtype("<" + p[1])
                        if pos + dt.itemsize > len(body):
                            raise ValueError(f"{path}: truncated binary PLY element {name!r}")
                        cols[p[0]].append(np.frombuffer(body, dt, 1, pos)[0])
                        pos += dt.itemsize
            values[name] = cols
    vert = values.get("vertex")
    face = values.get("face")
    if vert is None or not all(k in vert for k in "xyz"):
        raise ValueError(f"{path}: PLY has no vertex element with x, y, z")
    if face is None:
        raise ValueError(f"{path}: PLY has no face element")
    key = "vertex_indices" if "vertex_indices" in face else "vertex_index"
    if key not in face:
        raise ValueError(f"{path}: PLY face element has no vertex_indices list")
    V = np.stack([np.asarray(vert[c], np.float64) for c in "xyz"], -1)
    faces, src = [], []
    for j, poly in enumerate(face[key]):
        if len(poly) < 3:
            raise ValueError(f"{path}: PLY face with {len(poly)} < 3 vertices")
        for k in range(1, len(poly) - 1):
            faces.append([poly[0], poly[k], poly[k + 1]])
            src.append(j)
    faces = np.asarray(faces, np.int64)
    _check_finite_vertices(path, np.asarray(V, np.float64))
    if faces.min() < 0 or faces.max() >= len(V):
        raise ValueError(f"{path}: PLY face index out of range [0, {len(V) - 1}]")
    nn = np.stack([np.asarray(vert[c]) for c in ("nx", "ny", "nz")], -1) if "nx" in vert else None
    uvk = next(
        (k for k in (("u", "v"), ("s", "t"), ("texture_u", "texture_v")) if k[0] in vert), None
    )
    uv = np.stack([np.asarray(vert[c]) for c in uvk], -1) if uvk else None
    mesh = _mesh(V, faces, nn, uv)
    if not attributes:
        return mesh
    skip_v = {"x", "y", "z", "nx", "ny", "nz", *(uvk or ())}
    attrs = ply_attributes("vertex_", {k: v for k, v in vert.items() if k not in skip_v})
    fa = ply_attributes("face_", {k: v for k, v in face.items() if k != key})
    idx = np.asarray(src, np.int64)
    attrs.update({k: v[idx] for k, v in fa.items()})
    return mesh, attrs


_PLY_SCHEMES = (("x", "y", "z", "w"), ("r", "g", "b", "a"), ("0", "1", "2", "3"),
                ("1", "2", "3", "4"))  # fmt: skip


def ply_attributes(prefix, props) -> dict:
    """Group PLY properties (``name -> values``, in file order) into attributes as Mitsuba 3's
    PLY reader does: consecutive ``{p}_x, {p}_y, ...`` (or ``_r _g _b _a``, ``_0 _1 ...``,
    ``_1 _2 ...``) form one attribute ``{prefix}{p}`` with one channel per property;
    ``r g b [a]`` / ``red green blue [alpha]`` form ``{prefix}color``; any other property is a
    one-channel attribute ``{prefix}{name}``. Values are float64 ``(N, C)``."""
    names = list(props)
    out, i = {}, 0
    while i < len(names):
        n = names[i]
        group, base = [n], n
        for full in (("r", "g", "b", "a"), ("red", "green", "blue", "alpha")):
            if n == full[0]:
                k = 1
                while i + k < len(names) and k < 4 and names[i + k] == full[k]:
                    group.append(names[i + k])
                    k += 1
                base = "color"
        if len(group) == 1 and "_" in n:
            head, tail = n.rsplit("_", 1)
            for sch in _PLY_SCHEMES:
                if tail == sch[0]:
                    k = 1
                    while i + k < len(names) and k < 4 and names[i + k] == f"{head}_{sch[k]}":
                        group.append(names[i + k])
                        k += 1
                    base = head
                    break
        out[prefix + base] = np.stack([np.asarray(props[g], np.float64) for g in group], -1)
        i += len(group)
    return out


def save_obj(path, mesh: TriangleMesh) -> None:
    """Write ``mesh`` as OBJ (``v``, optional ``vt``/``vn``, ``f`` with matching indices)."""
    v = np.asarray(mesh.vertices)
    f = np.asarray(mesh.faces) + 1
    with open(path, "w") as fh:
        fh.writelines(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in v)
        if mesh.uvs is not None:
            fh.writelines(f"vt {a:.9g} {b:.9g}\n" for a, b in np.asarray(mesh.uvs))
        if mesh.normals is not None:
            fh.writelines(f"vn {a:.9g} {b:.9g} {c:.9g}\n" for a, b, c in np.asarray(mesh.normals))
        t, n = mesh.uvs is not None, mesh.normals is not None
        for tri in f:
            c = [f"{i}/{i if t else ''}/{i}" if n else (f"{i}/{i}" if t else f"{i}") for i in tri]
            fh.write("f " + " ".join(c) + "\n")


def save_ply(path, mesh: TriangleMesh, *, binary: bool = True) -> None:
    """Write ``mesh`` as PLY (``binary_little_endian`` or ``ascii``), float32 vertices."""
    v = np.asarray(mesh.vertices, np.float32)
    f = np.asarray(mesh.faces, np.int32)
    cols = [("x", v[:, 0]), ("y", v[:, 1]), ("z", v[:, 2])]
    if mesh.normals is not None:
        nn = np.asarray(mesh.normals, np.float32)
        cols += [("nx", nn[:, 0]), ("ny", nn[:, 1]), ("nz", nn[:, 2])]
    if mesh.uvs is not None:
        uv = np.asarray(mesh.uvs, np.float32)
        cols += [("u", uv[:, 0]), ("v", uv[:, 1])]
    fmt = "binary_little_endian" if binary else "ascii"
    head = [f"ply\nformat {fmt} 1.0\nelement vertex {len(v)}\n"]
    head += [f"property float {c}\n" for c, _ in cols]
    head += [f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"]
    with open(path, "wb") as fh:
        fh.write("".join(head).encode("ascii"))
        if binary:
            vd = np.empty(len(v), [(c, "<f4") for c, _ in cols])
            for c, a in cols:
                vd[c] = a
            fh.write(vd.tobytes())
            fd = np.empty(len(f), [("n", "u1"), ("i", "<i4", (3,))])
            fd["n"] = 3
            fd["i"] = f
            fh.write(fd.tobytes())
        else:
            vals = np.stack([a for _, a in cols], -1)
            fh.write("".join(" ".join(f"{x:.9g}" for x in r) + "\n" for r in vals).encode())
            fh.write("".join(f"3 {a} {b} {c}\n" for a, b, c in f).encode())


def make_uv_sphere(n: int, *, radius: float = 1.0, center=(0.0, 0.0, 0.0)) -> TriangleMesh:
    """Latitude-longitude sphere with ``n`` rings and ``2n`` segments (``4n(n-1)`` triangles).

    Outward-facing (counter-clockwise seen from outside), with unit vertex normals and
    ``uv = (phi / 2pi, theta / pi)``.
    """
    if not isinstance(n, (int, np.integer)) or n < 2:
        raise ValueError(f"n: expected an integer >= 2, got {n!r}")
    m = 2 * n
    th = np.linspace(0, np.pi, n + 1)
    ph = np.linspace(0, 2 * np.pi, m + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    nrm = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    uv = np.stack([P / (2 * np.pi), T / np.pi], -1).reshape(-1, 2)
    idx = np.arange((n + 1) * (m + 1)).reshape(n + 1, m + 1)
    faces = []
    for i in range(n):
        for j in range(m):
            a, b, c, d = idx[i, j], idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1]
            if i != 0:
                faces.append([a, b, d])
            if i != n - 1:
                faces.append([b, c, d])
    v = np.asarray(center, np.float64) + radius * nrm
    return _mesh(v, faces, nrm, uv)


def make_icosphere(level: int, *, radius: float = 1.0, center=(0.0, 0.0, 0.0)) -> TriangleMesh:
    """Subdivided icosahedron: ``20 * 4**level`` outward-facing triangles on a sphere."""
    if not isinstance(level, (int, np.integer)) or level < 0:
        raise ValueError(f"level: expected an integer >= 0, got {level!r}")
    g = (1 + 5**0.5) / 2
    v = [[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g],
         [0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]]  # fmt: skip
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]  # fmt: skip
    V = np.asarray(v, np.float64)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    F = np.asarray(f, np.int64)
    for _ in range(level):
        e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
        e.sort(axis=1)
        uniq, inv = np.unique(e, axis=0, return_inverse=True)
        mid = V[uniq[:, 0]] + V[uniq[:, 1]]
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = len(V) + inv.reshape(3, -1)
        a, b, c = F[:, 0], F[:, 1], F[:, 2]
        ab, bc, ca = m[0], m[1], m[2]
        F = np.concatenate(
            [np.stack(x, 1) for x in ([a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca])]
        )
        V = np.concatenate([V, mid])
    return _mesh(np.asarray(center, np.float64) + radius * V, F, V)


def make_triangle_soup(n: int, *, seed: int = 0, size: float = 0.05, extent: float = 1.0):
    """``n`` random triangles in the cube ``[-extent, extent]^3`` with edges of about ``size``.

    Vertices are a random centre plus offsets uniform in ``[-size, size]^3`` (NumPy
    ``default_rng(seed)``); used to build 1e2 ... 1e6 triangle benchmark scenes.
    """
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n: expected an integer >= 1, got {n!r}")
    rng = np.random.default_rng(seed)
    c = rng.uniform(-extent, extent, (n, 1, 3))
    v = (c + rng.uniform(-size, size, (n, 3, 3))).reshape(-1, 3)
    return _mesh(v, np.arange(3 * n).reshape(n, 3))


def vertex_normals(vertices, faces) -> np.ndarray:
    """Area-weighted unit vertex normals ``(V, 3)`` of an outward-wound triangle mesh (NumPy)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # |fn| = 2 area
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(ln > 0, ln, 1.0)


def make_blob(
    level: int = 5, *, seed: int = 0, lobes: int = 12, radius: float = 1.0, center=(0.0, 0.0, 0.0)
) -> TriangleMesh:
    """A smooth, bumpy closed surface ("bunny-like blob") of ``20 * 4**level`` triangles.

    An icosphere (:func:`make_icosphere`) whose vertices ``n`` are pushed out to radius
    ``radius * (1 + sum_k a_k exp((n.c_k - 1) / w_k^2))`` by ``lobes`` random Gaussian lobes
    (centres ``c_k`` uniform on the sphere, heights ``a_k`` in [0.2, 0.5], widths ``w_k`` in
    [0.2, 0.4]; NumPy ``default_rng(seed)``), with area-weighted vertex normals. Star-shaped
    around ``center``, so it is closed and free of self-intersections. Level 5 = 20 480
    triangles, used by configs/scenes/mesh.yaml.
    """
    if not isinstance(lobes, (int, np.integer)) or lobes < 0:
        raise ValueError(f"lobes: expected an integer >= 0, got {lobes!r}")
    ico = make_icosphere(level)
    n = np.asarray(ico.vertices, np.float64)
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(lobes, 3))
    c /= np.linalg.norm(c, axis=1, keepdims=True)
    a = rng.uniform(0.2, 0.5, lobes)
    w = rng.uniform(0.2, 0.4, lobes)
    r = 1.0 + np.sum(a * np.exp((n @ c.T - 1.0) / w**2), axis=1)
    v = np.asarray(center, np.float64) + radius * n * r[:, None]
    f = np.asarray(ico.faces)
    return _mesh(v, f, vertex_normals(v, f))


MESH_GENERATORS = {
    "blob": make_blob,
    "icosphere": make_icosphere,
    "uv_sphere": make_uv_sphere,
    "triangle_soup": make_triangle_soup,
}
"""Procedural meshes selectable in scene descriptions: ``{type: mesh, generator: {name: blob,
level: 5, seed: 0}}`` (the other keys are the generator's keyword arguments; ``icosphere`` takes
``level``, ``uv_sphere`` ``n``, ``triangle_soup`` ``n``)."""


_GENERATOR_POSITIVE = ("radius", "size", "extent")
_GENERATOR_INTEGERS = ("level", "n", "lobes", "seed")


def mesh_from_generator(spec, where: str = "generator") -> TriangleMesh:
    """The mesh of a ``{name: ..., **kwargs}`` generator description (:data:`MESH_GENERATORS`);
    unknown names or arguments, and bad values (``center``: 3 finite numbers; ``radius``,
    ``size``, ``extent``: positive numbers; ``level``, ``n``, ``lobes``, ``seed``: integers)
    raise ``ValueError`` naming ``where`` and the key (``generator.radius: ...``)."""
    if not isinstance(spec, dict) or "name" not in spec:
        raise ValueError(f"{where}: expected a mapping with a 'name' key, got {spec!r}")
    name = spec["name"]
    check_choice(name, f"{where}.name", sorted(MESH_GENERATORS))
    kwargs = {k: v for k, v in spec.items() if k != "name"}
    for k, v in kwargs.items():
        if k == "center":
            try:
                c = np.asarray(v, np.float64)
            except (TypeError, ValueError):
                c = None
            if c is None or c.shape != (3,) or not np.all(np.isfinite(c)):
                raise ValueError(f"{where}.center: expected 3 finite numbers, got {v!r}")
            kwargs[k] = tuple(float(x) for x in c)
        elif k in _GENERATOR_POSITIVE:
            ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            if not (ok and np.isfinite(v) and v > 0):
                raise ValueError(f"{where}.{k}: expected a positive number, got {v!r}")
        elif k in _GENERATOR_INTEGERS and (
            isinstance(v, bool) or not isinstance(v, (int, np.integer))
        ):
            raise ValueError(f"{where}.{k}: expected an integer, got {v!r}")
    try:
        return MESH_GENERATORS[name](**kwargs)
    except TypeError as e:
        raise ValueError(f"{where}: bad arguments for {name!r}: {e}") from None
    except ValueError as e:  # the generator's own check names its argument: `level: ...`
        message = str(e)
        key = message.split(":", 1)[0]
        raise ValueError(f"{where}.{message}" if key in kwargs else f"{where}: {message}") from None
