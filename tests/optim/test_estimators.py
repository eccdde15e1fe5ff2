"""decorrelated_loss / decorrelated_residuals: unbiased gradients and least-squares fixed points
for a noisy image (closed forms)."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx.optim import decorrelated_loss, decorrelated_residuals, fit_least_squares


def test_decorrelated_gradient_is_unbiased_where_the_correlated_one_is_not(x64):
    # I = theta (1 + sigma z), z ~ N(0, 1) per pixel; loss = mean((I - T)^2)
    # E[grad correlated] = 2 (theta (1 + sigma^2) - T); the true gradient is 2 (theta - T)
    theta, t, sigma, n = 0.8, 0.5, 0.5, 2048
    image = lambda th, k: th * (1.0 + sigma * jax.random.normal(k, (n,)))
    loss = lambda im: jnp.mean((im - t) ** 2)

    @jax.jit
    def grads(k):
        g_dec = jax.grad(lambda th: decorrelated_loss(lambda kk: image(th, kk), loss, k))(theta)
        g_cor = jax.grad(lambda th: loss(image(th, k)))(theta)
        v_dec = decorrelated_loss(lambda kk: image(theta, kk), loss, k)
        return g_dec, g_cor, v_dec

    g_dec, g_cor, v_dec = jax.vmap(grads)(jax.random.split(jax.random.key(0), 64))
    # standard error of the mean gradient over 64 x 2048 samples is ~1.5e-3 (3 sigma < 5e-3)
    np.testing.assert_allclose(float(jnp.mean(g_dec)), 2 * (theta - t), atol=5e-3)
    np.testing.assert_allclose(float(jnp.mean(g_cor)), 2 * (theta * (1 + sigma**2) - t), atol=5e-3)
    # the value is the plain loss of one image: E = (theta - t)^2 + theta^2 sigma^2
    np.testing.assert_allclose(
        float(jnp.mean(v_dec)), (theta - t) ** 2 + (theta * sigma) ** 2, rtol=5e-3
    )


SIGMA, T_VALUE, N_PIX = 0.5, 0.5, 4096


def _noisy_image(th, k):
    return th * (1.0 + SIGMA * jax.random.normal(k, (N_PIX,)))


def _dec_residuals(p, key):
    return decorrelated_residuals(lambda kk: _noisy_image(p, kk), T_VALUE, key)


def _one_image_residuals(p, key):
    return _noisy_image(p, key) - T_VALUE


def test_decorrelated_residuals_value_from_one_image_jacobian_from_the_other(x64):
    key = jax.random.key(3)
    ka, kb = jax.random.split(key)
    theta = 0.8

    @jax.jit
    def value_jvp_vjp(th):
        r, tangent = jax.jvp(lambda t: _dec_residuals(t, key), (th,), (1.0,))
        _, pull = jax.vjp(lambda t: _dec_residuals(t, key), th)
        return r, tangent, pull(jnp.ones(N_PIX))[0]

    r, tangent, cot = value_jvp_vjp(theta)
    np.testing.assert_allclose(r, _noisy_image(theta, ka) - T_VALUE, rtol=1e-12)
    # dI/dtheta = 1 + sigma z of image B, in forward and reverse mode
    jb = 1.0 + SIGMA * jax.random.normal(kb, (N_PIX,))
    np.testing.assert_allclose(tangent, jb, rtol=1e-12)
    np.testing.assert_allclose(cot, np.sum(jb), rtol=1e-12)


def test_least_squares_on_a_fixed_key_is_unbiased_with_decorrelated_residuals(x64):
    # LM on I = theta (1 + sigma z): with one image the fixed point is
    # theta* = T sum(1 + sigma z) / sum((1 + sigma z)^2) -> T / (1 + sigma^2) = 0.4;
    # with decorrelated residuals theta* = T sum(1 + s z_B) / sum((1 + s z_B)(1 + s z_A)) -> T;
    # per key, theta* - T ~ -T sigma (mean z_A) to first order: std T sigma sqrt((1 + sigma^2)
    # / n) = 0.0044 at n = 4096 pixels; over 32 keys 0.0008 (4 sigma: 3e-3); the second-order
    # bias is T sigma^2 2 / n ~ 6e-5
    dec, one = [], []
    for i in range(32):
        k = jax.random.key(100 + i)
        dec.append(float(fit_least_squares(_dec_residuals, 1.0, args=k).params))
        one.append(float(fit_least_squares(_one_image_residuals, 1.0, args=k).params))
    np.testing.assert_allclose(np.mean(dec), T_VALUE, atol=3e-3)
    np.testing.assert_allclose(np.mean(one), T_VALUE / (1 + SIGMA**2), atol=3e-3)
