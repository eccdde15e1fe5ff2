"""Mesh I/O (OBJ, PLY) round trips, malformed files, procedural meshes (host-side NumPy)."""

import numpy as np
import pytest

from jaxgfx.render.geometry import TriangleMesh, area
from jaxgfx.render.geometry import mesh_io as M

OBJ = """# a unit square as one quad, a triangle with negative indices, comments and groups
mtllib none.mtl
o square
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
g g1
s off
f 1/1/1 2/2/1 3/3/1 4/4/1
v 0 0 1
v 1 0 1
v 0 1 1
f -3/1/1 -2/2/1 -1/4/1
"""


def test_load_obj_polygons_negative_indices(tmp_path):
    path = tmp_path / "m.obj"
    path.write_text(OBJ)
    m = M.load_obj(path)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    assert f.shape == (3, 3) and v.shape == (7, 3)
    tri = v[f]
    # fan triangulation of the quad: (1,2,3), (1,3,4); then the negative-index triangle
    np.testing.assert_allclose(tri[0], [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    np.testing.assert_allclose(tri[1], [[0, 0, 0], [1, 1, 0], [0, 1, 0]])
    np.testing.assert_allclose(tri[2], [[0, 0, 1], [1, 0, 1], [0, 1, 1]])
    np.testing.assert_allclose(np.asarray(m.uvs)[f[2]], [[0, 0], [1, 0], [0, 1]])
    np.testing.assert_allclose(np.asarray(m.normals), np.tile([0, 0, 1.0], (7, 1)))
    np.testing.assert_allclose(area(m), 1.5, rtol=1e-6)


def test_load_obj_forms_without_attributes(tmp_path):
    path = tmp_path / "m.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf 1 2 3\n")
    m = M.load_obj(path)
    assert m.uvs is None and m.normals is None  # the second face has no normals
    assert m.faces.shape == (2, 3)


@pytest.mark.parametrize("with_attrs", [False, True])
def test_obj_round_trip(tmp_path, with_attrs):
    ico = M.make_icosphere(1)
    mesh = TriangleMesh(
        ico.vertices,
        ico.faces,
        normals=ico.normals if with_attrs else None,
        uvs=np.asarray(ico.vertices)[:, :2] if with_attrs else None,
    )
    M.save_obj(tmp_path / "r.obj", mesh)
    back = M.load_obj(tmp_path / "r.obj")
    # corners are re-indexed in first-use order: compare per-corner values
    fb, fm = np.asarray(back.faces), np.asarray(mesh.faces)
    np.testing.assert_allclose(np.asarray(back.vertices)[fb], np.asarray(mesh.vertices)[fm])
    if with_attrs:
        np.testing.assert_allclose(np.asarray(back.normals)[fb], np.asarray(mesh.normals)[fm])
        np.testing.assert_allclose(np.asarray(back.uvs)[fb], np.asarray(mesh.uvs)[fm])


@pytest.mark.parametrize("binary", [False, True])
def test_ply_round_trip(tmp_path, binary):
    ico = M.make_icosphere(1)
    mesh = TriangleMesh(ico.vertices, ico.faces, normals=ico.normals,
                        uvs=np.asarray(ico.vertices)[:, 1:])  # fmt: skip
    M.save_ply(tmp_path / "r.ply", mesh, binary=binary)
    back = M.load_ply(tmp_path / "r.ply")
    np.testing.assert_array_equal(back.faces, mesh.faces)
    np.testing.assert_allclose(back.vertices, mesh.vertices, rtol=1e-6)
    np.testing.assert_allclose(back.normals, mesh.normals, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(back.uvs, mesh.uvs, rtol=1e-6, atol=1e-7)


def test_load_ply_handwritten_quad_and_extra_props(tmp_path):
    text = (
        "ply\nformat ascii 1.0\ncomment hand made\nelement vertex 4\n"
        "property float x\nproperty float y\nproperty float z\nproperty uchar red\n"
        "element face 1\nproperty list uchar int vertex_indices\n"
        "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
        "0 0 0 255\n2 0 0 0\n2 1 0 0\n0 1 0 9\n4 0 1 2 3\n0 1\n"
    )
    (tmp_path / "q.ply").write_text(text)
    m = M.load_ply(tmp_path / "q.ply")
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_allclose(area(m), 2.0)
    # the same quad in binary, with a uint vertex count list and double coordinates
    head = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty double x\n"
        b"property double y\nproperty double z\nelement face 1\n"
        b"property list uint int vertex_index\nend_header\n"
    )
    v = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], "<f8").tobytes()
    f = np.array([4], "<u4").tobytes() + np.array([0, 1, 2, 3], "<i4").tobytes()
    (tmp_path / "b.ply").write_bytes(head + v + f)
    mb = M.load_ply(tmp_path / "b.ply")
    np.testing.assert_array_equal(mb.faces, m.faces)
    np.testing.assert_allclose(mb.vertices, m.vertices)


