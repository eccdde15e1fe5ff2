"""Loader details met by mitsuba-data's scenes (issues 23 and 24): the checkerboard's pattern for
scalar parameters (Mitsuba's ``eval_1``), a mask with a constant opacity on tessellated shapes,
``rawconstant`` and bitmap ``to_uv`` (closed forms, their errors, bump maps through ``to_uv``),
and the same against Mitsuba 3's plugins (``mitsuba``)."""

from __future__ import annotations

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.bsdf import BumpMap, Diffuse, TangentSpace
from jaxgfx.render.bsdf.texture import Texture, check_uv_transform, lookup
from jaxgfx.render.scene.load import material_from_desc
from jaxgfx.render.scene.mitsuba_xml import read_xml

SENSOR = (
    '<sensor type="perspective"><float name="fov" value="40"/><film type="hdrfilm">'
    '<integer name="width" value="4"/><integer name="height" value="4"/></film></sensor>'
)


def _read(tmp_path, body):
    p = tmp_path / "s.xml"
    body = body.replace(
        '<shape type="sphere">', '<shape type="sphere"><point name="center" z="5"/>'
    )
    p.write_text(f'<scene version="3.0.0">\n{SENSOR}\n{body}\n</scene>\n')
    return str(p), read_xml(str(p)).desc


# ------------------------------------------------------------------------ checkerboard eval_1

UV = np.array([[0.25, 0.25], [0.75, 0.25], [0.25, 0.75], [0.75, 0.75]])
# Mitsuba's checkerboard: eval (colours) gives color0 where (frac(u) > 1/2) == (frac(v) > 1/2),
# eval_1 (scalar parameters: alpha, weight, opacity, roughness) where they differ
EVAL_IS_C0 = np.array([True, False, False, True])


def test_checkerboard_of_a_scalar_parameter_takes_mitsubas_eval_1_pattern(tmp_path):
    body = ('<shape type="sphere"><bsdf type="roughconductor">'
            '<texture name="alpha" type="checkerboard"><float name="color0" value="0.05"/>'
            '<float name="color1" value="0.3"/></texture></bsdf></shape>'
            '<shape type="sphere" id="b"><point name="center" x="3" z="5"/><bsdf type="diffuse">'
            '<texture name="reflectance" type="checkerboard"><float name="color0" value="0.05"/>'
            '<float name="color1" value="0.3"/></texture></bsdf></shape>')  # fmt: skip
    _, desc = _read(tmp_path, body)
    # the material descriptions without the scene's one_sided flag (Mitsuba: not in twosided)
    rc, df = ({k: v for k, v in desc["materials"][n].items() if k != "one_sided"}
              for n in desc["materials"])  # fmt: skip
    at_rc = material_from_desc(rc).at(jnp.asarray(UV))
    at_df = material_from_desc(df).at(jnp.asarray(UV))
    np.testing.assert_allclose(at_rc.distribution.alpha_u, np.where(EVAL_IS_C0, 0.3, 0.05))
    np.testing.assert_allclose(at_df.reflectance[:, 0], np.where(EVAL_IS_C0, 0.05, 0.3))


@pytest.mark.mitsuba
def test_checkerboard_eval_and_eval_1_patterns_match_mitsuba():
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    tex = mi.load_dict({"type": "checkerboard", "color0": 0.05, "color1": 0.3})
    si = mi.SurfaceInteraction3f()
    for (u, v), c0 in zip(UV, EVAL_IS_C0, strict=True):
        si.uv = mi.Point2f(u, v)
        assert float(tex.eval(si)[0]) == pytest.approx(0.05 if c0 else 0.3)
        assert float(tex.eval_1(si)) == pytest.approx(0.3 if c0 else 0.05)


# ----------------------------------------------------- constant masks on tessellated shapes


