"""``optimizer.average`` reaches :func:`jaxgfx.optim.fit` as ``average_from`` and is recorded in
``result.json`` (the averaging itself is tested against closed forms in
tests/optim/test_average.py). The optimiser is replaced by a stub, and the target is a file,
so nothing renders or compiles."""

import numpy as np
import pytest

import jaxgfx.optim
from jaxgfx.optim import FitResult
from jaxgfx.pipelines.fit import FitJob, run_fit

from ._helpers import fit_cfg

ALPHA = "materials.metal.alpha"


@pytest.mark.parametrize(("average", "steps", "want_from"), [(0.5, 10, 5), (0.0, 10, None),
                                                           (0.25, 300, 225)])
def test_optimizer_average_reaches_the_fit_and_the_result(tmp_path, monkeypatch, average,
                                                          steps, want_from):
    target = tmp_path / "target.npy"
    np.save(target, np.full((8, 8, 3), 0.1, np.float32))
    seen = {}

    def stub_fit(loss, params, *, steps, average_from=None, **kw):
        seen["average_from"] = average_from
        p = {"scene": {ALPHA: np.float32(0.2)}, "camera": params["camera"]}
        hist = {"scene": {ALPHA: np.linspace(0.5, 0.2, steps + 1)}, "camera": {}}
        n = 0 if average_from is None else steps - average_from
        return FitResult(p, np.zeros(steps), hist, np.full(steps, 1e-3), 0.1, steps, "steps",
                         n_averaged=n)

    monkeypatch.setattr(jaxgfx.optim, "fit", stub_fit)
    cfg = fit_cfg(target=str(target), optimizer={"steps": steps, "average": average})
    out = run_fit(FitJob(cfg, None))
    assert seen["average_from"] == want_from
    assert out["params"][ALPHA] == pytest.approx(0.2)  # the fit's result, as returned
    if want_from is None:
        assert "average" not in out
    else:
        assert out["average"] == {"fraction": average, "from_step": want_from,
                                  "iterates": steps - want_from}
    assert out["config"]["optimizer"]["average"] == average
