"""Ablations of the camera-chain fit (docs/inverse.md section 2b), one line per case:

    python -m experiments.camera_chain_ablation base clean base:clip=245:um=1 calwb:clip=245

A case is NAME[:key=value...]: NAME a target/camera pair of CASES (base: the camera_chain
photos, 3 exposures through the "camera" curve with noise and JPEG 90; nojpeg, clean (no noise,
no JPEG), clean1 / clean025 / base1 one photo; gamma1 the inverse_camera target; cal*: the
calibrated response of ``CHAIN_REPORT`` (default out/camera_chain/calibrate/report.json, from
experiments.camera_chain) with exposure init 1 / 0.15 / 0.3 / 0.05, calwb: auto exposure and
white balance fitted), keys steps (300), size (32), spp (8), est (independent | correlated),
seed (0), clip (camera.clip_code), um (1: camera.clipped unmeasured). The fit's camera is the
true one (fixed) unless the case says otherwise."""

import os
import sys
import time

import numpy as np

CONFIGS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "configs")
TRUTH = {"materials.metal.alpha": 0.15, "materials.clay.reflectance": [0.7, 0.3, 0.15]}
REPORT = os.path.abspath(os.environ.get("CHAIN_REPORT", "out/camera_chain/calibrate/report.json"))


def run(name, tcam, fcam, steps=300, size=32, spp=8, est="independent", seed=0, clip=None, um=0):
    from jaxgfx.pipelines.fit import FitJob, run_fit

    fcam = dict(fcam)
    if um:
        fcam["clipped"] = "unmeasured"
    if clip:
        fcam["clip_code"] = clip
    cfg = {
        "scene": "scenes/inverse.yaml",
        "target": {"synthetic": TRUTH, "spp": 256, "seed": 7, "camera": tcam},
        "params": {"materials.metal.alpha": {"init": 0.5, "min": 0.01, "max": 1.0},
                   "materials.clay.reflectance": {"init": [0.5] * 3, "min": 0.0, "max": 1.0}},
        "camera": fcam,
        "optimizer": {"name": "adam", "lr": 0.05, "lr_final": 0.005, "steps": steps},
        "render": {"spp": spp, "integrator": "direct", "max_depth": 2, "width": size,
                   "height": size, "estimator": est},
        "progress": False,
        "seed": seed,
    }
    t = time.time()
    out = run_fit(FitJob.load(cfg, None, base_dir=CONFIGS))
    a = out["params"]["materials.metal.alpha"]
    rho = np.round(out["params"]["materials.clay.reflectance"], 3).tolist()
    err = out["errors"]["materials.clay.reflectance"]
    print(f"{name:40s} alpha {a:.4f} ({abs(a - 0.15) / 0.15 * 100:5.1f}%) rho {rho} err "
          f"{err:.3f} exp {out['camera']['exposure']:.3f} [{time.time() - t:.0f}s]", flush=True)
    return out


def true_cam(e0):
    return {"response": {"model": "camera"}, "exposure": {"init": e0}}


def cal_cam(e0, auto=False, wb=False):
    return {"response": {"from": REPORT}, "exposure": {"init": e0, "fit": True, "auto": auto},
            "white_balance": {"fit": wb}}


BASE = {"response": "camera", "exposure": 1.0, "exposures": [0.25, 1.0, 4.0],
        "noise": {"gain": 0.0002, "read_sigma": 0.001}, "jpeg": 90}
NOJPEG = {k: v for k, v in BASE.items() if k != "jpeg"}
CLEAN = {k: v for k, v in NOJPEG.items() if k != "noise"}
CASES = {
    "base": (BASE, true_cam(0.25)),
    "nojpeg": (NOJPEG, true_cam(0.25)),
    "clean": (CLEAN, true_cam(0.25)),
    "clean1": (dict(CLEAN, exposures=[1.0]), true_cam(1.0)),
    "clean025": (dict(CLEAN, exposures=[0.25]), true_cam(0.25)),
    "base1": (dict(BASE, exposures=[1.0]), true_cam(1.0)),
    "gamma1": ({"response": "gamma", "gamma": 1.7, "exposure": 1.6, "bits": 8},
               {"response": {"model": "gamma", "init": 1.7}, "exposure": {"init": 1.6}}),
    "cal1": (BASE, cal_cam(1.0)),
    "cal015": (BASE, cal_cam(0.15)),
    "cal03": (BASE, cal_cam(0.3)),
    "cal005": (BASE, cal_cam(0.05)),
    "calwb": (BASE, cal_cam(1.0, auto=True, wb=True)),
}


def main(argv) -> int:
    from jaxgfx.pipelines.fit import enable_compilation_cache

    enable_compilation_cache()
    for w in argv:
        name, *opts = w.split(":")
        kw = {}
        for o in opts:
            k, v = o.split("=")
            kw[k] = v if k == "est" else int(v)
        tc, fc = CASES[name]
        run(w, tc, fc, **kw)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
