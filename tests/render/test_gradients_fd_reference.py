"""The FD reference itself at the precision issue 10 asks for: the error bar on dα of the
glossy scene under 3 % of the value, and AD against it. A file of its own so that
``pytest -n 2 --dist loadfile`` (make test-slow) runs it beside the other FD files, not after
them on the same worker. Driver and check: ``_gradient_scenes.py``.

One module fixture renders everything once (α alone, path depth 4, h = 10 %, batches of
64 keys x 512 spp, one compiled program per kind of batch):

* 2 paired batches (AD and same-key FD per key, 128 keys): the AD-vs-FD check;
* 6 FD-only batches (forward renders only, 384 keys): with the FD of the paired batches, the
  reference at 512 keys x 512 spp, the sample count of the former 64 keys x 4096 spp.

Until 2026-12-05 this was two tests: the reference at 64 keys x 4096 spp paired (all eight
batches paid for the gradient: ~250 s of process CPU, 353 s in the last loaded slow run) and
``test_glossy_alpha_resolves_a_40_percent_bias`` in test_gradients_fd_high_spp.py (64 keys x
512 spp paired, its own compile: 106 s), which this fixture's paired part covers with twice
its keys. The fixture now: 196 s of process CPU (measured 2026-12-05 at load 8-13: 92 s for
the first paired batch with its compile, 29 s per further paired batch, 25 s for the first
FD-only batch with its compile, 10 s per further one; the old pair: ~290 s for the reference,
estimated from the same unit costs, plus 92 s measured for the 40 % test's config).
"""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
import _gradient_scenes as G  # noqa: E402

# slow: 196 s of process CPU for the fixture at load 8-13 (2 compiles + 2 paired + 6 FD-only
# batches of 64 keys x 512 spp, path depth 4); 714 s of wall at that load
pytestmark = pytest.mark.slow

PARAMS = G.GLOSSY_PARAMS[:1]  # α of the GGX sphere
BATCH = dict(spp=512, keys=64, integrator="path", max_depth=4)


@pytest.fixture(scope="module")
def alpha_ref():
    ad, fd_paired = [], []
    for seed in (3, 4):
        _, a, f = G.ad_fd_raw(G.glossy_scene(), PARAMS, seed=seed, **BATCH)
        ad.append(a)
        fd_paired.append(f)
    fd_only = [G.fd_only(G.glossy_scene(), PARAMS, seed=seed, **BATCH) for seed in range(5, 11)]
    ad, fd_paired = np.concatenate(ad), np.concatenate(fd_paired)
    fd_all = np.concatenate([fd_paired, *fd_only])
    return {
        "paired": G.summary(np.zeros(len(ad)), ad, fd_paired),
        "fd": fd_all.mean(0),
        "fd_se": fd_all.std(0, ddof=1) / np.sqrt(len(fd_all)),
        "keys": len(fd_all),
    }


def test_glossy_alpha_fd_error_bar_under_3_percent(alpha_ref):
    """Issue 10's requirement on the reference itself: the FD error bar on dα under 3 % of the
    value. 512 keys x 512 spp, h = 10 % (7 % at 64 keys x 512 spp, so 8x the samples: 2.65 %
    expected). Measured: FD -0.00554 +- 0.00014 per unit of the α scale, 2.5 %."""
    r = alpha_ref
    assert r["keys"] == 512
    assert r["fd_se"][0] < 0.03 * abs(r["fd"][0]), (r["fd_se"][0], r["fd"][0])


def test_glossy_alpha_ad_matches_fd_and_resolves_a_40_percent_bias(alpha_ref):
    """AD of dα against FD, two ways, each with its power stated (the bias that once passed
    every gradient test was 40 % of dα, issue 10):

    * paired (``G.check``, 4 standard errors of AD − FD over the 128 paired keys): the paired
      difference's standard error at 64 keys x 512 spp was 0.00050 on |dα| = 0.0063 (8 %), so
      ~6 % at 128 keys; the test asserts ``4 se < 0.4 |FD|``, so a 40 % error in dα stands at
      4 standard errors or more and fails ``G.check``;
    * against the 512-key FD reference (unpaired, ``4 sqrt(se_AD² + se_FD²)``): about 4.6 %
      of |dα| per standard error, so errors of ~20 % or more fail; asserted ``< 0.25 |FD|``.

    Measured (2026-12-05): paired AD -0.00621 +- 0.00020, FD -0.00581 +- 0.00029, difference
    -0.00039 +- 0.00033 (1.2 se; 4 se = 23 % of |FD|); against the reference -0.00066 +-
    0.00024 (-2.7 se; 4 se = 18 % of |FD|).
    """
    p = alpha_ref["paired"]
    G.check(PARAMS, p)
    assert 4 * p["diff_se"][0] < 0.4 * abs(p["fd"][0]), (p["diff_se"][0], p["fd"][0])
    se = np.hypot(p["ad_se"][0], alpha_ref["fd_se"][0])
    fd = alpha_ref["fd"][0]
    assert abs(p["ad"][0] - fd) <= 4 * se, (p["ad"][0], fd, se)
    assert 4 * se < 0.25 * abs(fd), (se, fd)
