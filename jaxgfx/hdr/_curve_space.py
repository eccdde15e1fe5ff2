"""The analytic space of log-inverse camera responses used by ``method="subspace"`` and by
``"debevec"``'s sparse-bracket rule (issue 26; see :mod:`jaxgfx.hdr._subspace`)."""

from __future__ import annotations

import numpy as np

__all__ = ["response_basis", "check_n_poly", "MAX_POLY"]

MAX_POLY = 8
"""Largest ``n_poly`` (Legendre terms of :func:`response_basis`)."""


def response_basis(n_levels: int, n_poly: int) -> np.ndarray:
    """Orthonormal basis ``(n_levels, 3 + n_poly)`` (float64, NumPy) of the log-inverse
    response space on uniform levels ``z_k = k / (L − 1)``: the span of
    ``1, ln z, ln(1 − z), P_1(2z − 1) … P_K(2z − 1)``. ``z`` is clipped to
    ``[0.5 / (L − 1), 1 − 0.5 / (L − 1)]`` so the first and last rows (black and clipped levels,
    censored in every fit) are finite. Orthonormalised by a QR decomposition (same span)."""
    z = np.linspace(0.0, 1.0, n_levels)
    eps = 0.5 / (n_levels - 1)
    zc = np.clip(z, eps, 1.0 - eps)
    cols = [np.ones(n_levels), np.log(zc), np.log1p(-zc)]
    x = 2.0 * z - 1.0
    for k in range(1, n_poly + 1):
        cols.append(np.polynomial.legendre.Legendre.basis(k)(x))
    q, _ = np.linalg.qr(np.stack(cols, axis=1))
    return q


def check_n_poly(n_poly):
    if isinstance(n_poly, bool) or not isinstance(n_poly, (int, np.integer)):
        raise ValueError(f"n_poly: expected an integer in 0…{MAX_POLY}, got {n_poly!r}")
    if not 0 <= n_poly <= MAX_POLY:
        raise ValueError(f"n_poly: expected an integer in 0…{MAX_POLY}, got {n_poly!r}")
