"""Bias of the renderer's d loss / d alpha on the inverse scene (issue 10), as the fit sees it.

    python -m experiments.roughness_grad_bias [--size 16] [--keys 32] [--out FILE]

Loss: L2 between a 16x16 render of configs/scenes/inverse.yaml (GGX metal at alpha) and a
256-spp target at alpha* = 0.25. At alpha in {0.15, 0.4}: the automatic-differentiation
gradient (primal and adjoint from independent 8-spp images, ``decorrelated_loss``) averaged
over ``keys`` keys, against central finite differences of ``(E I - T)²`` (h = 0.02, common
random numbers: the same 64-spp keys at alpha ± h, ``keys`` keys; the product of two
independent images' errors, so that ``∂ Var(I) / ∂ alpha``, which the decorrelated gradient
leaves out, is not in the reference). Prints JSON with both
means, their standard errors and the ratio, for ``integrator`` direct and path.
"""

from __future__ import annotations

import argparse
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from experiments._common import emit_json, log
from jaxgfx.optim import decorrelated_loss, l2_loss
from jaxgfx.render import load_scene, render

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--size", type=int, default=16)
    p.add_argument("--keys", type=int, default=32)
    p.add_argument("--integrators", default="direct")
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    with open(os.path.join(ROOT, "configs", "scenes", "inverse.yaml")) as f:
        d = yaml.safe_load(f)
    d["camera"]["width"] = d["camera"]["height"] = a.size
    scene = load_scene(d)
    out = {"size": a.size, "keys": a.keys}
    for integ in a.integrators.split(","):
        kw = {"integrator": integ, "max_depth": 3}
        target = render(
            scene.replace("materials.metal.alpha", 0.25), jax.random.key(99), spp=256, **kw
        )

        def loss_fd(alpha, key, kw=kw, target=target):
            # (E I - T)^2 without the Var(I) term: E[(I_a - T)(I_b - T)] of two independent
            # images. FD of l2_loss(I, T) would add d Var(I) / d alpha, which the decorrelated
            # AD gradient rightly leaves out (a third of the gradient at alpha 0.15, 64 spp)
            s = scene.replace("materials.metal.alpha", alpha)
            ka, kb = jax.random.split(key)
            ia = render(s, ka, spp=64, **kw)
            ib = render(s, kb, spp=64, **kw)
            return jnp.mean((ia - target) * (ib - target))

        def loss_ad(alpha, key, kw=kw, target=target):
            s = scene.replace("materials.metal.alpha", alpha)
            return decorrelated_loss(
                lambda kk: render(s, kk, spp=8, **kw), lambda im: l2_loss(im, target), key
            )

        g_ad = jax.jit(jax.grad(loss_ad))
        f_fd = jax.jit(loss_fd)
        res = {}
        for alpha in (0.15, 0.4):
            keys = [jax.random.key(1000 + i) for i in range(a.keys)]
            ad = np.array([float(g_ad(jnp.float32(alpha), k)) for k in keys])
            h = 0.02
            fd = np.array(
                [
                    (
                        float(f_fd(jnp.float32(alpha + h), k))
                        - float(f_fd(jnp.float32(alpha - h), k))
                    )
                    / (2 * h)
                    for k in keys
                ]
            )
            se = lambda x: float(np.std(x, ddof=1) / np.sqrt(len(x)))
            res[str(alpha)] = {
                "ad": float(ad.mean()),
                "ad_se": se(ad),
                "fd": float(fd.mean()),
                "fd_se": se(fd),
                "ratio_ad_over_fd": float(ad.mean() / fd.mean()),
            }
            log(integ, alpha, res[str(alpha)])
        out[integ] = res
    emit_json(out, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
