"""The fit's loss: render → (camera) → loss, one jitted program per render / loss
configuration and parameter set (camera choices are arrays, not part of the program)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgfx.color import LUMINANCE_WEIGHTS

from .camera import apply_camera, camera_blend, camera_to_linear, freeze
from .config import FitConfig
from .targets import build_scene

__all__ = ["make_loss", "cached_loss", "censored_linear_loss", "to_target_channels"]


def to_target_channels(img, grey: bool):
    """The render in the target's channels: RGB, or Rec. 709 luminance ``(..., 1)`` for a
    grey target."""
    if not grey:
        return img
    w = jnp.asarray(LUMINANCE_WEIGHTS["rec709"], img.dtype)
    return (img @ w)[..., None]


def _masked_mean(v, mask):
    if mask is None:
        return jnp.mean(v)
    m = jnp.broadcast_to(mask, v.shape)
    return jnp.sum(v * m) / jnp.sum(m)


def censored_linear_loss(img, codes, exposure, gamma, weights, code_max, mask=None):
    """Censored L2 in linear radiance: each code ``q`` is linearised through the current camera
    (``T = f⁻¹(q / c) / exposure``, a blend over the response models by ``weights``) and
    compared with the *linear* render, so the loss is quadratic in the Monte Carlo image and its
    expectation is unbiased (in code space, ``E f(Î) ≠ f(E Î)`` for a curved response: a
    noisy render through a concave response is darker on average, and the camera parameters
    absorb that). Clipped codes bound the radiance from one side (``q = c``: ``Î ≥
    f⁻¹((c - ½)/c)/e``; ``q = 0``: ``Î ≤ f⁻¹(½/c)/e``). Normalised by the mean linearised
    target so that its scale does not drift with the exposure. ``mask``: per-pixel weights
    (None: all pixels)."""

    def inv(z):
        return camera_blend(lambda m: camera_to_linear(z, exposure, gamma, model=m), weights)

    c = code_max
    t_mid = inv(codes / c)
    t_lo = inv((c - 0.5) / c)
    t_hi = inv(0.5 / c)
    e = jnp.where(
        codes >= c,
        jnp.maximum(t_lo - img, 0.0),
        jnp.where(codes <= 0, jnp.maximum(img - t_hi, 0.0), img - t_mid),
    )
    scale = jax.lax.stop_gradient(_masked_mean(t_mid, mask)) + 1e-6
    return _masked_mean(e * e, mask) / (scale * scale)


def make_loss(cfg: FitConfig, paths, ldr: bool, grey: bool = False, masked: bool = False):
    """The fit's loss ``loss(params, key, (scene, target, camera_args))`` for
    :func:`jaxgfx.optim.fit`.

    ``params = {"scene": {path: value}, "camera": {"exposure": e, "gamma": g}}``; for LDR
    targets ``camera_args = {"weights": one-hot over RESPONSE_MODELS, "free": [exposure free,
    gamma free]}`` (arrays, so that every camera variant of a scene shares one compiled
    program; a frozen camera parameter has a zero gradient and Adam leaves it unchanged).
    ``target`` is ``(pixels, mask)`` when ``masked``, else the pixels; ``grey`` compares the
    render's luminance."""
    from jaxgfx.optim import censored_l2_loss, decorrelated_loss, image_loss
    from jaxgfx.render import render

    r = cfg.render
    code_max = float(2 ** (cfg.camera.bits if cfg.camera else 8) - 1)
    paths = tuple(paths)
    kind, space = cfg.loss.kind, cfg.loss.space
    code_space = cfg.camera is not None and cfg.camera.space == "code"

    def image(scene, p, key, spp):
        s = build_scene(scene, paths, p["scene"])
        img = render(s, key, spp=spp, integrator=r.integrator, max_depth=r.max_depth)
        return to_target_channels(img, grey)

    def per_image_loss(img, target, p, cam_args):
        pixels, mask = target if masked else (target, None)
        if not ldr:
            return image_loss(img, pixels, kind=kind, space=space, mask=mask)
        e = freeze(p["camera"]["exposure"], cam_args["free"][0])
        g = freeze(p["camera"]["gamma"], cam_args["free"][1])
        if code_space:
            v = camera_blend(lambda m: apply_camera(img, e, g, model=m), cam_args["weights"])
            return censored_l2_loss(v, pixels, code_max=code_max, mask=mask)
        return censored_linear_loss(img, pixels, e, g, cam_args["weights"], code_max, mask)

    def loss(p, key, args):
        scene, target, cam_args = args
        if r.estimator == "correlated":
            return per_image_loss(image(scene, p, key, r.spp), target, p, cam_args)
        return decorrelated_loss(
            lambda k: image(scene, p, k, r.spp // 2),
            lambda im: per_image_loss(im, target, p, cam_args),
            key,
        )

    return loss


_LOSS_CACHE: dict = {}


def cached_loss(cfg: FitConfig, paths, ldr: bool, grey: bool = False, masked: bool = False):
    """One loss object (hence one compiled fit step) per render / loss configuration and
    parameter set; camera choices are arguments, not part of the program."""
    cam = (cfg.camera.bits, cfg.camera.space) if cfg.camera else None
    key = (cfg.render, cfg.loss, cam, tuple(paths), ldr, grey, masked)
    if key not in _LOSS_CACHE:
        _LOSS_CACHE[key] = make_loss(cfg, paths, ldr, grey, masked)
    return _LOSS_CACHE[key]
