"""Speed of jaxgfx.tonemap operators and exposure fusion vs OpenCV and pfstmo, in one run.

Usage::

    python -m benchmarks.tonemap                 # 2 MP (1632 x 1224) HDR image
    python -m benchmarks.tonemap --quick         # 256 x 256
    python -m benchmarks.tonemap --figure docs/images/tonemap_operators.png

Prints one JSON document (progress on stderr). jaxgfx is jitted: ``compile_s`` is lower+compile
time, ``jax_s`` the median steady-state time over ``--repeats`` runs (``block_until_ready``).
OpenCV is timed the same way on NumPy arrays; pfstmo (Debian ``pfstmo``, optional) is timed as a
whole ``pfsinpfm | pfstmo_* | pfsoutpfm`` pipeline minus the same pipeline with ``pfscat`` as the
operator (the file I/O cost). ``ratio_cv2`` / ``ratio_pfstmo`` = jax_s / peer_s (lower is
better). The machine may be shared: compare ratios within one run, not absolute times.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

import cv2
import jax
import numpy as np

from benchmarks._report import emit, machine
from benchmarks._timing import median_time, time_jax
from jaxgfx import tonemap as tm
from jaxgfx.hdr import exposure_fusion
from jaxgfx.hdr.synthetic import outdoor_hdr_scene as hdr_scene

JAX_CASES = {
    "drago": (tm.tonemap_Drago2003, {}),
    "reinhard": (tm.tonemap_Reinhard2002, {}),
    "reinhard_devlin": (tm.tonemap_Reinhard2005, {}),
    "filmic": (tm.tonemap_ACES_Narkowicz2015, {}),
    "exposure": (tm.tonemap_exposure, {"exposure": -4.0}),
    "reinhard_local": (tm.tonemap_Reinhard2002_local, {}),
    "contrast_inversion": (tm.tonemap_contrast_inversion, {}),
    "durand": (tm.tonemap_Durand2002, {"sigma_spatial": 40.0}),
    "fattal": (tm.tonemap_Fattal2002, {}),
    "mantiuk": (tm.tonemap_Mantiuk2006, {}),
}
CV_CASES = {
    "drago": lambda im: cv2.createTonemapDrago(1.0, 1.0, 0.85).process(im),
    "reinhard_devlin": lambda im: cv2.createTonemapReinhard(1.0, 0.0, 1.0, 0.0).process(im),
    "mantiuk": lambda im: cv2.createTonemapMantiuk(1.0, 0.7, 1.0).process(im),
}
PFS_CASES = {
    "drago": ["pfstmo_drago03"],
    "reinhard": ["pfstmo_reinhard02"],
    "reinhard_local": ["pfstmo_reinhard02", "--scales"],
    "durand": ["pfstmo_durand02", "-g"],
    "fattal": ["pfstmo_fattal02"],
    "mantiuk": ["pfstmo_mantiuk06"],
}


def _write_pfm(path, img):
    H, W, _ = img.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{W} {H}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(img[::-1]).astype("<f4").tobytes())


def time_pfs(img, cmd, repeats):
    with tempfile.TemporaryDirectory() as d:
        src, dst = os.path.join(d, "in.pfm"), os.path.join(d, "out.pfm")
        _write_pfm(src, img)

        def run(c):
            subprocess.run(
                f"pfsinpfm {src} | {' '.join(c)} | pfsoutpfm {dst}",
                shell=True,
                check=True,
                capture_output=True,
            )

        io_s = median_time(lambda: run(["pfscat"]), repeats)
        total = median_time(lambda: run(cmd), repeats)
        return max(total - io_s, 1e-6), io_s


def bench(H, W, repeats):
    img = hdr_scene(H, W)
    x = jax.numpy.asarray(img)
    have_pfs = shutil.which("pfstmo_drago03") is not None
    rows = {}
    for name, (fn, kw) in JAX_CASES.items():
        compile_s, jax_s = time_jax(
            lambda a, fn=fn, kw=kw: fn(a, encode="linear", **kw), x, repeats=repeats
        )
        row = {"compile_s": compile_s, "jax_s": jax_s}
        if name in CV_CASES:
            f = CV_CASES[name]
            f(img)
            row["cv2_s"] = median_time(lambda f=f: f(img), repeats)
            row["ratio_cv2"] = jax_s / row["cv2_s"]
        if have_pfs and name in PFS_CASES:
            row["pfstmo_s"], row["pfs_io_s"] = time_pfs(img, PFS_CASES[name], max(1, repeats // 2))
            row["ratio_pfstmo"] = jax_s / row["pfstmo_s"]
        rows[name] = row
        print(name, json.dumps(row), flush=True, file=sys.stderr)  # partial results
    rows["exposure_fusion"] = bench_fusion(img, repeats)
    return img, rows


def bench_fusion(img, repeats):
    """Exposure fusion of a 3-frame bracket of ``img`` vs ``cv2.createMergeMertens``: first
    calls (compile) apart, then interleaved pairs (jax, OpenCV) timed in wall clock and in
    process CPU time, a fresh input per call (the frames scaled by a new factor), results
    synchronised; OpenCV gets the uint8 frames it is used with, jaxgfx the float ones."""
    import time

    frames = np.stack(
        [np.clip(img * t / np.median(img), 0, 1) ** (1 / 2.2) for t in (0.02, 0.18, 1.6)]
    ).astype(np.float32)
    f8 = [np.round(f * 255).astype(np.uint8) for f in frames]
    merge = cv2.createMergeMertens(1.0, 1.0, 1.0)
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    jax.block_until_ready(exposure_fusion(jax.numpy.asarray(frames)))
    first_s = time.perf_counter() - t0
    merge.process(f8)
    wall = {"jax": [], "cv2": []}
    cpu = {"jax": [], "cv2": []}
    for _ in range(repeats):
        s = np.float32(rng.uniform(0.9, 1.0))
        xj = jax.numpy.asarray(frames * s)
        xc = [np.round(f * s * 255).astype(np.uint8) for f in frames]
        pair = (
            ("jax", lambda xj=xj: exposure_fusion(xj)),
            ("cv2", lambda xc=xc: merge.process(xc)),
        )
        for name, fn in pair:
            c0, w0 = time.process_time(), time.perf_counter()
            jax.block_until_ready(fn())
            wall[name].append(time.perf_counter() - w0)
            cpu[name].append(time.process_time() - c0)
    med = {k: float(np.median(v)) for k, v in wall.items()}
    cmed = {k: float(np.median(v)) for k, v in cpu.items()}
    return {
        "first_call_s": first_s,
        "jax_s": med["jax"],
        "cv2_s": med["cv2"],
        "ratio_cv2": med["jax"] / med["cv2"],
        "jax_cpu_s": cmed["jax"],
        "cv2_cpu_s": cmed["cv2"],
        "ratio_cv2_cpu": cmed["jax"] / cmed["cv2"],
        "loadavg_after": list(os.getloadavg()),
    }


def figure(img, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [
        "exposure",
        "drago",
        "reinhard",
        "filmic",
        "reinhard_local",
        "contrast_inversion",
        "durand",
        "fattal",
        "mantiuk",
    ]
    kws = {"exposure": {"exposure": -4.0}}
    fig, axes = plt.subplots(3, 3, figsize=(12, 9.9))
    for ax, name in zip(axes.ravel(), names, strict=True):
        ax.imshow(np.asarray(tm.TONEMAP_METHODS[name](img, **kws.get(name, {}))))
        ax.set_title(f"{name} ({tm.TONEMAP_METHODS[name].__name__})", fontsize=9)
        ax.axis("off")
    fig.tight_layout()
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    base = os.path.splitext(path)[0]
    # the global curves: display luminance vs world luminance / log-average
    Lw = np.logspace(-3, 3, 400).astype(np.float32)
    row = np.concatenate([Lw, [1e3]])[None]  # the maximum (1e3) sets Drago / Reinhard's white
    fig, ax = plt.subplots(figsize=(6.5, 4))
    stats = tm.AdaptationStats(np.float32(1.0), np.float32(1e3))
    curves = [
        ("drago b=0.65", tm.tonemap_Drago2003, {"bias": 0.65}),
        ("drago b=0.85", tm.tonemap_Drago2003, {"bias": 0.85}),
        ("drago b=0.95", tm.tonemap_Drago2003, {"bias": 0.95}),
        ("reinhard a=0.18", tm.tonemap_Reinhard2002, {}),
        ("ACES (Narkowicz)", tm.tonemap_ACES_Narkowicz2015, {}),
        ("Hable", tm.tonemap_Hable2010, {}),
        ("exposure 0 (clip)", tm.tonemap_exposure, {}),
    ]
    for label, fn, kw in curves:
        if fn is not tm.tonemap_exposure:
            kw = {**kw, "adaptation": stats}
        y = np.asarray(fn(row, encode="linear", **kw))[0, :-1]
        ax.semilogx(Lw, y, label=label)
    ax.set_xlabel("world luminance / log-average")
    ax.set_ylabel("display luminance (linear)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(base + "_curves.png", dpi=90)
    plt.close(fig)
    # video: a blinking light makes per-frame adaptation pump; smoothing removes it
    T = 48
    frames = np.repeat(hdr_scene(60, 80)[None], T, 0)
    on = (np.arange(T) // 6) % 2 == 1
    frames[on, 5:15, 5:15] = 2e5
    per = np.asarray(tm.tonemap_Reinhard2002(frames, encode="linear"))
    smo = np.asarray(tm.smooth_adaptation(frames, method="reinhard", rate=0.1, encode="linear"))
    m = lambda v: (v[:, 20:, 20:] @ np.array([0.2126, 0.7152, 0.0722])).mean(axis=(1, 2))
    fig, ax = plt.subplots(figsize=(6.5, 3.2))
    ax.plot(m(per), label="per-frame statistics")
    ax.plot(m(smo), label="smooth_adaptation (rate 0.1)")
    ax.set_xlabel("frame")
    ax.set_ylabel("mean display luminance\n(away from the light)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(base + "_flicker.png", dpi=90)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="256 x 256 instead of 2 MP")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--figure", default=None, help="write the side-by-side figure here")
    ap.add_argument("--out", default=None, help="also write the JSON here")
    ap.add_argument("--fusion-only", action="store_true", help="only the exposure fusion row")
    args = ap.parse_args(argv)
    H, W = (256, 256) if args.quick else (1224, 1632)
    if args.fusion_only:
        mach = machine(opencv=cv2.__version__, opencv_threads=cv2.getNumThreads())
        rows = {"exposure_fusion": bench_fusion(hdr_scene(H, W), args.repeats)}
        out = {
            "benchmark": "tonemap",
            "machine": mach,
            "image": [H, W, 3],
            "results": rows,
            "note": "shared machine: interleaved pairs; compare ratios within this run",
        }
        emit(out, args.out)
        return
    pfstmo = shutil.which("pfstmo_drago03") is not None
    mach = machine(opencv=cv2.__version__, opencv_threads=cv2.getNumThreads(), pfstmo=pfstmo)
    img, rows = bench(H, W, args.repeats)
    out = {
        "benchmark": "tonemap",
        "machine": mach,
        "image": [H, W, 3],
        "note": "shared machine: compare ratios within this run",
        "results": rows,
    }
    emit(out, args.out)
    if args.figure:
        figure(hdr_scene(300, 400), args.figure)


if __name__ == "__main__":
    main()
