"""The Debevec default of issue 26's last step: the curve-space prior at two strengths and
every candidate-grid pixel as a sample.

    python -m experiments.response_defaults [--why] [--rows] [--variance] [--timing]
        [--shoulder] [--json out.json]

``--why``: the synthetic stack of ``jaxgfx calibrate``'s default job (filmic curve, 5 frames
8× apart, shot-noise gain 2e-4, read σ 1e-3; 48×64 as in
``tests/pipelines/test_calibrate.py``, and 240×320 as in ``configs/calibrate.yaml``), with
and without sensor noise: for each candidate of the self-check (end-weighted fit,
inverse-slope fit, inverse-slope fit with the curve-space prior at ``lam`` ×1, ×3, ×10,
×100) its mean LOO error (levels, on the candidate grid), its curve error (ln RMS, levels
10-245) and the green curve's per-level error; the curve-space fit ``g_sub`` alone; and the
truth's ``ln x`` at the wave's extremes (:func:`why`).

``--rows``: every stack that docs/hdr.md reports for the defaults, with the previous default
(``smooth_prior="none"``, ``n_samples=4096``) and the new one, and OpenCV ``CalibrateDebevec +
MergeDebevec`` in the same run (:func:`rows`).

``--variance``: the spread of the fitted curve over noise realisations at 4096 and 16 384
samples (:func:`variance`). ``--timing``: the cost, A/B in one process (:func:`timing`).
``--shoulder``: why the sample count is the grid's and not a fixed 16 384 (:func:`shoulder`).
"""

from __future__ import annotations

import argparse
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx import hdr

from ._common import emit_json, log

OLD = {"smooth_prior": "none", "n_samples": 4096}
NEW: dict = {}  # the defaults
LEVELS = list(range(5, 251, 15))


def _r(v, n=3):
    return [round(float(x), n) for x in np.atleast_1d(np.asarray(v))]


def calibrate_stack(height=48, width=64, gain=None, read=None, response=None):
    """The stack of ``jaxgfx calibrate``'s synthetic default job (configs/calibrate.yaml)."""
    from jaxgfx.config import load_config
    from jaxgfx.pipelines.calibrate import CalibrateConfig

    syn = {"height": height, "width": width}
    if response:
        syn["response"] = response
    s = load_config(CalibrateConfig, {"synthetic": syn}).synthetic
    k1, k2 = jax.random.split(jax.random.key(s.seed))
    rad = hdr.synthetic_radiance(k1, s.height, s.width, dynamic_range=s.dynamic_range)
    return hdr.make_bracketed_stack(
        k2,
        rad,
        np.asarray(s.exposure_times),
        hdr.synthetic_response(s.response),
        bits=s.bits,
        gain=s.gain if gain is None else gain,
        read_sigma=s.read_sigma if read is None else read,
    )


def _candidates(st, strengths=(1.0, 3.0, 10.0, 100.0), lam=1e-6, passes=3):
    """The self-check's candidate curves ``{name: g (C, L)}`` and their LOO errors, built with
    the library's own pieces (same samples, solves and LOO as ``recover_response``)."""
    from jaxgfx.hdr import _debevec as D

    z = jnp.asarray(st.images, jnp.float32) / 255.0
    t = jnp.asarray(st.exposure_times, jnp.float32)
    n_lev, m = 256, 127
    lev, w, interior, valid = D.debevec_samples(z, None, None, None, n_lev, "hat", 0.2)
    log_t = jnp.log(t)
    g_sub, _ = D._subspace_fit(lev, interior, valid, log_t, m, lam, n_lev, w.dtype)
    zero = jnp.zeros_like(g_sub)
    g0 = jax.vmap(lambda lv, ww, gp: D.debevec_solve(lv, ww, log_t, n_lev, lam, m, gp))(
        lev, w, zero
    )
    base = interior.astype(w.dtype) * valid[..., None].astype(w.dtype)
    names = ["end-weighted", "inverse-slope"]
    cands = [(g0, w)]
    gs, ws = D._refit_chain(g0, lev, base, log_t, n_lev, m, [(lam, False)], passes, g_sub)
    cands.append((gs[-1], ws[-1]))
    for s in strengths:  # each prior'd chain from the plain inverse-slope fit
        gs, ws = D._refit_chain(
            cands[1][0], lev, base, log_t, n_lev, m, [(lam * s, True)], passes, g_sub
        )
        cands.append((gs[-1], ws[-1]))
        names.append(f"prior x{s:g}")
    _, _, _, errs = D._select_by_loo(z, t, cands, m, 0.5)
    out = {n: (c[0], float(e)) for n, c, e in zip(names, cands, np.asarray(errs), strict=True)}
    out["curve space g_sub (not a candidate)"] = (g_sub, float("nan"))
    return out


