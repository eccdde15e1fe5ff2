"""Leave-one-out on real JPEG brackets (issue 26): jaxgfx defaults vs OpenCV Debevec.

    python -m experiments.real_bracket

Data: ``tests/data/real_bracket/`` (256×256 crops of the HDR fusion dataset of Merianos &
Mitianoudis, IST 2016; origin and licence in its README). The JPEGs carry no EXIF, so the
exposure ratios are estimated with ``recover_response(..., method="polynomial")`` (Mitsunaga
& Nayar; starting from ±2 EV, its weak prior pulls towards them) and normalised to the middle
frame. Prints, per set, the ratios and the per-held-frame LOO error (levels, 0–255) of
jaxgfx's defaults (the ``slope`` merge), of jaxgfx with the ``hat`` merge and
``time_power=0`` and of OpenCV ``CalibrateDebevec`` + ``MergeDebevec`` (and the signed bias
per held frame), as JSON.
"""

from __future__ import annotations

import os

import numpy as np

from jaxgfx import hdr

from ._common import emit_json, log

DATA = os.path.join(os.path.dirname(__file__), "..", "tests", "data", "real_bracket")
SETS = ("oldhouse", "flowers")


def load(name):
    from PIL import Image

    return np.stack(
        [np.asarray(Image.open(os.path.join(DATA, f"{name}_{i}.png"))) for i in (1, 2, 3)]
    )


def estimate_times(images):
    p = hdr.recover_response(images, np.asarray([0.25, 1.0, 4.0]), method="polynomial")
    r = np.asarray(p.exposure_ratios, np.float64)
    return r / r[1]


def opencv_loo(images, times):
    import cv2
    import jax.numpy as jnp

    bgr = [np.ascontiguousarray(im[..., ::-1]) for im in images]
    tt = np.asarray(times, np.float32)
    crv = cv2.createCalibrateDebevec().process(bgr, tt)
    tab = np.log(np.maximum(crv[:, 0, ::-1].astype(np.float64), 1e-30))
    anchor = np.exp(0.5 * (tab[127] + tab[128]))
    tab = np.sort(tab, axis=0) + np.arange(256)[:, None] * 1e-6
    resp = hdr.CameraResponse(jnp.asarray(tab, jnp.float32), "table", "opencv", 255.0, 0.5)
    md = cv2.createMergeDebevec()

    def merge(z, t):
        b = [np.ascontiguousarray(im[..., ::-1]) for im in np.asarray(z)]
        return md.process(b, np.asarray(t, np.float32), crv)[..., ::-1] / anchor

    return hdr.leave_one_out(images, times, resp, merge=merge)


def measure():
    rows = []
    for name in SETS:
        ims = load(name)
        t = estimate_times(ims)
        r = hdr.recover_response(ims, t)
        ours = hdr.leave_one_out(ims, t, r)
        tp0 = hdr.leave_one_out(ims, t, r, weighting="hat", time_power=0.0)
        cv = opencv_loo(ims, t)
        row = {
            "set": name,
            "ratios": [round(float(v), 3) for v in t],
            "jaxgfx default": [round(float(v), 2) for v in np.asarray(ours.per_frame)],
            "jaxgfx, merge hat time_power=0": [
                round(float(v), 2) for v in np.asarray(tp0.per_frame)
            ],
            "OpenCV Debevec": [round(float(v), 2) for v in np.asarray(cv.per_frame)],
            "jaxgfx per-band bias": [round(float(v), 2) for v in np.asarray(ours.per_band_bias)],
            "jaxgfx per-frame bias": [round(float(v), 2) for v in np.asarray(ours.per_frame_bias)],
            "OpenCV per-frame bias": [round(float(v), 2) for v in np.asarray(cv.per_frame_bias)],
        }
        log(row)
        rows.append(row)
    return rows


def main(argv=None):
    emit_json(measure(), None)


if __name__ == "__main__":
    main()
