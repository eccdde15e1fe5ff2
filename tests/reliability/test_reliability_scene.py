# ruff: noqa: E501  (a table of cases: one case per line reads best)
"""Scene descriptions and parameter paths over bad inputs (issue 28): each case is ONE
``ValueError`` whose message is compared exactly (it names the shape and the key), raised by
``load_scene`` before anything is traced; parameter-path hints list only names a path may
use. Everything here loads tiny scenes (no render is compiled), so the file runs in seconds.
"""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

from jaxgfx.render import load_scene, render
from jaxgfx.render.geometry import TriangleMesh
from jaxgfx.render.geometry.mesh_io import mesh_from_generator

CAM = {"origin": [0, 0, 3], "target": [0, 0, 0], "fov": 45, "width": 8, "height": 6}
SPHERE = {"type": "sphere", "center": [0, 0, 0], "radius": 1}
V = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
F = [[0, 1, 2]]


def mesh_scene(**mesh):
    return {"camera": CAM, "shapes": [SPHERE, {"type": "mesh", **mesh}]}


RANGE = "out of range [0, 2] (3 vertices; indices are 0-based)"
MESH_CASES = {
    # faces: [[0, 1.5, 2]] was truncated to [0, 1, 2]
    "float-index": ({"vertices": V, "faces": [[0, 1.5, 2]]}, "shapes[1].faces[0]: expected integer vertex indices, got 1.5"),
    "float-index-integral": ({"vertices": V, "faces": [[0, 1, 2], [0, 2.0, 1]]}, "shapes[1].faces[1]: expected integer vertex indices, got 2.0"),
    "bool-index": ({"vertices": V, "faces": [[0, True, 2]]}, "shapes[1].faces[0]: expected integer vertex indices, got True"),
    # string faces gave NumPy's "ufunc 'minimum' did not contain a loop"
    "string-index": ({"vertices": V, "faces": [["0", "1", "2"]]}, "shapes[1].faces[0]: expected integer vertex indices, got '0'"),
    "faces-string": ({"vertices": V, "faces": "0 1 2"}, "shapes[1].faces: expected a list of [i, j, k] vertex index triples, got '0 1 2'"),
    "faces-null": ({"vertices": V, "faces": None}, "shapes[1].faces: expected a list of [i, j, k] vertex index triples, got None"),
    "faces-empty": ({"vertices": V, "faces": []}, "shapes[1].faces: expected at least one triangle, got none"),
    "faces-4-columns": ({"vertices": V, "faces": [[0, 1, 2, 0]]}, "shapes[1].faces[0]: expected 3 vertex indices [i, j, k], got [0, 1, 2, 0]"),
    # a ragged list gave NumPy's "inhomogeneous shape" message without the shape
    "faces-ragged": ({"vertices": V, "faces": [[0, 1, 2], [0, 1]]}, "shapes[1].faces[1]: expected 3 vertex indices [i, j, k], got [0, 1]"),
    "index-too-large": ({"vertices": V, "faces": [[0, 1, 2], [0, 1, 3]]}, f"shapes[1].faces[1]: vertex index 3 {RANGE}"),
    "index-negative": ({"vertices": V, "faces": [[0, -1, 2]]}, f"shapes[1].faces[0]: vertex index -1 {RANGE}"),
    "index-2**40": ({"vertices": V, "faces": [[0, 1, 2**40]]}, f"shapes[1].faces[0]: vertex index {2**40} {RANGE}"),
    "numpy-float-faces": ({"vertices": V, "faces": np.array([[0, 1, 2]], np.float32)}, "shapes[1].faces: expected integer vertex indices, got float32 values"),
    "numpy-index-range": ({"vertices": V, "faces": np.array([[0, 1, 2], [2, 7, 0]])}, f"shapes[1].faces[1]: vertex index 7 {RANGE}"),
    "vertex-nan": ({"vertices": [[0, 0, 0], [1, math.nan, 0], [0, 1, 0]], "faces": F}, "shapes[1].vertices: expected finite values, found 1 NaN/Inf entries"),
    "vertex-inf": ({"vertices": [[0, 0, 0], [1, 0, 0], [0, math.inf, 0]], "faces": F}, "shapes[1].vertices: expected finite values, found 1 NaN/Inf entries"),
    "vertices-2-columns": ({"vertices": [[0, 0], [1, 0], [0, 1]], "faces": F}, "shapes[1].vertices: expected rows of 3 coordinates (V, 3), got shape (3, 2)"),
    "vertices-4-columns": ({"vertices": [[0, 0, 0, 1]] * 3, "faces": F}, "shapes[1].vertices: expected rows of 3 coordinates (V, 3), got shape (3, 4)"),
    "vertices-strings": ({"vertices": [["a", "b", "c"]] * 3, "faces": F}, "shapes[1].vertices: expected numbers, got [['a', 'b', 'c'], ['a', 'b', 'c'], ['a', 'b', 'c']]"),
    "vertices-ragged": ({"vertices": [[0, 0, 0], [1, 0], [0, 1, 0]], "faces": F}, "shapes[1].vertices: expected numbers, got [[0, 0, 0], [1, 0], [0, 1, 0]]"),
    # `file` with inline vertices/faces used the file and ignored the inline mesh
    "file-and-inline": ({"file": "m.obj", "vertices": V, "faces": F}, "shapes[1]: expected one mesh source ('file', 'vertices' + 'faces' or 'generator'), got ['file', 'vertices', 'faces']"),
    "generator-and-inline": ({"generator": {"name": "icosphere", "level": 0}, "vertices": V, "faces": F}, "shapes[1]: expected one mesh source ('file', 'vertices' + 'faces' or 'generator'), got ['vertices', 'faces', 'generator']"),
    "vertices-without-faces": ({"vertices": V}, "shapes[1]: inline mesh without 'faces' (give both)"),
    "faces-without-vertices": ({"faces": F}, "shapes[1]: inline mesh without 'vertices' (give both)"),
    # scale: 0 was accepted and the mesh vanished (a sphere of radius 0 is refused)
    "scale-zero": ({"vertices": V, "faces": F, "scale": 0}, "shapes[1].scale: expected a positive number or 3 positive numbers, got 0.0"),
    "scale-negative": ({"vertices": V, "faces": F, "scale": -2}, "shapes[1].scale: expected a positive number or 3 positive numbers, got -2.0"),
    "scale-axis-zero": ({"vertices": V, "faces": F, "scale": [1, 0, 1]}, "shapes[1].scale: expected a positive number or 3 positive numbers, got [1.0, 0.0, 1.0]"),
    "scale-two-numbers": ({"vertices": V, "faces": F, "scale": [1, 2]}, "shapes[1].scale: expected a positive number or 3 positive numbers, got [1.0, 2.0]"),
    "scale-nan": ({"vertices": V, "faces": F, "scale": math.nan}, "shapes[1].scale: expected finite values, found 1 NaN/Inf entries"),
    "scale-string": ({"vertices": V, "faces": F, "scale": "big"}, "shapes[1].scale: expected numbers, got 'big'"),
    "file-not-a-path": ({"file": 3}, "shapes[1].file: expected a path, got 3"),
    "generator-radius-zero": ({"generator": {"name": "icosphere", "level": 0, "radius": 0}}, "shapes[1].generator.radius: expected a positive number, got 0"),
    "generator-center-short": ({"generator": {"name": "icosphere", "level": 0, "center": [0, 1]}}, "shapes[1].generator.center: expected 3 finite numbers, got [0, 1]"),
    "generator-level-string": ({"generator": {"name": "icosphere", "level": "2"}}, "shapes[1].generator.level: expected an integer, got '2'"),
    "generator-level-negative": ({"generator": {"name": "icosphere", "level": -1}}, "shapes[1].generator.level: expected an integer >= 0, got -1"),
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(MESH_CASES))
def test_bad_mesh_shape_is_one_clear_error(name):
    mesh, message = MESH_CASES[name]
    with pytest.raises(ValueError) as e:
        load_scene(mesh_scene(**mesh))
    assert str(e.value).startswith(message), str(e.value)


