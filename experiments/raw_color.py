"""Colour of a RAW merge against the scene's true colours (issue 26): a synthetic Canon EOS 5D
Mark II DNG bracket (hdr.write_dng_bracket), merged by `jaxgfx calibrate` with
``colorspace: camera`` (the old output) and ``rec709`` (the default); prints JSON with the
median CIEDE2000 of 4x4-block means (white = the brightest true block), over all blocks and
over blocks >= 2 px from a patch edge (no demosaicing fringe).

    python -m experiments.raw_color [--seed 1] [--patch 16]
"""

from __future__ import annotations

import argparse
import json
import tempfile

import jax.numpy as jnp
import numpy as np

from jaxgfx import color, hdr, io
from jaxgfx.pipelines.calibrate import CalibrateConfig, CalibrateJob, run_calibrate


def block_de(est, truth, b=4, interior=False):
    m = color.rgb_to_xyz_matrix("rec709")
    E, T, keep = [], [], []
    for i in range(0, truth.shape[0] - b + 1, b):
        for j in range(0, truth.shape[1] - b + 1, b):
            nb = truth[max(i - 2, 0) : i + b + 2, max(j - 2, 0) : j + b + 2].reshape(-1, 3)
            keep.append(np.ptp(nb, 0).max() == 0 or not interior)
            E.append(est[i : i + b, j : j + b].reshape(-1, 3).mean(0))
            T.append(truth[i : i + b, j : j + b].reshape(-1, 3).mean(0))
    E, T = np.array(E)[keep], np.array(T)[keep]
    s = 1.0 / (T @ m[1]).max()

    def lab(x):
        return color.xyz_to_lab(jnp.asarray((x * s) @ m.T, jnp.float32), white="D65")

    return np.asarray(color.delta_e_2000(lab(E), lab(T)))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--patch", type=int, default=16)
    args = p.parse_args(argv)
    out = {"seed": args.seed, "patch_px": args.patch}
    with tempfile.TemporaryDirectory() as d:
        paths, truth = hdr.write_dng_bracket(f"{d}/dng", seed=args.seed, patch=args.patch)
        for cs in ("camera", "rec709"):
            job = CalibrateJob(CalibrateConfig(colorspace=cs), paths, f"{d}/{cs}", progress=False)
            rep = run_calibrate(job)
            rad = io.read_exr(rep["outputs"]["radiance"])
            out[cs] = {
                "median_de2000_all_blocks": round(float(np.median(block_de(rad, truth))), 3),
                "median_de2000_interior_blocks": round(
                    float(np.median(block_de(rad, truth, interior=True))), 3
                ),
            }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
