"""The fit's loss: render → camera → loss over every target (+ priors), one jitted program per
render / loss configuration and parameter set (camera choices are arrays, not part of the
program)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgfx.color import LUMINANCE_WEIGHTS

from .camera import fit_level_table, freeze, photo_matrix
from .config import FitConfig
from .targets import build_scene

__all__ = [
    "make_loss",
    "photo_losses",
    "render_views",
    "stack_cameras",
    "VIEW_BATCHING",
    "cached_loss",
    "censored_linear_loss",
    "chroma_subsampled",
    "code_space_loss",
    "to_target_channels",
    "photo_gains",
    "texture_prior",
    "curve_smoothness",
    "curve_start_prior",
]


def to_target_channels(img, grey: bool):
    """The render in the target's channels: RGB, or Rec. 709 luminance ``(..., 1)`` for a
    grey target."""
    if not grey:
        return img
    w = jnp.asarray(LUMINANCE_WEIGHTS["rec709"], img.dtype)
    return (img @ w)[..., None]


def _masked_mean(v, mask, axes):
    if mask is None:
        return jnp.mean(v, axis=axes)
    m = jnp.broadcast_to(mask, v.shape)
    return jnp.sum(v * m, axis=axes) / jnp.sum(m, axis=axes)


REC601 = (0.299, 0.587, 0.114)
"""The JPEG codec's luma weights (JFIF: ITU-R BT.601)."""


def _triangle_upsample(s, axis: int):
    """×2 along ``axis`` as a JPEG decoder's "fancy" chroma upsampling does (libjpeg's
    ``h2v1`` / ``h2v2_fancy_upsample``): output sample ``2i`` is ``¾ s[i] + ¼ s[i−1]``,
    ``2i+1`` is ``¾ s[i] + ¼ s[i+1]``, the edge samples repeated."""
    s = jnp.moveaxis(s, axis, 0)
    prev = jnp.concatenate([s[:1], s[:-1]])
    nxt = jnp.concatenate([s[1:], s[-1:]])
    out = jnp.stack([0.75 * s + 0.25 * prev, 0.75 * s + 0.25 * nxt], axis=1)
    return jnp.moveaxis(out.reshape((2 * s.shape[0],) + s.shape[1:]), 0, axis)


