"""Poisson equation with Neumann boundaries, solved exactly by a 2-d DCT (via FFT)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax.scipy.fft import dctn, idctn

__all__ = ["solve_poisson_neumann", "divergence", "forward_gradients"]


def forward_gradients(I):
    """Forward differences of ``(..., H, W)``; zero across the last row/column (Neumann)."""
    gx = jnp.concatenate([I[..., :, 1:] - I[..., :, :-1], jnp.zeros_like(I[..., :, :1])], -1)
    gy = jnp.concatenate([I[..., 1:, :] - I[..., :-1, :], jnp.zeros_like(I[..., :1, :])], -2)
    return gx, gy


def divergence(gx, gy):
    """Backward-difference divergence, the negative adjoint of :func:`forward_gradients`
    (so that ``divergence(*forward_gradients(I))`` is the Neumann 5-point Laplacian)."""
    dx = gx - jnp.concatenate([jnp.zeros_like(gx[..., :, :1]), gx[..., :, :-1]], -1)
    dy = gy - jnp.concatenate([jnp.zeros_like(gy[..., :1, :]), gy[..., :-1, :]], -2)
    return dx + dy


def _eigenvalues(H, W, dtype):
    ky = jnp.arange(H, dtype=dtype)
    kx = jnp.arange(W, dtype=dtype)
    ly = 2.0 * jnp.cos(jnp.pi * ky / H) - 2.0
    lx = 2.0 * jnp.cos(jnp.pi * kx / W) - 2.0
    return ly[:, None] + lx[None, :]


def _solve(b, screen=0.0):
    H, W = b.shape[-2:]
    lam = _eigenvalues(H, W, b.dtype) - screen
    lam_safe = jnp.where(lam == 0, 1.0, lam)
    B = dctn(b, type=2, axes=(-2, -1), norm="ortho")
    X = jnp.where(lam == 0, 0.0, B / lam_safe)
    return idctn(X, type=2, axes=(-2, -1), norm="ortho")


@functools.partial(jax.custom_jvp, nondiff_argnums=(1,))
def solve_poisson_neumann(b, screen: float = 0.0):
    """Zero-mean solution ``I`` of ``Laplacian(I) = b - mean(b)`` with Neumann boundaries.

    The 5-point Laplacian with reflecting borders (``divergence(forward_gradients(I))``) is
    diagonal in the DCT-II basis, eigenvalues ``2cos(pi k/H) + 2cos(pi l/W) - 4``; the solve is
    one forward and one inverse orthonormal DCT (``jax.scipy.fft.dctn``, computed by FFT),
    ``O(HW log HW)``, exact up to rounding. The constant mode (eigenvalue 0) is dropped, so
    the solution has zero mean and ``b``'s mean is ignored (it is not in the operator's range).

    With ``screen = s > 0`` (static) it solves the *screened* equation ``(Laplacian - s) I = b``
    instead (eigenvalues shifted by ``-s``; no mode dropped): variations longer than about
    ``1 / sqrt(s)`` pixels are damped.

    Derivatives by implicit differentiation, not by differentiating the transform's internals:
    the solution operator ``S = A^+`` is linear, so the JVP is ``S`` applied to the tangent
    (one more solve; forward mode works, e.g. for Levenberg-Marquardt Jacobians) and reverse
    mode transposes it (``S`` is symmetric: the VJP is one solve of the cotangent).

    Args:
        b: ``(..., H, W)`` right-hand side.
        screen: static ``s >= 0``.

    Returns:
        ``(..., H, W)`` solution (zero-mean for ``screen = 0``).
    """
    return _solve(b, screen)


@solve_poisson_neumann.defjvp
def _jvp(screen, primals, tangents):
    (b,), (t,) = primals, tangents
    return _solve(b, screen), _solve(t, screen)