@pytest.mark.parametrize("shape", ["cube", "disk", "cylinder"])
def test_constant_and_textured_masks_on_tessellated_shapes_load(tmp_path, shape):
    mask = ('<bsdf type="mask"><float name="opacity" value="0.3"/><bsdf type="twosided">'
            '<bsdf type="diffuse"/></bsdf></bsdf>')  # fmt: skip
    at = '<transform name="to_world"><translate z="5"/></transform>'
    _, desc = _read(tmp_path, f'<shape type="{shape}">{at}{mask}</shape>')
    (m,) = desc["materials"].values()
    assert m["type"] == "mask" and m["opacity"] == 0.3
    tex = mask.replace('<float name="opacity" value="0.3"/>',
                       '<texture name="opacity" type="checkerboard"/>')  # fmt: skip
    # textured since the cube / disk / cylinder carry Mitsuba's uv layouts (test_shape_uv.py)
    _, desc = _read(tmp_path, f'<shape type="{shape}">{at}{tex}</shape>')
    (m,) = desc["materials"].values()
    assert m["type"] == "mask" and m["opacity"]["type"] == "checkerboard"


# ------------------------------------------------------------------------------ rawconstant


def test_rawconstant_values_and_errors(tmp_path):
    def nm(value):
        return (
            '<shape type="sphere"><bsdf type="normalmap"><texture name="normalmap" '
            f'type="rawconstant">{value}</texture><bsdf type="diffuse"/></bsdf></shape>'
        )

    _, desc = _read(tmp_path, nm('<vector name="value" x="0.5" y="0.5" z="1"/>'))
    (m,) = desc["materials"].values()
    assert m["normalmap"] == [0.5, 0.5, 1.0]  # read as written (no sRGB decoding)
    _, desc = _read(tmp_path, nm('<rgb name="value" value="0.2, 0.5, 0.9"/>'))
    assert next(iter(desc["materials"].values()))["normalmap"] == [0.2, 0.5, 0.9]
    _, desc = _read(tmp_path, '<shape type="sphere"><bsdf type="roughconductor"><texture '
                              'name="alpha" type="rawconstant"><float name="value" '
                              'value="0.2"/></texture></bsdf></shape>')  # fmt: skip
    assert next(iter(desc["materials"].values()))["alpha"] == 0.2
    for value, msg in (
        ("", "missing parameter 'value'"),
        ('<string name="value" value="x"/>', "value"),
        ('<vector name="value" x="0.5" y="0.5" z="1"/><float name="scale" value="2"/>',
         "parameter 'scale' is not supported"),
    ):  # fmt: skip
        with pytest.raises(ValueError, match=msg) as e:
            _read(tmp_path, nm(value))
        assert re.search(r"s\.xml:\d+", str(e.value)), str(e.value)  # file and line


# ------------------------------------------------------------------------------ bitmap to_uv

IMG = np.arange(12.0).reshape(3, 4, 1)
M = ((2.0, 0.0, -0.5), (0.5, 2.0, -0.25))  # u' = 2u - 0.5, v' = 0.5u + 2v - 0.25


@jax.jit
def _lookup(tex, uv):
    return lookup(tex, uv)


def test_to_uv_is_applied_before_the_lookup():
    uv = jnp.asarray([[0.3, 0.4], [0.62, 0.17], [0.9, 0.8]])
    uv2 = np.stack([2 * uv[:, 0] - 0.5, 0.5 * uv[:, 0] + 2 * uv[:, 1] - 0.25], -1)
    for wrap in ("repeat", "mirror", "clamp"):
        for filt in ("bilinear", "nearest"):
            a = _lookup(Texture(IMG, wrap=wrap, filter=filt, to_uv=M), uv)
            b = _lookup(Texture(IMG, wrap=wrap, filter=filt), jnp.asarray(uv2))
            np.testing.assert_allclose(a, b, rtol=1e-6)
    # closed form (bilinear, inside the image): texel (i, j) centred at ((j + .5)/4, (i + .5)/3)
    x, y = 0.4 * 4 - 0.5, 0.4 * 3 - 0.5  # uv' = (0.4, 0.4) from uv = (0.45, 0.2125)
    j, i = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - j, y - i
    want = ((1 - fy) * ((1 - fx) * IMG[i, j] + fx * IMG[i, j + 1])
            + fy * ((1 - fx) * IMG[i + 1, j] + fx * IMG[i + 1, j + 1]))  # fmt: skip
    got = _lookup(Texture(IMG, to_uv=M), jnp.asarray([[0.45, 0.2125]]))
    np.testing.assert_allclose(got[0], want, rtol=1e-6)