@pytest.mark.parametrize(
    ("name", "content", "match"),
    [
        ("a.obj", "v 0 0\nf 1 2 3\n", r"a\.obj:1"),
        ("b.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", r"b\.obj:4.*index 9"),
        ("c.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n", r"c\.obj:3"),
        ("d.obj", "v 0 0 0\nv x 0 0\n", r"d\.obj:2"),
        ("e.obj", "v 0 0 0\n", r"e\.obj: no faces"),
        ("f.ply", "plx\nend_header\n", r"f\.ply: not a PLY"),
        ("g.ply", "ply\nformat binary_big_endian 1.0\nend_header\n", r"g\.ply.*big_endian"),
        (
            "h.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
            "end_header\n0 0 0\n1 0 0\n",
            r"h\.ply: truncated",
        ),  # fmt: skip
        (
            "i.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
            "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n",
            r"i\.ply.*out of range",
        ),  # fmt: skip
    ],
)
def test_malformed_files_name_the_file(tmp_path, name, content, match):
    (tmp_path / name).write_text(content)
    loader = M.load_obj if name.endswith(".obj") else M.load_ply
    with pytest.raises(ValueError, match=match):
        loader(tmp_path / name)


def test_truncated_binary_ply(tmp_path):
    M.save_ply(tmp_path / "t.ply", M.make_icosphere(0))
    data = (tmp_path / "t.ply").read_bytes()
    (tmp_path / "t.ply").write_bytes(data[:-7])
    with pytest.raises(ValueError, match=r"t\.ply: truncated"):
        M.load_ply(tmp_path / "t.ply")


def _signed_volume(m):
    t = np.asarray(m.vertices, np.float64)[np.asarray(m.faces)]
    return np.sum(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2]))) / 6


def test_icosphere_and_uv_sphere():
    for level in range(4):
        m = M.make_icosphere(level, radius=2.0)
        assert m.faces.shape[0] == 20 * 4**level
        np.testing.assert_allclose(np.linalg.norm(m.vertices, axis=1), 2.0, rtol=1e-6)
    # outward winding: positive signed volume converging to 4/3 pi r^3
    vol = _signed_volume(M.make_icosphere(4, radius=2.0))
    np.testing.assert_allclose(vol, 4 / 3 * np.pi * 8, rtol=0.01)
    u = M.make_uv_sphere(16, center=(1, 0, 0))
    assert u.faces.shape[0] == 4 * 16 * 15
    r = np.linalg.norm(np.asarray(u.vertices) - [1, 0, 0], axis=1)
    np.testing.assert_allclose(r, 1.0, rtol=1e-6)
    np.testing.assert_allclose(_signed_volume(u), 4 / 3 * np.pi, rtol=0.03)
    assert np.all(np.asarray(area(u)) < 4 * np.pi)  # inscribed polyhedron
    np.testing.assert_allclose(area(u), 4 * np.pi, rtol=0.03)


def test_triangle_soup():
    m = M.make_triangle_soup(1000, size=0.1, seed=3)
    assert m.faces.shape == (1000, 3)
    assert np.all(np.abs(np.asarray(m.vertices)) <= 1.1 + 1e-6)
    f = np.asarray(M.make_triangle_soup(10, seed=3).faces)
    np.testing.assert_array_equal(f.ravel(), np.arange(30))
    with pytest.raises(ValueError, match="n"):
        M.make_triangle_soup(0)
    with pytest.raises(ValueError, match="level"):
        M.make_icosphere(-1)
