"""Warps: Jacobian-determinant identity (pdf = 1/|det J|), inverses, chi², Distribution2D."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import sampling as warp
from jaxgfx.testing import chi2_test

U_GRID = np.stack(
    np.meshgrid(np.linspace(0.03, 0.97, 8), np.linspace(0.02, 0.98, 8)), axis=-1
).reshape(-1, 2)

SPHERE_WARPS = {
    "uniform_sphere": (
        warp.square_to_uniform_sphere,
        warp.square_to_uniform_sphere_pdf,
        warp.uniform_sphere_to_square,
    ),
    "uniform_hemisphere": (
        warp.square_to_uniform_hemisphere,
        warp.square_to_uniform_hemisphere_pdf,
        warp.uniform_hemisphere_to_square,
    ),
    "cosine_hemisphere": (
        warp.square_to_cosine_hemisphere,
        warp.square_to_cosine_hemisphere_pdf,
        warp.cosine_hemisphere_to_square,
    ),
    "cone": (
        lambda u: warp.square_to_uniform_cone(u, 0.5),
        lambda v: warp.square_to_uniform_cone_pdf(v, 0.5),
        lambda v: warp.uniform_cone_to_square(v, 0.5),
    ),
    "phong_lobe": (
        lambda u: warp.square_to_phong_lobe(u, 7.5),
        lambda v: warp.square_to_phong_lobe_pdf(v, 7.5),
        lambda v: warp.phong_lobe_to_square(v, 7.5),
    ),
}


# 3.2 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
@pytest.mark.parametrize("name", list(SPHERE_WARPS))
def test_sphere_warp_pdf_is_inverse_jacobian(name, x64):
    """pdf(w(u)) · |∂w/∂u0 × ∂w/∂u1| = 1 (measure preservation) and inverse(w(u)) = u."""
    f, pdf, inv = SPHERE_WARPS[name]

    @jax.jit
    def run(u):
        w = f(u)
        jac = jax.vmap(jax.jacfwd(f))(u)  # (n, 3, 2)
        det = jnp.linalg.norm(jnp.cross(jac[..., 0], jac[..., 1]), axis=-1)
        return w, pdf(w) * det, inv(w)

    u = jnp.asarray(U_GRID, jnp.float64)
    w, prod, back = run(u)
    np.testing.assert_allclose(np.linalg.norm(w, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(prod, 1.0, rtol=1e-9)
    np.testing.assert_allclose(back, u, atol=1e-10)


@pytest.mark.parametrize("name", ["uniform_sphere", "cosine_hemisphere", "phong_lobe", "cone"])
def test_sphere_warp_chi2(name):
    f, pdf, _ = SPHERE_WARPS[name]
    ok, p, d = chi2_test(
        jax.jit(lambda u1, u2: f(u2)),
        jax.jit(pdf),
        key=jax.random.key(3),
        n_samples=50_000,
        res_theta=12,
        res_phi=24,
        test_count=4,
    )
    assert ok, (p, d["message"])
    assert d["pdf_integral"] == pytest.approx(1.0, abs=2e-3)


def test_disk_and_triangle_area_jacobians(x64):
    u = jnp.asarray(U_GRID, jnp.float64)
    for f, pdf, inv in [
        (
            warp.square_to_uniform_disk_concentric,
            warp.square_to_uniform_disk_concentric_pdf,
            warp.uniform_disk_to_square_concentric,
        ),
        (
            warp.square_to_uniform_triangle,
            warp.square_to_uniform_triangle_pdf,
            warp.uniform_triangle_to_square,
        ),
    ]:

        @jax.jit
        def run(u, f=f, pdf=pdf, inv=inv):
            p = f(u)
            det = jnp.abs(jnp.linalg.det(jax.vmap(jax.jacfwd(f))(u)))
            return pdf(p) * det, inv(p)

        prod, back = run(u)
        np.testing.assert_allclose(prod, 1.0, rtol=1e-9)
        np.testing.assert_allclose(back, u, atol=1e-10)
    # concentric map keeps the square's boundary on the circle and the centre at the origin
    edge = warp.square_to_uniform_disk_concentric(jnp.array([[1.0, 0.3], [0.5, 0.5]]))
    assert float(jnp.linalg.norm(edge[0])) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_array_equal(edge[1], [0.0, 0.0])
    assert float(warp.square_to_uniform_disk_concentric_pdf(jnp.array([0.9, 0.9]))) == 0.0


def test_warps_finite_grad_at_singular_points():
    u = jnp.array([[0.5, 0.5], [0.0, 0.0], [1.0, 0.25], [0.0, 1.0]])
    fs = [
        warp.square_to_uniform_disk_concentric,
        warp.square_to_cosine_hemisphere,
        warp.square_to_uniform_sphere,
        warp.square_to_uniform_triangle,
        lambda u: warp.square_to_phong_lobe(u, 3.0),
    ]

    @jax.jit
    def run(u):
        vals = [f(u) for f in fs]
        grads = [jax.grad(lambda u, f=f: jnp.sum(f(u)))(u) for f in fs]
        # Phong exponent gradient at u0 = 0 (cos θ = 0) is finite
        gn = jax.grad(lambda n: jnp.sum(warp.square_to_phong_lobe(u, n)))(3.0)
        return vals, grads, gn

    vals, grads, gn = run(u)
    for v in jax.tree_util.tree_leaves((vals, grads, gn)):
        assert np.all(np.isfinite(v))
    # values at the singular points: disk centre -> origin, cosine warp -> the pole
    np.testing.assert_allclose(vals[0][0], [0.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(vals[1][0], [0.0, 0.0, 1.0], atol=1e-7)


def test_warp_bad_input():
    with pytest.raises(ValueError, match="u"):
        warp.square_to_uniform_sphere(jnp.zeros((4, 3)))
    with pytest.raises(TypeError, match="u"):
        warp.square_to_cosine_hemisphere("abc")


# ------------------------------------------------------------------ Distribution2D

WEIGHTS = np.array([[1.0, 3.0, 0.0, 2.0], [0.0, 0.0, 0.0, 0.0], [4.0, 1.0, 1.0, 0.5]])


def test_distribution2d_pdf_values():
    d = jax.jit(warp.Distribution2D)(WEIGHTS)
    expected = WEIGHTS * WEIGHTS.size / WEIGHTS.sum()
    h, w = WEIGHTS.shape
    centres = np.stack(np.meshgrid((np.arange(w) + 0.5) / w, (np.arange(h) + 0.5) / h), axis=-1)
    pdf = jax.jit(lambda d, uv: d.pdf(uv))
    vals = pdf(d, jnp.asarray(centres))
    np.testing.assert_allclose(vals, expected, rtol=1e-6)
    # integrates to one over [0,1]^2; zero outside
    assert float(np.mean(vals)) == pytest.approx(1.0, rel=1e-6)
    assert float(pdf(d, jnp.array([1.5, 0.5]))) == 0.0
    one_row = warp.Distribution2D([[1.0, 3.0]])
    assert float(one_row.pdf(jnp.array([0.75, 0.5]))) == pytest.approx(1.5)


def test_distribution2d_sampling_frequencies_and_inverse():
    d = warp.Distribution2D(WEIGHTS)
    n = 40_000
    u = jax.random.uniform(jax.random.key(5), (n, 2))
    uv, pdf, pdf2, back = jax.jit(
        lambda d, u: (*d.sample(u), d.pdf(d.sample(u)[0]), d.invert(d.sample(u)[0]))
    )(d, u)
    h, w = WEIGHTS.shape
    col = np.clip((np.asarray(uv[:, 0]) * w).astype(int), 0, w - 1)
    row = np.clip((np.asarray(uv[:, 1]) * h).astype(int), 0, h - 1)
    counts = np.zeros_like(WEIGHTS)
    np.add.at(counts, (row, col), 1)
    p = WEIGHTS / WEIGHTS.sum()
    # binomial: |count - n p| < 5 sqrt(n p (1-p)) per texel; zero-weight texels never hit
    assert np.all(np.abs(counts - n * p) <= 5 * np.sqrt(n * p * (1 - p)) + 1e-9)
    np.testing.assert_allclose(pdf, pdf2, rtol=1e-6)
    np.testing.assert_allclose(back, u, atol=2e-5)


def test_distribution2d_uniform_fallback_and_errors():
    d = jax.jit(warp.Distribution2D)(np.zeros((2, 3)))
    np.testing.assert_allclose(
        jax.jit(lambda d, uv: d.pdf(uv))(d, jnp.array([[0.1, 0.1], [0.9, 0.9]])), 1.0
    )
    with pytest.raises(ValueError, match="weights"):
        warp.Distribution2D(np.array([[1.0, -1.0]]))
    with pytest.raises(ValueError, match="weights"):
        warp.Distribution2D(np.ones(3))
