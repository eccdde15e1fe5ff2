"""The curated mutants for ``tools/mutate.py`` (``make mutate``).

Each entry: ``name``, ``file``, ``old`` (exact text, found exactly once), ``new``, ``tests``
(pytest node ids, the smallest set that must catch it), ``why`` (the kind of bug it models).
When code moves, update ``old``/``tests`` here: a stale entry fails the check loudly.
"""

MUTANTS = [
    # ------------------------------------------------------------------ colour
    {
        "name": "color.delta_e_2000.swap_kC_kH",
        "file": "jaxgfx/color/difference.py",
        "old": "tC = dCp / (kC * SC)\n    tH = dHp / (kH * SH)",
        "new": "tC = dCp / (kH * SC)\n    tH = dHp / (kC * SH)",
        "tests": ["tests/color/test_difference.py::test_pure_chroma_difference_closed_form"],
        "why": "two terms swapped (issue 15: survived the whole colour suite)",
    },
    # ------------------------------------------------------------------ image
    {
        "name": "image.gaussian_blur.radius_floor",
        "file": "jaxgfx/image/filters.py",
        "old": "return int(math.ceil(truncate * s - 1e-9)) if s > 0 else 0",
        "new": "return int(math.floor(truncate * s + 1e-9)) if s > 0 else 0",
        "tests": ["tests/image/test_filters.py::test_gaussian_fractional_sigma_radius_rule"],
        "why": "ceil -> floor (issue 15: survived; every tested sigma had a whole 3 sigma)",
    },
    {
        "name": "image.gaussian_blur.sigma_x1.05",
        "file": "jaxgfx/image/filters.py",
        "old": "w = jax.nn.softmax(-(i * i) / (2.0 * s * s))",
        "new": "w = jax.nn.softmax(-(i * i) / (2.0 * 1.1025 * s * s))",
        "tests": ["tests/image/test_filters.py::test_gaussian_fractional_sigma_radius_rule"],
        "why": "a constant off by 5 %",
    },
    # ------------------------------------------------------------------ hdr
    {
        "name": "hdr.debevec_solve.weights_not_squared",
        "file": "jaxgfx/hdr/_debevec.py",
        "old": "w2 = weights * weights",
        "new": "w2 = weights",
        "tests": ["tests/hdr/test_debevec_reference.py"],
        "why": "a square dropped (issue 15: caught only by a 1 % margin)",
    },
    {
        "name": "hdr.merge_radiance.variance_x1.05",
        "file": "jaxgfx/hdr/merge.py",
        "old": "var = jnp.sum(w * w * var_e_j, axis=0) / (den * den)",
        "new": "var = 1.05 * jnp.sum(w * w * var_e_j, axis=0) / (den * den)",
        "tests": ["tests/hdr/test_merge.py::test_noise_weighting_variance_matches_monte_carlo"],
        "why": "a constant off by 5 % (issue 15: the 0.85-1.15 band let it pass)",
    },
    {
        "name": "image.add_gaussian_noise.sigma_x1.025",
        "file": "jaxgfx/image/noise.py",
        "old": "return x + sigma * jax.random.normal(key, x.shape, x.dtype)",
        "new": "return x + 1.025 * sigma * jax.random.normal(key, x.shape, x.dtype)",
        "tests": ["tests/image/test_noise.py::test_gaussian_noise_statistics_per_channel_sigma"],
        "why": "variance off by 5 % (issue 15: 5 sd on 4k samples let 10 % pass)",
    },
    {
        "name": "image.add_poisson_gaussian_noise.gain_x1.05",
        "file": "jaxgfx/image/noise.py",
        "old": "y = signal + safe_sqrt(gain * signal + read_sigma * read_sigma) * z",
        "new": "y = signal + safe_sqrt(1.05 * gain * signal + read_sigma * read_sigma) * z",
        "tests": ["tests/image/test_noise.py::test_poisson_gaussian_mean_variance"],
        "why": "a constant off by 5 % in the noise-level function",
    },
    {
        "name": "image.add_salt_and_pepper.amount_x1.05",
        "file": "jaxgfx/image/noise.py",
        "old": "hit = jax.random.uniform(k1, shape, x.dtype) < amount",
        "new": "hit = jax.random.uniform(k1, shape, x.dtype) < 1.05 * amount",
        "tests": ["tests/image/test_noise.py::test_salt_and_pepper_binomial_fractions"],
        "why": "a rate off by 5 %",
    },
    # ------------------------------------------------------------------ _math
    {
        "name": "math.safe_arccos.value_at_minus_one",
        "file": "jaxgfx/_math.py",
        "old": "jnp.where(x > 0, 0.0, jnp.pi))",
        "new": "jnp.where(x > 0, 0.0, 0.5 * jnp.pi))",
        "tests": ["tests/test_math.py::test_singular_points_values_and_grads"],
        "why": "a wrong fill value at a singular point (issue 15: only finiteness was checked)",
    },
    {
        "name": "math.safe_div.fill_ignored",
        "file": "jaxgfx/_math.py",
        "old": "return jnp.where(nz, a / b_safe, fill)",
        "new": "return jnp.where(nz, a / b_safe, 0.0)",
        "tests": ["tests/test_math.py::test_singular_points_values_and_grads"],
        "why": "an option silently ignored",
    },
    # ------------------------------------------------------------------ io
    {
        "name": "io.float_from_rgbe.exponent_bias",
        "file": "jaxgfx/io/hdr_rgbe.py",
        "old": "np.arange(256) - 136",
        "new": "np.arange(256) - 135",
        "tests": ["tests/io/test_hdr_rgbe.py::test_rgbe_known_values"],
        "why": "off by one in an exponent bias (a factor 2)",
    },
    # ------------------------------------------------------------------ render: film
    {
        "name": "render.GaussianFilter.stddev_x1.05",
        "file": "jaxgfx/render/film.py",
        "old": "s = self.stddev * jnp.sqrt(2.0)",
        "new": "s = 1.05 * self.stddev * jnp.sqrt(2.0)",
        "tests": ["tests/render/test_camera.py::test_gaussian_filter_moments"],
        "why": "a constant off by 5 % (issue 15: the test allowed 15 standard errors)",
    },
]
