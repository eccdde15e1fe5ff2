"""``benchmarks.inverse`` reports the fit's averaged estimate (``optimizer.average``) per step
from the history; its last value must be what ``jaxgfx.optim.fit(average_from=...)`` returns,
for jaxgfx and for the Mitsuba loop alike. Imported by name: tests do not import benchmarks
statically."""

import importlib

import numpy as np
import pytest

from jaxgfx.optim import fit


def test_benchmark_estimates_match_the_fits_average(x64):
    mod = importlib.import_module("benchmarks.inverse")
    lo, hi, n = 0.01, 1.0, 60
    k0 = mod.tail_start({"optimizer": {"average": 0.5}}, n)
    assert k0 == 30
    # SGD pulls a bounded parameter from 0.5 to 0.15: the iterates still move in the tail, so
    # the tail mean differs from the last iterate (by 1.5e-6, far above float64 rounding)
    res = fit(lambda p: (p["a"] - 0.15) ** 2, {"a": 0.5}, optimizer="sgd", steps=n,
              learning_rate=8.0, bounds={"a": (lo, hi)}, average_from=k0, progress=False)
    est = mod.estimates(res.history["a"], k0, lo, hi)
    assert est[-1] == pytest.approx(float(res.params["a"]), abs=1e-12)
    assert abs(est[-1] - res.history["a"][-1]) > 1e-7  # not the last iterate
    # before the tail (and with averaging off) the estimate is the iterate
    np.testing.assert_array_equal(est[: k0 + 1], res.history["a"][: k0 + 1])
    assert mod.tail_start({"optimizer": {}}, n) is None
    np.testing.assert_array_equal(mod.estimates(res.history["a"], None, lo, hi),
                                  res.history["a"])
    # settling of the estimate (window 1): the first step from which it stays within 2 %
    secs = np.arange(n + 1, dtype=np.float64)
    t = mod.time_to_within(est, secs, 0.15, window=1)
    ok = np.abs(est - 0.15) <= 0.02 * 0.15
    first = int(np.flatnonzero(~ok)[-1]) + 1 if not ok.all() else 0
    assert ok[-1] and 0 < first < n and t == secs[first]
