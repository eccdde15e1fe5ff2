"""``jaxgfx fit configs/inverse_material.yaml`` with ``render.adjoint: ad`` vs ``auto`` (path
replay there: every fitted parameter is a material's), as shipped (direct light, depth 2) and
with a path tracer of depth 4 (``--variants direct2,path4``); the fits run one after the other
in one process (each compiles its own step). Per fit: the adjoint chosen, step compile seconds,
median and total seconds of the steps, the process CPU and wall seconds of the whole fit, the
fitted values and their errors against the synthetic target's truth, and the final loss.

    python -m benchmarks.fit_adjoint [--steps 300] [--variants direct2,path4] [--out FILE]
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time

from benchmarks._report import emit, machine
from jaxgfx.config import load_config, read_yaml
from jaxgfx.pipelines.fit import FitConfig, FitJob, run_fit

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(ROOT, "configs", "inverse_material.yaml")


def fits(*, steps, variants):
    base = read_yaml(CONFIG)
    base["scene"] = os.path.join(ROOT, "configs", base["scene"])
    base["progress"] = False
    base["optimizer"]["steps"] = int(steps)
    out = {"config": "configs/inverse_material.yaml", "steps": steps}
    out["load_before"] = list(os.getloadavg())
    for var in variants:
        for adjoint in ("ad", "auto"):
            d = copy.deepcopy(base)
            if var == "path4":
                d["render"].update(integrator="path", max_depth=4)
            d["render"]["adjoint"] = adjoint
            t, w = time.process_time(), time.perf_counter()
            r = run_fit(FitJob(load_config(FitConfig, d), None))
            row = {
                "adjoint": r["adjoint"],
                "compile_s": round(r["compile_seconds"], 2),
                "step_s_median": round(r["seconds_per_step"], 4),
                "steps_s": round(r["seconds"], 2),
                "process_cpu_s": round(time.process_time() - t, 1),
                "wall_s": round(time.perf_counter() - w, 1),
                "params": r["params"],
                "errors": r.get("errors"),
                "final_loss": r["loss"][-1],
            }
            out[f"{var}_{adjoint}"] = row
            print(var, adjoint, row, file=sys.stderr, flush=True)
    out["load_after"] = list(os.getloadavg())
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--variants", default="direct2,path4")
    ap.add_argument("--out")
    a = ap.parse_args(argv)
    result = {"benchmark": "fit_adjoint", "machine": machine()}
    result["fit_adjoint"] = fits(steps=a.steps, variants=a.variants.split(","))
    emit(result, a.out)


if __name__ == "__main__":
    main()
