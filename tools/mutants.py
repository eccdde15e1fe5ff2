"""The curated mutants for ``tools/mutate.py`` (``make mutate``).

Each entry: ``name``, ``file``, ``old`` (exact text, found exactly once), ``new``, ``tests``
(pytest node ids, the smallest set that must catch it), ``why`` (the kind of bug it models).
When code moves, update ``old``/``tests`` here: a stale entry fails the check loudly.
"""

# the implicit-function step of SDFShape.hit (sphere_tracing.py has a second, functional copy)
_SDF_HIT = (
    "f_live = self.sdf(o_live + t[..., None] * d)\n"
    "        t = t - safe_div(f_live - sg(f_live), gd)"
)

_RR = "tests/test_defaults_render.py::test_path_russian_roulette_starts_after_five_bounces"
RR_OBJECT = _RR + "[object]"  # the defaults live once, on PathIntegrator

_DEGHOST = "tests/test_defaults.py::test_merge_deghosted_default_threshold_window_and_saturation"

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
        "name": "hdr.debevec.prior_strength_ignored",
        "file": "jaxgfx/hdr/_debevec.py",
        "old": "[(lam * s_k, True) for s_k in prior_strengths]",
        "new": "[(lam, True) for s_k in prior_strengths]",
        "tests": [
            "tests/hdr/test_prior_strengths.py::"
            "test_the_default_picks_the_stronger_prior_on_the_calibrate_job"
        ],
        "why": "a scale dropped: every prior'd candidate at lam (issue 26: the job's wave)",
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
        "old": "y = x + sigma * jax.random.normal(key, x.shape, x.dtype)",
        "new": "y = x + 1.025 * sigma * jax.random.normal(key, x.shape, x.dtype)",
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
        "old": "s2 = self.stddev * np.sqrt(2.0)",
        "new": "s2 = 1.05 * self.stddev * np.sqrt(2.0)",
        "tests": ["tests/render/test_camera.py::test_gaussian_filter_moments"],
        "why": "a constant off by 5 % (issue 15: the test allowed 15 standard errors)",
    },
    # ------------------------------------------------------------------ render: BSDFs
    {
        "name": "render.Diffuse.eval.drop_inv_pi",
        "file": "jaxgfx/render/bsdf/_diffuse.py",
        "old": "return mask3(valid, self.reflectance * (ci * INV_PI)[..., None])",
        "new": "return mask3(valid, self.reflectance * ci[..., None])",
        "tests": [
            "tests/render/test_integrator_references.py::test_whitted_integrating_sphere_direct_light"
        ],
        "why": "a factor of pi dropped",
    },
    {
        "name": "render.ggx_D.swap_alpha_u_v",
        "file": "jaxgfx/render/bsdf/microfacet.py",
        "old": "t = (m[..., 0] / au) ** 2 + (m[..., 1] / av) ** 2 + cz_s * cz_s",
        "new": "t = (m[..., 0] / av) ** 2 + (m[..., 1] / au) ** 2 + cz_s * cz_s",
        "tests": ["tests/render/test_bsdf_aniso.py"],
        "why": "two terms swapped (issue 15: the default test_bsdf.py missed it)",
    },
    {
        "name": "render.measured.jacobian_half",
        "file": "jaxgfx/render/bsdf/_measured.py",
        "old": "jnp.maximum(2.0 * _PI**2 * u_mx * sin_theta_m, 1e-6)",
        "new": "jnp.maximum(_PI**2 * u_mx * sin_theta_m, 1e-6)",
        "tests": [
            "tests/render/test_bsdf_measured.py::test_pdf_integrates_to_one_over_the_hemisphere"
        ],
        "why": "a factor of 2 dropped in the u_m -> solid angle Jacobian",
    },
    {
        "name": "render.measured.theta2u_scale",
        "file": "jaxgfx/render/bsdf/_measured.py",
        "old": "return safe_sqrt(t * (2.0 / _PI))",
        "new": "return safe_sqrt(t * (1.9 / _PI))",
        "tests": [
            "tests/render/test_bsdf_measured.py::"
            "test_eval_matches_the_analytic_brdf_to_the_tables_resolution"
        ],
        "why": "a constant off by 5 % in the elevation -> unit-square map",
    },
    {
        "name": "render.marginal2d.sample_segment_width",
        "file": "jaxgfx/render/bsdf/_marginal2d.py",
        "old": "u = u * (2.0 * inv_width)",
        "new": "u = u * inv_width",
        "tests": [
            "tests/render/test_bsdf_measured.py::"
            "test_warp_matches_the_closed_form_of_a_linear_density"
        ],
        "why": "a factor of 2 dropped in the linear-segment inversion",
    },
    # ------------------------------------------------------------------ render: integrators
    {
        "name": "render.path.throughput_x1.05",
        "file": "jaxgfx/render/integrators/_bounce.py",
        "old": "beta = beta * weight\n",
        "new": "beta = beta * weight * 1.05\n",
        "tests": [
            "tests/render/test_integrator_references.py::"
            "test_path_integrating_sphere_three_bounces_value_and_gradient"
        ],
        "why": "a constant off by 5 % in the multi-bounce throughput",
    },
    {
        "name": "render.path.mis_weights_swapped",
        "file": "jaxgfx/render/integrators/_bounce.py",
        "old": "w = jnp.where(l_delta, 1.0, C.mis_power(detach(lpdf), detach(bpdf)))",
        "new": "w = jnp.where(l_delta, 1.0, C.mis_power(detach(bpdf), detach(lpdf)))",
        "tests": ["tests/render/test_integrators.py::test_rectangular_area_light_irradiance"],
        "why": "two arguments swapped (MIS weights no longer sum to one)",
    },
    {
        "name": "render.whitted.direct_x1.05",
        "file": "jaxgfx/render/integrators/whitted.py",
        "old": "return jnp.where(ok[..., None], f * li * safe_div(1.0, pdf)[..., None], 0.0)",
        "new": "return jnp.where(ok[..., None], f * li * safe_div(1.05, pdf)[..., None], 0.0)",
        "tests": [
            "tests/render/test_integrator_references.py::test_whitted_integrating_sphere_direct_light"
        ],
        "why": "a constant off by 5 % (issue 15: whitted was checked only against direct/path)",
    },
    {
        "name": "render.aov.depth_x1.05",
        "file": "jaxgfx/render/integrators/aov.py",
        "old": "depth = jnp.where(hit.valid, hit.t, 0.0)[..., None]",
        "new": "depth = jnp.where(hit.valid, 1.05 * hit.t, 0.0)[..., None]",
        "tests": ["tests/render/test_integrator_references.py::test_aov_plane_closed_form"],
        "why": "a constant off by 5 %",
    },
    # ------------------------------------------------------------------ render: geometry
    {
        "name": "render.bvh.right_child_uses_left_test",
        "file": "jaxgfx/render/geometry/accel/bvh_sah.py",
        "old": "hl, hr = inner & chit[0], inner & chit[1]",
        "new": "hl, hr = inner & chit[0], inner & chit[0]",
        "tests": ["tests/render/test_accel.py::test_matches_brute_force"],
        "why": "copy-paste index error in the traversal",
    },
    {
        "name": "render.sdf.implicit_term_detached",
        "file": "jaxgfx/render/geometry/sphere_tracing.py",
        "old": _SDF_HIT,
        "new": _SDF_HIT.replace("f_live - sg(f_live)", "sg(f_live) - sg(f_live)"),
        "tests": [
            "tests/render/test_scene_features.py::"
            "test_sdf_radius_gradient_matches_finite_differences"
        ],
        "why": "a stop_gradient added: the hit no longer moves with the shape",
    },
    {
        "name": "render.sdf.implicit_term_x1.05",
        "file": "jaxgfx/render/geometry/sphere_tracing.py",
        "old": _SDF_HIT,
        "new": _SDF_HIT.replace("t = t - safe_div", "t = t - 1.05 * safe_div"),
        "tests": [
            "tests/render/test_scene_features.py::"
            "test_sdf_radius_gradient_matches_finite_differences"
        ],
        "why": "a constant off by 5 % in a gradient (issue 15: rtol 0.05 on a 0.3 % error)",
    },
    # ------------------------------------------------------------------ tonemap
    {
        "name": "tonemap.reinhard_curve.white_not_squared",
        "file": "jaxgfx/tonemap/_global.py",
        "old": "return Lm * (1.0 + safe_div(Lm, Lwhite * Lwhite)) / (1.0 + Lm)",
        "new": "return Lm * (1.0 + safe_div(Lm, Lwhite)) / (1.0 + Lm)",
        "tests": ["tests/tonemap/test_operators.py::test_drago_and_reinhard_match_paper_formulas"],
        "why": "a square dropped (Reinhard 2002, eq. 4)",
    },
    # ------------------------------------------------------------------ optim
    {
        "name": "optim.relative_l2.denominator_not_detached",
        "file": "jaxgfx/optim/_losses.py",
        "old": "return _reduce(d * d / (jax.lax.stop_gradient(tx) ** 2 + eps), mask)",
        "new": "return _reduce(d * d / (tx**2 + eps), mask)",
        "tests": [
            "tests/optim/test_losses.py::test_relative_l2_gradient_has_the_detached_denominator"
        ],
        "why": "a stop_gradient removed",
    },
    {
        "name": "optim.Interval.forward.sigmoid_slope",
        "file": "jaxgfx/optim/_transforms.py",
        "old": "return lo + (hi - lo) * jax.nn.sigmoid(u)",
        "new": "return lo + (hi - lo) * jax.nn.sigmoid(1.05 * u)",
        "tests": ["tests/optim/test_transforms.py::test_forward_and_derivative_closed_form"],
        "why": "a constant off by 5 %",
    },
    # ------------------------------------------------------------------ defaults (issue 28)
    # defaults set on purpose by earlier fixes: a changed default must fail a test
    {
        "name": "defaults.merge_radiance.time_power_1",
        "file": "jaxgfx/hdr/merge.py",
        "old": "    time_power: float = 2.0,\n    noise_ratio=SLOPE_NOISE_RATIO,\n):",
        "new": "    time_power: float = 1.0,\n    noise_ratio=SLOPE_NOISE_RATIO,\n):",
        "tests": ["tests/test_defaults.py::test_merge_default_is_slope_times_t_squared"],
        "why": "a default changed (hat x t^2 weights, commit 2b64734)",
    },
    {
        "name": "defaults.merge_radiance.weighting_hat",
        "file": "jaxgfx/hdr/merge.py",
        "old": '    weighting: str = "slope",\n    noise=None,',
        "new": '    weighting: str = "hat",\n    noise=None,',
        "tests": ["tests/test_defaults.py::test_merge_default_is_slope_times_t_squared"],
        "why": "a default changed (the slope weight, issue 26)",
    },
    {
        "name": "defaults.canny.sigma_1.1",
        "file": "jaxgfx/image/edges.py",
        "old": "    sigma=1.0,\n    low=0.1,",
        "new": "    sigma=1.1,\n    low=0.1,",
        "tests": ["tests/test_defaults.py::test_canny_default_sigma_is_skimages"],
        "why": "a default changed (scikit-image's sigma 1)",
    },
    {
        "name": "defaults.fit.optimizer_sgd",
        "file": "jaxgfx/optim/_loop.py",
        "old": '    optimizer="adam",\n    steps: int,',
        "new": '    optimizer="sgd",\n    steps: int,',
        "tests": ["tests/test_defaults.py::test_fit_default_adam_first_step"],
        "why": "a default changed (Adam)",
    },
    {
        "name": "defaults.fit.learning_rate_x2",
        "file": "jaxgfx/optim/_loop.py",
        "old": "learning_rate: float | Callable[[int], float] = 1e-2,",
        "new": "learning_rate: float | Callable[[int], float] = 2e-2,",
        "tests": ["tests/test_defaults.py::test_fit_default_adam_first_step"],
        "why": "a default changed (1e-2)",
    },
    {
        "name": "defaults.fit.patience_9",
        "file": "jaxgfx/optim/_loop.py",
        "old": "    patience: int = 10,",
        "new": "    patience: int = 9,",
        "tests": ["tests/test_defaults.py::test_fit_default_patience_with_tol"],
        "why": "a default changed (10 steps)",
    },
    {
        "name": "optim.fit.average_off_by_one",
        "file": "jaxgfx/optim/_loop.py",
        "old": "if average_from is not None and i >= average_from:",
        "new": "if average_from is not None and i >= average_from - 1:",
        "tests": ["tests/optim/test_average.py::test_average_of_a_known_sequence"],
        "why": "the averaging window one iterate too early (history[k0] included)",
    },
    {
        "name": "optim.fit.average_dropped",
        "file": "jaxgfx/optim/_loop.py",
        "old": "    if n_avg:\n        u = jax.tree.map(lambda s: s / n_avg, u_sum)",
        "new": "    if n_avg < 0:\n        u = jax.tree.map(lambda s: s / n_avg, u_sum)",
        "tests": [
            "tests/optim/test_average.py::"
            "test_averaging_a_noisy_quadratic_matches_the_stationary_variance"
        ],
        "why": "the average counted but the last iterate returned",
    },
    {
        "name": "defaults.render.integrator_direct",
        "file": "jaxgfx/render/render.py",
        "old": 'integrator: str | Integrator = "path",',
        "new": 'integrator: str | Integrator = "direct",',
        "tests": ["tests/test_defaults_render.py::test_render_default_integrator_is_path_depth_3"],
        "why": "a default changed (the path tracer)",
    },
    {
        "name": "defaults.PathIntegrator.max_depth_4",
        "file": "jaxgfx/render/integrators/path.py",
        "old": "    max_depth: int = eqx.field(static=True, default=3)\n    rr_depth",
        "new": "    max_depth: int = eqx.field(static=True, default=4)\n    rr_depth",
        "tests": ["tests/test_defaults_render.py::test_render_default_integrator_is_path_depth_3"],
        "why": "a default changed (Mitsuba depth 3: one indirect bounce)",
    },
    {
        "name": "defaults.PathIntegrator.rr_depth_4",
        "file": "jaxgfx/render/integrators/path.py",
        "old": "default=3)\n    rr_depth: int = eqx.field(static=True, default=5)",
        "new": "default=3)\n    rr_depth: int = eqx.field(static=True, default=4)",
        "tests": [RR_OBJECT],
        "why": "a default changed (Russian roulette after 5 bounces, as Mitsuba)",
    },
    {
        "name": "defaults.PathIntegrator.rr_depth_6",
        "file": "jaxgfx/render/integrators/path.py",
        "old": "default=3)\n    rr_depth: int = eqx.field(static=True, default=5)",
        "new": "default=3)\n    rr_depth: int = eqx.field(static=True, default=6)",
        "tests": [RR_OBJECT],
        "why": "a default changed (Russian roulette after 5 bounces, as Mitsuba)",
    },
    {
        "name": "defaults.merge_deghosted.threshold_4.5",
        "file": "jaxgfx/hdr/deghost.py",
        "old": "    threshold: float = 4.0,\n",
        "new": "    threshold: float = 4.5,\n",
        "tests": [_DEGHOST],
        "why": "a default changed (chi-square threshold 4, docs/hdr.md)",
    },
    {
        "name": "defaults.merge_deghosted.sigma_2.5",
        "file": "jaxgfx/hdr/deghost.py",
        "old": "    sigma: float = 2.0,\n    region_sigma",
        "new": "    sigma: float = 2.5,\n    region_sigma",
        "tests": [_DEGHOST],
        "why": "a default changed (consistency window 2 px)",
    },
    {
        "name": "defaults.merge_deghosted.region_sigma_5",
        "file": "jaxgfx/hdr/deghost.py",
        "old": "    region_sigma: float = 4.0,\n",
        "new": "    region_sigma: float = 5.0,\n",
        "tests": ["tests/test_defaults.py::test_merge_deghosted_default_region_window"],
        "why": "a default changed (per-region reference window 4 px)",
    },
    {
        "name": "defaults.merge_deghosted.saturation_0.99",
        "file": "jaxgfx/hdr/deghost.py",
        "old": "    saturation: float = 0.98,\n",
        "new": "    saturation: float = 0.99,\n",
        "tests": [_DEGHOST],
        "why": "a default changed (RAW clipping level 0.98)",
    },
    {
        "name": "defaults.contrast_inversion.k_5",
        "file": "jaxgfx/tonemap/_local.py",
        "old": "    k=4.0,\n    strength=0.3,",
        "new": "    k=5.0,\n    strength=0.3,",
        "tests": ["tests/test_defaults.py::test_contrast_inversion_defaults_k4_strength_0_3"],
        "why": "a default changed (k 4: the log-average to 0.2, commit 7cdd24a)",
    },
    {
        "name": "defaults.contrast_inversion.strength_1",
        "file": "jaxgfx/tonemap/_local.py",
        "old": "    k=4.0,\n    strength=0.3,",
        "new": "    k=4.0,\n    strength=1.0,",
        "tests": ["tests/test_defaults.py::test_contrast_inversion_defaults_k4_strength_0_3"],
        "why": "a default changed back to the lecture's full division (order of regions lost)",
    },
    {
        "name": "defaults.Reinhard2002.white_4",
        "file": "jaxgfx/tonemap/_global.py",
        "old": "    key=0.18,\n    white=None,",
        "new": "    key=0.18,\n    white=4.0,",
        "tests": ["tests/test_defaults.py::test_reinhard_default_white_is_the_image_maximum"],
        "why": "a default changed (white = the image maximum; `--list` once said 4)",
    },
    {
        "name": "defaults.Reinhard2005.intensity_unlimited",
        "file": "jaxgfx/tonemap/_global.py",
        "old": 'check_scalar(intensity, "intensity", lo=-8.0, hi=8.0,',
        "new": 'check_scalar(intensity, "intensity", lo=-1e9, hi=1e9,',
        "tests": [
            "tests/test_defaults.py::test_reinhard_devlin_intensity_is_limited_to_plus_minus_8"
        ],
        "why": "a range limit dropped (intensity 100 gave a black image, commit ea6698c)",
    },
    # ------------------------------------------------------------------ ellipsoids
    {
        "name": "render.ellipsoids.normal_one_inverse_scale",
        "file": "jaxgfx/render/geometry/ellipsoids.py",
        "old": "n = safe_normalize(_to_world(R, _to_local(R, p - c) * inv * inv))",
        "new": "n = safe_normalize(_to_world(R, _to_local(R, p - c) * inv))",
        "tests": ["tests/render/test_ellipsoids.py::test_hits_match_the_implicit_quadric"],
        "why": "the normal as R S⁻¹ l instead of the gradient R S⁻² l",
    },
    {
        "name": "render.ellipsoids.far_root",
        "file": "jaxgfx/render/geometry/ellipsoids.py",
        "old": "t = jnp.minimum(t1, t2)\n",
        "new": "t = jnp.maximum(t1, t2)\n",
        "tests": ["tests/render/test_ellipsoids.py::test_hard_cases_are_as_documented"],
        "why": "the exit instead of the entry (Mitsuba culls back faces: rays from inside miss)",
    },
    {
        "name": "render.ellipsoids.flat_hit",
        "file": "jaxgfx/render/geometry/ellipsoids.py",
        "old": "ok = (disc >= 0) & (A > 0) & ~flat & jnp.isfinite(t)",
        "new": "ok = (disc >= 0) & (A > 0) & jnp.isfinite(t)",
        "tests": ["tests/render/test_ellipsoids.py::test_hard_cases_are_as_documented"],
        "why": "a scale of 0 drawn as a cylinder (Mitsuba 3.9.1 never hits a flat ellipsoid)",
    },
    # ------------------------------------------------------------------ curves
    {
        "name": "render.curves.start_ball_always",
        "file": "jaxgfx/render/geometry/curves.py",
        "old": "self.start_cap = jnp.asarray(~np.isin(seg - 1, seg))",
        "new": "self.start_cap = jnp.asarray(np.ones(seg.size, bool))",
        "tests": ["tests/render/test_curves.py::test_hard_cases_are_as_documented"],
        "why": "Embree's joint rule dropped (a zero-length segment's successor draws its ball)",
    },
    {
        "name": "render.pplastic.one_fresnel_transmission",
        "file": "jaxgfx/render/bsdf/_pplastic.py",
        "old": "t = (1.0 - fresnel_dielectric(co, self.eta).r) * (1.0 - fresnel_dielectric(ci, "
        "self.eta).r)",
        "new": "t = 1.0 - fresnel_dielectric(ci, self.eta).r",
        "tests": ["tests/render/test_bsdf_polarized.py::test_eval_equals_the_formula"],
        "why": "the diffuse lobe entering the coat only (Mitsuba's pplastic crosses it twice)",
    },
    {
        "name": "render.pplastic.lobe_fresnel_at_normal",
        "file": "jaxgfx/render/bsdf/_pplastic.py",
        "old": "f = fresnel_dielectric(vdot(wo, h), self.eta).r",
        "new": "f = fresnel_dielectric(wo[..., 2], self.eta).r",
        "tests": ["tests/render/test_bsdf_polarized.py::test_eval_equals_the_formula"],
        "why": "the microfacet lobe's Fresnel at the macro normal instead of the half vector",
    },
    {
        "name": "render.delta_bsdf.eval_nonzero",
        "file": "jaxgfx/render/bsdf/_base.py",
        "old": "return jnp.zeros(shape, jnp.result_type(wo, wi, getattr(",
        "new": "return jnp.ones(shape, jnp.result_type(wo, wi, getattr(",
        "tests": ["tests/render/test_bsdf.py::test_delta_bsdfs"],
        "why": "a delta-only BSDF (Mirror, dielectrics, pass-throughs) with a non-zero eval",
    },
    {
        "name": "render.delta_bsdf.pdf_nonzero",
        "file": "jaxgfx/render/bsdf/_base.py",
        "old": "return jnp.zeros(jnp.broadcast_shapes(wo.shape, wi.shape)[:-1], jnp.result_type(",
        "new": "return jnp.ones(jnp.broadcast_shapes(wo.shape, wi.shape)[:-1], jnp.result_type(",
        "tests": ["tests/render/test_bsdf_polarized.py::test_pass_through_lobes"],
        "why": "a delta-only BSDF with a non-zero solid-angle pdf (MIS would weight it)",
    },
    {
        "name": "render.polarizer.factor",
        "file": "jaxgfx/render/bsdf/_polarizer.py",
        "old": "polarizing: bool = eqx.field(static=True, default=True)\n\n"
        "    FACTOR: ClassVar[float] = 0.5",
        "new": "polarizing: bool = eqx.field(static=True, default=True)\n\n"
        "    FACTOR: ClassVar[float] = 1.0",
        "tests": ["tests/render/test_bsdf_polarized.py::test_pass_through_lobes"],
        "why": "the polarizer as a plain pass-through (Mitsuba's RGB variants halve the light)",
    },
    {
        "name": "render.curves.zero_length_drawn",
        "file": "jaxgfx/render/geometry/curves.py",
        "old": "better = on & (L2 > 0) & (dd >= 0) & (t < best)",
        "new": "better = on & (dd >= 0) & (t < best)",
        "tests": ["tests/render/test_curves.py::test_hard_cases_are_as_documented"],
        "why": "a zero-length segment drawn as its ball (Mitsuba 3.9.1 draws nothing)",
    },
    {
        "name": "render.curves.radius_scaled_by_to_world",
        "file": "jaxgfx/render/scene/schema.py",
        "old": "pts = np.concatenate([pts[:, :3] @ m[:3, :3].T + m[:3, 3], pts[:, 3:]], 1)",
        "new": "pts = np.concatenate([pts[:, :3] @ m[:3, :3].T + m[:3, 3], "
        "pts[:, 3:] * abs(np.linalg.det(m[:3, :3])) ** (1 / 3)], 1)",
        "tests": ["tests/render/test_curves.py::test_scene_dict_xml_and_writer"],
        "why": "Mitsuba leaves the radii of curves unscaled by to_world",
    },
    {
        "name": "render.curves.bspline_sphere_envelope",
        "file": "jaxgfx/render/geometry/curves.py",
        "old": "    g1 = sum_last(q * dc)\n",
        "new": "    g1 = sum_last(q * dc) + r * dr\n",
        "tests": [
            "tests/render/test_curves_bspline.py::"
            "test_straight_bspline_is_a_tube_of_perpendicular_circles"
        ],
        "why": "the envelope of spheres instead of Embree's sweep of perpendicular circles",
    },
    # ------------------------------------------------------------------ sunsky
    {
        "name": "render.sunsky.mie_g_and_zenith_swapped",
        "file": "jaxgfx/render/sunsky.py",
        "old": "A, B, C, D, E, F, G, I, H = (params[:, k] for k in range(9))",
        "new": "A, B, C, D, E, F, G, H, I = (params[:, k] for k in range(9))",
        "tests": ["tests/render/test_sunsky.py::test_sky_is_the_papers_formula_on_the_raw_tables"],
        "why": "the paper's letter order, not the tables' (the first draft's bug: sky 60 % off)",
    },
    {
        "name": "render.sunsky.bezier_without_cube_root",
        "file": "jaxgfx/render/sunsky.py",
        "old": "x = jnp.minimum(_cbrt_pos(2.0 / math.pi * eta), 1.0 - 2.0**-24)",
        "new": "x = jnp.minimum(2.0 / math.pi * eta, 1.0 - 2.0**-24)",
        "tests": ["tests/render/test_sunsky.py::test_sky_is_the_papers_formula_on_the_raw_tables"],
        "why": "a missing power (invisible with the sun at the zenith, where x = 1 either way)",
    },
    {
        "name": "render.sunsky.irradiance_grid_half_cell",
        "file": "jaxgfx/render/sunsky.py",
        "old": "e = jnp.clip((jnp.rad2deg(_elevation(s)) - 2.0) / 3.0, 0.0, 29.0)",
        "new": "e = jnp.clip((jnp.rad2deg(_elevation(s)) - 0.5) / 3.0, 0.0, 29.0)",
        "tests": [
            "tests/render/test_sunsky.py::"
            "test_sun_disc_is_the_tables_irradiance_over_its_solid_angle"
        ],
        "why": "a table's grid origin off by half a cell (the sun's colour shifts with elevation)",
    },
    # ------------------------------------------------------------------ benchmarks
    {
        "name": "benchmarks.fitloop.verdict_bound_not_inclusive",
        "file": "benchmarks/fitloop.py",
        "old": 'return "met" if value <= target.threshold else "not met"',
        "new": 'return "met" if value < target.threshold else "not met"',
        "tests": [
            "tests/test_benchmark_fitloop.py::"
            "test_verdict_is_exact_at_the_bound_and_fails_just_past_it"
        ],
        "why": "issue 22's bounds are inclusive (<= 2x): a ratio at the bound is met",
    },
    # ------------------------------------------------------------------ pipelines: fit
    {
        "name": "pipelines.fit.shared_target_one_key",
        "file": "jaxgfx/pipelines/fit/job.py",
        "old": "imgs = [np.asarray(one(jax.random.fold_in(key, i), k)) for i in range(n)]",
        "new": "imgs = [np.asarray(one(key, k)) for i in range(n)]",
        "tests": [
            "tests/pipelines/test_fit_cold.py::"
            "test_target_render_is_four_renders_of_the_report_program"
        ],
        "why": "the target's n renders with one key: a k-spp image, n x the variance",
    },
    {
        "name": "pipelines.fit.shared_target_sum_not_mean",
        "file": "jaxgfx/pipelines/fit/job.py",
        "old": "return (np.sum(imgs, axis=0, dtype=np.float64) / n).astype(imgs[0].dtype)",
        "new": "return np.sum(imgs, axis=0, dtype=np.float64).astype(imgs[0].dtype)",
        "tests": [
            "tests/pipelines/test_fit_cold.py::"
            "test_target_render_is_four_renders_of_the_report_program"
        ],
        "why": "the n renders summed, not averaged (a target n times too bright)",
    },
]
