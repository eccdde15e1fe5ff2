"""Builders the pipeline tests share: the fit scene and validated fit configurations."""

import os

from jaxgfx.config import load_config
from jaxgfx.pipelines.fit import FitConfig

SCENE = os.path.join(os.path.dirname(__file__), "..", "..", "configs", "scenes", "inverse.yaml")
"""A GGX metal sphere under an area light (configs/scenes/inverse.yaml)."""

FIT_BASE = {
    "scene": SCENE,
    "target": {"synthetic": {"materials.metal.alpha": 0.15}, "spp": 16},
    "params": {"materials.metal.alpha": {"init": 0.5, "min": 0.01, "max": 1.0}},
    "render": {"spp": 4, "width": 8, "height": 8},
    "optimizer": {"steps": 3},
    "progress": False,
}
"""A small fit: α of the metal from a synthetic target, 8x8 at 4 spp, 3 steps, quiet."""


def fit_cfg(*defaults, **over) -> FitConfig:
    """``load_config(FitConfig, ...)`` of :data:`FIT_BASE` updated by each mapping of
    ``defaults`` and then by ``over`` (top-level sections replace the base's)."""
    base = dict(FIT_BASE)
    for d in defaults:
        base.update(d)
    base.update(over)
    return load_config(FitConfig, base)