def test_mesh_file_missing_names_shape_and_path(tmp_path):
    with pytest.raises(FileNotFoundError) as e:
        load_scene(mesh_scene(file="bunny.obj"), base_dir=str(tmp_path))
    assert e.value.strerror == "shapes[1].file: no such file"
    assert e.value.filename == str(tmp_path / "bunny.obj")


def test_good_inline_mesh_is_unchanged():
    # integer faces (lists or a NumPy array), a per-axis scale and a translation
    for faces in (F, np.array(F, np.int64), [np.array([0, 1, 2], np.int32)]):
        s = load_scene(mesh_scene(vertices=V, faces=faces, scale=[2, 3, 4], translate=[1, 0, 0]))
        m = s.shapes[-1]
        np.testing.assert_array_equal(np.asarray(m.faces), [[0, 1, 2]])
        np.testing.assert_allclose(np.asarray(m.vertices), [[1, 0, 0], [3, 0, 0], [1, 3, 0]])


@pytest.mark.parametrize(
    "faces, message",
    [
        ([["0", "1", "2"]], "faces: expected an integer array, got dtype <U1"),
        (
            [[0, 1, 2], [0, 1]],
            "faces: expected an array of numbers, got a ragged or non-numeric sequence",
        ),
        ([[0, 1, 2**40]], "faces: indices must lie in [0, 2], got range [0, 1099511627776]"),
        ([[0, 1.0, 2]], "faces: expected an integer array, got dtype float64"),
    ],
)
def test_triangle_mesh_constructor_errors(faces, message):
    # string faces gave JAX's "not a valid JAX array type", 2**40 an OverflowError
    with pytest.raises(ValueError) as e:
        TriangleMesh(V, faces)
    assert str(e.value) == message


