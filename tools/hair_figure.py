"""The figure of docs/render_bsdf.md's ``hair`` section: six vertical cylinders with Mitsuba's
``hair`` BSDF (Chiang et al. 2016), their colour set by the melanin concentrations only
(eumelanin / pheomelanin, left to right: 0.05/0, 0.3/0, 0.8/0.2, 1.3/0.2 (Mitsuba's default),
0.4/1.5 (red), 8/0 (black)), β_m = 0.25, β_n = 0.3, α = 2°, under a point light and a dim
environment, rendered by jaxgfx (path, depth 6; the cylinders fill the frame's height). Run
from the repository root::

    JAX_PLATFORMS=cpu python tools/hair_figure.py [--width 288] [--height 112] [--spp 64]
        [--out docs/images/render_hair_melanin.png]

(~1 min of CPU, a few minutes wall-clock on 2 shared cores at load 11, at the defaults.) The
cylinder's uv puts the fibre axis along the cylinder (docs/render_bsdf.md, the ``h``
convention). Shown with the sRGB curve (``jaxgfx.color.transfer.linear_to_srgb``).
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[1]

MELANIN = [(0.05, 0.0), (0.3, 0.0), (0.8, 0.2), (1.3, 0.2), (0.4, 1.5), (8.0, 0.0)]

XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="6"/></integrator>
  <sensor type="perspective"><float name="fov" value="24"/>
    <transform name="to_world"><lookat origin="0, 0, 10" target="0, 0, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="{w}"/><integer name="height" value="{h}"/>
      <rfilter type="box"/></film>
  </sensor>
  {shapes}
  <emitter type="point"><point name="position" x="-3" y="4" z="6"/>
    <rgb name="intensity" value="60"/></emitter>
  <emitter type="constant"><rgb name="radiance" value="0.05"/></emitter>
</scene>
"""
SHAPE = """<shape type="cylinder"><float name="radius" value="0.32"/>
    <transform name="to_world"><scale z="3"/><rotate x="1" angle="-90"/>
      <translate x="{x}" y="-1.5"/>
    </transform>
    <bsdf type="hair"><float name="eumelanin" value="{eu}"/>
      <float name="pheomelanin" value="{ph}"/>
      <float name="longitudinal_roughness" value="0.25"/></bsdf></shape>"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--width", type=int, default=288)
    ap.add_argument("--height", type=int, default=112)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "render_hair_melanin.png"))
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    import jax
    from _figure import srgb_display

    from jaxgfx import io
    from jaxgfx.render import load_scene, render
    from jaxgfx.render.scene.mitsuba_xml import read_xml

    n = len(MELANIN)
    shapes = "\n  ".join(SHAPE.format(x=0.8 * (i - (n - 1) / 2), eu=eu, ph=ph)
                         for i, (eu, ph) in enumerate(MELANIN))  # fmt: skip
    with tempfile.TemporaryDirectory() as d:
        path = pathlib.Path(d) / "hair.xml"
        path.write_text(XML.format(w=a.width, h=a.height, shapes=shapes))
        x = read_xml(str(path))
    scene = load_scene(x.desc)
    img = render(scene, jax.random.key(0), spp=a.spp, integrator=x.integrator,
                 max_depth=x.max_depth)  # fmt: skip
    img = srgb_display(img)
    io.write_png(a.out, img)
    print(a.out, img.shape, "mean", img.mean((0, 1)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
