"""The figure of docs/render_geometry.md's "Ellipsoids" section: 24 rotated anisotropic
ellipsoids (Mitsuba 3's ``ellipsoids`` shape, extent 1; numpy seed 0) in two shapes, a diffuse
one and a rough-plastic one, on a diffuse floor under a rectangular area light and a dim
constant sky, rendered by jaxgfx (path tracer, max_depth 3) and, when ``mitsuba`` is
installed, by Mitsuba 3 from the same description (``render_mitsuba``: the ellipsoids go to
Mitsuba as PLY files). Run from the repository root::

    JAX_PLATFORMS=cpu python tools/ellipsoids_figure.py [--res 160] [--spp 64]
        [--out docs/images/render_ellipsoids.png]

Prints both images' channel means and the process CPU seconds of each render (compile
included for jaxgfx).
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]


def ellipsoids(n, seed):
    """``(centers, scales, quaternions x y z w)`` lists of ``n`` ellipsoids resting near the
    floor (y = 0)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    s = rng.uniform(0.08, 0.3, (n, 3))
    c = np.c_[rng.uniform(-1.3, 1.3, n), s.min(1) * 0.8, rng.uniform(-0.9, 0.9, n)]
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    half = rng.uniform(0, math.pi / 2, (n, 1))
    q = np.c_[axis * np.sin(half), np.cos(half)]
    return c.tolist(), s.tolist(), q.tolist()


def scene(res):
    c0, s0, q0 = ellipsoids(12, 0)
    c1, s1, q1 = ellipsoids(12, 1)
    return {
        "camera": {"origin": [0, 1.5, -3.2], "target": [0, 0.1, 0], "fov": 42,
                   "width": res, "height": res * 3 // 4},
        "materials": {"clay": {"type": "diffuse", "reflectance": [0.7, 0.42, 0.2]},
                      "glaze": {"type": "roughplastic", "alpha": 0.15,
                                "diffuse_reflectance": [0.1, 0.25, 0.6]},
                      "floor": {"type": "diffuse", "reflectance": [0.45, 0.45, 0.42]}},
        "shapes": [
            {"type": "ellipsoids", "centers": c0, "scales": s0, "quaternions": q0,
             "extent": 1.0, "material": "clay"},
            {"type": "ellipsoids", "centers": c1, "scales": s1, "quaternions": q1,
             "extent": 1.0, "material": "glaze"},
            {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 1, 0], "size": [8, 8],
             "material": "floor"}],
        "emitters": [{"type": "area", "radiance": [5, 4.8, 4.4],
                      "shape": {"type": "rectangle", "center": [1, 2.6, -0.6],
                                "normal": [0, -1, 0], "size": [1.2, 1.2]}},
                     {"type": "constant", "radiance": [0.08, 0.09, 0.11]}],
    }  # fmt: skip


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=160)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "render_ellipsoids.png"))
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from _figure import jaxgfx_and_mitsuba_figure

    jaxgfx_and_mitsuba_figure(scene(a.res), a.spp, a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