def test_triangle_mesh_string_vertices():
    with pytest.raises(ValueError) as e:
        TriangleMesh([["a", "b", "c"]] * 3, F)
    assert str(e.value) == "vertices: expected a numeric array, got dtype <U1"


def test_generator_error_names_where():
    with pytest.raises(ValueError) as e:
        mesh_from_generator({"name": "uv_sphere", "n": 1}, "generator")
    assert str(e.value) == "generator.n: expected an integer >= 2, got 1"


# ----------------------------------------------------------------------------- camera


@pytest.mark.parametrize(
    "key, value, message",
    [
        ("width", 0, "camera.width: expected a positive integer, got 0"),
        ("height", 2.5, "camera.height: expected a positive integer, got 2.5"),
        ("fov_axis", "z", "camera.fov_axis: expected one of ('x', 'y'), got 'z'"),
        ("target", [0, 0, 3], "camera.target: must differ from origin"),
    ],
)
def test_camera_errors_carry_the_section(key, value, message):
    # the constructors' messages were "width: ...", without the section
    with pytest.raises(ValueError) as e:
        load_scene({"camera": {**CAM, key: value}, "shapes": [SPHERE]})
    assert str(e.value) == message


# ----------------------------------------------------------------------------- YAML files


def test_scene_yaml_duplicate_key_names_file_and_line(tmp_path):
    p = tmp_path / "scene.yaml"
    p.write_text(
        "camera: {origin: [0, 0, 3], target: [0, 0, 0], fov: 45, width: 8, height: 6}\n"
        "shapes:\n"
        "  - {type: sphere, center: [0, 0, 0], radius: 1, radius: 2}\n"
    )
    with pytest.raises(ValueError) as e:
        load_scene(p)
    assert str(e.value) == f"{p}:3: duplicate key 'radius' (first given on line 3)"


# ----------------------------------------------------------------------------- materials, paths


HINT_SCENE = {
    "camera": CAM,
    "shapes": [
        {**SPHERE, "material": "metal"},
        {"type": "mesh", "vertices": V, "faces": F},  # no material: the loader's __default__
        {"type": "sdf", "expr": {"op": "sphere", "center": [2, 1, 0], "radius": 0.5}, "material": "clay"},
    ],
    "materials": {
        "metal": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.3},
        "clay": {"type": "diffuse", "reflectance": {"type": "checkerboard", "color0": 0.8, "color1": 0.2}},
    },
    "emitters": [  # an area light without material: the loader's __black__
        {"type": "area", "shape": {"type": "rectangle", "center": [0, 4, 0], "normal": [0, -1, 0]}, "radiance": 1},
        {"type": "point", "position": [1, 1, 1], "intensity": 1},
    ],
}  # fmt: skip


@pytest.fixture(scope="module")
def hint_scene():
    return load_scene(HINT_SCENE)


