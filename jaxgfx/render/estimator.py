"""The Monte Carlo estimator over the image plane: the one owner of the sample layout and of
the pass scan.

:func:`render_partial` is the sum over sample passes that :func:`jaxgfx.render.render`,
:func:`jaxgfx.render.render_sharded` (per device: some rows or some passes) and the
edge-sampling boundary term (:mod:`jaxgfx.render.visibility`, through :func:`pass_scan`) are
built from; :func:`resolve_integrator` turns ``render``'s string options into an
:class:`~jaxgfx.render.integrators.Integrator` object at the API edge. Nothing here imports
``render.py``, ``visibility.py`` or ``distributed.py``: they compose this module.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jaxgfx._checks import check_choice, check_positive_int
from jaxgfx._math import fusion_barrier
from jaxgfx.render.film import pixel_samples
from jaxgfx.render.integrators import INTEGRATORS, SAMPLING, Integrator, make_integrator
from jaxgfx.render.integrators.path import REPLAY_RADIANCE_NAME, STRATEGIES, PathIntegrator
from jaxgfx.render.sampler import uniform, uniform_blocks

__all__ = ["render_partial", "resolve_integrator", "pass_scan", "passes_per_step"]


RAYS_PER_STEP = 1 << 16
"""Target number of camera rays traced together in one step of the pass scan: a small image
traces several sample passes per ``lax.scan`` step (:func:`passes_per_step`), so its kernels see
about as many rays as a large image's and the per-step overhead is shared (issue 22)."""


LENS_STREAM = 0x1E45
"""What :func:`render_partial` folds into the camera key for the lens numbers of a camera with
``lens_uniforms > 0`` (:class:`~jaxgfx.render.camera.ThinLensCamera`): pass ``s``'s numbers
are ``uniform(fold_in(fold_in(camera key, LENS_STREAM), s), (H, W, lens_uniforms))``."""


CHECKPOINT_ONE_STEP = False
"""Whether :func:`pass_scan` checkpoints a scan of a single step of several passes (``False``:
it runs the step as plain code, see there)."""


REPLAY_KEEPS_RADIANCE = True
"""With a path-replay integrator (``adjoint="replay"``), :func:`render_partial`'s checkpointed
pass steps keep what its forward pass stores per ray (6 numbers: 24 bytes per sample in
float32) so that the backward sweep does not trace every path a second time before replaying
it; ``False``: keep nothing per step (memory flat in spp too) and recompute the forward
(docs/performance.md, "Renderer gradients", has both)."""


