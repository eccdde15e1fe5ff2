"""The figure of docs/render.md's "Sun and sky: ``sunsky``": a diffuse sphere on a diffuse plane
under the sunsky (turbidity 3, the sun at two elevations, out of view) rendered by jaxgfx and by
Mitsuba 3 (``scalar_rgb``, the same scene written by ``to_mitsuba_dict``), side by side; also
prints the image means, the 8 x 8 block z of K replicate renders each
(``tests/render/_scenes.replicate_block_z``) and the sky's agreement at 20 000 directions. Run
from the repository root (needs Mitsuba 3)::

    JAX_PLATFORMS=cpu python tools/sunsky_figure.py [--res 64] [--spp 64] [--k 4]
        [--out docs/images/render_sunsky.png]

(~2 min on 2 shared cores at the defaults.) Shown with exposure x3 and the sRGB curve.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
ELEVATIONS = (8.0, 45.0)


def _scene(elev, res):
    e, a = math.radians(elev), math.radians(-120.0)
    sun = [math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]
    return {
        "camera": {"origin": [0.0, -4.0, 1.0], "target": [0.0, 0.0, 0.8], "up": [0, 0, 1],
                   "fov": 60, "width": res, "height": res},  # fmt: skip
        "shapes": [{"type": "sphere", "center": [0.0, 0.0, 0.5], "radius": 0.5, "material": "d"},
                   {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 0, 1],
                    "size": [40, 40], "material": "g"}],  # fmt: skip
        "materials": {"d": {"type": "diffuse", "reflectance": [0.7, 0.5, 0.3]},
                      "g": {"type": "diffuse", "reflectance": 0.4}},  # fmt: skip
        "emitters": [{"type": "sunsky", "sun_direction": sun, "turbidity": 3.0}],
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--k", type=int, default=4, help="replicate renders per renderer")
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "render_sunsky.png"))
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    import jax
    import jax.numpy as jnp
    import matplotlib
    import mitsuba as mi

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from _figure import save_figure, srgb_display

    from jaxgfx.render import load_scene, render
    from jaxgfx.render.scene.mitsuba import to_mitsuba_dict
    from jaxgfx.render.sunsky import SunSky
    from tests.render._scenes import replicate_block_z

    mi.set_variant("scalar_rgb")
    f = jax.jit(jax.vmap(lambda s, k: render(s, k, spp=a.spp, integrator="path", max_depth=3),
                         in_axes=(None, 0)))  # fmt: skip
    fig, axes = plt.subplots(2, 2, figsize=(6.4, 6.8), dpi=100)
    for row, elev in enumerate(ELEVATIONS):
        desc = _scene(elev, a.res)
        ours = np.asarray(f(load_scene(desc), jax.random.split(jax.random.key(row), a.k)))
        md = to_mitsuba_dict(desc, mi=mi)
        md["integrator"] = {"type": "path", "max_depth": 3}
        ms = mi.load_dict(md)
        theirs = np.stack([np.array(mi.render(ms, spp=a.spp, seed=s))[..., :3]
                           for s in range(a.k)]).astype(np.float64)  # fmt: skip
        z = replicate_block_z(ours.astype(np.float64), theirs)[0]
        m_ours = ours.astype(np.float64).mean((0, 1, 2)).round(4).tolist()
        print(f"sun at {elev:g} deg: image mean jaxgfx {m_ours} "
              f"Mitsuba {theirs.mean((0, 1, 2)).round(4).tolist()}; 8 x 8 block |z| max "
              f"{z.max():.2f}, RMS {math.sqrt((z**2).mean()):.2f} ({z.size} block channels)")
        for col, (img, who) in enumerate(((ours, "jaxgfx"), (theirs, "Mitsuba 3.9.1"))):
            ax = axes[row, col]
            ax.imshow(srgb_display(img.mean(0), 3.0))
            ax.set_title(f"{who}, sun at {elev:g}°", fontsize=9)
            ax.axis("off")
        # the sky alone: eval at 20 000 upper directions against Mitsuba's
        rng = np.random.default_rng(row)
        d = rng.normal(size=(20_000, 3))
        d[:, 2] = np.abs(d[:, 2])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        sun = np.asarray(desc["emitters"][0]["sun_direction"])
        sky = SunSky.create(sun, turbidity=3.0)
        e_ours = np.asarray(jax.jit(lambda e, x: e.eval(x))(sky, jnp.asarray(d, jnp.float32)))
        em = mi.load_dict({"type": "sunsky", "sun_direction": sun.tolist(), "turbidity": 3.0})
        si = mi.SurfaceInteraction3f()
        e_mi = []
        for x in d:
            si.wi = mi.Vector3f(*(-x))
            e_mi.append(np.array(em.eval(si)))
        e_mi = np.array(e_mi, np.float64)
        rel = np.abs(e_ours - e_mi).max(1) / np.abs(e_mi).max(1)
        print(f"  eval at 20000 directions: max relative difference {rel.max():.2e}, "
              f"median {np.median(rel):.2e}")
    fig.suptitle(f"sunsky, turbidity 3: path depth 3, {a.res}², {a.k} x {a.spp} spp each",
                 fontsize=10)  # fmt: skip
    fig.tight_layout()
    save_figure(fig, a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
