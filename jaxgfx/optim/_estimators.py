"""Unbiased gradients of non-linear losses of Monte Carlo images: independent primal and
adjoint samples (Nimier-David et al. 2020, §4; Azinović et al. 2019). The one home of the
decorrelation scheme: :func:`decorrelated` (a function whose reverse-mode derivative uses a
second key), :func:`decorrelated_loss` (a loss of two images) and
:func:`decorrelated_residuals` (least-squares residuals of two images)."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

__all__ = ["decorrelated", "decorrelated_loss", "decorrelated_residuals"]


def _two_images(image_fn: Callable, key):
    """Images ``A`` (no derivative) and ``B`` of ``image_fn`` with the independent keys
    ``jax.random.split(key)``: two calls, not ``jax.vmap`` over the keys. Measured on the
    32x32 inverse scene (docs/inverse.md §4, CPU): a render vmapped over two keys ran 25-40x
    slower than two calls (forward-mode Jacobian at 2 x 64 spp 2.6 s against 0.08 s, the
    Adam step's gradient at 2 x 4 spp 0.30 s against 0.007 s) and compiled 4-10x longer.
    (That was render's fusion barriers turning into selects under ``vmap``; since they stay
    barriers, a vmapped render costs about the same per key as separate calls:
    docs/performance.md "Batches of keys". Two calls remain the simple choice here.)"""
    ka, kb = jax.random.split(key)
    return jax.lax.stop_gradient(image_fn(ka)), image_fn(kb)


def decorrelated_loss(image_fn: Callable, loss_fn: Callable, key):
    """``loss_fn(image)`` of a Monte Carlo ``image_fn(key)`` with an unbiased gradient.

    With one image ``I``, ``∇ E[(I - T)²] = 2 (E I - T) ∇E I`` but the estimator
    ``∇ (I - T)² = 2 (I - T) ∇I`` has expectation ``2 (E I - T) ∇E I + ∇ Var I``: the
    correlation between the primal ``I`` and its derivative biases the fit towards parameters
    of lower variance (e.g. darker albedo). This evaluates two images with independent keys
    (``jax.random.split(key)``), takes the value and
    ``∂loss/∂I`` from image A and the derivative of the image from image B:

        value = loss(A),   ∇ = (∂loss/∂I at A) · ∇B      (Nimier-David et al. 2020, §4)

    which is unbiased whenever ``∂loss/∂I`` is affine in ``I`` (L2, masked L2, censored L2 away
    from the clip level) and consistent otherwise. Parameters that ``loss_fn`` itself closes
    over (a camera response, an exposure) get their gradient through ``loss(A)`` directly.
    Each image should use half the sample budget of the single-image estimator.

    Returns a scalar whose value is ``loss(A)`` and whose gradient is the estimator above.
    Example (``tests/optim/test_estimators.py``): for ``I = θ (1 + σ z)`` and the loss
    ``(I - T)²`` the mean gradient is ``2 (θ - T)``, not ``2 (θ (1 + σ²) - T)``.
    """
    a, b = _two_images(image_fn, key)
    val, dl_da = jax.value_and_grad(loss_fn)(a)
    return val + jnp.sum(jax.lax.stop_gradient(dl_da) * (b - jax.lax.stop_gradient(b)))


def decorrelated_residuals(image_fn: Callable, target, key):
    """Residuals ``A - target`` of a Monte Carlo ``image_fn(key)`` whose Jacobian is that of
    an independent image ``B``: for :func:`~jaxgfx.optim.fit_least_squares` on a fixed key.

    Two images with independent keys (``jax.random.split(key)``); the value is
    ``A - target``, the derivative (forward and reverse mode) is ``∂B``. With one image the
    Gauss–Newton / Levenberg–Marquardt fixed point ``Jᵀ r = 0`` pairs the noise of the Jacobian
    with the noise of the residual, ``E[Jᵀ r] = Jᵀ_E (E I - T) + Cov(∂I, I)``, which pulls the
    fit towards parameters of lower variance (the ``∇ Var I`` bias of
    :func:`decorrelated_loss`); with independent images the covariance term vanishes and the
    fit's error is the noise of ``A`` at the solution (it shrinks as ``1/√spp``).

    Example (``tests/optim/test_estimators.py``): for ``I = θ (1 + σ z)`` and target ``T``, LM
    on one image ends on average at ``T / (1 + σ²)``, on these residuals at ``T``.
    """
    a, b = _two_images(image_fn, key)
    return a + (b - jax.lax.stop_gradient(b)) - target


def decorrelated(fn, *, salt: int = 0x5EED):
    """``fn(params, key)`` whose reverse-mode derivative uses an independent key.

    The value is ``fn(params, key)``; the vector-Jacobian product is that of
    ``fn(params, fold_in(key, salt))``. Use it for losses that are non-linear in a Monte Carlo
    estimate (e.g. ``mean((render(...) - target)²)``): the gradient ``2 (I - T) ∂I`` is then an
    unbiased estimate of the gradient of ``(E[I] - T)²``, while correlated samples add the
    covariance ``2 Cov(I, ∂I)``. Cost: the backward pass re-runs the forward pass with the second
    key (one extra forward). Reverse mode only (a ``jax.custom_vjp``).

    Example::

        img = decorrelated(lambda s, k: render(s, k, spp=4))  # jaxgfx.render.render
        jax.grad(lambda s: jnp.mean((img(s, key) - target) ** 2))(scene)
    """

    @jax.custom_vjp
    def wrapped(params, key):
        return fn(params, key)

    def fwd(params, key):
        return fn(params, key), (params, key)

    def bwd(res, ct):
        params, key = res
        _, vjp = jax.vjp(lambda p: fn(p, jax.random.fold_in(key, salt)), params)
        (g,) = vjp(ct)
        return g, None

    wrapped.defvjp(fwd, bwd)
    return wrapped
