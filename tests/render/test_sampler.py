"""Counter-based uniform numbers: known hash values, uniformity and independence."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from jaxgfx.render.sampler import pcg_hash, uniform, uniform_blocks


def _pcg_reference(v):
    # Jarzynski & Olano 2020, listing 2, in NumPy uint32 arithmetic
    v = np.asarray(v, np.uint64)
    m = np.uint64(0xFFFFFFFF)
    state = (v * np.uint64(747796405) + np.uint64(2891336453)) & m
    word = (
        ((state >> ((state >> np.uint64(28)) + np.uint64(4))) ^ state) * np.uint64(277803737)
    ) & m
    return ((word >> np.uint64(22)) ^ word).astype(np.uint32)


def test_pcg_hash_known_values():
    v = np.array([0, 1, 2, 12345, 2**32 - 1], np.uint32)
    np.testing.assert_array_equal(jax.jit(pcg_hash)(v), _pcg_reference(v))
    assert int(pcg_hash(jnp.uint32(0))) == 129708002  # value printed by the C listing


def test_uniform_range_moments_and_ks():
    u = np.asarray(jax.jit(uniform, static_argnums=1)(jax.random.key(3), (200_000,)))
    assert u.dtype == np.float32 and u.min() >= 0.0 and u.max() < 1.0
    n = u.size
    assert abs(u.mean() - 0.5) < 4 * np.sqrt(1 / 12 / n)
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    # consecutive numbers are uncorrelated (lag-1 correlation ~ N(0, 1/n))
    r = np.corrcoef(u[:-1], u[1:])[0, 1]
    assert abs(r) < 4 / np.sqrt(n)
    # pairs fill the unit square evenly (chi2 over a 16x16 grid)
    h, _, _ = np.histogram2d(u[0::2], u[1::2], bins=16, range=[[0, 1], [0, 1]])
    assert stats.chisquare(h.ravel()).pvalue > 1e-3


def test_uniform_keys_differ_and_are_reproducible(x64):
    a = uniform(jax.random.key(0), (1000,))
    b = uniform(jax.random.key(0), (1000,))
    c = uniform(jax.random.key(1), (1000,))
    np.testing.assert_array_equal(a, b)
    assert np.abs(np.corrcoef(a, c)[0, 1]) < 4 / np.sqrt(1000)
    d = uniform(jax.random.key(0), (10, 10), jnp.float64)
    assert d.dtype == jnp.float64 and float(d.min()) >= 0 and float(d.max()) < 1


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_uniform_blocks_are_the_same_numbers(x64, dtype):
    """Path replay's numbers drawn one bounce at a time (``UniformBlocks.block``) are bit for
    bit ``uniform``'s array, for whole images, row subsets (with padding rows beyond the image)
    and under ``jit`` with a traced block index; too few axes is an error naming ``shape``."""
    key, shape = jax.random.key(5), (6, 5, 4, 7)
    for rows in (None, jnp.array([0, 3, 7])):
        want = np.asarray(uniform(key, shape, dtype, rows=rows))
        ub = uniform_blocks(key, shape, dtype, rows=rows)
        assert ub.shape == want.shape
        np.testing.assert_array_equal(np.asarray(ub.array()), want)
        got = jax.jit(lambda ub, i: ub.block(i))(ub, jnp.int32(2))
        np.testing.assert_array_equal(np.asarray(got), want[..., 2, :])
    flat = uniform_blocks(key, shape, dtype).reshape(30)
    want = np.asarray(uniform(key, shape, dtype)).reshape(30, 4, 7)[:, 3]
    np.testing.assert_array_equal(np.asarray(flat.block(3)), want)
    with pytest.raises(ValueError, match="shape"):
        uniform_blocks(key, (4, 7))