def test_to_uv_errors(tmp_path):
    for m, msg in (
        (np.eye(3) + np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0]]), "expected an affine map"),
        (np.eye(2), "expected a finite 2 x 3"),
        ([[1.0, 0.0, np.nan], [0.0, 1.0, 0.0]], "expected a finite 2 x 3"),
    ):
        with pytest.raises(ValueError, match="to_uv: " + msg):
            Texture(IMG, to_uv=m)
    with pytest.raises(ValueError, match=r"reflectance\.to_uv: expected a finite 2 x 3"):
        material_from_desc({"type": "diffuse", "reflectance": {"type": "bitmap", "image": IMG,
                                                               "to_uv": [[1.0, 0.0]]}})  # fmt: skip
    assert check_uv_transform(np.eye(3), "m") == ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    # XML: a projective to_uv (last row not 0 0 0 1) is refused with file and line
    body = ('<shape type="sphere"><bsdf type="diffuse"><texture name="reflectance" '
            'type="bitmap"><string name="filename" value="t.exr"/><transform name="to_uv">'
            '<matrix value="1 0 0 0 0 1 0 0 0 0 1 0 0.5 0 0 1"/></transform></texture></bsdf>'
            "</shape>")  # fmt: skip
    from jaxgfx import io

    io.write_exr(str(tmp_path / "t.exr"), np.ones((2, 2, 3), np.float32))
    with pytest.raises(ValueError, match=r"s\.xml:\d+: .*to_uv.*expected an affine transform"):
        _read(tmp_path, body)


def test_bump_map_honours_to_uv():
    """``h(M uv)``: the bump normal at ``uv`` with ``to_uv = 2 uv`` is the one of the plain
    texture at ``2 uv`` with twice the scale (chain rule through the lookup)."""
    rng = np.random.default_rng(0)
    img = rng.uniform(size=(8, 8, 1))
    rows = lambda r: jnp.asarray([r] * 3)  # noqa: E731
    tg = TangentSpace(s=rows([1.0, 0, 0]), t=rows([0.0, 1, 0]), du=rows([1.0, 0.2]),
                      dv=rows([0.1, 1.0]))  # fmt: skip
    uv = jnp.asarray([[0.13, 0.21], [0.3, 0.07], [0.41, 0.33]])
    a = BumpMap(Diffuse(0.5), Texture(img, to_uv=((2.0, 0, 0), (0, 2.0, 0))), 0.3)
    b = BumpMap(Diffuse(0.5), Texture(img), 0.6)
    na = jax.jit(lambda m, q: m._normal(q, tg))(a, uv)
    nb = jax.jit(lambda m, q: m._normal(q, tg))(b, 2 * uv)
    np.testing.assert_allclose(na, nb, rtol=1e-5, atol=1e-7)
    assert not np.allclose(na, jax.jit(lambda m, q: m._normal(q, tg))(b, uv), atol=1e-3)


@pytest.mark.mitsuba
def test_bitmap_to_uv_matches_mitsuba():
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(1)
    img = rng.uniform(size=(5, 7, 3))
    t4 = mi.ScalarTransform4f().translate([-0.5, -0.25, 0]) @ mi.ScalarTransform4f().scale(
        [2.0, 3.0, 1.0]
    )
    m = np.array(t4.matrix)
    to_uv = ((m[0, 0], m[0, 1], m[0, 3]), (m[1, 0], m[1, 1], m[1, 3]))
    uv = rng.uniform(size=(16, 2))
    for wrap in ("repeat", "mirror", "clamp"):
        for filt in ("bilinear", "nearest"):
            ref = mi.load_dict({"type": "bitmap", "data": mi.TensorXf(img), "raw": True,
                                "to_uv": t4, "wrap_mode": wrap, "filter_type": filt})  # fmt: skip
            ours = _lookup(Texture(img, wrap=wrap, filter=filt, to_uv=to_uv), jnp.asarray(uv))
            si = mi.SurfaceInteraction3f()
            for k in range(len(uv)):
                si.uv = mi.Point2f(*uv[k])
                np.testing.assert_allclose(ours[k], np.array(ref.eval(si)), rtol=1e-4, atol=1e-5)