@pytest.mark.parametrize(
    "path, message",
    [
        # `alpha` (an alias) was missing and `distribution` was listed as if a parameter
        ("materials.metal.alph", "materials.metal.alph: no parameter 'alph'; have ['alpha', 'alpha_u', 'alpha_v', 'distribution.alpha_u', 'distribution.alpha_v', 'reflectance']"),
        ("materials.clay.color", "materials.clay.color: no parameter 'color'; have ['reflectance.color0', 'reflectance.color1']"),
        # __default__ and __black__ were listed
        ("materials.steel.alpha", "materials.steel.alpha: unknown material; have ['metal', 'clay']"),
        ("emitters.point.intensity", "emitters.point.intensity: no parameter 'intensity'; have ['positions', 'intensities']"),
        ("emitters.area.0.radiant", "emitters.area.0.radiant: no parameter 'radiant'; have ['radiance']"),
        # int('x') / tuple index errors before
        ("emitters.area.x.radiance", "emitters.area.x.radiance: expected an area light index in 0..0, got 'x'"),
        ("shapes.9.radii", "shapes.9.radii: expected a shape index in 0..3, got '9'"),
        ("shapes.x.radii", "shapes.x.radii: expected a shape index in 0..3, got 'x'"),
        ("shapes.1.faces_", "shapes.1.faces_: no parameter 'faces_'; have ['vertices']"),
        ("shapes.2.sdf.radiu", "shapes.2.sdf.radiu: no parameter 'radiu'; have ['sdf.center', 'sdf.radius']"),
        ("camera.fovv", "camera.fovv: no parameter 'fovv'; have ['origin', 'target', 'up', 'fov']"),
    ],
)  # fmt: skip
def test_parameter_path_hints(hint_scene, path, message):
    with pytest.raises(ValueError) as e:
        hint_scene.get(path)
    assert str(e.value) == message


def test_every_hinted_name_is_a_valid_path(hint_scene):
    # the hint's names are exactly what a path may give after the object
    from jaxgfx.render.scene.scene import parameter_names

    s = hint_scene
    objects = {
        "materials.metal": s.materials[s.material_names.index("metal")],
        "materials.clay": s.materials[s.material_names.index("clay")],
        "camera": s.camera,
        "emitters.point": s.point_lights,
        "emitters.area.0": s.area_lights[0],
        **{f"shapes.{i}": sh for i, sh in enumerate(s.shapes)},
    }
    n = 0
    for prefix, obj in objects.items():
        for name in parameter_names(obj):
            assert s.get(f"{prefix}.{name}") is not None
            n += 1
    # metal 6, clay 2, camera 4, point lights 2, area light 1; shapes: spheres 2, mesh 1,
    # sdf 2, the area light's rectangle 3
    assert n == 6 + 2 + 4 + 2 + 1 + (2 + 1 + 2 + 3)


def test_reserved_material_names_are_refused():
    desc = {
        **HINT_SCENE,
        "materials": {**HINT_SCENE["materials"], "__black__": {"type": "diffuse"}},
    }
    with pytest.raises(ValueError) as e:
        load_scene(desc)
    assert str(e.value) == (
        "materials.__black__: names of the form __NAME__ are the loader's own "
        "(__default__, __black__); rename the material"
    )
    desc = {"camera": CAM, "shapes": [SPHERE, {**SPHERE, "material": "__default__"}]}
    with pytest.raises(ValueError) as e:
        load_scene(desc)
    assert str(e.value) == "shapes[1].material: unknown material '__default__'; have []"


# ----------------------------------------------------------------------------- spp limit

SPP_MESSAGE = (
    "spp: 100000000 samples per pixel at 8x6 pixels need 9600000000 random numbers, more than "
    "the 2**32 of one key; use spp <= 44739242 (and average renders made with split keys for more)"
)


def test_render_spp_over_the_key_limit_names_spp():
    s = load_scene({"camera": CAM, "shapes": [SPHERE]})
    # 8 * 6 * 44739242 * 2 = 4294967232 <= 2**32 < 8 * 6 * 44739243 * 2
    assert 8 * 6 * 44739242 * 2 <= 2**32 < 8 * 6 * 44739243 * 2
    with pytest.raises(ValueError) as e:
        jax.eval_shape(lambda k: render(s, k, spp=100_000_000), jax.random.key(0))
    assert str(e.value) == SPP_MESSAGE
    # the CLI names the option as typed, `--spp`: test_reliability_cli.py
