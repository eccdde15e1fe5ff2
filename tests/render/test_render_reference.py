"""Per-pixel z-tests of renders against independent higher-sample references of the same
integrator (Mitsuba 3's render regression practice), with negative controls showing the test
can fail.

These are NOISE-CONSISTENCY tests, not references: both sides are jaxgfx renders (other keys,
other light-sampling strategies, an envmap vs the equivalent constant emitter), so a bias
shared by both sides passes. Bias is caught by the closed forms (test_integrators.py,
test_integrator_references.py, test_hard_cases.py) and the Mitsuba 3 comparisons
(test_mitsuba.py); see docs/testing.md.

Each side renders ``K`` independent images of ``spp`` samples with different keys; per pixel the
mean ``m`` and the sample variance ``s²`` over the ``K`` images give
``z = (m_test - m_ref) / sqrt(s²_test / K_test + s²_ref / K_ref)``. With ``K = 32`` both
variances have 31 degrees of freedom, so under the null hypothesis ``|z| > 3`` happens for about
0.4 % of the pixels (t distribution with ~60 dof); the test requires ≥ 97.5 % of the pixel
channels with ``|z| < 3``. Pixels whose samples are all identical (zero variance on both sides)
pass when the means agree to float32 rounding.
"""

import jax
import numpy as np
import pytest

from jaxgfx.render.integrators.path import STRATEGIES
from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene

from ._scenes import env_scene, example_scene


def _example(width=16, *, floor=0.5, metal=1.0, full=True):
    return load_scene(example_scene(width, floor=floor, metal=metal, full=full))


def _stats(scene, seed, k, spp, integrator, max_depth=3):
    """Per-pixel mean and variance of the mean over ``k`` independent renders (one compile:
    ``spp`` is static, the keys are not)."""
    keys = jax.random.split(jax.random.key(seed), k)
    x = np.stack(
        [
            np.asarray(render(scene, kk, spp=spp, integrator=integrator, max_depth=max_depth))
            for kk in keys
        ]
    ).astype(np.float64)
    return x.mean(0), x.var(0, ddof=1) / k


def z_pass_fraction(ref, test, *, threshold=3.0):
    """Fraction of pixel channels with ``|z| < threshold`` (see the module docstring)."""
    (m_r, v_r), (m_t, v_t) = ref, test
    var = v_r + v_t
    diff = np.abs(m_t - m_r)
    exact = diff <= 1e-5 * (1.0 + np.abs(m_r))
    z = np.where(var > 0, diff / np.sqrt(np.where(var > 0, var, 1.0)), np.inf)
    return float(np.mean(exact | (z < threshold)))


K, SPP = 32, 32


@pytest.mark.slow  # issue 9: ~14 s of a loaded 2-core run; out of make test
def test_ztest_direct_passes_and_detects_a_10_percent_albedo_change():
    scene = _example(full=False)
    ref = _stats(scene, 1, K, SPP, "direct")
    frac = z_pass_fraction(ref, _stats(scene, 2, K, SPP, "direct"))
    assert frac >= 0.975, frac
    # negative control: floor and metal albedo +10 % → many pixels fail
    biased = _stats(_example(floor=0.55, metal=1.1, full=False), 2, K, SPP, "direct")
    frac_bad = z_pass_fraction(ref, biased)
    assert frac_bad < 0.9, frac_bad


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["path", "whitted", "direct"])
def test_ztest_24px_each_integrator(integrator):
    scene = _example(24)
    ref = _stats(scene, 11, 2 * K, SPP, integrator)
    frac = z_pass_fraction(ref, _stats(scene, 12, K, SPP, integrator))
    assert frac >= 0.975, frac
    biased = _stats(_example(24, floor=0.55, metal=1.1), 12, K, SPP, integrator)
    frac_bad = z_pass_fraction(ref, biased)
    assert frac_bad < 0.93, frac_bad  # measured 0.88 / 0.85 / 0.68


# ------------------------------------------------------------------------------------------
# environment-map importance sampling


def _strategy_stats(scene, seed, k, spp, strategy):
    """Direct illumination with one sampling strategy: ``"mis"``, ``"light"`` (light sampling
    only) or ``"bsdf"`` (BSDF sampling only); mean and variance of the mean over ``k`` renders."""
    keys = jax.random.split(jax.random.key(seed), k)
    x = np.stack(
        [
            np.asarray(render(scene, kk, spp=spp, integrator="direct", strategy=strategy))
            for kk in keys
        ]
    )
    x = x.astype(np.float64)
    return x.mean(0), x.var(0, ddof=1) / k


def _env_scene(emitter, width=12):
    return load_scene(env_scene(emitter, width))


@pytest.mark.slow  # issue 9: ~19 s of a loaded 2-core run; out of make test
def test_constant_envmap_matches_constant_emitter():
    img = np.full((8, 16, 3), 0.7, np.float32)
    env = _env_scene({"type": "envmap", "image": img})
    const = _env_scene({"type": "constant", "radiance": 0.7})
    a = _stats(env, 21, 16, 16, "direct")
    b = _stats(const, 22, 16, 16, "direct")
    assert z_pass_fraction(a, b) >= 0.975
    np.testing.assert_allclose(a[0].mean(), b[0].mean(), rtol=5 * np.sqrt(a[1].mean()) / 0.3)


def _peaked_env(sharp=False):
    """Dim sky (0.05) plus a bright spot (peak 500) above the scene: a Gaussian of 1.5 texels
    (``sharp=False``) or a hard 2x2-texel square (``sharp=True``, whose bilinear radiance
    against the piecewise-constant sampling density makes light-only sampling heavy-tailed)."""
    img = np.full((16, 32, 3), 0.05, np.float32)
    if sharp:
        img[3:5, 9:11] = 500.0
    else:
        i, j = np.mgrid[0:16, 0:32]
        img += (500.0 * np.exp(-((i - 4.0) ** 2 + (j - 10.0) ** 2) / (2 * 1.5**2)))[..., None]
    return {"type": "envmap", "image": img}


@pytest.mark.slow
def test_peaked_envmap_light_bsdf_mis_agree_and_mis_reduces_variance():
    scene = _env_scene(_peaked_env())
    res = {s: _strategy_stats(scene, 30 + i, 32, 16, s) for i, s in enumerate(STRATEGIES)}
    for s in ("light", "bsdf"):
        assert z_pass_fraction(res["mis"], res[s]) >= 0.975, s
    var = {s: float(np.mean(v)) for s, (_, v) in res.items()}
    assert var["mis"] < 0.5 * var["bsdf"], var


@pytest.mark.slow
def test_sharp_envmap_sun_light_sampling_is_unbiased_and_low_variance():
    """A hard 2x2-texel sun: the sampling density comes from the texel-averaged bilinear
    radiance, so light-only sampling covers the half-texel ring the bilinear lookup lights up
    (before: variance 8.7 and 8 % low; after: 0.024, agreeing with MIS)."""
    scene = _env_scene(_peaked_env(sharp=True))
    res = {s: _strategy_stats(scene, 30 + i, 32, 16, s) for i, s in enumerate(STRATEGIES)}
    assert z_pass_fraction(res["mis"], res["light"]) >= 0.975
    var = {s: float(np.mean(v)) for s, (_, v) in res.items()}
    assert var["light"] < 2.0 * var["mis"], var
    assert var["mis"] < 0.1 * var["bsdf"], var
