"""Per-pixel reliability weights for response recovery and radiance merging.

All weights are functions of the *normalised* pixel level ``z`` in ``[0, 1]`` (``0`` black,
``1`` the largest code value), peak at 1 and vanish at both ends (``w(0) = w(1) = 0``) so that
clipped pixels never contribute. They are registered in :data:`WEIGHTINGS`; the
noise-optimal weight (Granados et al. 2010) needs a noise model and the response, so it lives in
:func:`jaxgfx.hdr.merge_radiance` (``weighting="noise"``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._checks import check_choice

__all__ = [
    "weight_hat",
    "weight_gaussian",
    "weight_linear",
    "WEIGHTINGS",
    "get_weighting",
]


@jax.jit
def weight_hat(z):
    """Debevec & Malik (1997) hat: ``w(z) = 2 min(z, 1 - z)`` on normalised levels.

    ``z``: any shape, normalised levels in ``[0, 1]`` (values outside are clipped).
    Returns weights in ``[0, 1]``; ``w(0.5) = 1``, ``w(0) = w(1) = 0``.

    Example: ``weight_hat(0.25) → 0.5``.
    """
    z = jnp.clip(z, 0.0, 1.0)
    return 2.0 * jnp.minimum(z, 1.0 - z)


@jax.jit
def weight_gaussian(z):
    """Robertson, Borman & Stevenson (2003) Gaussian-like weight, shifted to vanish at the ends.

    ``w(z) = (exp(-16 (z - 0.5)^2) - e^-4) / (1 - e^-4)`` (the paper's
    ``exp(-4 (z - 127.5)^2 / 127.5^2)`` on 8-bit codes, minus its end value so that
    ``w(0) = w(1) = 0``). Example: ``weight_gaussian(0.5) → 1``.
    """
    z = jnp.clip(z, 0.0, 1.0)
    # e^-4 in z's dtype (no array op at import time: importing inside a trace must work); the
    # ends are set to 0 exactly, as a compiled exp need not equal the folded constant's
    g_end = jnp.exp(jnp.asarray(-4.0, z.dtype))
    w = (jnp.exp(-16.0 * (z - 0.5) ** 2) - g_end) / (1.0 - g_end)
    return jnp.where((z <= 0.0) | (z >= 1.0), 0.0, jnp.maximum(w, 0.0))


@jax.jit
def weight_linear(z, *, knee: float = 0.9):
    """Signal-proportional weight ``w(z) = z / knee`` up to ``knee``, then a ramp to 0 at 1.

    Favours bright (high-SNR) pixels as photon noise suggests, while still dropping clipped
    ones. Example: ``weight_linear(0.45) → 0.5``, ``weight_linear(0.95) → 0.5``.
    """
    z = jnp.clip(z, 0.0, 1.0)
    return jnp.where(z <= knee, z / knee, (1.0 - z) / (1.0 - knee))


WEIGHTINGS = {
    "hat": weight_hat,
    "gaussian": weight_gaussian,
    "linear": weight_linear,
}
"""Weight functions of the normalised level, by name (``"noise"`` is handled by the merge)."""


def get_weighting(name: str):
    """The weight function registered under ``name`` in :data:`WEIGHTINGS`."""
    check_choice(name, "weighting", tuple(WEIGHTINGS))
    return WEIGHTINGS[name]
