"""Mitsuba's path replay backpropagation integrators ``prb`` / ``prb_basic`` (issue 24) read as
jaxgfx's ``PathIntegrator(adjoint="replay")``: Mitsuba's defaults (max_depth 6, rr_depth 5),
``prb_basic``'s BSDF-only sampling without Russian roulette, the refusals, and the writer round
trip."""

import pytest

from jaxgfx.render.estimator import resolve_integrator
from jaxgfx.render.integrators import PathIntegrator
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

XML = """<scene version="3.0.0">
  <integrator type="{kind}">{body}</integrator>
  <sensor type="perspective"><float name="fov" value="40"/>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film>
  </sensor>
  <shape type="sphere"><point name="center" x="0" y="0" z="5"/></shape>
  <emitter type="constant"/>
</scene>
"""


def _read(tmp_path, kind, body=""):
    p = tmp_path / "s.xml"
    p.write_text(XML.format(kind=kind, body=body))
    return read_xml(str(p))


def test_prb_is_the_replay_path_integrator(tmp_path):
    x = _read(tmp_path, "prb")
    assert (x.integrator, x.max_depth, x.rr_depth, x.adjoint, x.strategy) == (
        "path", 6, 5, "replay", "mis")  # Mitsuba's ADIntegrator defaults  # fmt: skip
    integ = resolve_integrator(x.integrator_spec)
    assert isinstance(integ, PathIntegrator)
    assert (integ.max_depth, integ.rr_depth, integ.adjoint, integ.strategy) == (6, 5, "replay",
                                                                                 "mis")  # fmt: skip
    x = _read(tmp_path, "prb", '<integer name="max_depth" value="-1"/>'
                               '<integer name="rr_depth" value="3"/>')  # fmt: skip
    assert (x.max_depth, x.rr_depth) == (None, 3)
    assert "max_depth" not in x.integrator_spec
    b = _read(tmp_path, "prb_basic", '<integer name="max_depth" value="4"/>')
    # BSDF sampling only and Russian roulette never reached (rr_depth = max_depth)
    assert (b.max_depth, b.rr_depth, b.adjoint, b.strategy) == (4, 4, "replay", "bsdf")
    integ = resolve_integrator(b.integrator_spec)
    assert (integ.strategy, integ.adjoint, integ.rr_depth) == ("bsdf", "replay", 4)
    p = _read(tmp_path, "path")  # unchanged for path
    assert (p.adjoint, p.strategy, p.max_depth) == ("ad", "mis", None)
    assert resolve_integrator(p.integrator_spec).adjoint == "ad"


@pytest.mark.parametrize(("kind", "body", "match"), [
    ("prb", '<boolean name="hide_emitters" value="true"/>', r"s.xml:2: .*hide_emitters"),
    ("prb_basic", '<integer name="max_depth" value="0"/>', "max_depth -1 or >= 1"),
    ("prb", '<integer name="rr_depth" value="0"/>', "rr_depth >= 1"),
])  # fmt: skip
def test_prb_refusals_name_the_file_and_line(tmp_path, kind, body, match):
    with pytest.raises(ValueError, match=match):
        _read(tmp_path, kind, body)


@pytest.mark.parametrize("kind", ["prb", "prb_basic"])
def test_prb_is_written_back(tmp_path, kind):
    x = _read(tmp_path, kind, '<integer name="max_depth" value="5"/>')
    w = save_scene(load_scene(x.desc), str(tmp_path / "w.xml"), integrator=kind, max_depth=5,
                   rr_depth=x.rr_depth)  # fmt: skip
    with open(w) as f:
        assert f'<integrator type="{kind}"' in f.read()
    y = read_xml(w)
    assert (y.integrator_spec, y.rr_depth) == (x.integrator_spec, x.rr_depth)
    w = save_scene(load_scene(x.desc), str(tmp_path / "u.xml"), integrator=kind)
    assert read_xml(w).max_depth is None  # Mitsuba's -1
