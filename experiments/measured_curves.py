"""Response recovery on brackets exposed through *measured* camera curves (issue 26).

    python -m experiments.measured_curves [--figure docs/images/hdr_measured_curves.png]

Curves: the DoRF database's Ektachrome 320T (red, green, blue; Grossberg & Nayar 2003), read
from ``tests/data/dorf/ektachrome320t.crf`` with :func:`jaxgfx.hdr.read_dorf_curves` and
turned into tabulated responses with :func:`jaxgfx.hdr.response_from_curve`; each curve is
used for all three channels of one stack. Scene: ``synthetic_radiance`` 96×96, 1e3:1 (no real
radiance map is in the repository). Brackets: a camera's 3-frame AEB (±3 EV) and 5 frames
2 EV apart, the longest exposure 20 (so the darkest radiance reaches the toe), 8-bit, shot
gain 1e-5 and read σ 2e-4 (about 0.6 code of noise in the mid-tones). Prints, per curve and
bracket, the median |Δ ln E| (``radiance_error(..., per_channel=True)``) of jaxgfx's
defaults (which of its two Debevec fits the self-check chose, the bracket overlap and whether
the sparse-bracket rule chose the ``"subspace"`` fit), the end-weighted fit alone
(``reweight_passes=0``, the default before issue 26), Debevec without the end weight, the
default without the sparse-bracket rule (``sparse_overlap=0``), ``method="subspace"``,
``spline``, OpenCV ``CalibrateDebevec + MergeDebevec`` and the true curve through
``merge_radiance``, as JSON.
"""

from __future__ import annotations

import argparse
import os

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx import hdr

from ._common import emit_json, log

DATA = os.path.join(os.path.dirname(__file__), "..", "tests", "data", "dorf", "ektachrome320t.crf")
BRACKETS = {
    "AEB 3 frames ±3 EV": (1 / 8, 1.0, 8.0),
    "5 frames 2 EV apart": (1 / 16, 1 / 4, 1.0, 4.0, 16.0),
}
T_LONG = 20.0
GAIN, READ = 1e-5, 2e-4


def measured_stacks(size=96, seed=2):
    """``[(curve name, bracket name, BracketedStack)]`` for every DoRF curve of the data file."""
    curves = hdr.read_dorf_curves(DATA)
    rad = hdr.synthetic_radiance(jax.random.key(1), size, size, dynamic_range=1e3)
    out = []
    for cname, (irr, bri) in curves.items():
        resp = hdr.response_from_curve(irr, np.repeat(bri[:, None], 3, axis=1))
        for bname, times in BRACKETS.items():
            t = jnp.asarray(times) / max(times) * T_LONG
            st = hdr.make_bracketed_stack(
                jax.random.key(seed), rad, t, resp, bits=8, gain=GAIN, read_sigma=READ
            )
            out.append((cname, bname, st))
    return out


def opencv_debevec_merge(images, times):
    import cv2

    bgr = [np.ascontiguousarray(np.asarray(im)[..., ::-1]) for im in images]
    tt = np.asarray(times, np.float32)
    crv = cv2.createCalibrateDebevec().process(bgr, tt)
    return cv2.createMergeDebevec().process(bgr, tt, crv)[..., ::-1]


def measure(with_spline=True):
    rows = []
    for cname, bname, st in measured_stacks():

        def err(e, st=st):
            return float(hdr.radiance_error(jnp.asarray(e), st.radiance, per_channel=True))

        r = {"curve": cname, "bracket": bname}
        d = hdr.recover_response(st.images, st.exposure_times)
        r["jaxgfx default"] = err(hdr.merge_radiance(st.images, st.exposure_times, d))
        r["inverse-slope fit chosen"] = bool(d.diagnostics["inverse_slope_chosen"])
        r["subspace chosen"] = bool(np.all(d.diagnostics["subspace_chosen"]))
        r["overlap"] = round(float(np.min(d.diagnostics["overlap"])), 3)
        d1 = hdr.recover_response(
            st.images, st.exposure_times, reweight_passes=0, sparse_overlap=0.0
        )
        r["end-weighted only"] = err(hdr.merge_radiance(st.images, st.exposure_times, d1))
        d0 = hdr.recover_response(
            st.images, st.exposure_times, end_weight=0.0, reweight_passes=0, sparse_overlap=0.0
        )
        r["debevec end_weight=0"] = err(hdr.merge_radiance(st.images, st.exposure_times, d0))
        fr = hdr.recover_response(st.images, st.exposure_times, sparse_overlap=0.0)
        r["free table (sparse_overlap=0)"] = err(
            hdr.merge_radiance(st.images, st.exposure_times, fr)
        )
        sp = hdr.recover_response(st.images, st.exposure_times, method="subspace")
        r["subspace"] = err(hdr.merge_radiance(st.images, st.exposure_times, sp))
        if with_spline:
            s = hdr.recover_response(st.images, st.exposure_times, method="spline")
            r["spline"] = err(hdr.merge_radiance(st.images, st.exposure_times, s))
        r["OpenCV Debevec"] = err(opencv_debevec_merge(st.images, st.exposure_times))
        r["true curve"] = err(hdr.merge_radiance(st.images, st.exposure_times, st.response))
        log(r)
        rows.append(r)
    return rows


def figure(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    skip = ("curve", "bracket", "inverse-slope fit chosen", "subspace chosen", "overlap")
    keys = [k for k in rows[0] if k not in skip]
    fig, ax = plt.subplots(figsize=(10.5, 3.6))
    x = np.arange(len(rows))
    w = 0.8 / len(keys)
    for i, k in enumerate(keys):
        ax.bar(x + (i - (len(keys) - 1) / 2) * w, [r[k] for r in rows], w, label=k)
    ax.set_xticks(x)
    ax.set_xticklabels(
        [f"{r['curve'].replace('Ektachrome-320TCD', '')}\n{r['bracket']}" for r in rows], fontsize=7
    )
    ax.set_ylabel("median |Δ ln E|")
    ax.set_title("Brackets through measured curves (DoRF Ektachrome 320T), lower is better")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figure", default=None)
    ap.add_argument("--json", default=None)
    ap.add_argument("--no-spline", action="store_true")
    a = ap.parse_args(argv)
    rows = measure(with_spline=not a.no_spline)
    if a.figure:
        figure(rows, a.figure)
    emit_json(rows, a.json)


if __name__ == "__main__":
    main()
