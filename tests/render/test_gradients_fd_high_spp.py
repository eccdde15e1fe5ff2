"""Slow renderer-gradient checks: AD against same-key central finite differences at enough
samples that a biased derivative shows (issue 10), and the negative control that shows the
check can fail. The reference and tolerances are those of ``test_gradients_fd.py`` (see its
docstring); the driver and the check live in ``_gradient_scenes.py``. A file of its own so
that ``pytest -n 2 --dist loadfile`` (make test-slow) spreads the FD programs over both cores.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
import _gradient_scenes as G  # noqa: E402

pytestmark = pytest.mark.slow


def test_glossy_scene_high_spp():
    """Issue 10's scene at 32 keys x 512 spp. Every parameter agrees with FD at 4 standard
    errors. The power of the α check is stated, not assumed: the paired difference's standard
    error is 14 % of |dα| here (measured: 0.0007 against 0.0049), so an error in dα of 57 % or
    more fails at 4 standard errors. The attached-sampling bias (+130 %) is caught; a 40 % one
    (the bias that once passed every gradient test) needs more keys: that check is in
    test_gradients_fd_reference.py (α alone, 128 paired keys x 512 spp).

    It also covers what ``test_glossy_scene_ad_matches_fd`` of test_gradients_fd.py checked
    (the same scene and parameters at 32 keys x 128 spp, removed 2026-12-05: a compile of its
    own, 67 s in the last slow run): 4x its samples, so the statistical tolerances here are
    half of that one's, and its assertion that FD resolves dα (error bar under 1/3 of the value)."""
    s = G.run(
        G.glossy_scene(), G.GLOSSY_PARAMS, spp=512, keys=32, integrator="path", max_depth=4, seed=1
    )
    G.check(G.GLOSSY_PARAMS, s)
    assert 4 * s["diff_se"][0] < 0.6 * abs(s["fd"][0]), (s["diff_se"][0], s["fd"][0])
    assert s["fd_se"][0] < abs(s["fd"][0]) / 3
    # the smooth parameters are resolved to 3 % by FD alone
    assert np.all(s["fd_se"][1:] < 0.03 * np.abs(s["fd"][1:]))


def test_glass_scene_path():
    s = G.run(G.glass_scene(), G.GLASS_PARAMS, spp=128, keys=16, integrator="path", max_depth=5)
    G.check(G.GLASS_PARAMS, s)


def test_glass_scene_whitted():
    """Whitted splits at the glass sphere (both branches, Fresnel-weighted), so the batch doubles
    per level: depth 3 (four branches) is 190 s on 2 cores and passes (glass η at 0.8 standard
    errors, measured). At depth 5 (16 branches) the check took 705 s and failed in CI; which
    parameter failed was not recorded (issue 10)."""
    s = G.run(G.glass_scene(), G.GLASS_PARAMS, spp=64, keys=16, integrator="whitted", max_depth=3)
    G.check(G.GLASS_PARAMS, s)


def test_envmap_scene():
    s = G.run(G.envmap_scene(), G.ENVMAP_PARAMS, spp=128, keys=16, integrator="path", max_depth=3)
    G.check(G.ENVMAP_PARAMS, s)


MATERIALS_RUN = dict(spp=256, keys=16, integrator="direct")  # one program for the two below


def test_materials_high_spp():
    """Every parameter of rough plastic, Phong, an anisotropic complex-IOR conductor, point
    intensity and area radiance under MIS direct lighting. (Also covers the 8 keys x 64 spp
    check that test_gradients_fd.py had, at half its statistical tolerance.)"""
    s = G.run(G.materials_scene(), G.MATERIALS_PARAMS, seed=1, **MATERIALS_RUN)
    G.check(G.MATERIALS_PARAMS, s)


def test_tiny_alpha_gradient_is_finite_and_zero():
    """α = 1e-6 (issue 10: AD gave -1.6e5 on the image mean): the roughness used is
    max(α, 1e-4), the image is flat in α there and FD of the same key is exactly 0; AD must
    agree, not explode. The same compiled program as ``test_materials_high_spp`` (only the base
    values differ): 6.6 s of process CPU after it, measured (moved here from
    test_gradients_fd.py, where it shared the removed 8 keys x 64 spp program)."""
    params = [(p, 1e-6 if "alpha" in p else b) for p, b in G.MATERIALS_PARAMS]
    s = G.run(G.materials_scene(), params, **MATERIALS_RUN)
    for i, (p, _) in enumerate(params):
        assert np.isfinite(s["ad"][i]) and np.isfinite(s["fd"][i]), p
        if "alpha" in p:
            assert s["fd"][i] == 0.0 and s["ad"][i] == 0.0, p


def test_attached_sampling_fails_the_glossy_check():
    """Negative control: the same check with ``sampling="attached"`` (plain AD through the
    samplers) fails on α. At 32 keys the bias (AD/FD = 2.3 at 8², issue 10) stood at 3.8
    standard errors, under the check's 4; 64 keys put it near 5.4."""
    params = G.GLOSSY_PARAMS[:1]
    s = G.run(
        G.glossy_scene(),
        params,
        spp=128,
        keys=64,
        integrator="path",
        max_depth=4,
        sampling="attached",
    )
    assert abs(s["diff"][0]) > 4 * s["diff_se"][0], (s["diff"][0], s["diff_se"][0])
