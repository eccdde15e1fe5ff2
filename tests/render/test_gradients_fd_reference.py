"""The FD reference itself at the precision issue 10 asks for: the error bar on dα of the
glossy scene under 3 % of the value. A file of its own (~9 min on 2 cores) so that
``pytest -n 2 --dist loadfile`` (make test-slow) runs it beside the other FD files, not after
them on the same worker. Driver and check: ``_gradient_scenes.py``.
"""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
import _gradient_scenes as G  # noqa: E402

# issue 9: ~530 s on a quiet 2-core machine (both cores): slow
pytestmark = pytest.mark.slow


def test_glossy_alpha_fd_error_bar_under_3_percent():
    """Issue 10's requirement on the reference itself: the FD error bar on dα under 3 % of the
    value (64 keys x 4096 spp, h = 10 %; it was 7 % at 512 spp, so 8x the samples), and AD
    within the check's 4 standard errors of it."""
    params = G.GLOSSY_PARAMS[:1]
    s = G.run(G.glossy_scene(), params, spp=4096, keys=64, integrator="path", max_depth=4, seed=3)
    G.check(params, s)
    assert s["fd_se"][0] < 0.03 * abs(s["fd"][0]), (s["fd_se"][0], s["fd"][0])
