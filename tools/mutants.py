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
]
