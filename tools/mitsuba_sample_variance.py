"""Per-pixel sample variance of a Mitsuba 3 scene from independent renders (test tolerances).

Usage: ``python tools/mitsuba_sample_variance.py SCENE.xml OUT.exr [--renders N] [--spp S]``
(Mitsuba 3 in the environment; variant ``llvm_ad_rgb`` when ``DRJIT_LIBLLVM_PATH`` is set,
else ``scalar_rgb``).

mitsuba-data's ``*_ref_rgb_var.exr`` images (``moment`` integrator) are negative in up to 13 %
of the pixels of some scenes and near zero in many 4×4 blocks, so a block z computed from them
is meaningless there: Mitsuba's own 16-spp renders of ``bsdf_spheres/test_envmap`` give a block
z RMS of 6-85 (median 29) against the reference with those variances
(docs/render_scenes.md). This tool renders the scene ``N`` times with seeds ``0 .. N-1`` at
``S`` spp (the ``moment`` wrapper's first three channels: the RGB estimate) and writes
``S * var_n(image_n)`` (float64 sample variance over the renders, ``ddof = 1``): the variance of
one sample, as the reference variance images mean it, for ``N S`` samples per pixel.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("out")
    ap.add_argument("--renders", type=int, default=256)
    ap.add_argument("--spp", type=int, default=32)
    a = ap.parse_args(argv)
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb" if os.environ.get("DRJIT_LIBLLVM_PATH") else "scalar_rgb")
    t = time.time()
    scene = mi.load_file(a.scene)
    s1 = s2 = 0.0
    for seed in range(a.renders):
        img = np.asarray(mi.render(scene, spp=a.spp, seed=seed), np.float64)[..., :3]
        s1, s2 = s1 + img, s2 + img * img
    n = a.renders
    mean = s1 / n
    var = np.maximum(s2 - n * mean * mean, 0.0) / (n - 1) * a.spp
    from jaxgfx import io

    io.write_exr(a.out, var.astype(np.float32))
    print(f"{a.scene}: {n} renders x {a.spp} spp in {time.time() - t:.1f} s; mean "
          f"{mean.mean((0, 1))}, mean sample variance {var.mean((0, 1))}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
