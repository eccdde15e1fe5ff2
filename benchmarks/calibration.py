"""Benchmark: response recovery + radiance merge, jaxgfx vs OpenCV, errors next to times.

    python benchmarks/calibration.py [--quick] [--sizes 1024x1024 2448x2448] [--out FILE]

A 5-frame 8-bit stack (exposures x4 apart, sRGB response, shot + read noise) of the
synthetic scene; jaxgfx ``recover_response`` (Debevec, default options) + ``merge_radiance``
timed after a warm-up call (compile time reported separately), OpenCV's
CalibrateDebevec + MergeDebevec and CalibrateRobertson + MergeRobertson in the same run;
``speed_ratio_vs_opencv_debevec`` = jaxgfx time / OpenCV time (< 1: jaxgfx faster).
``--cold`` also times a fresh Python process doing recover + merge once on the first size,
twice: with an empty persistent compilation cache (cold: compiling) and again with the cache
it filled (warm start, what a second ``jaxgfx calibrate`` sees). Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import cv2  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from benchmarks._report import emit, machine  # noqa: E402
from jaxgfx import hdr  # noqa: E402


def _best(fn, repeat):
    times = []
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def _cv_resp(crv):
    tab = np.log(np.maximum(crv[:, 0, ::-1].astype(np.float64), 1e-30)).astype(np.float32)
    return hdr.CameraResponse(jnp.asarray(tab), "table", "opencv", 255.0, 0.5)


def run(h, w, repeat, robertson=True):
    times = jnp.asarray([1.0, 4.0, 16.0, 64.0, 256.0])
    rad = hdr.synthetic_radiance(jax.random.key(1), h, w, dynamic_range=1e4)
    st = hdr.make_bracketed_stack(jax.random.key(2), rad, times, hdr.synthetic_response("srgb"))
    images = jax.block_until_ready(st.images)
    imgs_np = np.asarray(images)
    t_np = np.asarray(times, np.float32)

    def ours():
        r = hdr.recover_response(images, times)
        e = hdr.merge_radiance(images, times, r)
        return jax.block_until_ready((r, e))

    t0 = time.perf_counter()
    ours()
    first = time.perf_counter() - t0
    t_ours, (r, e) = _best(ours, repeat)
    t_rec, _ = _best(lambda: jax.block_until_ready(hdr.recover_response(images, times)), repeat)
    res = {
        "size": f"{w}x{h}",
        "megapixels": round(h * w / 1e6, 2),
        "jaxgfx_debevec": {
            "seconds": round(t_ours, 4),
            "recover_seconds": round(t_rec, 4),
            "compile_seconds": round(first - t_ours, 3),
            "curve_error": float(hdr.response_curve_error(r, st.response)),
            "radiance_error": float(hdr.radiance_error(e, st.radiance)),
        },
    }
    bgr = [np.ascontiguousarray(im[..., ::-1]) for im in imgs_np]
    peers = [("opencv_debevec", cv2.createCalibrateDebevec, cv2.createMergeDebevec)]
    if robertson:
        peers.append(("opencv_robertson", cv2.createCalibrateRobertson, cv2.createMergeRobertson))
    for name, cal, mer in peers:

        def peer(cal=cal, mer=mer):
            crv = cal().process(bgr, t_np)
            return crv, mer().process(bgr, t_np, crv)

        t_cv, (crv, e_cv) = _best(peer, repeat)
        t_cal, _ = _best(lambda cal=cal: cal().process(bgr, t_np), repeat)
        if name == "opencv_debevec":
            res["speed_ratio_vs_opencv_debevec"] = round(t_ours / t_cv, 3)
            t_m, _ = _best(lambda: jax.block_until_ready(hdr.merge_radiance(images, times, r)), 2)
            t_mcv, _ = _best(lambda crv=crv, mer=mer: mer().process(bgr, t_np, crv), 2)
            res["merge_ratio_vs_opencv_debevec"] = round(t_m / t_mcv, 3)
        res[name] = {
            "seconds": round(t_cv, 4),
            "recover_seconds": round(t_cal, 4),
            "curve_error": float(hdr.response_curve_error(_cv_resp(crv), st.response)),
            "radiance_error": float(
                hdr.radiance_error(jnp.asarray(e_cv[..., ::-1].copy()), st.radiance)
            ),
        }
    return res


_COLD = """
import sys, time
t0 = time.perf_counter()
from jaxgfx._jaxcache import enable_compilation_cache
enable_compilation_cache()
import jax, jax.numpy as jnp
from jaxgfx import hdr
h, w = int(sys.argv[1]), int(sys.argv[2])
times = jnp.asarray([1.0, 4.0, 16.0, 64.0, 256.0])
rad = hdr.synthetic_radiance(jax.random.key(1), h, w, dynamic_range=1e4)
st = hdr.make_bracketed_stack(jax.random.key(2), rad, times, hdr.synthetic_response("srgb"))
images = jax.block_until_ready(st.images)
t1 = time.perf_counter()
r = hdr.recover_response(images, times)
jax.block_until_ready(hdr.merge_radiance(images, times, r))
print(time.perf_counter() - t1)
"""


def cold_warm(h, w):
    """Seconds for recover + merge in a fresh process: empty cache, then the filled cache."""
    import subprocess
    import tempfile

    out = {}
    with tempfile.TemporaryDirectory() as d:
        env = {**os.environ, "JAXGFX_CACHE_DIR": d}
        root = os.path.join(os.path.dirname(__file__), "..")
        env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
        for label in ("cold_process_seconds", "cached_process_seconds"):
            p = subprocess.run(
                [sys.executable, "-c", _COLD, str(h), str(w)],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            out[label] = round(float(p.stdout.strip().splitlines()[-1]), 3)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="256x256 only, 1 repeat")
    ap.add_argument("--sizes", nargs="*", default=["1024x1024", "3000x2000"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cold", action="store_true", help="cold vs cached-process times")
    ap.add_argument("--no-robertson", action="store_true", help="skip OpenCV Robertson (slow)")
    ap.add_argument("--out", default=None, help="also write the JSON here")
    a = ap.parse_args(argv)
    sizes = ["256x256"] if a.quick else a.sizes
    repeat = 1 if a.quick else a.repeat
    out = {
        "benchmark": "calibration",
        "machine": machine(opencv=cv2.__version__, opencv_threads=cv2.getNumThreads()),
        "runs": [],
    }
    for k, s in enumerate(sizes):
        w, h = (int(v) for v in s.split("x"))
        out["runs"].append(run(h, w, repeat, robertson=not a.no_robertson))
        if a.cold and k == 0:
            out["runs"][-1]["jaxgfx_process"] = cold_warm(h, w)
        print(json.dumps(out["runs"][-1]), file=sys.stderr, flush=True)  # partial results
    emit(out, a.out)


if __name__ == "__main__":
    main()
