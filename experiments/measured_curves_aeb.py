"""Why the 3-frame AEB through measured curves loses to OpenCV (issue 26): Debevec's end
weight and smoothness, and ``spline``, scored by the radiance error *and* by the
leave-one-out self-check that the default uses to choose between its candidates.

    python -m experiments.measured_curves_aeb [--spline] [--levels] [--subspace] [--checks]
        [--timing] [--timing-prior] [--overlap] [--prior]
        [--figure docs/images/hdr_subspace_aeb.png]

Stacks: ``experiments.measured_curves.measured_stacks`` (DoRF Ektachrome 320T curves, 96×96,
AEB 3 frames ±3 EV and 5 frames 2 EV apart). For ``end_weight`` in {0, 0.05, 0.2} and ``lam``
in {1e-6, 3e-6, 1e-5} (``reweight_passes=0``: the single fit) prints median |Δ ln E| per
channel-scale and the mean LOO error (levels, default merge); with ``--spline`` also
``method="spline"`` (its fit time included: slow) and the default's two LOO candidates.
``--subspace``: ``method="subspace"`` for ``n_poly`` 0…4 (radiance error, LOO, bracket
overlap) on every stack instead. ``--figure PATH``: the curve-space basis (``n_poly=2``) and,
for the three AEB stacks, the default's curve, the free table (``sparse_overlap=0``) and
OpenCV's against the measured truth. ``--checks``: ``"subspace"`` on the real JPEG brackets
and the analytic synthetic stacks (data its ``n_poly=0`` choice did not see). ``--timing``:
the cost of the sparse-bracket rule, A/B in one process (``--timing-prior``: of the smoothness
prior's candidate). ``--overlap``: the rule's statistic on every stack family (no fits).
``--prior``: the curve-space smoothness prior on the 5-frame brackets (:func:`prior_rows`).
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

from jaxgfx import hdr

from ._common import emit_json, log
from .measured_curves import measured_stacks


def _score(st, r):
    e = hdr.merge_radiance(st.images, st.exposure_times, r)
    loo = hdr.leave_one_out(st.images, st.exposure_times, r).mean_abs_error
    return round(float(hdr.radiance_error(e, st.radiance, per_channel=True)), 3), round(
        float(loo), 2
    )


def measure(spline=False):
    rows = []
    for cname, bname, st in measured_stacks():
        row = {"curve": cname[17:], "bracket": bname}
        for ew in (0.0, 0.05, 0.2):
            for lam in (1e-6, 3e-6, 1e-5):
                r = hdr.recover_response(
                    st.images,
                    st.exposure_times,
                    lam=lam,
                    end_weight=ew,
                    reweight_passes=0,
                    sparse_overlap=0.0,
                )
                row[f"end_weight {ew:g}, lam {lam:g}: |d ln E|, LOO"] = _score(st, r)
        if spline:
            t0 = time.perf_counter()
            r = hdr.recover_response(st.images, st.exposure_times, method="spline")
            jax.block_until_ready(r.params)
            row["spline fit s"] = round(time.perf_counter() - t0, 1)
            row["spline: |d ln E|, LOO"] = _score(st, r)
            d = hdr.recover_response(st.images, st.exposure_times)
            row["default: |d ln E|, LOO"] = _score(st, d)
            row["default LOO candidates"] = [
                round(float(v), 2) for v in np.asarray(d.diagnostics["loo_candidates"])
            ]
        log(row)
        rows.append(row)
    return rows


def levels():
    """Red AEB: per-level error of the end-weighted fit and of OpenCV's curve against the
    measured truth (ln, after the median offset over levels 30-224), every 15 levels from 5,
    and the red histogram of each frame in bins of 32 levels."""
    import cv2
    import jax.numpy as jnp

    cname, bname, st = next(s for s in measured_stacks() if "Red" in s[0] and "AEB" in s[1])
    lv = jnp.broadcast_to(jnp.linspace(0, 1, 256)[:, None], (256, 3))
    gt = np.log(np.asarray(st.response.to_linear_normalized(lv)))[:, 0]
    out = {"levels": list(range(5, 251, 15))}
    d = hdr.recover_response(st.images, st.exposure_times, reweight_passes=0, sparse_overlap=0.0)
    bgr = [np.ascontiguousarray(np.asarray(im)[..., ::-1]) for im in st.images]
    crv = cv2.createCalibrateDebevec().process(bgr, np.asarray(st.exposure_times, np.float32))
    tab = np.log(np.maximum(crv[:, 0, ::-1].astype(np.float64), 1e-30)).astype(np.float32)
    cv = hdr.CameraResponse(jnp.asarray(tab), "table", "opencv", 255.0, 0.5)
    for name, r in (("end-weighted fit", d), ("OpenCV", cv)):
        err = np.log(np.asarray(r.to_linear_normalized(lv)))[:, 0] - gt
        err -= np.median(err[30:225])
        out[name] = [round(float(v), 3) for v in err[5:251:15]]
    for j in range(3):
        h = np.bincount(np.asarray(st.images[j][..., 0]).ravel(), minlength=256)
        out[f"frame {j} red histogram /32"] = [
            int(v) for v in np.add.reduceat(h, range(0, 256, 32))
        ]
    out["true slope ln/level"] = [round(float(v), 3) for v in np.gradient(gt)[5:251:15]]
    return out


def subspace_rows():
    rows = []
    for cname, bname, st in measured_stacks():
        row = {"curve": cname[17:], "bracket": bname}
        d = hdr.recover_response(st.images, st.exposure_times)
        row["overlap"] = [round(float(v), 3) for v in np.asarray(d.diagnostics["overlap"])]
        row["default: |d ln E|, LOO"] = _score(st, d)
        for k in range(5):
            r = hdr.recover_response(st.images, st.exposure_times, method="subspace", n_poly=k)
            row[f"subspace n_poly={k}: |d ln E|, LOO"] = _score(st, r)
        log(row)
        rows.append(row)
    return rows


def analytic_stack(name):
    """The analytic stacks of ``tests/hdr/_stacks.py`` (64x64, 5 frames x4 apart, 8-bit, gain
    1e-4, read sigma 1e-3) through ``hdr.synthetic_response(name)``."""
    import jax.numpy as jnp

    rad = hdr.synthetic_radiance(jax.random.key(1), 64, 64, dynamic_range=1e4)
    return hdr.make_bracketed_stack(
        jax.random.key(2),
        rad,
        jnp.asarray((1.0, 4.0, 16.0, 64.0, 256.0)),
        hdr.synthetic_response(name),
        bits=8,
        gain=1e-4,
        read_sigma=1e-3,
    )


def checks():
    """``method="subspace"`` on data its ``n_poly=0`` choice did not see: the real JPEG
    brackets (LOO per held frame, levels; default and OpenCV in the same run) and the analytic
    synthetic stacks of ``tests/hdr/test_response.py::test_debevec_beats_opencv`` (radiance
    error and curve error)."""
    import jax.numpy as jnp

    from .measured_curves import opencv_debevec_merge
    from .merge_weight import REAL_RATIOS
    from .real_bracket import load, opencv_loo

    def pf(r, ims, t):
        return [round(float(v), 2) for v in np.asarray(hdr.leave_one_out(ims, t, r).per_frame)]

    rows = []
    for name, ratios in REAL_RATIOS.items():
        ims, t = load(name), np.asarray(ratios)
        row = {"stack": f"real {name}", "metric": "LOO per held frame (levels)"}
        d = hdr.recover_response(ims, t)
        row["well exposed in 2 frames"] = [round(float(v), 3) for v in d.diagnostics["overlap"]]
        row["default"] = pf(d, ims, t)
        for k in (0, 1, 2, 4):
            row[f"subspace n_poly={k}"] = pf(
                hdr.recover_response(ims, t, method="subspace", n_poly=k), ims, t
            )
        row["OpenCV"] = [round(float(v), 2) for v in np.asarray(opencv_loo(ims, t).per_frame)]
        log(row)
        rows.append(row)
    for name in ("gamma2.2", "srgb", "filmic", "log"):
        st = analytic_stack(name)
        row = {"stack": f"synthetic {name}", "metric": "radiance error, curve error"}

        def sc(r, st=st):
            e = hdr.merge_radiance(st.images, st.exposure_times, r)
            return (
                round(float(hdr.radiance_error(e, st.radiance)), 4),
                round(float(hdr.response_curve_error(r, st.response)), 4),
            )

        d = hdr.recover_response(st.images, st.exposure_times)
        row["well exposed in 2 frames"] = [round(float(v), 3) for v in d.diagnostics["overlap"]]
        row["default"] = sc(d)
        for k in (0, 2):
            r = hdr.recover_response(st.images, st.exposure_times, method="subspace", n_poly=k)
            row[f"subspace n_poly={k}"] = sc(r)
        cv_e = jnp.asarray(opencv_debevec_merge(st.images, st.exposure_times))
        row["OpenCV"] = round(float(hdr.radiance_error(cv_e, st.radiance)), 4)
        log(row)
        rows.append(row)
    return rows


def overlaps():
    """The sparse-bracket rule's statistic (:func:`jaxgfx.hdr._debevec.bracket_overlap`,
    per channel, on the whole image) for every stack family of the tests and tables: the
    measured-curve brackets, the real JPEG brackets, the JPEG-like stacks of
    ``experiments.merge_weight`` and the analytic synthetic stacks (no fits)."""
    import jax.numpy as jnp

    from jaxgfx.hdr._debevec import bracket_overlap

    from .merge_weight import JPEG_LIKE, REAL_RATIOS
    from .real_bracket import load

    def ov(ims):
        z = jnp.asarray(np.asarray(ims), jnp.float32) / 255.0
        return [round(float(v), 3) for v in bracket_overlap(z)]

    out = {}
    for cname, bname, st in measured_stacks():
        out[f"measured {cname[17:]} {bname}"] = ov(st.images)
    for name in REAL_RATIOS:
        out[f"real {name}"] = ov(load(name))
    rad = hdr.synthetic_radiance(jax.random.key(1), 96, 96, dynamic_range=1e4)
    for label, (name, times, *shift) in JPEG_LIKE.items():
        st = hdr.make_jpeg_stack(
            jax.random.key(2), rad, jnp.asarray(times), name, max_shift=(shift or [0.0])[0]
        )
        out[f"JPEG-like {label}"] = ov(st.images)
    for name in ("gamma2.2", "srgb", "filmic", "log"):
        out[f"synthetic {name}"] = ov(analytic_stack(name).images)
    log(out)
    return out


def prior_rows():
    """The smoothness prior on the 5-frame brackets (issue 26's red row): for
    ``smooth_prior`` "none", "auto" (the default since issue 26's last step) and "subspace", the
    radiance error, the self-check's LOO candidates and whether the prior'd fit was chosen;
    the ``lam`` sweep without the prior (the rejected alternative: lowering λ); OpenCV; and
    the red curve's per-level error (ln, after the median offset over levels 30-224, every 15
    levels from 5) for "none", "auto" and OpenCV."""
    import jax.numpy as jnp

    from .measured_curves import opencv_debevec_merge

    rows = []
    lv = jnp.broadcast_to(jnp.linspace(0, 1, 256)[:, None], (256, 3))
    for cname, bname, st in measured_stacks():
        if "5 frames" not in bname:
            continue
        row = {"curve": cname[17:], "bracket": bname}
        gt = np.log(np.asarray(st.response.to_linear_normalized(lv)))[:, 0]
        fits = {}
        for sp in ("none", "auto", "subspace"):
            r = hdr.recover_response(st.images, st.exposure_times, smooth_prior=sp)
            fits[sp] = r
            row[f"smooth_prior={sp}: |d ln E|, LOO"] = _score(st, r)
            row[f"smooth_prior={sp}: LOO candidates"] = [
                round(float(v), 3) for v in np.asarray(r.diagnostics["loo_candidates"])
            ]
            row[f"smooth_prior={sp}: prior chosen"] = bool(r.diagnostics["prior_chosen"])
        for lam in (3e-7, 3e-6):
            r = hdr.recover_response(st.images, st.exposure_times, smooth_prior="none", lam=lam)
            row[f"none, lam {lam:g}: |d ln E|, LOO candidates"] = [
                _score(st, r)[0],
                [round(float(v), 3) for v in np.asarray(r.diagnostics["loo_candidates"])],
            ]
        e_cv = opencv_debevec_merge(st.images, st.exposure_times)
        row["OpenCV |d ln E|"] = round(
            float(hdr.radiance_error(jnp.asarray(e_cv), st.radiance, per_channel=True)), 3
        )
        if "Red" in cname:
            import cv2

            bgr = [np.ascontiguousarray(np.asarray(im)[..., ::-1]) for im in st.images]
            t32 = np.asarray(st.exposure_times, np.float32)
            crv = cv2.createCalibrateDebevec().process(bgr, t32)
            tab = np.log(np.maximum(crv[:, 0, ::-1].astype(np.float64), 1e-30))
            cv = hdr.CameraResponse(jnp.asarray(tab, jnp.float32), "table", "opencv", 255.0, 0.5)
            row["levels"] = list(range(5, 251, 15))
            for name, r in (("none", fits["none"]), ("auto", fits["auto"]), ("OpenCV", cv)):
                err = np.log(np.asarray(r.to_linear_normalized(lv)))[:, 0] - gt
                err -= np.median(err[30:225])
                row[f"per-level error {name}"] = [round(float(v), 3) for v in err[5:251:15]]
        log(row)
        rows.append(row)
    return rows


def timing(what="rule"):
    """``recover_response`` with the sparse-bracket rule off (``sparse_overlap=0``, the code
    path before it) and on (default) — or, with ``what="prior"``, with
    (``smooth_prior="none"``) and ``"auto"`` —, interleaved in one process
    on the green 96×96 AEB and 5-frame stacks: first call after ``jax.clear_caches()``
    (compile) and the median of 4 steady calls, process CPU seconds and wall seconds, 2
    repeats."""
    import os
    import time

    def run(st, **o):
        c0, w0 = time.process_time(), time.perf_counter()
        r = hdr.recover_response(st.images, st.exposure_times, **o)
        jax.block_until_ready(r.params)
        return time.process_time() - c0, time.perf_counter() - w0

    stacks = {b: s for c, b, s in measured_stacks() if "Green" in c}
    out = {"load average": [round(v, 1) for v in os.getloadavg()]}
    for _ in range(2):
        for bname, st in stacks.items():
            ab = {  # (A, B): B the option the A/B is about
                "rule": (("rule off", {"sparse_overlap": 0.0}), ("default", {})),
                "prior": (("prior off", {"smooth_prior": "none"}), ("prior on (default)", {})),
            }
            for label, o in ab[what]:
                jax.clear_caches()
                first = run(st, **o)
                steady = [run(st, **o) for _ in range(4)]
                out.setdefault(f"{bname}, {label}", []).append(
                    {
                        "first call cpu s": round(first[0], 2),
                        "first call wall s": round(first[1], 2),
                        "steady cpu ms": round(1e3 * float(np.median([s[0] for s in steady])), 1),
                        "steady wall ms": round(1e3 * float(np.median([s[1] for s in steady])), 1),
                    }
                )
    out["load average after"] = [round(v, 1) for v in os.getloadavg()]
    log(out)
    return out


def figure(path):
    import cv2
    import jax.numpy as jnp
    import matplotlib

    from jaxgfx.hdr._subspace import response_basis

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(14, 3.4))
    lv = np.arange(256)
    b = response_basis(256, 2)
    for k, name in enumerate(["1", "ln z", "ln(1-z)", "P1", "P2"]):
        axes[0].plot(lv, b[:, k], label=f"basis {k} (from {name})")
    axes[0].set_title("curve-space basis (orthonormal, n_poly=2)")
    axes[0].set_xlabel("level")
    axes[0].legend(fontsize=6)
    zz = jnp.broadcast_to(jnp.linspace(0, 1, 256)[:, None], (256, 3))
    aeb = [s for s in measured_stacks() if "AEB" in s[1]]
    for ax, (cname, _, st) in zip(axes[1:], aeb, strict=True):
        gt = np.log(np.asarray(st.response.to_linear_normalized(zz)))[:, 0]
        bgr = [np.ascontiguousarray(np.asarray(im)[..., ::-1]) for im in st.images]
        crv = cv2.createCalibrateDebevec().process(bgr, np.asarray(st.exposure_times, np.float32))
        tab = np.log(np.maximum(crv[:, 0, ::-1].astype(np.float64), 1e-30)).astype(np.float32)
        cv = hdr.CameraResponse(jnp.asarray(tab), "table", "opencv", 255.0, 0.5)
        curves = {
            "truth": st.response,
            "default (subspace chosen)": hdr.recover_response(st.images, st.exposure_times),
            "free table (sparse_overlap=0)": hdr.recover_response(
                st.images, st.exposure_times, sparse_overlap=0.0
            ),
            "OpenCV Debevec": cv,
        }
        for label, r in curves.items():
            g = np.log(np.asarray(r.to_linear_normalized(zz)))[:, 0]
            g = g - np.median((g - gt)[30:225]) if label != "truth" else g
            ax.plot(lv, g, label=label, lw=1.5 if label == "truth" else 1.0)
        ax.set_title(f"AEB ±3 EV, {cname[17:]}")
        ax.set_xlabel("level")
        ax.set_ylim(-8, 2)
        ax.legend(fontsize=6)
    axes[1].set_ylabel("ln x (offset to the truth, levels 30-224)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spline", action="store_true")
    ap.add_argument("--levels", action="store_true", help="only the red AEB per-level errors")
    ap.add_argument("--subspace", action="store_true", help="only method='subspace' by n_poly")
    ap.add_argument("--figure", default=None, help="only the basis / AEB curves figure")
    ap.add_argument("--checks", action="store_true", help="only subspace on real/synthetic")
    ap.add_argument("--timing", action="store_true", help="only the rule's cost, A/B")
    ap.add_argument("--overlap", action="store_true", help="only the rule's statistic")
    ap.add_argument("--prior", action="store_true", help="only the smoothness prior, 5 frames")
    ap.add_argument("--timing-prior", action="store_true", help="only the prior's cost, A/B")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    if a.figure:
        figure(a.figure)
        return
    if a.subspace:
        emit_json(subspace_rows(), a.json)
        return
    if a.checks:
        emit_json(checks(), a.json)
        return
    if a.timing or a.timing_prior:
        emit_json(timing("prior" if a.timing_prior else "rule"), a.json)
        return
    if a.prior:
        emit_json(prior_rows(), a.json)
        return
    if a.overlap:
        emit_json(overlaps(), a.json)
        return
    emit_json(levels() if a.levels else measure(spline=a.spline), a.json)


if __name__ == "__main__":
    main()
