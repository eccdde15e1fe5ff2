"""Debevec & Malik (1997) response recovery: weighted least squares for g = ln f^{-1}."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._checks import check_choice, check_nonnegative
from .._math import spd_solve_small
from ._curve_space import response_basis
from ._model import CameraResponse, resolve_anchor
from ._sampling import _stride_for, level_index, monotone_repair, select_samples
from .weighting import get_weighting

DEBEVEC_MAX_CANDIDATES = 1 << 14


def grid_samples(h, w, max_candidates=None):
    """Default ``n_samples`` of ``"debevec"`` for an ``h × w`` image: the number of pixels of
    :func:`select_samples`' candidate grid (at most ``max_candidates``, default
    :data:`DEBEVEC_MAX_CANDIDATES`), rounded down to a multiple of its 32 intensity bins (at
    least 32): as many samples as candidates, so a bin with its share of them keeps every one
    (docs/hdr.md, "Pixel samples")."""
    mc = DEBEVEC_MAX_CANDIDATES if max_candidates is None else int(max_candidates)
    s = _stride_for(h, w, mc)
    oy = (h - 1 - ((h - 1) // s) * s) // 2
    ox = (w - 1 - ((w - 1) // s) * s) // 2
    n = len(range(oy, h, s)) * len(range(ox, w, s))
    return max(32, (n // 32) * 32)


SPARSE_OVERLAP = 0.06
"""Default ``sparse_overlap`` of ``"debevec"``: a channel in which fewer than this fraction of
the candidate pixels is well exposed (8-bit levels 16…239, :data:`WELL_EXPOSED`) in at least
2 frames (:func:`bracket_overlap`) is fitted in the 3-parameter curve space of
``"subspace"`` (``n_poly=0``) instead of the free table. Measured (docs/hdr.md, "Measured
curves"): 0.00–0.04 on the 3-frame ±3 EV AEBs through the Ektachrome curves (where the free
table loses to OpenCV and the subspace fit wins); 0.10–0.99 on every other bracket of the
tests (5-frame measured, real JPEG, JPEG-like and analytic synthetic stacks), where the free
table is kept."""

SMOOTH_PRIORS = ("auto", "subspace", "none")
"""Values of ``smooth_prior`` of ``"debevec"``: what the smoothness term pulls the table
towards. ``"none"``: a straight line, ``λ S(g)`` (Debevec & Malik's term); ``"subspace"``:
the channel's 3-parameter curve-space fit ``g_sub`` (:mod:`jaxgfx.hdr._subspace`,
``n_poly=0``), ``λ S(g − g_sub)``, in every fit; ``"auto"`` (the default): the
inverse-slope fit with the ``"subspace"`` prior at each of ``prior_strengths`` (× ``λ``) is a
candidate of the leave-one-out choice (with ``reweight_passes > 0``; the end-weighted fit and
the plain inverse-slope fit keep ``"none"``)."""

PRIOR_STRENGTHS = (1.0, 10.0)
"""Default ``prior_strengths`` of ``"debevec"``: with ``smooth_prior="auto"`` one candidate of
the self-check per entry, the inverse-slope fit with the curve-space smoothness prior at
``λ · s``."""


def _check_strengths(v):
    try:
        out = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        out = ()
    if not out or len(out) > 4 or not all(0 < x < 1e6 for x in out):
        raise ValueError(
            f"prior_strengths: expected 1 to 4 numbers in (0, 1e6) (multiples of lam), got {v!r}"
        )
    return out


WELL_EXPOSED = (16.0 / 255.0, 239.0 / 255.0)
"""Normalised level range counted as well exposed by :func:`bracket_overlap` (1/16 of the
range from black and from clipping)."""

__all__ = [
    "recover_debevec",
    "default_levels",
    "debevec_solve",
    "debevec_system",
    "debevec_samples",
    "data_residual_rms",
    "inverse_slope_weights",
    "subspace_solve",
    "bracket_overlap",
    "SPARSE_OVERLAP",
    "WELL_EXPOSED",
    "SMOOTH_PRIORS",
]


def default_levels(code_max: float, n_levels: int | None) -> int:
    """Table size: ``n_levels`` if given, else 256 (16-bit and float data are binned to 256
    levels: with 1024 the float32 normal equations lose accuracy, measured curve error
    0.02 → 0.15 at 512 bins on a 16-bit 1e6:1 stack)."""
    if n_levels is not None:
        if isinstance(n_levels, bool) or not isinstance(n_levels, int) or n_levels < 8:
            raise ValueError(f"n_levels: expected an integer >= 8, got {n_levels!r}")
        return n_levels
    return 256


def smoothness_matrix(n_levels, dtype):
    """``R`` with ``g^T R g`` = mean over knots ``k = 1…L−2`` of ``(hat(z_k) g''(z_k))²``,
    ``g''`` the second difference on the normalised level axis (Debevec & Malik's smoothness
    term, made independent of the table size ``L``)."""
    import numpy as np

    n = n_levels
    z = np.linspace(0.0, 1.0, n)
    k = np.arange(1, n - 1)
    hat = 2.0 * np.minimum(z[k], 1.0 - z[k])
    hz2 = (1.0 / (n - 1)) ** 2
    d2 = np.zeros((n - 2, n))
    d2[k - 1, k - 1] = 1.0 / hz2
    d2[k - 1, k] = -2.0 / hz2
    d2[k - 1, k + 1] = 1.0 / hz2
    rw = hat**2 / (n - 2)
    return jnp.asarray((d2.T * rw[None, :]) @ d2, dtype)


def debevec_solve(levels, weights, log_t, n_levels, lam, anchor_index, prior=None):
    """Solve Debevec–Malik's system for one channel (:func:`debevec_system`), ``g`` ``(L,)``.

    ``prior`` ``(L,)`` (optional): the smoothness term penalises the curvature of ``g − prior``
    instead of ``g`` (``λ S(g − prior)``), so a curved prior's shape is not smoothed away; the
    ridge below then pulls towards the prior too."""
    a, b = debevec_system(levels, weights, log_t, n_levels, lam, anchor_index)
    # a 1e-7 relative ridge: levels no pixel reaches have no equation but the smoothness
    ridge = 1e-7 * jnp.mean(jnp.diag(a))
    if prior is not None:
        b = b + lam * (smoothness_matrix(n_levels, a.dtype) @ prior) + ridge * prior
    a = a + jnp.eye(n_levels, dtype=a.dtype) * ridge
    return jnp.linalg.solve(a, b)


def debevec_system(levels, weights, log_t, n_levels, lam, anchor_index):
    """Debevec–Malik's normal equations for one channel, the per-pixel unknowns eliminated.

    Minimises ``Σ_ij W_ij² (g[Z_ij] − u_i − ln t_j)² / Σ W² + λ S(g) + g[m]²`` over the
    table ``g`` (``L``) and the pixel log-irradiances ``u`` (``P``):
    ``u`` enters block-diagonally, so the Schur complement leaves an ``L × L`` SPD system
    (built by scatter-adds in ``O(P N²)``). ``S`` is :func:`smoothness_matrix`.

    ``levels``/``weights``: ``(P, N)``; ``log_t``: ``(N,)``. Returns ``(A, b)``, ``A``
    ``(L, L)`` SPD and ``b`` ``(L,)``: the objective is ``gᵀAg − 2bᵀg + const``.
    """
    p, n = levels.shape
    dt = weights.dtype
    w2 = weights * weights
    tot = jnp.maximum(jnp.sum(w2), jnp.finfo(dt).tiny)
    w2 = w2 / tot
    flat = levels.reshape(-1)
    diag = jax.ops.segment_sum(w2.reshape(-1), flat, num_segments=n_levels)
    rhs_g = jax.ops.segment_sum((w2 * log_t[None, :]).reshape(-1), flat, num_segments=n_levels)
    d = jnp.sum(w2, axis=1)  # (P,)
    has = d > 0
    dinv = jnp.where(has, 1.0 / jnp.where(has, d, 1.0), 0.0)
    rhs_u = -jnp.sum(w2 * log_t[None, :], axis=1)  # (P,)
    # Schur complement  S = H_gu D^-1 H_gu^T  by scatter of the N^2 pairs of each pixel
    pair_val = (w2[:, :, None] * w2[:, None, :]) * dinv[:, None, None]
    pair_idx = levels[:, :, None] * n_levels + levels[:, None, :]
    s = jax.ops.segment_sum(
        pair_val.reshape(-1), pair_idx.reshape(-1), num_segments=n_levels * n_levels
    ).reshape(n_levels, n_levels)
    corr = jax.ops.segment_sum(
        (-w2 * (rhs_u * dinv)[:, None]).reshape(-1), flat, num_segments=n_levels
    )
    a = jnp.diag(diag) - s
    b = rhs_g - corr
    a = a + lam * smoothness_matrix(n_levels, dt)
    a = a.at[anchor_index, anchor_index].add(1.0)
    return a, b


def subspace_solve(levels, weights, log_t, basis, lam, anchor_index):
    """One channel: the coefficients ``c`` ``(K,)`` minimising Debevec–Malik's objective over
    ``g = basis @ c`` (``basis`` ``(L, K)``)."""
    n_levels = basis.shape[0]
    a, b = debevec_system(levels, weights, log_t, n_levels, lam, anchor_index)
    # no LAPACK call (spd_solve_small): in recover_debevec this small solve is independent of
    # the table's LAPACK solves, and two independent LAPACK calls in one program hung the XLA
    # CPU runtime intermittently (issue 26)
    return spd_solve_small(basis.T @ a @ basis, basis.T @ b)


def inverse_slope_weights(g, anchor_index):
    """Per-level data weights ``min(1, s_med / s(z))`` ``(C, L)`` from a fitted table ``g``
    ``(C, L)``: ``s`` the slope of the monotone-repaired table in ``ln x`` per level (central
    differences), ``s_med`` its median over the middle three quarters of the levels. At a
    constant noise in levels, the noise of ``ln x`` at level ``z`` is proportional to
    ``g'(z)``, so ``1 / g'`` is its inverse standard deviation (Robertson et al.'s and
    Granados et al.'s inverse-variance weighting in exposure units); capped at 1 so the flat
    mid-tones of a steep curve do not swamp the system."""
    gm = monotone_repair(g.T, anchor_index).T
    sl = jnp.maximum(jnp.gradient(gm, axis=1), 1e-6)
    n = g.shape[1]
    ref = jnp.median(sl[:, n // 8 : n - n // 8], axis=1, keepdims=True)
    return jnp.minimum(ref / sl, 1.0)


def _refit_chain(g0, lev, base, log_t, n_lev, m, stages, passes, g_sub):
    """The inverse-slope refits, ``passes`` per stage, each from the previous curve (from
    ``g0`` ``(C, L)``): stage ``(lam, prior)`` solves with data weights
    :func:`inverse_slope_weights` of the previous curve times ``base``, smoothness ``lam`` and,
    if ``prior``, the curve-space prior ``g_sub`` (:func:`debevec_solve`). One ``lax.scan``
    over all refits: the program holds one solve (its LAPACK calls ordered by the loop) however
    many candidates there are. Returns every refit's ``(g, w)`` stacked, ``(S·passes, C, ...)``."""
    lams = jnp.asarray([lm for lm, _ in stages for _ in range(passes)], base.dtype)
    use = jnp.asarray([float(p) for _, p in stages for _ in range(passes)], base.dtype)
    gp0 = jnp.zeros_like(g0) if g_sub is None else g_sub
    solve = jax.vmap(
        lambda lv, ww, gp, lm: debevec_solve(lv, ww, log_t, n_lev, lm, m, gp),
        in_axes=(0, 0, 0, None),
    )

    def step(g, xs):
        lm, u = xs
        f = inverse_slope_weights(g, m)
        w1 = base * jnp.take_along_axis(
            f[:, None, :], lev.reshape(lev.shape[0], 1, -1), axis=2
        ).reshape(lev.shape)
        g1 = solve(lev, w1, gp0 * u, lm)
        return g1, (g1, w1)

    _, (gs, ws) = jax.lax.scan(step, g0, (lams, use))
    return gs, ws


def _select_by_loo(z, t, candidates, m, anchor_z):
    """Of the candidate fits ``[(g, w), ...]`` the one with the smallest leave-one-out
    re-exposure error (default merge) on the sampled candidate grid ``z``: ``(g, w, index,
    errors)``."""
    from .merge import SLOPE_NOISE_RATIO
    from .selfcheck import LOO_BANDS, _loo_jit

    def loo(g):
        r = CameraResponse(monotone_repair(g.T, m), "table", "debevec", 1.0, anchor_z)
        return _loo_jit(
            z,
            t,
            r,
            None,
            jnp.asarray(SLOPE_NOISE_RATIO, z.dtype),
            weighting="slope",
            code_max=1.0,
            edges=LOO_BANDS,
            time_power=2.0,
        ).mean_abs_error

    gs = jnp.stack([g for g, _ in candidates])
    # one loop over the candidates, not K independent LOO loops in the program: with three
    # the XLA CPU runtime intermittently hung (every thread in a futex wait) on 256x256 stacks
    errs = jax.lax.map(loo, gs)
    errs = jnp.where(jnp.isnan(errs), jnp.inf, errs)
    k = jnp.argmin(errs)
    g = gs[k]
    w = jnp.stack([w for _, w in candidates])[k]
    return g, w, k, errs


def debevec_samples(z, key, n_samples, max_candidates, n_lev, weighting, end_weight):
    """The sampled levels and data weights of a Debevec-type fit: ``(lev, w, interior,
    valid)``, ``lev``/``w``/``interior`` ``(C, P, N)``, ``valid`` ``(C, P)``. Pixels from
    :func:`select_samples` (``flat_reach=2``), levels binned to ``n_lev``, weight
    ``weighting(z) + end_weight`` on every level but the first and the last (black and
    clipped values are censored: weight 0)."""
    wfun = get_weighting(weighting)
    if key is None:
        key = jax.random.key(0)
    mc = DEBEVEC_MAX_CANDIDATES if max_candidates is None else int(max_candidates)
    if n_samples is None:
        n_samples = grid_samples(z.shape[1], z.shape[2], mc)
    samples, valid = select_samples(
        key, z, n_samples=n_samples, flat_reach=2, max_candidates=max(mc, n_samples)
    )
    lev = level_index(samples, n_lev)  # (C, P, N)
    zq = lev.astype(z.dtype) / (n_lev - 1)
    interior = (lev > 0) & (lev < n_lev - 1)
    w = jnp.where(interior, wfun(zq) + end_weight, 0.0) * valid[..., None].astype(z.dtype)
    return lev, w, interior, valid


def data_residual_rms(g, lev, w, log_t):
    """Weighted RMS (ln units) of the data equations ``g[Z] − u − ln t`` per channel, the
    per-pixel ``u`` at its optimum; ``g`` ``(C, L)``, ``lev``/``w`` ``(C, P, N)``."""
    gz = jnp.take_along_axis(g[:, None, :], lev.reshape(lev.shape[0], 1, -1), axis=2).reshape(
        lev.shape
    )
    h = gz - log_t
    w2 = w * w
    den = jnp.sum(w2, axis=2, keepdims=True)
    u = jnp.sum(w2 * h, axis=2, keepdims=True) / jnp.where(den > 0, den, 1.0)
    return jnp.sqrt(
        jnp.sum(w2 * (h - u) ** 2, axis=(1, 2)) / jnp.maximum(jnp.sum(w2, axis=(1, 2)), 1e-30)
    )


def bracket_overlap(z):
    """Per channel ``(C,)``: the fraction of pixels of the stack ``z`` ``(N, H, W, C)``
    (normalised) that are well exposed (:data:`WELL_EXPOSED`, levels 16…239 of 255) in at
    least 2 frames."""
    lo, hi = WELL_EXPOSED
    inside = (z >= lo - 1e-6) & (z <= hi + 1e-6)
    return jnp.mean((jnp.sum(inside, axis=0) >= 2).astype(z.dtype), axis=(0, 1))


def _subspace_fit(lev, interior, valid, log_t, m, lam, n_lev, dtype):
    """The ``"subspace"`` fit (``n_poly=0``, hat weights, no end weight) of every channel:
    ``(g_sub, ws)``, the table ``(C, L)`` and its data weights ``(C, P, N)``."""
    zq = lev.astype(dtype) / (n_lev - 1)
    ws = jnp.where(interior, 1.0 - jnp.abs(2.0 * zq - 1.0), 0.0) * valid[..., None].astype(dtype)
    basis = jnp.asarray(response_basis(n_lev, 0), dtype)
    c = jax.vmap(lambda lv, ww: subspace_solve(lv, ww, log_t, basis, lam, m))(lev, ws)
    return c @ basis.T, ws


def _sparse_subspace(z, g, w, g_sub, ws, threshold):
    """Replace the channels whose bracket overlap (:func:`bracket_overlap`) is below
    ``threshold`` by the ``"subspace"`` fit ``g_sub`` (weights ``ws``)."""
    ov = bracket_overlap(z)
    pick = ov < threshold  # (C,)
    g = jnp.where(pick[:, None], g_sub, g)
    w = jnp.where(pick[:, None, None], ws, w)
    return g, w, {"overlap": ov, "subspace_chosen": pick}


def recover_debevec(
    z,
    t,
    code_max,
    *,
    key=None,
    n_samples: int | None = None,
    lam: float = 1e-6,
    n_levels: int | None = None,
    weighting: str = "hat",
    anchor="mid",
    end_weight: float = 0.2,
    max_candidates: int = None,
    reweight_passes: int = 3,
    sparse_overlap: float = SPARSE_OVERLAP,
    smooth_prior: str = "auto",
    prior_strengths: tuple = PRIOR_STRENGTHS,
):
    """Debevec & Malik (1997) response recovery (method ``"debevec"``).

    ``z``: ``(N, H, W, C)`` normalised stack, ``t``: ``(N,)`` ascending seconds. Samples
    ``n_samples`` pixels per channel with :func:`select_samples` (stratified over intensity,
    away from edges, deterministic for a ``key``), bins levels to ``n_levels`` (256 for 8-bit
    16-bit and float input by default), solves the least-squares system with
    ``weighting`` (Debevec's hat) plus ``end_weight`` on every level except the first and
    last (black and clipped values are censored: weight 0), and smoothness ``lam``, then makes
    the table strictly increasing with :func:`monotone_repair` (OpenCV's ``CalibrateDebevec``
    does not). ``end_weight`` keeps the toe and shoulder driven by the data there rather than
    extrapolated by the smoothness term: with the plain hat (``end_weight=0``) the curve of a
    JPEG-like stack had its toe too high and its shoulder too low, as on real photographs
    (docs/hdr.md, "JPEG-like stacks"). Samples are picked away from edges by central
    differences that skip the pixel itself, so they are not selected on their own noise.
    Candidates: a regular grid of at most ``max_candidates`` pixels (default
    ``DEBEVEC_MAX_CANDIDATES`` = 16 384, cut out by one strided slice before anything else:
    at 1 MP recovery takes 0.15 s instead of 0.63 s with 65 536, same curve error).
    ``reweight_passes`` (default 3; 0 turns it off): a second, inverse-variance fit and a
    choice between the two by a self-check. Starting from the end-weighted curve, the data
    equations are reweighted ``reweight_passes`` times by :func:`inverse_slope_weights` of
    the previous curve (``min(1, s_med / g'(z))``, no hat, no end weight: the inverse
    standard deviation of ``ln x`` at constant noise in levels), and of the candidate curves
    (these two, and the prior'd ones below) the one with the smallest leave-one-out
    re-exposure error (:func:`jaxgfx.hdr.leave_one_out`,
    default merge, on the candidate grid) is returned. Neither weighting wins everywhere: on
    brackets through measured film curves (steep toe, flat shoulder, issue 26) the end weight
    bent the curve (radiance error 0.097–0.112 on 5-frame brackets; 0.008–0.023 with the
    inverse-slope fit), while on JPEG-like stacks with a lifted black the inverse-slope fit
    lost the toe (LOO 8.2 vs 5.1 levels); the self-check picked the better curve on 9 of 10
    such stacks (docs/hdr.md, "Measured curves").
    Returns a ``"table"`` :class:`CameraResponse`; ``diagnostics["residual_rms"]`` is the
    weighted RMS of the data equations per channel (in ln units) of the returned fit;
    with ``reweight_passes > 0`` also ``diagnostics["loo_candidates"]`` (the LOO error of
    the end-weighted curve, of the inverse-slope curve and of the prior'd ones, levels on
    0–255) and
    ``diagnostics["inverse_slope_chosen"]`` (bool).
    ``sparse_overlap`` (default :data:`SPARSE_OVERLAP` = 0.06; 0 turns it off): a channel in
    which fewer than this fraction of the candidate pixels is well exposed (levels 16…239) in
    at least 2 frames (:func:`bracket_overlap`; a 3-frame ±3 EV AEB of a film-like curve) gets the
    3-parameter ``"subspace"`` fit (``1, ln z, ln(1 − z)``; :mod:`jaxgfx.hdr._subspace`)
    instead: its free table is under-determined there (issue 26, docs/hdr.md "Measured
    curves"). ``diagnostics["overlap"]`` and ``diagnostics["subspace_chosen"]`` ``(C,)``.
    ``smooth_prior`` (:data:`SMOOTH_PRIORS`, default ``"auto"``) and ``prior_strengths``
    (default :data:`PRIOR_STRENGTHS` = ``(1, 10)``): with ``"auto"`` and ``reweight_passes >
    0`` the self-check has one more candidate per strength ``s``, the inverse-slope fit whose
    smoothness term is ``λ s · S(g − g_sub)`` (:func:`debevec_solve` with ``prior``),
    ``g_sub`` the channel's 3-parameter ``"subspace"`` fit, each chain started from the
    previous one's curve. Debevec's ``λ S(g)`` pulls a film curve's steep toe and flat
    shoulder towards a straight line (a ±0.04 ln mid-tone wave on the red 5-frame measured
    bracket: 0.023 vs OpenCV 0.019; 0.011 with the prior). Two strengths because with every
    exposure step the same ratio ``r`` a wave of ``g`` with period ``ln r`` is invisible to the
    data and to the self-check, and sensor noise fills it: on ``jaxgfx calibrate``'s synthetic
    job the candidate at ``λ`` alone had a 0.18 ln RMS wave, the one at ``10 λ`` 0.04 and a
    lower LOO (docs/hdr.md, "The Debevec default"). ``diagnostics["loo_candidates"]`` is then
    ``(2 + len(prior_strengths),)`` and ``diagnostics["prior_chosen"]`` says whether a prior'd
    fit was returned. ``"none"``: the two plain candidates; ``"subspace"``: the prior (at
    ``λ``) in every fit.
    ``n_samples`` (default ``None``): :func:`grid_samples`, as many as the candidate grid has
    pixels (16 384 from 128×128 up; the table's variance falls with the count: 4096 → 16 384
    halved the spread of the fitted curve over noise realisations).
    """
    check_nonnegative(lam, "lam")
    check_nonnegative(end_weight, "end_weight")
    if isinstance(sparse_overlap, bool) or not (
        isinstance(sparse_overlap, (int, float)) and 0 <= sparse_overlap <= 1
    ):
        raise ValueError(f"sparse_overlap: expected a number in [0, 1], got {sparse_overlap!r}")
    if (
        isinstance(reweight_passes, bool)
        or not isinstance(reweight_passes, int)
        or not (0 <= reweight_passes <= 10)
    ):
        raise ValueError(f"reweight_passes: expected an integer in 0…10, got {reweight_passes!r}")
    check_choice(smooth_prior, "smooth_prior", SMOOTH_PRIORS)
    prior_strengths = _check_strengths(prior_strengths)
    anchor_z = resolve_anchor(anchor)
    n_lev = default_levels(code_max, n_levels)
    lev, w, interior, valid = debevec_samples(
        z, key, n_samples, max_candidates, n_lev, weighting, end_weight
    )
    log_t = jnp.log(t)
    m = (n_lev - 1) // 2
    g_sub = ws = None
    if sparse_overlap > 0 or smooth_prior != "none":
        g_sub, ws = _subspace_fit(lev, interior, valid, log_t, m, lam, n_lev, w.dtype)
    zero = jnp.zeros((z.shape[-1], n_lev), w.dtype)
    g = jax.vmap(lambda lv, ww, gp: debevec_solve(lv, ww, log_t, n_lev, lam, m, gp))(
        lev, w, g_sub if smooth_prior == "subspace" else zero
    )  # (C, L)
    extra = {}
    if reweight_passes > 0:
        base = interior.astype(w.dtype) * valid[..., None].astype(w.dtype)
        # the chains of refits, one after the other: the plain inverse-slope fit, then (with
        # "auto") one prior'd chain per strength, each started from the previous chain's curve
        if smooth_prior == "auto":
            stages = [(lam, False)] + [(lam * s_k, True) for s_k in prior_strengths]
        else:
            stages = [(lam, smooth_prior == "subspace")]
        gs, ws_ = _refit_chain(g, lev, base, log_t, n_lev, m, stages, reweight_passes, g_sub)
        ends = [(k + 1) * reweight_passes - 1 for k in range(len(stages))]
        cands = [(g, w)] + [(gs[e], ws_[e]) for e in ends]
        g, w, k, errs = _select_by_loo(z, t, cands, m, anchor_z)
        extra = {
            "loo_candidates": errs,
            "inverse_slope_chosen": k >= 1,
            "prior_chosen": (k >= 2)
            if smooth_prior == "auto"
            else jnp.asarray(smooth_prior == "subspace"),
        }
    if sparse_overlap > 0:
        g, w, extra2 = _sparse_subspace(z, g, w, g_sub, ws, sparse_overlap)
        extra = {**extra, **extra2}
    res = data_residual_rms(g, lev, w, log_t)
    table = monotone_repair(g.T, m)
    return CameraResponse(
        table,
        "table",
        "debevec",
        float(code_max),
        anchor_z,
        None,
        {"residual_rms": res, "raw_log_exposure": g.T, **extra},
    )
