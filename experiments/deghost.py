"""Ghost-free merge on brackets with a moving object (issue 27): errors against ground truth.

    python -m experiments.deghost [--size 64] [--figure docs/images/hdr_deghost.png] [--out FILE]

Scene: ``hdr.synthetic_radiance`` (1e3:1), 5 exposures 2 stops apart, a textured disc that is
at a different position in every frame (``hdr.synthetic.make_moving_object_stack``), shot and
read noise, 8-bit sRGB (LDR path, true response) or float linear (RAW path). Reference: the
middle frame; ground truth: the radiance that frame saw. Per path and merge (plain
``merge_radiance(weighting="noise")``, ``merge_deghosted``, and the oracle: the same
noise-optimal merge of exactly the frames that saw the reference's content) the median and
95th percentile of ``|ln E - ln E_true|`` (after the median log ratio of the static pixels) in
the static region, the moving region (pixels where any frame saw something else) and at the
ghost positions (the object in other frames only). Prints JSON.
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

from experiments._common import emit_json
from jaxgfx import hdr
from jaxgfx.hdr.synthetic import make_moving_object_stack

REF = 2


def _err(R, truth, static):
    d = np.log(np.maximum(np.asarray(R, np.float64), 1e-30)) - np.log(np.asarray(truth))
    return np.abs(d - np.median(d[static])).max(-1)


def measure(size: int, raw: bool):
    E = hdr.synthetic_radiance(jax.random.key(0), size, size, dynamic_range=1e3)
    t = 4.0 ** np.arange(-2, 3)
    if raw:
        resp = hdr.CameraResponse.gamma(1.0, channels=3, anchor="unit")
        bits = None
    else:
        resp, bits = hdr.synthetic_response("srgb"), 8
    step = size / 6.0
    centers = [(0.62 * size, 0.2 * size + step * j) for j in range(5)]
    ms = make_moving_object_stack(
        jax.random.key(1), E, t, resp, centers=centers, radius=size / 10, level=0.05, bits=bits
    )
    imgs, noise = ms.stack.images, ms.stack.noise
    fr = np.asarray(ms.frames_radiance)
    same = np.all(fr == fr[REF][None], -1)
    static, moving = same.all(0), ~same.all(0)
    ghost = moving & ~np.asarray(ms.object_masks[REF])
    res = hdr.merge_deghosted(imgs, t, None if raw else resp, noise=noise, reference=REF)
    plain = hdr.merge_radiance(imgs, t, resp, weighting="noise", noise=noise)
    zero = np.zeros((), np.asarray(imgs).dtype)
    oracle = hdr.merge_radiance(
        np.where(same[..., None], np.asarray(imgs), zero), t, resp, weighting="noise", noise=noise
    )
    out = {}
    for name, R in (("plain", plain), ("deghosted", res.radiance), ("oracle", oracle)):
        e = _err(R, fr[REF], static)
        out[name] = {
            region: {"median": float(np.median(e[m])), "p95": float(np.percentile(e[m], 95))}
            for region, m in (("static", static), ("moving", moving), ("ghost", ghost))
        }
    out["frames_used_mean"] = np.asarray(res.used).mean((1, 2)).round(3).tolist()
    return out, (np.asarray(imgs), fr[REF], np.asarray(plain), np.asarray(res.radiance), res)


def figure(path, data):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    imgs, truth, plain, dg, res = data

    def show(E):
        s = np.median(truth) / np.median(E)
        return np.clip((E * s / np.percentile(truth, 99)) ** (1 / 2.2), 0, 1)

    fig, ax = plt.subplots(1, 5, figsize=(15, 3.3))
    panels = [
        (imgs[1], "frame 2 of 5 (8-bit)"),
        (show(plain), "merge_radiance: ghosts"),
        (show(dg), "merge_deghosted"),
        (show(truth), "truth (reference frame's scene)"),
    ]
    for a, (im, title) in zip(ax, panels, strict=False):
        a.imshow(im)
        a.set_title(title, fontsize=9)
        a.axis("off")
    used = np.asarray(res.used).sum(0)
    im = ax[4].imshow(used, cmap="viridis", vmin=1, vmax=imgs.shape[0])
    ax[4].set_title("frames merged per pixel", fontsize=9)
    ax[4].axis("off")
    fig.colorbar(im, ax=ax[4], fraction=0.046)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--figure", default=None, help="write the LDR comparison figure here")
    p.add_argument("--out", default=None, help="also write the JSON here")
    args = p.parse_args(argv)
    ldr, data = measure(args.size, raw=False)
    raw, _ = measure(args.size, raw=True)
    emit_json({"size": args.size, "reference": REF, "ldr_8bit": ldr, "raw_linear": raw}, args.out)
    if args.figure:
        figure(args.figure, data)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