def chroma_subsampled(img, weight, block):
    """``img`` ``(N, H, W, 3)`` (code or linear values) as a JPEG codec with chroma
    subsampling returns it: the luma ``wᵀx`` (``w`` :data:`REC601`) per pixel, the chroma
    ``x − 1·wᵀx`` (what Cb, Cr carry: a linear map of them) averaged over the codec's chroma
    blocks ``block = (rows, columns)`` (``(2, 2)``: 4:2:0, ``(1, 2)``: 4:2:2; the encoder's
    box downsampling) and brought back to the pixels by the decoder's triangle ("fancy")
    upsampling. ``weight`` ``(N, H, W, 1)`` ≥ 0: the pixels that take part in a block's mean
    (a block without any takes its neighbours' chroma: the upsampling is normalised by the
    blocks that have pixels; a pixel whose blocks all have none gets chroma 0); sizes not a
    multiple of the block are padded with weight 0. Linear in ``img``: a loss on it stays
    quadratic in the Monte Carlo image. The 8×8 DCT quantisation is not modelled."""
    w = jnp.asarray(REC601, img.dtype)
    luma = img @ w
    chroma = img - luma[..., None]
    bh, bw = block
    n, h, wd, c = img.shape
    pad = ((0, 0), (0, (-h) % bh), (0, (-wd) % bw), (0, 0))
    weight = jnp.broadcast_to(weight, (n, h, wd, 1)).astype(img.dtype)

    def block_sum(a):
        a = jnp.pad(a, pad)
        return a.reshape(n, a.shape[1] // bh, bh, a.shape[2] // bw, bw, a.shape[3]).sum((2, 4))

    sw = block_sum(weight)
    has = (sw > 0).astype(img.dtype)
    mean = block_sum(chroma * weight) / jnp.maximum(sw, 1e-12)

    def up(a):
        if bh == 2:
            a = _triangle_upsample(a, 1)
        if bw == 2:
            a = _triangle_upsample(a, 2)
        return a[:, :h, :wd]

    up_chroma = up(mean * has) / jnp.maximum(up(has), 1e-12)
    return luma[..., None] + up_chroma


def censored_linear_loss(
    img, codes, table, gain, code_max, mask=None, clip_code=None, unmeasured_only=None, *,
    per_photo: bool = False, view_of=None, chroma_block=None,
):
    """Censored L2 in linear radiance, summed over photos (``per_photo``: each photo's term,
    ``(N,)``).

    ``img`` ``(H, W, C)`` the linear render (or ``(N, H, W, C)``: each photo's own, several
    views); ``codes`` ``(N, H, W, C)`` integer codes of
    ``N`` photos (or ``(H, W, C)``: one); ``table`` the camera's level table ``(2^bits, C)``
    (:func:`~jaxgfx.pipelines.fit.camera.level_table`: ``ln f⁻¹`` at the codes and at the
    half-codes ½ and ``c − ½`` in slots 0 and ``c``); ``gain`` ``(N, C)`` (or broadcastable)
    the exposure × white-balance gain of each photo. Each code ``q`` is linearised through the
    current camera, ``T = f⁻¹(q / c) / gain``, and compared with the *linear* render, so the
    loss is quadratic in the Monte Carlo image and its expectation is unbiased (in code space
    ``E f(Î) ≠ f(E Î)`` for a curved response). Clipped codes only bound the radiance
    (``q = c``: ``Î ≥ f⁻¹((c − ½)/c) / gain``; ``q = 0``: ``Î ≤ f⁻¹(½/c) / gain``): one
    gather gives both, the bounds being the table's end slots. Each photo's term is
    normalised by its mean linearised target (so its scale does not drift with the exposure);
    ``mask`` ``(N, H, W, 1)`` (or ``(H, W, 1)``) per-pixel weights, None: all pixels.
    ``clip_code`` (an integer code ``k``, a traced scalar allowed; None: ``c``): every code
    ``q ≥ k`` is censored like a clipped one, ``Î ≥ f⁻¹((k − ½)/c) / gain`` (``ln f⁻¹`` at
    ``k − ½`` interpolated halfway between the table's codes ``k − 1`` and ``k``) — for JPEG
    photos, whose clipped highlights ring down to codes ~235–254, and for a calibrated curve
    trusted only below some level. ``unmeasured_only`` (a 0/1 scalar, traced allowed): a
    censored code of one photo counts only where no other photo measures that pixel (an
    uncensored code there): the hinge of a bound is biased by the render's Monte Carlo noise
    (``E max(t − Î, 0) > max(t − E Î, 0)``: a noisy render is pushed above the bound), and a
    pixel that a darker (brighter) photo of the bracket measures needs no bound. ``view_of``
    ``(N,)`` (several views): the view of each photo; a pixel is then "measured" only by the
    photos of its own view (pixel ``(i, j)`` of another view is another point of the scene).
    ``chroma_block`` (``(rows, columns)``, None: off; ``loss.jpeg_chroma``): JPEG photos whose
    chroma the codec subsampled — at each pixel whose channels are all measured the render
    is compared as the codec would return it (:func:`chroma_subsampled`: luma per pixel,
    chroma averaged over the block's measured pixels and upsampled as the decoder does, in
    linear values); censored channels keep their hinge."""
    single = codes.ndim == 3
    if single:
        codes = codes[None]
        mask = None if mask is None else mask[None]
    c = int(round(code_max))
    nch = codes.shape[-1]
    q = jnp.clip(codes, 0, c).astype(jnp.int32)
    table = jnp.broadcast_to(table, (table.shape[0], nch))
    gain = jnp.broadcast_to(jnp.asarray(gain, img.dtype), (codes.shape[0], nch))
    if clip_code is not None:
        k = jnp.clip(jnp.asarray(clip_code, jnp.int32), 2, c)
        g_k = jnp.where(k >= c, table[c], 0.5 * (table[k - 1] + table[jnp.minimum(k, c - 1)]))
        table = table.at[c].set(g_k)
        q = jnp.where(q >= k, c, q)
    t = jnp.exp(table[q, jnp.arange(nch)]) / gain[:, None, None, :]
    e = jnp.where(q >= c, jnp.maximum(t - img, 0.0),
                  jnp.where(q <= 0, jnp.maximum(img - t, 0.0), img - t))
    if unmeasured_only is not None:
        censored = (q >= c) | (q <= 0)
        if view_of is None:
            measured = jnp.sum(~censored, axis=0, keepdims=True) > 0
        else:  # only the photos of the same view measure a pixel
            vo = jnp.asarray(view_of)
            same = (vo[:, None] == vo[None, :]).astype(img.dtype)
            measured = jnp.einsum("jk,khwc->jhwc", same, (~censored).astype(img.dtype)) > 0
        drop = censored & measured & (jnp.asarray(unmeasured_only) > 0)
        e = jnp.where(drop, 0.0, e)
    if chroma_block is not None and nch == 3:  # the render as the codec returns it
        full = ~jnp.any((q >= c) | (q <= 0), axis=-1, keepdims=True)
        weight = full.astype(img.dtype) * (1.0 if mask is None else mask)
        g = gain[:, None, None, :]  # the codec sees the exposed (white-balanced) values
        im = jnp.broadcast_to(img, e.shape) * g
        e = jnp.where(full, e + (chroma_subsampled(im, weight, chroma_block) - im) / g, e)
    axes = (1, 2, 3)
    scale = jax.lax.stop_gradient(_masked_mean(t, mask, axes)) + 1e-6
    terms = _masked_mean(e * e, mask, axes) / (scale * scale)
    return terms if per_photo else jnp.sum(terms)


def code_space_loss(img, codes, table, gain, code_max, mask=None, *, per_photo: bool = False):
    """:func:`jaxgfx.optim.censored_l2_loss` on display values, summed over photos: the
    render through each photo's camera, ``v = f(gain · img)`` (the level table inverted by
    interpolation in ``ln x``), against the codes. Biased for low-spp renders (module doc of
    :mod:`jaxgfx.pipelines.fit`); ``camera.space: code``. ``img`` ``(H, W, C)``, or
    ``(N, H, W, C)``: each photo's own render (several views); ``per_photo``: the terms
    ``(N,)``."""
    from jaxgfx.optim import censored_l2_loss

    from .camera import code_levels

    if codes.ndim == 3:
        codes = codes[None]
        mask = None if mask is None else mask[None]
    bits = {256: 8, 65536: 16}[table.shape[0]]
    zl = jnp.asarray(code_levels(bits), img.dtype) / code_max
    nch = codes.shape[-1]
    table = jnp.broadcast_to(table, (table.shape[0], nch))
    gain = jnp.broadcast_to(jnp.asarray(gain, img.dtype), (codes.shape[0], nch))
    terms = []
    for j in range(codes.shape[0]):
        lx = jnp.log(jnp.maximum(gain[j] * (img[j] if img.ndim == 4 else img), 1e-30))
        v = jnp.stack(
            [jnp.interp(lx[..., k], table[:, k], zl) for k in range(nch)], axis=-1
        )
        terms.append(censored_l2_loss(
            v, codes[j], code_max=code_max, mask=None if mask is None else mask[j]
        ))
    terms = jnp.stack(terms)
    return terms if per_photo else jnp.sum(terms)


def photo_gains(cam_p, cam_args, nch: int, white_balance: bool = True):
    """``(N, C)`` gain of each photo: exposure × its relative exposure × white balance (the
    frozen entries without gradient; ``white_balance`` False: without it — a colour matrix
    carries it, :func:`~jaxgfx.pipelines.fit.camera.photo_matrix`)."""
    free = cam_args["free"]
    e = freeze(cam_p["exposure"], free["exposure"])
    r = freeze(cam_p["photo_exposure"], free["photo_exposure"])
    if not white_balance:
        return e * r[:, None] * jnp.ones((1, nch), r.dtype)
    wb = freeze(cam_p["white_balance"], free["white_balance"])
    wb = wb[:nch] if nch == 3 else jnp.ones((1,), wb.dtype)
    return e * r[:, None] * wb[None, :]


def texture_prior(x, kind: str):
    """Smoothness of a texel grid ``x`` ``(H, W, C)``: ``"tv"`` the mean Charbonnier total
    variation ``√(∂x² + ∂y² + ε²) − ε`` (ε = 1e-3), ``"laplacian"`` the mean squared
    5-point Laplacian over the interior texels (``H, W >= 3``; a linear ramp costs 0)."""
    if kind == "tv":
        dx = jnp.diff(x, axis=1)[:-1]
        dy = jnp.diff(x, axis=0)[:, :-1]
        eps = 1e-3
        return jnp.mean(jnp.sqrt(dx * dx + dy * dy + eps * eps) - eps)
    lap = x[:-2, 1:-1] + x[2:, 1:-1] + x[1:-1, :-2] + x[1:-1, 2:] - 4.0 * x[1:-1, 1:-1]
    return jnp.mean(lap * lap)


def curve_smoothness(cam_p):
    """Mean squared second difference of the free-form curve's ``ln x`` knots (its
    smoothness prior; the curve is monotone by construction)."""
    from .camera import free_response

    g = free_response(cam_p["curve"]).params
    d2 = g[2:] - 2.0 * g[1:-1] + g[:-2]
    return jnp.mean(d2 * d2)


def curve_start_prior(cam_p, prior):
    """``mean_k Σ_c w_kc (ln x_kc − g0_kc)²``: the free-form curve's distance from its start
    ``prior["g0"]`` ``(K, C)``, weighted per knot by ``prior["w"]`` (``camera.response.
    start_prior``: heavier where the photos hold few pixels)."""
    from .camera import free_response

    g = free_response(cam_p["curve"]).params
    return jnp.mean(jnp.sum(prior["w"] * (g - prior["g0"]) ** 2, axis=-1))


VIEW_BATCHING = ("vmap", "loop")
"""How the fit step renders several views: ``vmap`` (one batched render over the stacked
cameras, one trace) or ``loop`` (one render per view in a Python loop: the render is traced
once per view). docs/inverse.md, "Several views", has the measured compile and step times."""

VIEW_BATCH = "vmap"  # the default (the measured faster one to compile, docs/inverse.md)


def render_views(scene, cameras, key, render_fn, batching: str = VIEW_BATCH):
    """``(V, H, W, C)``: ``render_fn(scene with camera v, key_v)`` for each camera of the
    stacked camera pytree ``cameras`` (leaves with a leading axis ``V``), with independent
    keys ``jax.random.split(key, V)``."""
    import equinox as eqx

    n = jax.tree.leaves(cameras)[0].shape[0]
    keys = jax.random.split(key, n)

    def one(cam, k):
        return render_fn(eqx.tree_at(lambda sc: sc.camera, scene, cam), k)

    if batching == "vmap":
        return jax.vmap(one)(cameras, keys)
    return jnp.stack([
        one(jax.tree.map(lambda x, v=v: x[v], cameras), keys[v]) for v in range(n)
    ])


def stack_cameras(cameras):
    """The cameras of several views (one class, one size) as one pytree with a leading view
    axis."""
    return jax.tree.map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *cameras)


