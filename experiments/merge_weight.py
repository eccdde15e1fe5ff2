"""The merge weight (issue 26): ``hat · (t/t_max)^p`` for p = 0, 1, 2 vs ``"slope"``.

    python -m experiments.merge_weight [--json out.json] [--figure docs/images/hdr_merge_weight.png]

Same curve per stack (jaxgfx's default ``recover_response``), merged with each weighting:

* real JPEG brackets (``tests/data/real_bracket``, ratios as in
  ``tests/hdr/test_real_bracket.py``): leave-one-out error per held frame (levels 0–255),
  OpenCV ``CalibrateDebevec + MergeDebevec`` in the same run;
* brackets through the measured DoRF curves (``experiments.measured_curves``): median
  ``|Δ ln E|`` per channel-scale, OpenCV in the same run;
* the JPEG-like synthetic stacks of issue 16 (``tests/hdr/test_selfcheck.py``): LOO, OpenCV.

``--middle``: flowers' held-out middle frame per level band (:func:`middle_frame`).
``--samples``: the real brackets by pixel-sample count (:func:`sample_rows`); with ``--only
jpeg`` / ``--only measured`` also those stacks' rows with ``n_samples=16384``.

Prints JSON rows ``{"stack", "metric", <weighting>: value, ..., "OpenCV": value}``.
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx import hdr

from ._common import emit_json, log
from .measured_curves import measured_stacks, opencv_debevec_merge
from .real_bracket import load, opencv_loo

REAL_RATIOS = {"oldhouse": (0.299, 1.0, 4.259), "flowers": (0.30, 1.0, 3.83)}
WEIGHTS = {
    "hat t^0": {"weighting": "hat", "time_power": 0.0},
    "hat t^1": {"weighting": "hat", "time_power": 1.0},
    "hat t^2": {"weighting": "hat", "time_power": 2.0},
    "slope": {"weighting": "slope"},
}
JPEG_LIKE = {
    "camera, 3 frames x8": ("camera", (1 / 64, 1 / 8, 1.0)),
    "camera-offset, 3 frames x8": ("camera-offset", (1 / 64, 1 / 8, 1.0)),
    "camera, 5 frames x4": ("camera", (1 / 256, 1 / 64, 1 / 16, 1 / 4, 1.0)),
    "srgb, 5 frames x4": ("srgb", (1 / 256, 1 / 64, 1 / 16, 1 / 4, 1.0)),
    "filmic, 5 frames x4": ("filmic", (1 / 256, 1 / 64, 1 / 16, 1 / 4, 1.0)),
    "log, 5 frames x4": ("log", (1 / 256, 1 / 64, 1 / 16, 1 / 4, 1.0)),
    "camera, 5 frames, misaligned 0.7 px": ("camera", (1 / 256, 1 / 64, 1 / 16, 1 / 4, 1.0), 0.7),
}


def _r(v):
    return [round(float(x), 3) for x in np.atleast_1d(np.asarray(v))]


def real_rows(**fit):
    rows = []
    for name, ratios in REAL_RATIOS.items():
        ims, t = load(name), np.asarray(ratios)
        r = hdr.recover_response(ims, t, **fit)
        row = {"stack": f"real {name}", "metric": "LOO per held frame (levels)"}
        row["self-check candidates (LOO on the candidate grid)"] = _r(
            r.diagnostics["loo_candidates"]
        )
        row["prior chosen"] = bool(r.diagnostics["prior_chosen"])
        for k, o in WEIGHTS.items():
            row[k] = _r(hdr.leave_one_out(ims, t, r, **o).per_frame)
        row["OpenCV"] = _r(opencv_loo(ims, t).per_frame)
        log(row)
        rows.append(row)
    return rows


def measured_rows(**fit):
    rows = []
    for cname, bname, st in measured_stacks():
        r = hdr.recover_response(st.images, st.exposure_times, **fit)
        row = {"stack": f"{cname[17:]} {bname}", "metric": "median |d ln E|"}
        for k, o in WEIGHTS.items():
            e = hdr.merge_radiance(st.images, st.exposure_times, r, **o)
            row[k] = _r(hdr.radiance_error(e, st.radiance, per_channel=True))
        e_cv = opencv_debevec_merge(st.images, st.exposure_times)
        row["OpenCV"] = _r(hdr.radiance_error(jnp.asarray(e_cv), st.radiance, per_channel=True))
        log(row)
        rows.append(row)
    return rows


def sample_rows():
    """Issue 26's flowers middle frame: the real brackets' LOO per held frame with the
    default ``recover_response`` and with more pixel samples — ``n_samples=16384`` (up to 512
    per intensity bin: every candidate of a 256x256 crop's 128x128 grid in the sparse bins,
    textured ones included) and the same count taken as the flattest quarter of a 4x larger
    grid (``max_candidates=65536``) — with OpenCV in the same run; ``slope`` merge."""
    fits = {
        "previous default (n_samples 4096)": {"n_samples": 4096},
        "n_samples 16384 (the default's grid size here)": {"n_samples": 16384},
        "n_samples 16384, max_candidates 65536": {"n_samples": 16384, "max_candidates": 65536},
    }
    rows = []
    for name, ratios in REAL_RATIOS.items():
        ims, t = load(name), np.asarray(ratios)
        row = {"stack": f"real {name}", "metric": "LOO per held frame (levels)"}
        for k, o in fits.items():
            r = hdr.recover_response(ims, t, **o)
            row[k] = _r(hdr.leave_one_out(ims, t, r).per_frame)
        row["OpenCV"] = _r(opencv_loo(ims, t).per_frame)
        log(row)
        rows.append(row)
    return rows


def jpeg_rows(**fit):

    rows = []
    rad = hdr.synthetic_radiance(jax.random.key(1), 96, 96, dynamic_range=1e4)
    for label, (name, times, *shift) in JPEG_LIKE.items():
        st = hdr.make_jpeg_stack(
            jax.random.key(2), rad, jnp.asarray(times), name, max_shift=(shift or [0.0])[0]
        )
        r = hdr.recover_response(st.images, st.exposure_times, **fit)
        row = {"stack": f"JPEG-like {label}", "metric": "LOO mean (levels)"}
        row["prior chosen"] = bool(r.diagnostics["prior_chosen"])
        for k, o in WEIGHTS.items():
            row[k] = _r(hdr.leave_one_out(st.images, st.exposure_times, r, **o).mean_abs_error)
        row["OpenCV"] = _r(opencv_loo(st.images, st.exposure_times).mean_abs_error)
        log(row)
        rows.append(row)
    return rows


def figure(rows, path):
    """Error relative to OpenCV's (1 = a tie; below 1 jaxgfx wins), one bar per weighting."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels, vals = [], {k: [] for k in WEIGHTS}
    for r in rows:
        cv = np.asarray(r["OpenCV"])
        names = ["short", "middle", "long"] if cv.size == 3 else [""]
        for i, nm in enumerate(names):
            labels.append(f"{r['stack']} {nm}".replace("JPEG-like ", "").strip())
            for k in WEIGHTS:
                vals[k].append(float(np.asarray(r[k])[i] / cv[i]))
    fig, ax = plt.subplots(figsize=(11, 3.8))
    x = np.arange(len(labels))
    w = 0.8 / len(WEIGHTS)
    for i, k in enumerate(WEIGHTS):
        ax.bar(x + (i - (len(WEIGHTS) - 1) / 2) * w, vals[k], w, label=k)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(x)
    ax.set_xticklabels(labels, rotation=60, ha="right", fontsize=6)
    ax.set_ylabel("error / OpenCV Debevec's")
    ax.set_title("Merge weights (same curve per stack); below 1: better than OpenCV")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def middle_frame(name="flowers"):
    """Issue 26's open real-bracket row: the held-out *middle* frame of ``name`` predicted
    from the other two (frames sorted by time), per level band of 32 of the actual level:
    mean signed error (levels) and pixel count, for the default curve (free table; the
    bracket's overlap is above ``SPARSE_OVERLAP``), the ``"subspace"`` curve (``n_poly`` 0 and
    2) merged with the default merge, and OpenCV's curve with OpenCV's merge."""
    import cv2

    ims, t = load(name), np.asarray(REAL_RATIOS[name])
    held = ims[1]
    rest, tr = ims[[0, 2]], t[[0, 2]]
    edges = np.arange(0, 257, 32)
    band = np.clip(np.digitize(held, edges) - 1, 0, len(edges) - 2)
    keep = (held > 0) & (held < 255)

    def bands(pred):
        e = np.asarray(pred, np.float64) - held
        out = {"mean abs (levels)": round(float(np.mean(np.abs(e[keep]))), 2)}
        out["signed by band"] = [
            round(float(np.mean(e[keep & (band == b)])), 2) if np.any(keep & (band == b)) else None
            for b in range(len(edges) - 1)
        ]
        return out

    row = {"stack": name, "held": "middle", "bands": edges.tolist()}
    row["count by band"] = [int(np.sum(keep & (band == b))) for b in range(len(edges) - 1)]
    d = hdr.recover_response(ims, t)
    row["overlap"] = _r(np.asarray(d.diagnostics["overlap"]))
    fits = {"default": d, "n_samples=16384": hdr.recover_response(ims, t, n_samples=16384)}
    for npoly in (0, 2):
        fits[f"subspace n_poly={npoly}"] = hdr.recover_response(
            ims, t, method="subspace", n_poly=npoly
        )
    for k, r in fits.items():
        e = hdr.merge_radiance(rest, tr, r)
        row[k] = bands(np.clip(np.round(np.asarray(r.from_linear(e * t[1]))), 0, 255))
    bgr = [np.ascontiguousarray(im[..., ::-1]) for im in ims]
    crv = cv2.createCalibrateDebevec().process(bgr, t.astype(np.float32))
    e = cv2.createMergeDebevec().process(
        [bgr[0], bgr[2]], tr.astype(np.float32), crv
    )  # BGR, OpenCV's unit
    inv = [np.interp(e[..., c] * t[1], crv[:, 0, c], np.arange(256)) for c in range(3)]
    row["OpenCV"] = bands(np.round(np.stack(inv[::-1], axis=-1)))
    log(row)
    return [row]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None)
    ap.add_argument("--figure", default=None)
    ap.add_argument("--only", choices=("real", "measured", "jpeg"), default=None)
    ap.add_argument(
        "--middle", action="store_true", help="only flowers' held middle frame, per level"
    )
    ap.add_argument(
        "--samples", action="store_true", help="only the real brackets by pixel-sample count"
    )
    a = ap.parse_args(argv)
    if a.samples:
        rows = sample_rows()
        if a.only in ("measured", "jpeg"):  # the other stacks with n_samples=16384
            rows += (measured_rows if a.only == "measured" else jpeg_rows)(n_samples=16384)
        emit_json(rows, a.json)
        return
    if a.middle:
        emit_json(middle_frame(), a.json)
        return
    rows = []
    for part, fn in (("real", real_rows), ("measured", measured_rows), ("jpeg", jpeg_rows)):
        if a.only in (None, part):
            rows += fn()
    if a.figure:
        figure(rows, a.figure)
    emit_json(rows, a.json)


if __name__ == "__main__":
    main()
