"""decorrelated_loss: unbiased gradient of a squared error of a noisy image (closed form)."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx.optim import decorrelated_loss


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
