"""Fit a tone-mapping operator to a target display image; before/after images, loss curve.

    python -m experiments.tonemap_fit --config configs/tonemap_fit.yaml --out out/tonemap_fit

Writes ``hdr_preview.png`` (the input through the initial parameters), ``target.png``,
``fitted.png``, ``loss.png`` (loss per step) and ``result.json`` (true, initial and fitted
parameters, final loss). The fit is :func:`jaxgfx.tonemap.fit_tonemap`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys

import numpy as np

from jaxgfx import io
from jaxgfx import tonemap as tm
from jaxgfx.config import load_config


@dataclasses.dataclass(frozen=True)
class TonemapFitConfig:
    operator: str = "drago"
    fit: tuple[str, ...] = ("bias", "saturation")
    init: dict = dataclasses.field(default_factory=dict)
    target_op: str = "drago"
    target_params: dict = dataclasses.field(default_factory=dict)
    hdr: str | None = None
    target: str | None = None
    size: tuple[int, ...] = (96, 128)
    solver: str = "adam"
    steps: int = 300
    learning_rate: float = 0.05
    loss: str = "lab"

    def validate(self):
        for name in (self.operator, self.target_op):
            if name not in tm.TONEMAP_METHODS:
                raise ValueError(
                    f"operator: expected one of {list(tm.TONEMAP_METHODS)}, got {name!r}"
                )
        if len(self.size) != 2 or min(self.size) < 8:
            raise ValueError(f"size: expected [H, W] >= 8, got {self.size!r}")


def synthetic_scene(H, W):
    from jaxgfx.hdr.synthetic import outdoor_hdr_scene as hdr_scene

    return hdr_scene(H, W)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default="configs/tonemap_fit.yaml")
    p.add_argument("--out", default="out/tonemap_fit")
    args = p.parse_args(argv)
    cfg = load_config(TonemapFitConfig, args.config)
    hdr = io.read_any(cfg.hdr) if cfg.hdr else synthetic_scene(*cfg.size)
    hdr = np.maximum(np.asarray(hdr, np.float32)[..., :3], 0.0)
    if cfg.target:
        target = io.read_image(cfg.target, as_float=True)[..., :3]
    else:
        target = np.asarray(tm.TONEMAP_METHODS[cfg.target_op](hdr, **cfg.target_params))
    init = dict(cfg.init)
    before = np.asarray(tm.TONEMAP_METHODS[cfg.operator](hdr, **init))
    res = tm.fit_tonemap(
        cfg.operator,
        hdr,
        target,
        init=init,
        fit=tuple(cfg.fit),
        steps=cfg.steps,
        solver=cfg.solver,
        learning_rate=cfg.learning_rate,
        loss=cfg.loss,
    )
    after = np.asarray(tm.TONEMAP_METHODS[cfg.operator](hdr, **res.params))
    os.makedirs(args.out, exist_ok=True)
    io.write_png(os.path.join(args.out, "before.png"), before)
    io.write_png(os.path.join(args.out, "target.png"), target.astype(np.float32))
    io.write_png(os.path.join(args.out, "fitted.png"), after)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.semilogy(np.asarray(res.loss_history))
    ax.set_xlabel("step")
    ax.set_ylabel(f"loss ({cfg.loss})")
    ax.set_title(f"fit {cfg.operator} ({cfg.solver})")
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "loss.png"), dpi=100)
    plt.close(fig)
    result = {
        "operator": cfg.operator,
        "true": dict(cfg.target_params) if not cfg.target else None,
        "init": init,
        "fitted": res.params,
        "final_loss": res.loss,
        "initial_loss": float(res.loss_history[0]),
    }
    with open(os.path.join(args.out, "result.json"), "w") as f:
        json.dump(result, f, indent=1)
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
