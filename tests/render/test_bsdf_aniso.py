"""One cheap anisotropic GGX chi² case in the default run (issue 15).

An anisotropic GGX whose ``D`` swaps ``alpha_u`` and ``alpha_v`` (or a sampler that does)
draws a lobe stretched along the wrong axis: with ``alpha = (0.15, 0.6)`` the chi² statistic of
such a mutant is in the thousands on 16 × 32 cells, against a 1 % critical value of ~600.
The isotropic cases cannot see it; the finer anisotropic cases in test_bsdf.py run with -m slow.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx.render.bsdf import RoughConductor
from jaxgfx.testing import chi2_test


def test_ggx_anisotropic_chi2_and_weights():
    bsdf = RoughConductor(0.15, alpha_v=0.6)
    c, phi = 0.7, 0.4
    s = math.sqrt(1 - c * c)
    wo = jnp.array([s * math.cos(phi), s * math.sin(phi), c])
    store = {}

    @jax.jit
    def sample(b, u1, u2):
        r = b.sample(wo, u1, u2)
        return jnp.where((r.pdf > 0)[:, None], r.wi, 0.0), r

    def sample_fn(u1, u2):
        w, store["s"] = sample(bsdf, u1, u2)
        return w

    pdf = jax.jit(lambda b, w: b.pdf(wo, w))
    ok, p, det = chi2_test(
        sample_fn,
        lambda w: pdf(bsdf, w),
        key=jax.random.key(3),
        n_samples=20_000,
        res_theta=16,
        res_phi=32,
        ires=8,
    )
    assert ok, (p, det["message"])
    r = store["s"]
    valid = np.asarray(r.pdf) > 0
    assert valid.mean() > 0.5
    # sample weight = eval * |cos| / pdf (eval includes the cosine), on the drawn directions
    ev = np.asarray(jax.jit(lambda b, w: b.eval(wo, w))(bsdf, r.wi))[valid]
    np.testing.assert_allclose(
        np.asarray(r.weight)[valid], ev / np.asarray(r.pdf)[valid][:, None], rtol=2e-3, atol=1e-6
    )
