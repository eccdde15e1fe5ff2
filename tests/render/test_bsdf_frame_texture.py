"""Shading frames (Duff et al. 2017) and textures (bilinear vs scipy.ndimage as oracle)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy.ndimage import map_coordinates

from jaxgfx.render.bsdf.texture import Texture, lookup
from jaxgfx.render.geometry.frame import (
    cos_theta,
    frame_from_normal,
    sincos_phi,
    tan2_theta,
    to_local,
    to_world,
)


@jax.jit
def _frame_checks(n, v):
    f = frame_from_normal(n)
    return f, to_local(f, n), to_world(f, to_local(f, v))


def test_frame_orthonormal_and_roundtrip(rng):
    n = rng.normal(size=(64, 3))
    n = np.concatenate([n, [[0, 0, 1.0], [0, 0, -1.0], [1e-8, 0, -1.0], [1.0, 0, 0]]])
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    v = rng.normal(size=n.shape)
    f, nl, back = _frame_checks(jnp.asarray(n, jnp.float32), jnp.asarray(v, jnp.float32))
    s, t = np.asarray(f.s), np.asarray(f.t)
    for a, b in [(s, t), (s, n), (t, n)]:
        np.testing.assert_allclose(np.sum(a * b, -1), 0.0, atol=2e-6)
    for a in (s, t):
        np.testing.assert_allclose(np.linalg.norm(a, axis=-1), 1.0, atol=2e-6)
    np.testing.assert_allclose(np.cross(s, t), n, atol=3e-6)  # right-handed
    np.testing.assert_allclose(nl, np.broadcast_to([0, 0, 1.0], n.shape), atol=2e-6)
    np.testing.assert_allclose(back, v, atol=1e-5)
    g = jax.jit(jax.grad(lambda n: jnp.sum(frame_from_normal(n).s)))(jnp.array([0.0, 0, -1.0]))
    assert np.all(np.isfinite(g))


def test_spherical_helpers():
    w = jnp.array([[0.6, 0.0, 0.8], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    np.testing.assert_allclose(cos_theta(w), [0.8, 1.0, 0.0])
    np.testing.assert_allclose(tan2_theta(w), [0.5625, 0.0, 0.0], rtol=1e-6)
    sp, cp = sincos_phi(w)
    np.testing.assert_allclose(sp, [0.0, 0.0, -1.0], atol=1e-7)
    np.testing.assert_allclose(cp, [1.0, 1.0, 0.0], atol=1e-7)


_lookup = jax.jit(lookup)


@pytest.mark.parametrize(
    "wrap,mode", [("repeat", "grid-wrap"), ("clamp", "nearest"), ("mirror", "reflect")]
)
def test_bilinear_matches_scipy(wrap, mode, rng):
    img = rng.uniform(size=(7, 9, 3)).astype(np.float32)
    uv = rng.uniform(-1.3, 2.2, size=(200, 2)).astype(np.float32)
    tex = Texture(img, wrap=wrap)
    got = np.asarray(_lookup(tex, jnp.asarray(uv)))
    rows = uv[:, 1] * 7 - 0.5
    cols = uv[:, 0] * 9 - 0.5
    ref = np.stack(
        [map_coordinates(img[..., c], [rows, cols], order=1, mode=mode) for c in range(3)], -1
    )
    np.testing.assert_allclose(got, ref, atol=2e-5)


def test_nearest_constant_and_grads(x64):
    img = np.arange(12, dtype=np.float64).reshape(3, 4, 1)
    tex = Texture(img, filter="nearest", wrap="clamp")
    uv = jnp.array([[0.1, 0.1], [0.9, 0.5], [0.6, 0.95], [1.7, -0.2]])
    np.testing.assert_allclose(_lookup(tex, uv)[:, 0], [0.0, 7.0, 10.0, 3.0])
    # 1x2 texture: halfway between texel centres
    assert float(lookup(Texture([[0.0, 1.0]]), jnp.array([0.5, 0.5]))[0]) == pytest.approx(0.5)
    c = lookup(0.25, uv)
    assert c.shape == (4,) and float(c[0]) == 0.25
    c3 = lookup(jnp.array([0.1, 0.2, 0.3]), uv)
    assert c3.shape == (4, 3)
    # differentiable in texel values and uv (inside texel cells)
    uv2 = jnp.array([[0.31, 0.42], [0.77, 0.18]])
    f = jax.jit(lambda im, uv: lookup(Texture(im), uv))
    check_grads(f, (jnp.asarray(img), uv2), order=1, modes=["rev"])


def test_texture_errors():
    with pytest.raises(ValueError, match="wrap"):
        Texture(np.zeros((2, 2, 3)), wrap="border")
    with pytest.raises(ValueError, match="image"):
        Texture(np.zeros((2, 2, 3, 4)))
    with pytest.raises(ValueError, match="uv"):
        lookup(Texture(np.zeros((2, 2))), jnp.zeros((3,)))
