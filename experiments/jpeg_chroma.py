"""What the JPEG-aware loss (``loss.jpeg_chroma``) recovers from one 4:2:0 JPEG, without a
renderer: a 24×24 texture seen at one pixel per texel, fitted per pixel (tv prior 1e-3, 400
Adam steps from 0.4) to a quality-90 4:2:0 JPEG (Pillow) of its sRGB codes, with and
without the chroma model, for colour blocks of 2×2, 3×3 and 4×4 texels (the 2×2 and 4×4
blocks align with the codec's chroma blocks, the 3×3 ones straddle them).

    python -m experiments.jpeg_chroma

Prints the PSNR of each fit (docs/inverse.md, "A JPEG-aware loss"); the 2×2 case is the
default test ``tests/pipelines/test_fit_jpeg_chroma.py::
test_a_texture_is_recovered_from_a_4_2_0_jpeg_only_with_the_chroma_model``.
"""

from __future__ import annotations

import json
import sys

import numpy as np


def fit_psnr(block_texels: int, chroma: bool, steps: int = 400, seed: int = 3) -> float:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import optax

    from jaxgfx import hdr
    from jaxgfx.pipelines.fit.camera import level_table
    from jaxgfx.pipelines.fit.loss import censored_linear_loss, texture_prior

    resp = hdr.CameraResponse.analytic("srgb", anchor="unit")
    table = level_table(resp, 8)
    blocks = np.random.default_rng(seed).uniform(0.05, 0.8, size=(1, 12, 12, 3))
    lin = np.repeat(np.repeat(blocks, block_texels, 1), block_texels, 2)[:, :24, :24]
    codes = np.round(np.clip(np.asarray(resp.from_linear_normalized(lin)), 0, 1) * 255)
    photo = hdr.jpeg_roundtrip(codes.astype(np.uint8), quality=90).astype(np.float64)
    block = (2, 2) if chroma else None

    def f(x):
        return censored_linear_loss(
            x, photo, table, 1.0, 255.0, chroma_block=block
        ) + 1e-3 * texture_prior(x[0], "tv")

    opt = optax.adam(0.02)

    @jax.jit
    def run(x):
        def step(carry, _):
            x, st = carry
            u, st = opt.update(jax.grad(f)(x), st)
            return (jnp.clip(optax.apply_updates(x, u), 0.0, 1.0), st), None

        return jax.lax.scan(step, (x, opt.init(x)), None, length=steps)[0][0]

    x = np.asarray(run(jnp.full(photo.shape, 0.4)))
    return float(10 * np.log10(1.0 / np.mean((x - lin) ** 2)))


def main() -> int:
    rows = {
        f"{b}x{b}": {"plain": fit_psnr(b, False), "jpeg_chroma": fit_psnr(b, True)}
        for b in (2, 3, 4)
    }
    print(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
