"""What a fit writes: ``result.json``, the loss/parameter curves and the before / after /
target previews."""

from __future__ import annotations

import json
import os

import numpy as np

__all__ = ["OUTPUT_NAMES", "plain", "srgb8", "plot_curves", "write_outputs"]

OUTPUT_NAMES = (
    "result.json", "curves.png", "before.png", "after.png", "target.png", "response.json",
)
"""Every file a fit may write (``response.json``: the fitted camera response of an LDR fit,
:func:`jaxgfx.hdr.save_response`)."""


def srgb8(img, scale=1.0):
    """8-bit sRGB preview of linear ``img`` scaled by ``scale`` (clipped to [0, 1])."""
    from jaxgfx.color import linear_to_srgb

    v = np.asarray(linear_to_srgb(np.clip(np.asarray(img, np.float32) * scale, 0.0, 1.0)))
    return np.round(np.clip(v, 0, 1) * 255).astype(np.uint8)


def plain(x):
    """A JSON value: a float for a scalar, nested lists otherwise."""
    a = np.asarray(x, np.float64)
    return float(a) if a.ndim == 0 else a.tolist()


def plot_curves(path, res, names, truth):
    """Loss and each fitted parameter against steps and against seconds (dashed: truth)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = 1 + len(names)
    fig, axes = plt.subplots(n, 2, figsize=(9, 2.3 * n), squeeze=False)
    steps = np.arange(res.n_steps + 1)
    t = np.concatenate([[0.0], np.cumsum(res.seconds)])
    for col, (xs, xl) in enumerate(((steps, "step"), (t, "seconds (after compilation)"))):
        ax = axes[0, col]
        ax.semilogy(xs[:-1], np.maximum(res.loss, 1e-30), color="k", lw=1)
        ax.set_ylabel("loss")
        ax.grid(alpha=0.3)
        for row, (group, name) in enumerate(names, start=1):
            ax = axes[row, col]
            hist = np.asarray(res.history[group][name], np.float64).reshape(len(xs), -1)
            colors = ("tab:red", "tab:green", "tab:blue") if hist.shape[1] == 3 else [None] * 99
            for c in range(min(hist.shape[1], 12)):
                ax.plot(xs, hist[:, c], color=colors[c], lw=1.2)
                if truth is not None and name in truth:
                    tv = np.asarray(truth[name], np.float64).reshape(-1)
                    ax.axhline(tv[min(c, tv.size - 1)], color=colors[c] or "k", ls="--", lw=0.8)
            ax.set_ylabel(
                name.split(".")[-2] + "." + name.split(".")[-1] if "." in name else name, fontsize=8
            )
            ax.grid(alpha=0.3)
        axes[-1, col].set_xlabel(xl)
    fig.suptitle("fit: loss and parameters (dashed: truth)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_outputs(out_dir, result, res, *, before, after, target, names, truth):
    """Write the previews (``before`` / ``after`` / ``target``: uint8 images), the curves and
    ``result.json`` into ``out_dir``."""
    from jaxgfx.io import write_png

    write_png(os.path.join(out_dir, "before.png"), before)
    write_png(os.path.join(out_dir, "after.png"), after)
    write_png(os.path.join(out_dir, "target.png"), target)
    plot_curves(os.path.join(out_dir, "curves.png"), res, names, truth)
    with open(os.path.join(out_dir, "result.json"), "w", encoding="utf-8") as f:
        json.dump(result, f, indent=1)