def _curve_err(g, true_resp, channel=1):
    from jaxgfx.hdr._sampling import monotone_repair

    zn = jnp.broadcast_to(jnp.linspace(0.0, 1.0, 256)[:, None], (256, g.shape[0]))
    with np.errstate(divide="ignore"):
        tl = np.log(np.asarray(true_resp.to_linear_normalized(zn), np.float64))
    d = np.asarray(monotone_repair(jnp.asarray(g).T, 127), np.float64) - tl
    d = d - d[10:246].mean(0, keepdims=True)
    return float(np.sqrt(np.mean(d[10:246] ** 2))), d[LEVELS, channel]


def why():
    rows = []
    for (h, w), noise in (((48, 64), True), ((48, 64), False), ((240, 320), True)):
        st = calibrate_stack(h, w, *(() if noise else (0.0, 0.0)))
        row = {"stack": f"calibrate default job {h}x{w}", "sensor noise": noise}
        row["levels"] = LEVELS
        for name, (g, loo) in _candidates(st).items():
            rms, d = _curve_err(g, st.response)
            row[name] = {"LOO": round(loo, 3), "curve ln RMS": round(rms, 3), "green": _r(d)}
        log(row)
        rows.append(row)
    zn = jnp.broadcast_to(jnp.asarray([20, 65, 155, 230], jnp.float32)[:, None] / 255.0, (4, 3))
    tl = np.log(np.asarray(st.response.to_linear_normalized(zn)))[:, 1]
    rows.append(
        {
            "true ln x at levels 20 / 65 / 155 / 230": _r(tl),
            "steps 20->155, 65->230 (ln 8 = 2.079)": _r([tl[2] - tl[0], tl[3] - tl[1]]),
        }
    )
    log(rows[-1])
    return rows


def _fits():
    return {"previous default": OLD, "default": NEW}