def photo_losses(cfg: FitConfig, ldr: bool, img, target, p_camera, cam_args, table,
                 masked: bool = False):
    """Each photo's loss term ``(N,)``: ``img`` the render ``(H, W, C)`` (one view) or each
    photo's render ``(N, H, W, C)``, ``target`` the pixels ``(N, H, W, C)`` (or ``(pixels,
    mask)`` when ``masked``); LDR photos through the camera (``p_camera``, ``cam_args``, level
    ``table``), radiance targets by ``cfg.loss``. The fit minimises their sum (plus priors)."""
    from jaxgfx.optim import image_loss

    pixels, mask = target if masked else (target, None)
    if not ldr:
        if pixels.ndim == 3:
            return image_loss(img, pixels, kind=cfg.loss.kind, space=cfg.loss.space,
                              mask=mask)[None]
        return jnp.stack([
            image_loss(img[j] if img.ndim == 4 else img, pixels[j], kind=cfg.loss.kind,
                       space=cfg.loss.space, mask=None if mask is None else mask[j])
            for j in range(pixels.shape[0])
        ])
    bits = cfg.camera.bits
    code_max = float(2**bits - 1)
    if cfg.camera.has_matrix:
        img = img @ photo_matrix(p_camera, cam_args).T.astype(img.dtype)
        gain = photo_gains(p_camera, cam_args, img.shape[-1], white_balance=False)
    else:
        gain = photo_gains(p_camera, cam_args, img.shape[-1])
    if cfg.camera.space == "code":
        return code_space_loss(img, pixels, table, gain, code_max, mask, per_photo=True)
    from .config import JPEG_CHROMA

    return censored_linear_loss(img, pixels, table, gain, code_max, mask,
                                cam_args.get("clip_code"), cam_args.get("unmeasured"),
                                per_photo=True, view_of=cam_args.get("view_of"),
                                chroma_block=JPEG_CHROMA[cfg.loss.jpeg_chroma])