def passes_per_step(rays_per_pass: int, n_passes: int, target: int | None = RAYS_PER_STEP) -> int:
    """How many sample passes of ``rays_per_pass`` rays one scan step traces: about
    ``target / rays_per_pass`` (at least 1, at most ``n_passes``), evened out so that the
    ``ceil(n_passes / k)`` steps of ``k`` passes pad as few passes as possible.
    ``target`` ``None`` or ``0``: 1 (one pass per step).

    >>> passes_per_step(96 * 72, 16), passes_per_step(384 * 288, 16), passes_per_step(1024, 8)
    (8, 1, 8)
    """
    if not target or n_passes <= 1:
        return 1
    k = max(1, min(n_passes, target // max(int(rays_per_pass), 1)))
    steps = -(-n_passes // k)
    return -(-n_passes // steps)


def pass_scan(one_pass, passes, acc0, weights=None, *, per_step: int = 1, policy=None):
    """``acc0 + Σ_s weights[s] · one_pass(s)`` over the pass indices ``passes`` ``(P,)``, one
    ``lax.scan`` step per ``per_step`` passes, each step checkpointed: the reverse sweep
    recomputes a step from its pass indices, so the memory of ``jax.grad`` does not grow with
    the number of passes (a plain loop stores every intermediate of every pass;
    docs/render_gradients.md). ``weights``: ``None`` (1 each; ``x * 1`` is exact, so the sum is
    that of the unweighted passes).

    ``per_step == 1``: ``one_pass(s)`` takes one pass index. ``per_step = k > 1``:
    ``one_pass(ss)`` takes ``k`` pass indices ``(k,)`` and returns the ``k`` passes stacked
    ``(k, *acc0.shape)`` (traced together, e.g. as one batch of rays); ``passes`` is padded to a
    multiple of ``k`` with weight-0 repeats of its last index; when that makes a single step it
    runs without scan and checkpoint (the recomputation would hold the same intermediates).
    The sum is taken in the same order, pass by pass, as with ``per_step = 1``, so the result
    is the same up to the rounding of the differently compiled passes. ``policy``: the
    checkpoints' ``jax.checkpoint`` policy (``None``: save nothing)."""
    if weights is None:
        weights = jnp.ones(passes.shape, acc0.dtype)
    k = int(per_step)
    if k == 1:
        one = jax.checkpoint(one_pass, prevent_cse=False, policy=policy)

        def body(acc, sw):
            s, wt = sw
            return acc + wt.astype(acc.dtype) * one(s), None

        acc, _ = jax.lax.scan(body, acc0, (passes, weights))
        return acc
    n = passes.shape[0]
    pad = -n % k
    if pad:
        passes = jnp.concatenate([passes, jnp.broadcast_to(passes[-1:], (pad,))])
        weights = jnp.concatenate([weights, jnp.zeros((pad,), weights.dtype)])
    steps = (n + pad) // k
    # one step: no scan and no checkpoint. The checkpoint's recomputation would hold the same
    # intermediates as plain reverse mode (one step's), so it only adds a copy of the forward
    # program to compile and to run (issue 22: the 32x32 fit step); CHECKPOINT_ONE_STEP = True
    # restores it (benchmarks/render_compile.py)
    group = (
        one_pass
        if steps == 1 and not CHECKPOINT_ONE_STEP
        else jax.checkpoint(one_pass, prevent_cse=False, policy=policy)
    )

    def body_k(acc, sw):
        ss, wts = sw
        out = group(ss)
        for j in range(k):  # the order of the one-pass scan: ((acc + p0) + p1) + ...
            acc = acc + wts[j].astype(acc.dtype) * out[j]
        return acc, None

    xs = (passes.reshape(-1, k), weights.reshape(-1, k).astype(acc0.dtype))
    if steps == 1 and not CHECKPOINT_ONE_STEP:
        return body_k(acc0, (xs[0][0], xs[1][0]))[0]
    acc, _ = jax.lax.scan(body_k, acc0, xs)
    return acc


def resolve_integrator(
    integrator: str | Integrator | dict,
    *,
    max_depth: int | None = None,
    rr_depth: int | None = None,
    strategy: str | None = None,
    sampling: str | None = None,
    caller: str = "render",
) -> Integrator:
    """The :class:`Integrator` that ``render(..., integrator=..., max_depth=...)`` runs.

    An object is returned as is (options beside it: ``TypeError`` naming them and ``caller``);
    a name of :data:`INTEGRATORS` is built by :func:`make_integrator` from the options given
    (not ``None``); the others keep the class's defaults (``PathIntegrator``: ``max_depth=3``,
    ``rr_depth=5``, ``strategy="mis"``, ``sampling="detached"``). An option the named
    integrator does not have is a ``TypeError`` naming it (``"aov"`` with ``max_depth``; the
    depth of ``"direct"`` is 2). Bad names and values raise ``ValueError`` naming the option.
    Runs on the host, before tracing.

    A mapping is the scene-file / config form ``{type: NAME, OPTION: VALUE, ...}`` (e.g.
    ``{type: path, max_depth: 4, adjoint: replay}``): ``NAME`` with those options, to which the
    keyword options are added (one given both ways: ``TypeError``).
    """
    given = {
        k: v
        for k, v in (
            ("max_depth", max_depth),
            ("rr_depth", rr_depth),
            ("strategy", strategy),
            ("sampling", sampling),
        )
        if v is not None
    }
    if isinstance(integrator, dict):
        opts = dict(integrator)
        name = opts.pop("type", None)
        if not isinstance(name, str):
            raise ValueError(f"integrator.type: expected an integrator name, got {name!r}")
        check_choice(name, "integrator.type", tuple(INTEGRATORS))
        both = sorted(set(given) & set(opts))
        if both:
            raise TypeError(f"{', '.join(both)}: given in the integrator mapping and to {caller}()")
        return make_integrator(name, **{**opts, **given})
    if isinstance(integrator, Integrator):
        if given:
            raise TypeError(
                f"{', '.join(given)}: set on the integrator object "
                f"({type(integrator).__name__}), not passed to {caller}()"
            )
        return integrator
    check_choice(integrator, "integrator", tuple(INTEGRATORS))
    # an option the named integrator does not take is an error (make_integrator) unless it is
    # render's default value (PathIntegrator's defaults: max_depth 3, rr_depth 5, "mis",
    # "detached"), which changes nothing: render(integrator="whitted", strategy="mis") is fine,
    # render(integrator="direct", max_depth=5) is refused
    fields = {f.name for f in dataclasses.fields(INTEGRATORS[integrator])}
    defaults = {f.name: f.default for f in dataclasses.fields(PathIntegrator)}
    given = {k: v for k, v in given.items() if k in fields or v != defaults.get(k, object())}
    if "strategy" in given:
        check_choice(given["strategy"], "strategy", STRATEGIES)
    if "sampling" in given:
        check_choice(given["sampling"], "sampling", SAMPLING)
    for name in ("max_depth", "rr_depth"):
        if name in given:
            check_positive_int(given[name], name)
    return make_integrator(integrator, **given)


def render_partial(
    scene,
    key,
    integrator: Integrator,
    *,
    spp: int,
    rows=None,
    passes=None,
    weights=None,
    rays_per_step: int | None = RAYS_PER_STEP,
):
    """UNNORMALISED sum ``(R, W, C)`` over sample passes of the radiance of some image rows.

    The single definition of the sample layout of :func:`jaxgfx.render.render`, which returns
    ``render_partial(scene, key, integrator, spp=spp) / spp``:
    ``key`` splits into a camera key (``film.pixel_samples``: stratified when ``spp`` is a
    square, ``(H, W, spp, 2)``) and a key into which pass ``s`` is folded for the integrator's
    uniform numbers of shape ``(H, W, *integrator.random_shape)``; a camera with a lens
    (``camera.lens_uniforms > 0``) gets ``(H, W, lens_uniforms)`` more per pass from the camera
    key (:data:`LENS_STREAM`), other cameras none; pass ``s`` traces one ray per
    pixel through camera sample ``s`` (an integrator whose ``uniform_blocks`` is true, path
    replay, gets the same numbers as a :class:`~jaxgfx.render.sampler.UniformBlocks`, drawn
    bounce by bounce); the passes run through :func:`pass_scan`,
    :func:`passes_per_step` ``(R W, P, rays_per_step)`` of them per scan step, stacked along the
    rows (``(k R, W)`` rays): a small image does not pay one step's overhead per pass, and
    every sample keeps its random numbers (``rays_per_step=None``: one pass per step; same
    image up to the rounding of the differently compiled program, tests/render/test_layout.py).
    A filter with negative lobes (``mitchell``, ``catmullrom``, ``lanczos``) multiplies each
    sample's radiance by its signed weight (``film.pixel_samples(..., with_weights=True)``).
    A camera with a ``ray_weight`` (:class:`~jaxgfx.render.camera.IrradianceMeter`: ``pi``)
    multiplies the sum by it.

    ``rows``: ``None`` (all ``H`` rows) or global row indices ``(R,)`` (int32, may be traced;
    rows ``>= H`` are padding: rendered beyond the image with their own numbers). A row's
    samples and numbers are those of the whole image's row, so the pixel is computed by the same
    operations. ``passes``: ``None`` (``0 .. spp - 1``) or pass indices ``(P,)`` in
    ``[0, spp)`` (may be traced); ``weights``: ``None`` (1 each) or ``(P,)`` factors per pass
    (0 for padding passes). The estimate is the sum divided by the total weight of the passes
    (``spp`` once every pass is summed, on one device or over several);
    :mod:`jaxgfx.render.distributed` splits the rows or the passes over devices with it.
    Package-internal (not in ``__all__``); jittable, differentiable.
    """
    w, h = scene.width, scene.height
    kp, ku = jax.random.split(key)
    dtype = scene.dtype
    px, wt = pixel_samples(kp, w, h, spp, scene.rfilter, rows=rows, dtype=dtype, with_weights=True)
    # px (R, W, spp, 2); wt (R, W, spp): a negative-lobe filter's signed sample weights, None
    # for the others (their program is unchanged)
    shape_u = integrator.random_shape
    r = px.shape[0]
    # a camera with a lens (ThinLensCamera) takes `lens_uniforms` numbers per ray, drawn from
    # their own key; a pinhole or matrix camera (0) draws nothing: its program is unchanged
    n_lens = getattr(scene.camera, "lens_uniforms", 0)
    kl = jax.random.fold_in(kp, LENS_STREAM) if n_lens else None

    def rays(pxs, ul):
        if ul is None:
            o, d = scene.camera.generate_ray(pxs)
        else:
            o, d = scene.camera.generate_ray(pxs, ul)
        o, d = o.astype(dtype), d.astype(dtype)
        return fusion_barrier((o, d))  # measured 635 -> 518 ns/sample (direct, one core)

    # a path-replay integrator takes its numbers as a UniformBlocks (the same numbers, drawn
    # bounce by bounce inside its loops: its memory does not grow with the depth)
    blocks = getattr(integrator, "uniform_blocks", False)
    draw = uniform_blocks if blocks else uniform

    def numbers(s):
        return draw(jax.random.fold_in(ku, s), (h, w, *shape_u), dtype, rows=rows)

    def lens(s):  # (R, W, n_lens): pass s's lens numbers of the rows, as `numbers`
        return uniform(jax.random.fold_in(kl, s), (h, w, n_lens), dtype, rows=rows)

    def one_pass(s):
        o, d = rays(px[:, :, s, :], lens(s) if n_lens else None)
        u = None if shape_u is None else numbers(s)
        out = integrator(scene, o, d, u)
        return out if wt is None else out * wt[:, :, s, None]

    def k_passes(ss):  # (k,) pass indices -> (k, R, W, C): the k passes as one (k R, W) batch
        k = ss.shape[0]
        pxs = jnp.moveaxis(px[:, :, ss, :], 2, 0).reshape(k * r, w, 2)
        ul = jax.vmap(lens)(ss).reshape(k * r, w, n_lens) if n_lens else None
        o, d = rays(pxs, ul)
        u = None
        if shape_u is not None:
            u = jax.vmap(numbers)(ss)
            u = u.reshape(k * r, w) if blocks else u.reshape(k * r, w, *shape_u)
        out = integrator(scene, o, d, u).reshape(k, r, w, -1)
        return out if wt is None else out * jnp.moveaxis(wt[:, :, ss], 2, 0)[..., None]

    if passes is None:
        passes = jnp.arange(spp)
    k = passes_per_step(r * w, passes.shape[0], rays_per_step)
    acc0 = jnp.zeros((r, w, integrator.n_channels), dtype)
    policy = None
    if getattr(integrator, "adjoint", "ad") == "replay" and REPLAY_KEEPS_RADIANCE:
        policy = jax.checkpoint_policies.save_only_these_names(REPLAY_RADIANCE_NAME)
    fn = k_passes if k > 1 else one_pass
    out = pass_scan(fn, passes, acc0, weights, per_step=k, policy=policy)
    # a sensor whose rays carry a constant weight (IrradianceMeter: pi); others: unchanged
    ray_weight = getattr(scene.camera, "ray_weight", None)
    return out if ray_weight is None else out * jnp.asarray(ray_weight, dtype)
