"""How Mitsuba 3's own renders score against a mitsuba-data reference (calibrates test tolerances).

Usage: ``PYTHONPATH=$PWD python tools/mitsuba_reference_noise.py SCENE.xml REF_rgb.exr
[VAR.exr ...] [--renders N] [--spp S] [--seed0 K]`` (Mitsuba 3 in the environment; variant
``llvm_ad_rgb`` when ``DRJIT_LIBLLVM_PATH`` is set, else ``scalar_rgb``).

Renders the scene ``N`` times (seeds ``K .. K+N-1``, ``S`` spp) and scores each render against
the reference with the statistics of ``tests/render/test_mitsuba_xml_render.py`` (``compare``),
once with the reference's own ``*_rgb_var.exr`` and once with each extra variance image given
(e.g. a ``*_samplevar.exr`` of ``tools/mitsuba_sample_variance.py``). Prints per variance image:
the fraction of negative pixels per channel, the standard deviation and largest ``|z|`` of the
channel means, the block z RMS (median, min, max), the smallest fraction of blocks with
``|z| < 3.5`` and the median block relative RMSE against the noise level. A calibrated variance
gives standard deviation ~1 and block z RMS ~1 for Mitsuba itself. The numbers quoted in
docs/render_scenes.md (the ¶ and (*) notes) come from this tool with ``--renders 64 --seed0
1000`` (¶) and ``--renders 32 --seed0 1000`` ((*)), llvm_ad_rgb, 16 spp.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("ref")
    ap.add_argument("var", nargs="*")
    ap.add_argument("--renders", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seed0", type=int, default=1000)
    a = ap.parse_args(argv)
    import mitsuba as mi

    from jaxgfx import io
    from tests.render.test_mitsuba_xml_render import compare, refs

    mi.set_variant("llvm_ad_rgb" if os.environ.get("DRJIT_LIBLLVM_PATH") else "scalar_rgb")
    scene = mi.load_file(a.scene)
    imgs = [np.asarray(mi.render(scene, spp=a.spp, seed=a.seed0 + k), np.float64)[..., :3]
            for k in range(a.renders)]  # fmt: skip
    ref, var0 = refs(a.ref)
    np.set_printoptions(precision=3, suppress=True)
    for label, var in [("reference variance", var0)] + [
        (p, np.asarray(io.read_any(p), np.float64)[..., :3]) for p in a.var
    ]:
        cs = [compare(img, ref, var, a.spp) for img in imgs]
        zm = np.array([c["z_mean"] for c in cs])
        zr = np.array([c["z_rms"] for c in cs])
        print(f"{label}: negative pixels {(var < 0).mean((0, 1))}; channel-mean z std "
              f"{zm.std(0)}, max |z| {np.abs(zm).max(0)}; block z RMS median "
              f"{np.median(zr):.2f} (min {zr.min():.2f}, max {zr.max():.2f}); blocks |z| < 3.5 "
              f"min {min(c['frac_3_5'] for c in cs):.3f}; rel. RMSE median "
              f"{np.median([c['rel_rmse'] for c in cs]):.3f} (noise "
              f"{cs[0]['noise_rel_rmse']:.3f})")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
