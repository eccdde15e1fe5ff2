"""What rough plastic's small-alpha ``R_int`` quadrature (``bsdf/_coating.py``) costs a scene
that does not need it: compile and warm run time of ``configs/scenes/textured.yaml`` (rough
plastic, alpha 0.2), path tracing, ``max_depth`` 4, 4 spp, with the quadrature's ``lax.cond``
branch compiled ("on", the library) and removed ("off"). Interleaved A/B, fresh interpreter
per run (compile caches off). Run from the repository root on a quiet machine::

    JAX_PLATFORMS=cpu python tools/coat_small_alpha_cost.py [--pairs 3]
"""

from __future__ import annotations

import json
import pathlib
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]


def one(mode: str) -> dict:
    import jax

    sys.path.insert(0, str(ROOT))
    import jaxgfx.render.bsdf._coating as coating
    from jaxgfx.render import load_scene, render

    if mode == "off":
        coating._small_alpha_correction = lambda d, eta, ok, spline: 0.0
    scene = load_scene(str(ROOT / "configs/scenes/textured.yaml"))
    f = jax.jit(lambda s, k: render(s, k, spp=4, integrator="path", max_depth=4))
    t = time.perf_counter()
    c = f.lower(scene, jax.random.key(0)).compile()
    compile_s = time.perf_counter() - t
    c(scene, jax.random.key(1)).block_until_ready()
    t = time.perf_counter()
    for i in range(5):
        c(scene, jax.random.key(2 + i)).block_until_ready()
    return {"mode": mode, "compile_s": compile_s, "run_s": (time.perf_counter() - t) / 5}


def main():
    if len(sys.argv) > 2 and sys.argv[1] == "--one":
        print(json.dumps(one(sys.argv[2])))
        return
    pairs = int(sys.argv[sys.argv.index("--pairs") + 1]) if "--pairs" in sys.argv else 3
    rows = []
    for _ in range(pairs):
        for mode in ("off", "on"):
            out = subprocess.run(
                [sys.executable, __file__, "--one", mode],
                capture_output=True, text=True, check=True,
            )  # fmt: skip
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
            print(json.dumps(rows[-1]), flush=True)
    for mode in ("off", "on"):
        c = sorted(r["compile_s"] for r in rows if r["mode"] == mode)
        r = sorted(r["run_s"] for r in rows if r["mode"] == mode)
        print(json.dumps({"mode": mode, "compile_s_median": c[len(c) // 2],
                          "run_s_median": r[len(r) // 2]}))  # fmt: skip


if __name__ == "__main__":
    main()
