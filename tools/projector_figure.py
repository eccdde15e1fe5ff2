"""The figure of docs/render.md's "Lights: spot texture and projector": configs/scenes/projector.xml
(a projector casting ``projector_slide.png`` and a spot casting ``projector_gobo.png`` onto a
diffuse floor) rendered by jaxgfx, beside the two images as they are stored. Run from the
repository root::

    JAX_PLATFORMS=cpu python tools/projector_figure.py [--res 192] [--spp 64]
        [--out docs/images/render_projector.png]

(~1 min on 2 shared cores at the defaults.) The render is shown with exposure x4 and the sRGB
curve (``jaxgfx.color.transfer.linear_to_srgb``); the images as their PNGs encode them.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=192)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "render_projector.png"))
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    import jax
    import matplotlib
    from _figure import save_figure, srgb_display

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from jaxgfx import io
    from jaxgfx.render import load_scene, render
    from jaxgfx.render.scene.mitsuba_xml import read_xml

    scenes = ROOT / "configs" / "scenes"
    x = read_xml(str(scenes / "projector.xml"), res=str(a.res), spp=str(a.spp))
    img = render(load_scene(x.desc), jax.random.key(0), spp=a.spp, integrator=x.integrator,
                 max_depth=x.max_depth)  # fmt: skip
    shown = srgb_display(img, 4.0)
    slide = io.read_image(str(scenes / "projector_slide.png"))
    gobo = io.read_image(str(scenes / "projector_gobo.png"))
    fig = plt.figure(figsize=(8.4, 4.2), dpi=100)
    ax = fig.add_axes([0.0, 0.0, 0.6, 0.92])
    ax.imshow(shown)
    ax.set_title(f"jaxgfx, direct, {a.res}², {a.spp} spp", fontsize=9)
    ax.axis("off")
    for k, (im, title) in enumerate([(slide, "projector irradiance (12 x 9)"),
                                     (gobo, "spot texture (8 x 8)")]):  # fmt: skip
        ax = fig.add_axes([0.64, 0.52 - 0.48 * k, 0.34, 0.38])
        ax.imshow(np.asarray(im)[..., :3], interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    save_figure(fig, a.out)
    print(f"wrote {a.out}; image mean {np.asarray(img).mean(axis=(0, 1)).round(4).tolist()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
