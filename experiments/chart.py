"""Colour-chart calibration of a RAW bracket (issue 26): a synthetic Canon EOS 5D Mark II DNG
bracket of a ColorChecker in perspective (hdr.colorchecker_scene, hdr.write_dng_bracket), whose
files carry the camera's published ColorMatrix1/2 mixed by up to ``--mix`` (a profile that is
off; 0: the true one), merged by `jaxgfx calibrate --chart ...` with each chart model; prints
JSON with the per-model median / max CIEDE2000 of the 24 patches before (the file's matrix) and
after the fit, and of radiance.exr's patches against the reference (white patch = reference).

    python -m experiments.chart [--seed 3] [--mix 0.12] [--figure docs/images/chart.png]
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile

import numpy as np

from jaxgfx import color, hdr, io
from jaxgfx.hdr.raw import CHART_MODELS, chart_patch_means, colorchecker_reference
from jaxgfx.pipelines.calibrate import CalibrateConfig, CalibrateJob, run_calibrate

CORNERS = np.array([[10.3, 8.6], [101.2, 12.4], [98.7, 71.5], [12.8, 68.2]])


def write_bracket(folder, *, seed: int = 3, mix: float = 0.12):
    """The bracket (80x112, 3 frames 2 EV apart, 60 000 e- at white, 2 DN read noise)."""
    cam = hdr.CANON_EOS_5D_MARK_II
    m = np.eye(3) + mix * np.array([[0.0, 1.0, -0.5], [-0.4, 0.0, 0.8], [0.7, -0.8, 0.0]])
    tagged = {**cam, **{k: m @ np.asarray(cam[k]) for k in ("color_matrix1", "color_matrix2")}}
    scene = hdr.colorchecker_scene(80, 112, CORNERS)
    paths, _ = hdr.write_dng_bracket(folder, height=80, width=112, scene=scene, seed=seed,
                                     camera=tagged, true_camera=cam)  # fmt: skip
    return paths


def radiance_delta_e(radiance) -> np.ndarray:
    """ΔE00 of radiance.exr's (linear Rec.709) patches against the ColorChecker reference."""
    rgb = np.asarray(chart_patch_means(radiance, CORNERS), np.float64)
    cat = np.asarray(color.chromatic_adaptation_matrix("D65", "D50"), np.float64)
    xyz = rgb @ (cat @ color.rgb_to_xyz_matrix("rec709")).T
    ref = colorchecker_reference().xyz
    xyz = xyz * ref[18, 1] / xyz[18, 1]

    def lab(x):
        return color.xyz_to_lab(np.asarray(x, np.float32), white="D50")

    return np.asarray(color.delta_e_2000(lab(xyz), lab(ref)), np.float64)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--mix", type=float, default=0.12)
    p.add_argument("--figure", default=None, help="copy the matrix run's chart.png here")
    args = p.parse_args(argv)
    out: dict = {"seed": args.seed, "mix": args.mix}
    chart = tuple(float(v) for v in CORNERS.ravel())
    with tempfile.TemporaryDirectory() as d:
        paths = write_bracket(f"{d}/dng", seed=args.seed, mix=args.mix)
        for model in CHART_MODELS:
            cfg = CalibrateConfig(chart=chart, chart_model=model)
            rep = run_calibrate(CalibrateJob(cfg, paths, f"{d}/{model}", progress=False))
            c = rep["chart"]
            de = radiance_delta_e(io.read_exr(rep["outputs"]["radiance"]))
            out[model] = {
                "before_median": round(c["before"]["median"], 3),
                "before_max": round(c["before"]["max"], 3),
                "after_median": round(c["after"]["median"], 3),
                "after_max": round(c["after"]["max"], 3),
                "radiance_exr_median": round(float(np.median(de)), 3),
                "chart_step_s": rep["timings_s"]["chart"],
            }
            if model == "matrix" and args.figure:
                shutil.copyfile(rep["outputs"]["chart_plot"], args.figure)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
