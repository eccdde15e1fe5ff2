"""``make demo``: the main job (camera calibration + HDR merge) on the embedded synthetic
stack, the image-processing demo, and renders of configs/scenes/example.yaml and
textured.yaml. Writes
everything under ``--out`` (default ``out/``)."""

from __future__ import annotations

import argparse
import os
import sys

from jaxgfx.config import load_config
from jaxgfx.pipelines.calibrate import CalibrateConfig, CalibrateJob, run_calibrate
from jaxgfx.pipelines.image_demo import ImageDemoJob, run_image_demo
from jaxgfx.pipelines.render import RenderJob, run_render


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--out", default="out")
    p.add_argument("--config", default="configs/calibrate.yaml")
    p.add_argument("--quiet", action="store_true")
    args = p.parse_args(argv)

    cfg = load_config(CalibrateConfig, args.config if os.path.exists(args.config) else None)
    cal_dir = os.path.join(args.out, "calibrate")
    report = run_calibrate(
        CalibrateJob(config=cfg, out=cal_dir, overwrite=True, progress=not args.quiet)
    )
    print(f"[calibrate] outputs in {os.path.abspath(cal_dir)}")
    for name, path in report["outputs"].items():
        print(f"  {name:14s} {path}")
    for method, e in report.get("errors_vs_ground_truth", {}).items():
        print(
            f"  {method:12s} curve RMSE(ln) {e['curve_rmse_ln']:.4f}   "
            f"radiance median|dln| {e['radiance_median_abs_ln']:.4f}"
        )

    img_dir = os.path.join(args.out, "image")
    res = run_image_demo(ImageDemoJob(img_dir))
    print(f"[image] {len(res['paths'])} outputs in {os.path.abspath(img_dir)}")

    # the example scene of issue 5, the textured-materials example (bitmap/checkerboard) and
    # the mesh scene (20k triangles, traced by Embree when installed)
    for name in ("example", "textured", "mesh"):
        scene_path = os.path.join("configs", "scenes", f"{name}.yaml")
        if os.path.exists(scene_path):
            out = os.path.join(args.out, "render", f"{name}.exr")
            job = RenderJob(scene_path, out, spp=16, integrator="path", overwrite=True)
            res = run_render(job)
            print(f"[render] {' and '.join(res['outputs'].values())} ({res['seconds']:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
