"""Debevec–Malik's least squares restricted to a low-dimensional space of log-inverse
responses (method ``"subspace"``, issue 26).

With few, sparsely overlapping frames (a camera's 3-frame ±3 EV AEB) a free 256-level table is
under-determined: consecutive frames overlap only in the toe and the shoulder, and the curve
hangs on a chain of ``ln 8`` steps from the censored toe. Grossberg & Nayar ("Modeling the
space of camera response functions", PAMI 2004) constrain the curve to a few-parameter linear
model instead. Their EMoR basis is the PCA of the DoRF database's 201 measured curves; the
DoRF file is not available to this repository without the test curves (Ektachrome 320T) in
it, so the space used here is analytic and holds no measured data:

    g(z) = ln f⁻¹(z) = c₀ + c₁ ln z + c₂ ln(1 − z) + Σ_{k=1..K} d_k P_k(2z − 1)

``c₁ ln z`` is the gamma family (``x = z^γ``); ``c₁ ln z + c₂ ln(1 − z)`` spans the
log-logistic (Hurter–Driffield sigmoid in log exposure) family ``ln x = m + logit(z) / a`` with
different toe and shoulder slopes; the Legendre polynomials ``P_k`` bend the mid-tones. ``g`` is
linear in the coefficients, so Debevec's equations stay linear: with ``g = B c`` the normal
equations ``A g = b`` of :func:`jaxgfx.hdr._debevec.debevec_system` become the
``(3 + K) × (3 + K)`` system ``Bᵀ A B c = Bᵀ b`` (the anchor ``g[mid] = 0`` and the smoothness
term included), solved per channel in the same jitted chain, differentiable in the exposure
times.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._checks import check_nonnegative
from ._curve_space import MAX_POLY, check_n_poly, response_basis
from ._debevec import data_residual_rms, debevec_samples, default_levels, subspace_solve
from ._model import CameraResponse, resolve_anchor
from ._sampling import monotone_repair

__all__ = ["recover_subspace", "response_basis", "MAX_POLY"]


def recover_subspace(
    z,
    t,
    code_max,
    *,
    key=None,
    n_samples: int = 4096,
    lam: float = 1e-6,
    n_levels: int | None = None,
    weighting: str = "hat",
    anchor="mid",
    end_weight: float = 0.0,
    max_candidates: int = None,
    n_poly: int = 0,
):
    """Debevec–Malik response recovery in a low-dimensional curve space (method
    ``"subspace"``).

    Same pixel samples, data weights (``weighting`` + ``end_weight`` on the interior levels),
    smoothness ``lam`` and anchor as ``"debevec"`` (:func:`jaxgfx.hdr._debevec.recover_debevec`),
    but the table is ``g = B c`` with ``B`` = :func:`response_basis` ``(n_levels, 3 + n_poly)``
    (``1, ln z, ln(1 − z)`` and ``n_poly`` Legendre polynomials): ``3 + n_poly`` unknowns per
    channel instead of 256, which a sparse bracket (3 frames ±3 EV) can determine. A curve in
    the span is recovered exactly from consistent data. The table is made strictly
    increasing with :func:`monotone_repair` as for ``"debevec"``.

    Returns a ``"table"`` :class:`CameraResponse`; ``diagnostics["coefficients"]`` ``(C, 3 +
    n_poly)`` (in the orthonormal basis), ``diagnostics["residual_rms"]`` per channel.
    """
    check_nonnegative(lam, "lam")
    check_nonnegative(end_weight, "end_weight")
    check_n_poly(n_poly)
    anchor_z = resolve_anchor(anchor)
    n_lev = default_levels(code_max, n_levels)
    lev, w, _, _ = debevec_samples(z, key, n_samples, max_candidates, n_lev, weighting, end_weight)
    log_t = jnp.log(t)
    m = (n_lev - 1) // 2
    basis = jnp.asarray(response_basis(n_lev, n_poly), w.dtype)
    c = jax.vmap(lambda lv, ww: subspace_solve(lv, ww, log_t, basis, lam, m))(lev, w)
    g = c @ basis.T  # (C, L)
    res = data_residual_rms(g, lev, w, log_t)
    return CameraResponse(
        monotone_repair(g.T, m),
        "table",
        "subspace",
        float(code_max),
        anchor_z,
        None,
        {"residual_rms": res, "raw_log_exposure": g.T, "coefficients": c},
    )
