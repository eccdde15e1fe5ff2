"""``render.adjoint`` of ``jaxgfx fit``: ``auto`` chooses path replay where every fitted
parameter is one replay differentiates and AD otherwise (jaxgfx.pipelines.fit.job.choose_adjoint),
the choice reaches the fit step and result.json."""

from __future__ import annotations

import re

import numpy as np
import pytest

from jaxgfx.io import write_exr
from jaxgfx.pipelines.fit import FitJob, prepare_fit, run_fit
from jaxgfx.pipelines.fit import job as fit_job
from jaxgfx.pipelines.fit.job import choose_adjoint

from ._helpers import fit_cfg

PATH = {"spp": 4, "width": 8, "height": 8, "integrator": "path", "max_depth": 3}


def _choice(params, render=None):
    cfg = fit_cfg(params=params, render={**PATH, "adjoint": "auto", **(render or {})})
    return choose_adjoint(cfg, prepare_fit(cfg))


@pytest.mark.parametrize(
    "params",
    [
        {"materials.metal.alpha": {"init": 0.5, "min": 0.01, "max": 1.0}},
        {
            "materials.clay.reflectance": {"init": [0.5, 0.5, 0.5]},
            "emitters.area.0.radiance": {"init": [4, 4, 4]},
            "emitters.environment.radiance": {"init": [0.1, 0.1, 0.1]},
        },
    ],
)
def test_auto_chooses_replay_for_material_and_emitter_parameters(params):
    got = _choice(params)
    assert got == {"adjoint": "replay", "why": "auto: every fitted parameter is one replay covers"}


@pytest.mark.parametrize(
    ("path", "init", "named"),
    [
        ("shapes.0.radii", [0.5], r"params\.shapes\.0\.radii: .*shapes"),
        ("camera.origin", [0, 1.2, 4], r"params\.camera\.origin: .*camera"),
    ],
)
def test_auto_chooses_ad_for_geometry_and_camera(path, init, named):
    params = {"materials.metal.alpha": {"init": 0.5, "min": 0.01, "max": 1.0}, path: {"init": init}}
    got = _choice(params)
    assert got["adjoint"] == "ad"
    assert re.search(named, got["why"]), got["why"]


def test_auto_without_replay_integrator_and_given_adjoints():
    alpha = {"materials.metal.alpha": {"init": 0.5, "min": 0.01, "max": 1.0}}
    got = _choice(alpha, {"integrator": "whitted", "max_depth": 2})
    assert got["adjoint"] == "ad" and "whitted" in got["why"]
    for given in ("ad", "replay"):
        cfg = fit_cfg(params=alpha, render={**PATH, "adjoint": given})
        assert choose_adjoint(cfg, prepare_fit(cfg)) == {"adjoint": given, "why": "render.adjoint"}
    with pytest.raises(ValueError, match="render.adjoint"):
        fit_cfg(render={"adjoint": "automatic"})


class _Stop(Exception):
    pass


def test_auto_choice_reaches_the_fit_step(monkeypatch, tmp_path):
    """The loss the fit step is built from renders with the chosen adjoint (stopped there: the
    fit itself is the other tests' business; a target file, so nothing is rendered)."""
    seen = []

    def spy(cfg, *a, **k):
        seen.append(cfg.render.integrator_spec)
        raise _Stop

    monkeypatch.setattr(fit_job, "cached_loss", spy)
    direct = {**PATH, "integrator": "direct", "max_depth": 2, "adjoint": "auto"}
    write_exr(tmp_path / "t.exr", np.full((8, 8, 3), 0.5, np.float32))
    cfg = fit_cfg(render=direct, target=str(tmp_path / "t.exr"))
    with pytest.raises(_Stop):
        run_fit(FitJob(cfg, None))
    assert seen == [{"type": "direct", "adjoint": "replay"}]


# slow: ~44 s at load ~3 (two fits with their step compiles: direct light, 8x8, 4 spp, 3 steps)
@pytest.mark.slow
def test_auto_fit_reports_replay_and_follows_the_ad_fit():
    """The same fit with ``adjoint: ad`` and ``auto`` (replay here): ``auto`` is recorded in
    result.json as replay, and, with the same keys, its gradients are AD's up to float32
    rounding, so the three Adam steps land on the same α (to 1e-4; a step is lr = 0.02)."""
    direct = {**PATH, "integrator": "direct", "max_depth": 2}
    outs = {
        adj: run_fit(FitJob(fit_cfg(render={**direct, "adjoint": adj}), None))
        for adj in ("ad", "auto")
    }
    assert outs["ad"]["adjoint"] == {"adjoint": "ad", "why": "render.adjoint"}
    assert outs["auto"]["adjoint"]["adjoint"] == "replay"
    assert outs["auto"]["config"]["render"]["adjoint"] == "auto"
    a_ad = outs["ad"]["params"]["materials.metal.alpha"]
    a_auto = outs["auto"]["params"]["materials.metal.alpha"]
    assert abs(a_ad - 0.5) > 0.01  # the fit moved
    assert abs(a_auto - a_ad) < 1e-4, (a_auto, a_ad)
