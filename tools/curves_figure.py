"""The figure of docs/render.md's "Curves: ``linearcurve``": a tuft of grass (120 blades of
5 segments each, tapering from 0.02 to 0.004, random lean and bend; numpy seed 0) on a diffuse
ground under a sun and a constant sky, rendered by jaxgfx (path tracer, max_depth 3) and, when
``mitsuba`` is installed, by Mitsuba 3 from the same description (``render_mitsuba``). Run from
the repository root::

    JAX_PLATFORMS=cpu python tools/curves_figure.py [--res 128] [--spp 32]
        [--out docs/images/render_curves.png]

Prints the scene's segment count, both images' channel means and the process CPU seconds of
each render (compile included for jaxgfx).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]


def grass(n_blades=120, n_points=6, seed=0):
    """Curves ``[[x, y, z, radius], ...]`` of a tuft of grass blades (y up)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    curves = []
    for _ in range(n_blades):
        r0 = 0.6 * np.sqrt(rng.random())
        phi = 2 * np.pi * rng.random()
        base = np.array([r0 * np.cos(phi), 0.0, r0 * np.sin(phi)])
        lean = rng.normal(0, 0.25, 2)
        height = 0.6 + 0.5 * rng.random()
        s = np.linspace(0, 1, n_points)[:, None]
        bend = s**2 * np.array([lean[0], 0, lean[1]])
        pts = base + s * np.array([0, height, 0]) + bend
        radius = 0.02 - 0.016 * s
        curves.append(np.concatenate([pts, radius], 1).tolist())
    return curves


def scene(res):
    return {
        "camera": {"origin": [0, 0.7, 2.6], "target": [0, 0.45, 0], "fov": 40,
                   "width": res, "height": res * 3 // 4},
        "materials": {"grass": {"type": "diffuse", "reflectance": [0.18, 0.45, 0.08]},
                      "ground": {"type": "diffuse", "reflectance": [0.35, 0.28, 0.2]}},
        "shapes": [{"type": "linearcurve", "curves": grass(), "material": "grass"},
                   {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 1, 0],
                    "size": [6, 6], "material": "ground"}],
        "emitters": [{"type": "directional", "direction": [-0.5, -1, -0.4],
                      "irradiance": [2.5, 2.4, 2.2]},
                     {"type": "constant", "radiance": [0.35, 0.4, 0.5]}],
    }  # fmt: skip


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "render_curves.png"))
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from _figure import jaxgfx_and_mitsuba_figure

    from jaxgfx.render import load_scene

    desc = scene(a.res)
    sc = load_scene(desc)
    print(f"{sum(getattr(s, 'segment_count', 0) for s in sc.shapes)} segments")
    jaxgfx_and_mitsuba_figure(desc, a.spp, a.out, scene=sc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
