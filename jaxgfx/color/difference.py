"""Colour differences in CIELAB: CIE 1976 and CIEDE2000.

The public functions validate their inputs eagerly, then call one jitted core (``_*``; the
weights ``kL, kC, kH`` are traced, so a new value does not recompile).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._checks import check_positive
from .._math import safe_atan2, safe_norm, safe_sqrt
from ._common import as_colour

__all__ = ["delta_e_1976", "delta_e_2000", "delta_e_2000_residuals"]

_TWO_PI = 2.0 * jnp.pi
_25_POW_7 = 25.0**7


def delta_e_1976(lab1, lab2):
    """CIE 1976 colour difference: Euclidean distance in L*a*b*.

    Args:
      lab1, lab2: ``(..., 3)`` CIELAB colours (broadcastable).

    Returns:
      ``(...)`` array. The gradient at identical colours is 0 (finite).

    Example:
      >>> float(delta_e_1976(jnp.array([50.0, 0, 0]), jnp.array([53.0, 4.0, 0])))
      5.0
    """
    return _delta_e_1976(as_colour(lab1, "lab1"), as_colour(lab2, "lab2"))


@jax.jit
def _delta_e_1976(lab1, lab2):
    return safe_norm(lab1 - lab2, axis=-1)


def _checked_pair(lab1, lab2, kL, kC, kH):
    """The two Lab arguments as arrays and the weights checked positive (CIEDE2000's checks)."""
    for v, n in ((kL, "kL"), (kC, "kC"), (kH, "kH")):
        check_positive(v, n)
    return as_colour(lab1, "lab1"), as_colour(lab2, "lab2")


def delta_e_2000(lab1, lab2, *, kL=1.0, kC=1.0, kH=1.0):
    """CIEDE2000 colour difference (CIE 142-2001), as specified by Sharma, Wu & Dalal (2005),
    "The CIEDE2000 color-difference formula: implementation notes, supplementary test data,
    and mathematical observations", Color Res. Appl. 30(1).

    Follows the paper's equations (2)-(23) including its conventions for the hue mean and
    difference when a chroma is zero and for the ±180° wrap. Symmetric in its arguments.

    Args:
      lab1, lab2: ``(..., 3)`` CIELAB colours (broadcastable).
      kL, kC, kH: parametric weighting factors (> 0; 1 for reference conditions).

    Returns:
      ``(...)`` non-negative array.

    Gradients: finite everywhere. At identical colours the returned gradient is 0 (a
    subgradient of the cone-shaped minimum) and at ``a* = b* = 0`` the hue terms contribute 0.
    The formula itself is discontinuous where the two hues are 180° apart (paper, §3).

    Example (pair 1 of the paper's Table 1):
      >>> round(float(delta_e_2000(jnp.array([50.0, 2.6772, -79.7751]),
      ...                          jnp.array([50.0, 0.0, -82.7485]))), 4)
      2.0425
    """
    lab1, lab2 = _checked_pair(lab1, lab2, kL, kC, kH)
    return _delta_e_2000(lab1, lab2, kL, kC, kH)


def delta_e_2000_residuals(lab1, lab2, *, kL=1.0, kC=1.0, kH=1.0):
    """CIEDE2000 as a vector for least squares: ``(..., 3)`` residuals whose Euclidean norm is
    :func:`delta_e_2000` (so ``Σ ||r||² = Σ ΔE00²``).

    CIEDE2000 is ``ΔE² = tL² + tC² + tH² + RT·tC·tH`` with ``tL = ΔL'/(kL SL)``,
    ``tC = ΔC'/(kC SC)``, ``tH = ΔH'/(kH SH)`` (Sharma, Wu & Dalal 2005, eq. 22); completing
    the square gives ``r = (tL, tC + RT tH / 2, tH sqrt(1 - RT²/4))`` (``|RT| <= sqrt(3)``, so
    the root is real). Unlike ``ΔE`` itself (a cone at 0), ``r`` is smooth where two colours
    meet, which is what Gauss-Newton / Levenberg-Marquardt need; the colour-chart fit of
    :mod:`jaxgfx.hdr.raw.chart` minimises it.

    Example:
      >>> a, b = jnp.array([50.0, 2.6772, -79.7751]), jnp.array([50.0, 0.0, -82.7485])
      >>> round(float(jnp.linalg.norm(delta_e_2000_residuals(a, b))), 4)
      2.0425
    """
    lab1, lab2 = _checked_pair(lab1, lab2, kL, kC, kH)
    return _delta_e_2000_residuals(lab1, lab2, kL, kC, kH)


@jax.jit
def _delta_e_2000(lab1, lab2, kL, kC, kH):
    tL, tC, tH, RT = _delta_e_2000_terms(lab1, lab2, kL, kC, kH)
    return safe_sqrt(tL * tL + tC * tC + tH * tH + RT * tC * tH)


@jax.jit
def _delta_e_2000_residuals(lab1, lab2, kL, kC, kH):
    tL, tC, tH, RT = _delta_e_2000_terms(lab1, lab2, kL, kC, kH)
    return jnp.stack([tL, tC + 0.5 * RT * tH, tH * jnp.sqrt(1.0 - 0.25 * RT * RT)], axis=-1)


def _delta_e_2000_terms(lab1, lab2, kL, kC, kH):
    """``(tL, tC, tH, RT)`` of Sharma, Wu & Dalal (2005), eq. (2)-(22)."""
    L1, a1, b1 = lab1[..., 0], lab1[..., 1], lab1[..., 2]
    L2, a2, b2 = lab2[..., 0], lab2[..., 1], lab2[..., 2]

    # (2)-(7): a' rescaling, C', h'
    C1 = safe_sqrt(a1 * a1 + b1 * b1)
    C2 = safe_sqrt(a2 * a2 + b2 * b2)
    Cbar = 0.5 * (C1 + C2)
    Cbar7 = Cbar**7
    G = 0.5 * (1.0 - safe_sqrt(Cbar7 / (Cbar7 + _25_POW_7)))
    a1p = (1.0 + G) * a1
    a2p = (1.0 + G) * a2
    C1p = safe_sqrt(a1p * a1p + b1 * b1)
    C2p = safe_sqrt(a2p * a2p + b2 * b2)
    h1p = jnp.mod(safe_atan2(b1, a1p), _TWO_PI)
    h2p = jnp.mod(safe_atan2(b2, a2p), _TWO_PI)

    # (8)-(10): differences
    dLp = L2 - L1
    dCp = C2p - C1p
    prod = C1p * C2p
    zero_c = prod == 0
    dh = h2p - h1p
    dhp = jnp.where(dh > jnp.pi, dh - _TWO_PI, jnp.where(dh < -jnp.pi, dh + _TWO_PI, dh))
    dhp = jnp.where(zero_c, 0.0, dhp)
    dHp = 2.0 * safe_sqrt(prod) * jnp.sin(0.5 * dhp)

    # (12)-(22): weighting functions
    Lbp = 0.5 * (L1 + L2)
    Cbp = 0.5 * (C1p + C2p)
    hsum = h1p + h2p
    far = jnp.abs(h1p - h2p) > jnp.pi
    hbp = jnp.where(far, jnp.where(hsum < _TWO_PI, hsum + _TWO_PI, hsum - _TWO_PI), hsum) * 0.5
    hbp = jnp.where(zero_c, hsum, hbp)
    deg = jnp.pi / 180.0
    T = (
        1.0
        - 0.17 * jnp.cos(hbp - 30.0 * deg)
        + 0.24 * jnp.cos(2.0 * hbp)
        + 0.32 * jnp.cos(3.0 * hbp + 6.0 * deg)
        - 0.20 * jnp.cos(4.0 * hbp - 63.0 * deg)
    )
    dtheta = 30.0 * deg * jnp.exp(-(((hbp / deg - 275.0) / 25.0) ** 2))
    Cbp7 = Cbp**7
    RC = 2.0 * safe_sqrt(Cbp7 / (Cbp7 + _25_POW_7))
    l50 = (Lbp - 50.0) ** 2
    SL = 1.0 + 0.015 * l50 / jnp.sqrt(20.0 + l50)
    SC = 1.0 + 0.045 * Cbp
    SH = 1.0 + 0.015 * Cbp * T
    RT = -jnp.sin(2.0 * dtheta) * RC

    tL = dLp / (kL * SL)
    tC = dCp / (kC * SC)
    tH = dHp / (kH * SH)
    return tL, tC, tH, RT