def make_loss(
    cfg: FitConfig, paths, ldr: bool, grey: bool = False, masked: bool = False, priors=(),
    scaled=(), views: bool = False, batching: str | None = None,
):
    """The fit's loss ``loss(params, key, (scene, target, camera_args))`` for
    :func:`jaxgfx.optim.fit`.

    ``params = {"scene": {path: value}, "camera": {...}}``; for LDR targets ``params
    ["camera"]`` holds ``exposure`` (scalar), ``photo_exposure`` ``(N,)`` (relative
    exposures), ``white_balance`` ``(3,)``, ``gamma`` and ``curve`` (the free-form curve's
    parameters), and ``camera_args`` ``{"weights": one-hot over CURVE_KINDS, "fixed": the fixed
    curve's level table, "free": {name: mask}, "smoothness": weight}`` — arrays, so every
    camera variant of a scene shares one compiled program (a frozen parameter has a zero
    gradient and Adam leaves it unchanged). ``target`` is ``(pixels, mask)`` when ``masked``,
    else the pixels (``(N, H, W, C)`` codes of ``N`` photos of one view for LDR targets: one
    render serves them all). ``priors``: ``((path, kind), ...)`` texel-grid priors whose
    weights are ``camera_args["priors"][path][kind]`` (arrays); ``scaled``: ``((path, (k,
    Interval)), ...)`` parameters with their own learning rate (``k`` times the optimiser's),
    fitted as ``v`` with ``x = Interval.forward(k · v)``. ``grey`` compares the render's
    luminance. ``views``: several views — ``camera_args["views"]`` the stacked cameras
    (:func:`stack_cameras`, ``V`` views) and ``camera_args["view_of"]`` ``(N,)`` the view of
    each photo: each view is rendered once per image (``batching``: :data:`VIEW_BATCHING`,
    None: :data:`VIEW_BATCH`) and the photos' terms are summed."""
    from jaxgfx.optim import decorrelated_loss
    from jaxgfx.render import render

    r = cfg.render
    bits = cfg.camera.bits if cfg.camera else 8
    tone_op = cfg.camera.tone_op if cfg.camera else None
    paths = tuple(paths)
    scaled = dict(scaled)
    batching = VIEW_BATCH if batching is None else batching

    def scene_values(p):
        """The scene parameters: a parameter with its own learning rate is fitted as ``v``
        with ``x = bounds.forward(k · v)`` (Adam's steps in ``v`` are ``k``× larger in the
        bijection's space: a per-parameter learning rate ``k · lr``)."""
        vals = dict(p["scene"])
        for path, (k, interval) in scaled.items():
            vals[path] = interval.forward(k * vals[path])
        return vals

    def image(scene, p, key, spp, cam_args):
        s = build_scene(scene, paths, scene_values(p))

        def one(sc, k):
            img = render(sc, k, spp=spp, integrator=r.integrator_spec, max_depth=r.max_depth)
            return to_target_channels(img, grey)

        if not views:
            return one(s, key)
        imgs = render_views(s, cam_args["views"], key, one, batching)
        return imgs[cam_args["view_of"]]  # each photo's view

    def per_image_loss(img, target, p, cam_args, table):
        return jnp.sum(photo_losses(cfg, ldr, img, target, p["camera"], cam_args, table,
                                    masked))

    def loss(p, key, args):
        scene, target, cam_args = args
        if ldr and "curve_lr" in cam_args:  # camera.response.lr: the curve fitted as u / k
            u = cam_args["curve_lr"] * p["camera"]["curve"]
            p = {**p, "camera": {**p["camera"], "curve": u}}
        table = fit_level_table(p["camera"], cam_args, bits, tone_op) if ldr else None
        if r.estimator == "correlated":
            value = per_image_loss(image(scene, p, key, r.spp, cam_args), target, p, cam_args,
                                   table)
        else:
            value = decorrelated_loss(
                lambda k: image(scene, p, k, r.spp // 2, cam_args),
                lambda im: per_image_loss(im, target, p, cam_args, table),
                key,
            )
        vals = scene_values(p) if priors else None
        for path, prior in priors:
            value = value + cam_args["priors"][path][prior] * texture_prior(vals[path], prior)
        if ldr:
            value = value + cam_args["smoothness"] * curve_smoothness(p["camera"])
            if "curve_prior" in cam_args:  # camera.response.start_prior (absent: no term)
                value = value + curve_start_prior(p["camera"], cam_args["curve_prior"])
        return value

    return loss


_LOSS_CACHE: dict = {}


def cached_loss(
    cfg: FitConfig, paths, ldr: bool, grey: bool = False, masked: bool = False, priors=(),
    scaled=(), views: bool = False, batching: str | None = None,
):
    """One loss object (hence one compiled fit step) per render / loss configuration and
    parameter set; camera choices and prior weights are arguments, not part of the
    program."""
    cam = ((cfg.camera.bits, cfg.camera.space, cfg.camera.has_matrix, cfg.camera.tone_op)
           if cfg.camera else None)
    batching = VIEW_BATCH if batching is None else batching
    key = (cfg.render, cfg.loss, cam, tuple(paths), ldr, grey, masked, tuple(priors),
           tuple(scaled), views, batching if views else None)
    if key not in _LOSS_CACHE:
        _LOSS_CACHE[key] = make_loss(cfg, paths, ldr, grey, masked, priors, scaled, views,
                                     batching)
    return _LOSS_CACHE[key]