def rows():
    from .measured_curves import measured_stacks, opencv_debevec_merge
    from .merge_weight import JPEG_LIKE, REAL_RATIOS
    from .real_bracket import load, opencv_loo

    out = []

    def cands(r):
        return _r(r.diagnostics["loo_candidates"])

    for resp in ("filmic", "srgb", "gamma2.2", "log", "s-curve"):
        st = calibrate_stack(response=resp)
        row = {"stack": f"calibrate job 48x64, {resp}", "metric": "curve ln RMS / |d ln E|"}
        for k, o in _fits().items():
            r = hdr.recover_response(st.images, st.exposure_times, **o)
            e = hdr.merge_radiance(st.images, st.exposure_times, r)
            row[k] = _r(
                [hdr.response_curve_error(r, st.response), hdr.radiance_error(e, st.radiance)]
            )
            row[k + " candidates"] = cands(r)
        log(row)
        out.append(row)
    for cname, bname, st in measured_stacks():
        row = {"stack": f"{cname[17:]} {bname}", "metric": "median |d ln E| per channel"}
        for k, o in _fits().items():
            r = hdr.recover_response(st.images, st.exposure_times, **o)
            e = hdr.merge_radiance(st.images, st.exposure_times, r)
            row[k] = _r(hdr.radiance_error(e, st.radiance, per_channel=True), 4)
            row[k + " candidates"] = cands(r)
        e = opencv_debevec_merge(st.images, st.exposure_times)
        row["OpenCV"] = _r(hdr.radiance_error(jnp.asarray(e), st.radiance, per_channel=True), 4)
        log(row)
        out.append(row)
    for name, ratios in REAL_RATIOS.items():
        ims, t = load(name), np.asarray(ratios)
        row = {"stack": f"real {name}", "metric": "LOO per held frame (levels)"}
        for k, o in _fits().items():
            r = hdr.recover_response(ims, t, **o)
            row[k] = _r(hdr.leave_one_out(ims, t, r).per_frame)
            row[k + " candidates"] = cands(r)
        row["OpenCV"] = _r(opencv_loo(ims, t).per_frame)
        log(row)
        out.append(row)
    rad = hdr.synthetic_radiance(jax.random.key(1), 96, 96, dynamic_range=1e4)
    for label, (name, times, *shift) in JPEG_LIKE.items():
        st = hdr.make_jpeg_stack(
            jax.random.key(2), rad, jnp.asarray(times), name, max_shift=(shift or [0.0])[0]
        )
        row = {"stack": f"JPEG-like {label}", "metric": "LOO mean (levels)"}
        for k, o in _fits().items():
            r = hdr.recover_response(st.images, st.exposure_times, **o)
            row[k] = _r(hdr.leave_one_out(st.images, st.exposure_times, r).mean_abs_error)
            row[k + " candidates"] = cands(r)
        row["OpenCV"] = _r(opencv_loo(st.images, st.exposure_times).mean_abs_error)
        log(row)
        out.append(row)
    return out


def variance(n_real=6):
    """The estimator's variance: ``n_real`` noise realisations of one 256×256 scene (a
    128×128 candidate grid) through the sRGB curve and the JPEG-like camera curve (5 frames 4×
    apart, 8-bit, gain 1e-4, read σ 1e-3, no JPEG coding), fitted with 4096 and with 16 384
    samples (everything else default): the curve error against the truth (ln RMS over levels
    10-245, mean over realisations) and the spread of the curve over realisations (the
    per-level standard deviation of ``ln x`` after each curve's mean offset, RMS over levels
    10-245)."""
    rad = hdr.synthetic_radiance(jax.random.key(7), 256, 256, dynamic_range=1e3)
    times = np.asarray([1 / 256, 1 / 64, 1 / 16, 1 / 4, 1.0]) * 4.0
    zn = jnp.broadcast_to(jnp.arange(10, 246, dtype=jnp.float32)[:, None] / 255.0, (236, 3))
    out = []
    for curve in ("srgb", "camera"):
        resp = hdr.synthetic_response(curve)
        row = {"curve": curve, "realisations": n_real}
        for ns in (4096, 16384):
            errs, tabs = [], []
            for k in range(n_real):
                st = hdr.make_bracketed_stack(jax.random.key(100 + k), rad, times, resp, bits=8)
                r = hdr.recover_response(st.images, st.exposure_times, n_samples=ns)
                errs.append(float(hdr.response_curve_error(r, resp)))
                g = np.log(np.asarray(r.to_linear_normalized(zn), np.float64))
                tabs.append(g - g.mean(0, keepdims=True))
            sd = np.std(np.stack(tabs), axis=0, ddof=1)
            row[f"n_samples {ns}: curve error mean"] = round(float(np.mean(errs)), 4)
            row[f"n_samples {ns}: spread over realisations (ln RMS)"] = round(
                float(np.sqrt(np.mean(sd**2))), 4
            )
        log(row)
        out.append(row)
    return out


