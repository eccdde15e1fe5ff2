"""Mitsuba's ``serialized`` mesh format (jaxgfx/render/geometry/serialized.py).

Default: files built here byte by byte from the format description (Mitsuba docs, "serialized"
shape; several meshes, versions 3 and 4, single and double precision) read back; malformed
files refused naming the file. ``mitsuba`` marker: mitsuba-data's small test files
(tests/data/mitsuba/tests/serialized, ORIGIN.md) and a built two-mesh file read by Mitsuba
3.9.1's own loader (``mi.load_dict`` + ``mi.traverse``) give the same arrays.
"""

from __future__ import annotations

import os
import struct
import zlib

import numpy as np
import pytest

from jaxgfx.render.geometry.serialized import read_serialized, serialized_mesh_count

DATA = os.path.join(os.path.dirname(__file__), "..", "data", "mitsuba", "tests", "serialized")
FILES = ["rectangle_normals", "rectangle_uv", "rectangle_normals_uv"]


def _mesh_bytes(v, f, *, version=4, name="m", n=None, uv=None, double=False):
    flags = (0x2000 if double else 0x1000) | (0x1 if n is not None else 0) | (
        0x2 if uv is not None else 0)  # fmt: skip
    dt = "<f8" if double else "<f4"
    body = struct.pack("<I", flags)
    if version == 4:
        body += name.encode() + b"\0"
    body += struct.pack("<QQ", len(v), len(f))
    for a in (v, n, uv):
        if a is not None:
            body += np.asarray(a, dt).tobytes()
    body += np.asarray(f, "<u4").tobytes()
    return struct.pack("<HH", 0x041C, version) + zlib.compress(body)


def _file(tmp_path, meshes, version=4):
    blobs = [_mesh_bytes(*m[:2], version=version, **m[2]) for m in meshes]
    offs, data = [], b""
    for b in blobs:
        offs.append(len(data))
        data += b
    fmt = "<Q" if version == 4 else "<I"
    data += b"".join(struct.pack(fmt, o) for o in offs) + struct.pack("<I", len(blobs))
    p = tmp_path / f"m{version}.serialized"
    p.write_bytes(data)
    return str(p)


TRI = ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
QUAD = ([[0, 0, 1], [2, 0, 1], [2, 3, 1], [0, 3, 1]], [[0, 1, 2], [0, 2, 3]])


@pytest.mark.parametrize("version", [3, 4])
def test_built_files_read_back(tmp_path, version):
    n = [[0, 0, 1]] * 4
    uv = [[0, 0], [1, 0], [1, 1], [0, 1]]
    p = _file(tmp_path, [(*TRI, {"name": "tri"}),
                         (*QUAD, {"name": "quad", "n": n, "uv": uv, "double": True})],
              version)  # fmt: skip
    assert serialized_mesh_count(p) == 2
    a, b = read_serialized(p, 0), read_serialized(p, 1)
    assert (a.name, b.name) == (("tri", "quad") if version == 4 else ("", ""))
    np.testing.assert_array_equal(a.vertices, TRI[0])
    np.testing.assert_array_equal(a.faces, TRI[1])
    assert a.normals is None and a.uvs is None and a.colors is None
    np.testing.assert_array_equal(b.vertices, QUAD[0])
    np.testing.assert_array_equal(b.faces, QUAD[1])
    np.testing.assert_array_equal(b.normals, n)
    np.testing.assert_array_equal(b.uvs, uv)


def test_malformed_files_are_refused_naming_the_file(tmp_path):
    p = _file(tmp_path, [(*TRI, {})])
    with pytest.raises(ValueError, match=r"m4\.serialized: shape_index 1 out of range .* 1 mesh"):
        read_serialized(p, 1)
    bad = tmp_path / "bad.serialized"
    bad.write_bytes(b"\x06\x00\x00\x00SER_V1" + b"\0" * 8)
    with pytest.raises(ValueError, match=r"bad\.serialized: not a Mitsuba serialized mesh file"):
        read_serialized(str(bad))
    cut = tmp_path / "cut.serialized"
    raw = _mesh_bytes(*TRI)
    cut.write_bytes(raw[:4] + zlib.compress(zlib.decompress(raw[4:])[:-4]) + struct.pack(
        "<QI", 0, 1))  # fmt: skip
    with pytest.raises(ValueError, match=r"cut\.serialized: mesh 0: truncated data"):
        read_serialized(str(cut))


@pytest.mark.mitsuba
def test_mitsuba_reads_the_same_meshes(tmp_path):
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    built = _file(tmp_path, [(*TRI, {}), (*QUAD, {"uv": [[0, 0], [1, 0], [1, 1], [0, 1]]})])
    cases = [(os.path.join(DATA, f"{n}.serialized"), 0) for n in FILES]
    cases += [(built, 0), (built, 1)]
    for path, i in cases:
        ours = read_serialized(path, i)
        p = mi.traverse(mi.load_dict({"type": "serialized", "filename": path, "shape_index": i}))
        np.testing.assert_allclose(np.reshape(p["vertex_positions"], (-1, 3)), ours.vertices,
                                   rtol=1e-7, err_msg=path)  # fmt: skip
        np.testing.assert_array_equal(np.reshape(p["faces"], (-1, 3)), ours.faces)
        if ours.normals is not None:
            np.testing.assert_allclose(np.reshape(p["vertex_normals"], (-1, 3)), ours.normals,
                                       rtol=1e-7)  # fmt: skip
        if ours.uvs is not None:  # not flipped, unlike OBJ
            np.testing.assert_allclose(np.reshape(p["vertex_texcoords"], (-1, 2)), ours.uvs,
                                       rtol=1e-7)  # fmt: skip


def test_xml_serialized_shape_loads_with_its_index_and_transform(tmp_path):
    from jaxgfx.render.scene.mitsuba_xml import read_xml

    _file(tmp_path, [(*TRI, {}), (*QUAD, {"n": [[0, 0, 1]] * 4})])
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><sensor type="perspective"/>'
        '<shape type="serialized"><string name="filename" value="m4.serialized"/>'
        '<integer name="shape_index" value="1"/>'
        '<transform name="to_world"><translate x="5"/></transform></shape></scene>'
    )
    (shape,) = read_xml(str(tmp_path / "s.xml")).desc["shapes"]
    assert shape["type"] == "mesh" and shape["vertices"] == QUAD[0] and shape["faces"] == QUAD[1]
    assert shape["normals"] == [[0, 0, 1]] * 4
    np.testing.assert_allclose(np.asarray(shape["to_world"])[:3, 3], [5, 0, 0])
    (tmp_path / "bad.xml").write_text(
        '<scene version="3.0.0"><sensor type="perspective"/>\n'
        '<shape type="serialized" id="s"><string name="filename" value="m4.serialized"/>'
        '<integer name="shape_index" value="2"/></shape></scene>'
    )
    with pytest.raises(ValueError, match=r"bad\.xml:2: <shape type='serialized' id='s'>.*"
                                         r"shape_index 2 out of range"):  # fmt: skip
        read_xml(str(tmp_path / "bad.xml"))