def shoulder():
    """The JPEG-like camera 3-frame stack of ``tests/hdr/test_selfcheck.py`` (96×96, 3 frames
    8× apart): the fitted curve's toe ``x(2)/x(128)`` and shoulder ``x(250)/x(128)`` (truth
    0.0086 and 6.44; the test asserts 0.004–0.012 and 5.0–8.5), the curve error and the LOO,
    for the previous default, a fixed 16 384 samples and the default (9 216 = the grid)."""
    rad = hdr.synthetic_radiance(jax.random.key(1), 96, 96, dynamic_range=1e4)
    st = hdr.make_jpeg_stack(jax.random.key(2), rad, jnp.asarray((1 / 64, 1 / 8, 1.0)), "camera")
    z = jnp.asarray([[2 / 255] * 3, [128 / 255] * 3, [250 / 255] * 3])
    out = []
    for label, o in (
        ("previous default", OLD),
        ("n_samples 16384", {"n_samples": 16384}),
        ("default", NEW),
    ):
        r = hdr.recover_response(st.images, st.exposure_times, **o)
        x = np.asarray(r.to_linear_normalized(z)).mean(axis=1)
        row = {"fit": label, "toe": round(float(x[0] / x[1]), 4)}
        row["shoulder"] = round(float(x[2] / x[1]), 2)
        row["curve ln RMS"] = round(float(hdr.response_curve_error(r, st.response)), 3)
        row["LOO"] = round(
            float(hdr.leave_one_out(st.images, st.exposure_times, r).mean_abs_error), 3
        )
        row["candidates"] = _r(r.diagnostics["loo_candidates"])
        log(row)
        out.append(row)
    return out


def timing(repeats=2):
    """``recover_response`` with the previous default (:data:`OLD`) and the new one,
    interleaved in one process: the green 96×96 5-frame measured stack, the real flowers
    bracket (256×256) and a 1 MP synthetic sRGB stack (5 frames); first call after
    ``jax.clear_caches()`` (compile) and the median of 4 steady calls, process CPU s and wall
    s."""
    from .measured_curves import measured_stacks
    from .real_bracket import load

    def run(ims, t, **o):
        c0, w0 = time.process_time(), time.perf_counter()
        r = hdr.recover_response(ims, t, **o)
        jax.block_until_ready(r.params)
        return time.process_time() - c0, time.perf_counter() - w0

    st5 = next(s for c, b, s in measured_stacks() if "Green" in c and "5" in b)
    big = hdr.make_bracketed_stack(
        jax.random.key(3),
        hdr.synthetic_radiance(jax.random.key(4), 1024, 1024, dynamic_range=1e3),
        jnp.asarray([1 / 64, 1 / 16, 1 / 4, 1.0, 4.0]),
        hdr.synthetic_response("srgb"),
    )
    stacks = {
        "96x96 5 frames": (np.asarray(st5.images), np.asarray(st5.exposure_times)),
        "flowers 256x256": (load("flowers"), np.asarray([0.30, 1.0, 3.83])),
        "1 MP 5 frames": (np.asarray(big.images), np.asarray(big.exposure_times)),
    }
    out = {"load average": _r(os.getloadavg(), 1)}
    for _ in range(repeats):
        for sname, (ims, t) in stacks.items():
            for label, o in _fits().items():
                jax.clear_caches()
                first = run(ims, t, **o)
                steady = [run(ims, t, **o) for _ in range(4)]
                out.setdefault(f"{sname}, {label}", []).append(
                    {
                        "first call cpu s": round(first[0], 2),
                        "first call wall s": round(first[1], 2),
                        "steady cpu ms": round(1e3 * float(np.median([s[0] for s in steady])), 1),
                        "steady wall ms": round(1e3 * float(np.median([s[1] for s in steady])), 1),
                    }
                )
    out["load average after"] = _r(os.getloadavg(), 1)
    log(out)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--why", action="store_true")
    ap.add_argument("--rows", action="store_true")
    ap.add_argument("--variance", action="store_true")
    ap.add_argument("--timing", action="store_true")
    ap.add_argument("--shoulder", action="store_true")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    out = {}
    fns = {"why": why, "rows": rows, "variance": variance, "timing": timing, "shoulder": shoulder}
    for flag, fn in fns.items():
        if getattr(a, flag):
            out[flag] = fn()
    emit_json(out, a.json)


if __name__ == "__main__":
    main()
