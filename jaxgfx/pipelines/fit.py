"""Inverse rendering from a config: fit scene parameters (and an unknown camera) to a target.

``run_fit(cfg, out_dir)`` loads the initial scene, the target (a linear EXR/HDR, an 8-bit
PNG/JPEG "photo", or a synthetic target rendered here at known parameter values), checks every
parameter path, size and bound *before* rendering, fits with :func:`jaxgfx.optim.fit` and
writes::

    result.json   fitted params {path: value}, camera, loss per step, seconds, truth and errors,
                  the parameter history per step (parameters of <= 16 values)
    curves.png    loss and each parameter against steps and against seconds
    before.png    the initial scene (through the fitted camera for LDR targets)
    after.png     the fitted scene
    target.png    the target

Config (YAML, see configs/inverse_material.yaml and docs/inverse.md)::

    scene: configs/scenes/inverse.yaml     # any parameter path of Scene.replace
    target: path/to/target.exr             # or target.png, or {synthetic: {...}} (below)
    params:
      materials.metal.alpha: {init: 0.5, min: 0.001, max: 1.0}
      materials.clay.reflectance: {init: [0.5, 0.5, 0.5], min: 0.0, max: 1.0}
    camera:                                # LDR targets only: the unknown camera
      response: {model: gamma, fit: true, init: 2.2}   # gamma | srgb | linear | s-curve | ...
      exposure: {init: 1.0, fit: true}
    optimizer: {name: adam, lr: 0.02, steps: 200}
    render: {spp: 16, max_depth: 2, integrator: direct}
    loss: {kind: l2, space: linear}

A synthetic target: ``target: {synthetic: {materials.metal.alpha: 0.15}, spp: 256, seed: 7,
camera: {response: gamma, gamma: 1.8, exposure: 1.5, bits: 8}}`` renders the scene with those
values (and, with ``camera``, makes an 8-bit photo through that camera: exposure, response,
clipping, quantisation); ``result.json`` then reports the parameter errors.

The camera model for LDR targets: ``v = response(exposure · L)`` with a
:class:`jaxgfx.hdr.CameraResponse` (anchor ``"unit"``, so ``response(1) = 1``: ``gamma`` is
``v = x^(1/γ)``, ``srgb`` the sRGB OETF). ``camera.space: linear`` (default) linearises the
8-bit codes through the current camera and compares radiance (censored at the clip levels:
clipped highlights only bound the prediction); ``camera.space: code`` compares display values
with :func:`jaxgfx.optim.censored_l2_loss`, which is biased for low-spp renders (the response
is curved: ``E f(Î) ≠ f(E Î)``). The render, the camera and the loss are one jitted program.

Monte Carlo gradients: ``render.estimator: independent`` (default) renders two half-spp images
with independent keys and takes the primal from one and the adjoint from the other, so the
gradient of a squared error is unbiased (with one image, ``E[∇(I - T)²]`` gains
``∇ Var(I)``); ``correlated`` uses one image for both.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from typing import Any

import numpy as np

from jaxgfx._jaxcache import enable_compilation_cache
from jaxgfx.config import config_to_dict, load_config, read_yaml

__all__ = [
    "FitJob",
    "FitConfig",
    "ParamSpec",
    "CameraConfig",
    "OptimizerConfig",
    "RenderConfig",
    "LossConfig",
    "RESPONSE_MODELS",
    "apply_camera",
    "camera_to_linear",
    "prepare_fit",
    "run_fit",
    "enable_compilation_cache",
]

RESPONSE_MODELS = ("gamma", "srgb", "linear", "s-curve", "filmic", "log")
"""Camera response models for LDR targets (``gamma`` has a fitted exponent; the others are the
fixed analytic curves of :meth:`jaxgfx.hdr.CameraResponse.analytic`)."""

LDR_TARGET_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
HDR_TARGET_EXTENSIONS = (".exr", ".hdr", ".pic", ".rgbe", ".npy")


@dataclasses.dataclass(frozen=True)
class ParamSpec:
    """One fitted parameter: ``init`` (None: the scene's value), bounds ``min``/``max``."""

    init: float | tuple[float, ...] | None = None
    min: float | None = None
    max: float | None = None


@dataclasses.dataclass(frozen=True)
class ResponseSpec:
    model: str = "srgb"
    fit: bool = False
    init: float = 2.2  # gamma exponent (model "gamma")
    min: float = 0.2
    max: float = 6.0

    def validate(self):
        if self.model not in RESPONSE_MODELS:
            raise ValueError(
                f"camera.response.model: expected one of {RESPONSE_MODELS}, got {self.model!r}"
            )
        if self.fit and self.model != "gamma":
            raise ValueError(
                f"camera.response.fit: only the 'gamma' model has parameters, got {self.model!r}"
            )
        if not self.min < self.init < self.max:
            raise ValueError(
                f"camera.response: init {self.init} outside the bounds ({self.min}, {self.max})"
            )


@dataclasses.dataclass(frozen=True)
class ExposureSpec:
    init: float = 1.0
    fit: bool = False
    min: float = 1e-3
    max: float = 1e3

    def validate(self):
        if not 0 < self.min < self.init < self.max:
            raise ValueError(
                f"camera.exposure: expected 0 < min < init < max, got init {self.init} and "
                f"bounds ({self.min}, {self.max})"
            )


@dataclasses.dataclass(frozen=True)
class CameraConfig:
    """The unknown camera between the rendered radiance and an LDR target."""

    response: ResponseSpec = ResponseSpec()
    exposure: ExposureSpec = ExposureSpec()
    bits: int = 8
    space: str = "linear"  # where the loss compares: linear (unbiased) | code (see module doc)

    def validate(self):
        if self.bits not in (8, 16):
            raise ValueError(f"camera.bits: expected 8 or 16, got {self.bits}")
        if self.space not in ("linear", "code"):
            raise ValueError(f"camera.space: expected 'linear' or 'code', got {self.space!r}")


@dataclasses.dataclass(frozen=True)
class OptimizerConfig:
    name: str = "adam"
    lr: float = 0.02
    steps: int = 200
    tol: float | None = None
    lr_final: float | None = None  # exponential decay from lr to lr_final over the steps

    def validate(self):
        if not self.lr > 0 or (self.lr_final is not None and not self.lr_final > 0):
            raise ValueError("optimizer.lr / lr_final: expected positive numbers")
        if self.steps < 1:
            raise ValueError(f"optimizer.steps: expected >= 1, got {self.steps}")

    def schedule(self):
        """The learning rate: a number, or ``k -> lr · (lr_final / lr)^(k / (steps - 1))``."""
        if self.lr_final is None:
            return self.lr
        lr, ratio, n = self.lr, self.lr_final / self.lr, max(self.steps - 1, 1)
        return lambda k: lr * ratio ** (min(k, n) / n)


@dataclasses.dataclass(frozen=True)
class RenderConfig:
    spp: int = 16
    max_depth: int = 2
    integrator: str = "direct"
    width: int | None = None  # overrides the scene camera's resolution
    height: int | None = None
    estimator: str = "independent"  # independent | correlated (see module doc)

    def validate(self):
        if self.estimator not in ("independent", "correlated"):
            raise ValueError(
                f"render.estimator: expected 'independent' or 'correlated', got {self.estimator!r}"
            )
        if self.spp < 1 or (self.estimator == "independent" and self.spp < 2):
            raise ValueError(f"render.spp: expected >= 2 (two half-spp images), got {self.spp}")


@dataclasses.dataclass(frozen=True)
class LossConfig:
    kind: str = "l2"  # l2 | relative_l2 | l1 (linear targets); LDR targets use censored L2
    space: str = "linear"  # linear | log | lab


@dataclasses.dataclass(frozen=True)
class FitConfig:
    scene: str
    target: Any  # path, or {synthetic: {path: value}, spp, seed, camera}
    params: dict
    camera: CameraConfig | None = None
    optimizer: OptimizerConfig = OptimizerConfig()
    render: RenderConfig = RenderConfig()
    loss: LossConfig = LossConfig()
    seed: int = 0
    progress: bool = True

    def validate(self):
        if not isinstance(self.params, dict) or not self.params:
            raise ValueError("params: expected a mapping {parameter path: {init, min, max}}")
        if not isinstance(self.target, (str, dict)):
            raise ValueError("target: expected a file path or {synthetic: {...}}")


# -------------------------------------------------------------------------------------------
# the camera model


def apply_camera(radiance, exposure, gamma, *, model: str):
    """Continuous display value ``v = response(exposure · radiance)`` (not clipped, not
    quantised). ``model``: a name in :data:`RESPONSE_MODELS`; ``gamma`` is used by ``"gamma"``
    only (``v = x^(1/γ)``). Example: ``apply_camera(0.25, 1.0, 2.0, model="gamma")`` → 0.5."""
    import jax.numpy as jnp

    from jaxgfx.hdr import CameraResponse

    x = exposure * jnp.asarray(radiance)
    if model == "linear":
        return x
    if model == "gamma":
        resp = CameraResponse.gamma(jnp.reshape(gamma, (1,)), anchor="unit")
    else:
        resp = CameraResponse.analytic(model, anchor="unit")
    return resp.from_linear_normalized(x)


def _quantise(v, bits):
    c = 2**bits - 1
    return np.round(np.clip(np.asarray(v, np.float64), 0.0, 1.0) * c)


# -------------------------------------------------------------------------------------------
# preparation: everything checked before rendering


@dataclasses.dataclass
class _Prepared:
    scene: Any
    paths: list
    init: dict
    bounds: dict
    truth: dict | None
    target_spec: Any
    ldr: bool


def _resolve(path: str, base: str | None) -> str:
    if os.path.exists(path) or base is None:
        return path
    alt = os.path.join(base, path)
    return alt if os.path.exists(alt) else path


def _load_scene(cfg: FitConfig, base: str | None):
    from jaxgfx.render import load_scene

    spath = _resolve(cfg.scene, base)
    desc = read_yaml(spath)
    if cfg.render.width is not None or cfg.render.height is not None:
        cam = dict(desc.get("camera", {}))
        if cfg.render.width is not None:
            cam["width"] = cfg.render.width
        if cfg.render.height is not None:
            cam["height"] = cfg.render.height
        desc["camera"] = cam
    return load_scene(desc, base_dir=os.path.dirname(os.path.abspath(spath)))


def _param_spec(path, raw) -> ParamSpec:
    if isinstance(raw, ParamSpec):
        return raw
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ValueError(f"params.{path}: expected a mapping with init/min/max, got {raw!r}")
    return load_config(ParamSpec, raw)


def _check_value(path, scene_value, value, what):
    v = np.asarray(value, np.float64)
    try:
        np.broadcast_to(v, scene_value.shape)
    except ValueError:
        raise ValueError(
            f"params.{path}.{what}: shape {v.shape} does not fit the parameter's shape "
            f"{tuple(scene_value.shape)}"
        ) from None
    if not np.all(np.isfinite(v)):
        raise ValueError(f"params.{path}.{what}: expected finite numbers, got {value!r}")
    return v


def _target_dims(spec, base):
    """(height, width, is_ldr) of a target file without decoding more than needed."""
    path = _resolve(spec, base)
    if not os.path.exists(path):
        raise FileNotFoundError(f"target: file not found: {spec}")
    ext = os.path.splitext(path)[1].lower()
    if ext in LDR_TARGET_EXTENSIONS:
        from PIL import Image

        with Image.open(path) as im:
            return im.height, im.width, True, path
    if ext == ".exr":
        from jaxgfx.io import read_exr_header

        h = read_exr_header(path)
        if "height" in h and "width" in h:
            return int(h["height"]), int(h["width"]), False, path
    if ext in HDR_TARGET_EXTENSIONS:
        from jaxgfx.io import read_any

        arr = np.load(path) if ext == ".npy" else read_any(path)
        return arr.shape[0], arr.shape[1], False, path
    raise ValueError(
        f"target: unsupported file type {ext!r}; expected one of "
        f"{LDR_TARGET_EXTENSIONS + HDR_TARGET_EXTENSIONS}"
    )


def prepare_fit(cfg: FitConfig, *, base_dir: str | None = None) -> _Prepared:
    """Load the scene and check parameters, bounds, the target's size and kind (no rendering).

    Raises ``ValueError`` naming the offending config entry: an unknown parameter path, an init
    or bound of the wrong shape, bounds that exclude the init, a target whose size differs from
    the camera's, an LDR target without ``camera`` (or a linear one with it).
    """
    scene = _load_scene(cfg, base_dir)
    paths, init, bounds = [], {}, {}
    for path, raw in cfg.params.items():
        spec = _param_spec(path, raw)
        try:
            current = scene.get(path)
        except (ValueError, IndexError, AttributeError) as e:
            raise ValueError(f"params.{path}: unknown parameter path ({e})") from None
        x0 = np.asarray(current, np.float64) if spec.init is None else spec.init
        x0 = np.broadcast_to(_check_value(path, current, x0, "init"), current.shape)
        lo = None if spec.min is None else _check_value(path, current, spec.min, "min")
        hi = None if spec.max is None else _check_value(path, current, spec.max, "max")
        if lo is not None and hi is not None and not np.all(lo < hi):
            raise ValueError(f"params.{path}: expected min < max, got ({spec.min}, {spec.max})")
        if (lo is not None and np.any(x0 < lo)) or (hi is not None and np.any(x0 > hi)):
            raise ValueError(
                f"params.{path}: the bounds ({spec.min}, {spec.max}) exclude the init "
                f"{np.asarray(x0).tolist()}"
            )
        paths.append(path)
        init[path] = np.array(x0, np.float32)
        lo_b = None if lo is None else np.broadcast_to(lo, current.shape)
        hi_b = None if hi is None else np.broadcast_to(hi, current.shape)
        bounds[path] = (lo_b, hi_b)

    h, w = scene.height, scene.width
    truth = None
    if isinstance(cfg.target, dict):
        t = dict(cfg.target)
        unknown = set(t) - {"synthetic", "spp", "seed", "camera"}
        if unknown or "synthetic" not in t:
            raise ValueError(
                "target: expected a file path or {synthetic: {path: value}, spp, seed, camera}"
                + (f"; unknown keys {sorted(unknown)}" if unknown else "")
            )
        truth = {}
        for path, value in (t["synthetic"] or {}).items():
            try:
                current = scene.get(path)
            except (ValueError, IndexError, AttributeError) as e:
                raise ValueError(f"target.synthetic.{path}: unknown parameter path ({e})") from None
            truth[path] = np.broadcast_to(
                _check_value(path, current, value, "synthetic value"), current.shape
            ).astype(np.float32)
        ldr = t.get("camera") is not None
        if ldr:
            cam = dict(t["camera"])
            bad = set(cam) - {"response", "gamma", "exposure", "bits"}
            if bad:
                raise ValueError(f"target.camera: unknown keys {sorted(bad)}")
            if cam.get("response", "gamma") not in RESPONSE_MODELS:
                raise ValueError(
                    f"target.camera.response: expected one of {RESPONSE_MODELS}, got "
                    f"{cam.get('response')!r}"
                )
        target_spec = t
    else:
        th, tw, ldr, path = _target_dims(cfg.target, base_dir)
        if (th, tw) != (h, w):
            raise ValueError(
                f"target: size {tw}x{th} (W x H) differs from the scene camera's {w}x{h}; "
                "set render.width/height or resize the target"
            )
        target_spec = path
    if ldr and not isinstance(cfg.target, dict) and cfg.camera is not None and cfg.camera.bits != 8:
        raise ValueError("camera.bits: LDR target files are read as 8-bit codes; expected 8")
    if ldr and cfg.camera is None:
        raise ValueError("camera: an LDR (8-bit) target needs a camera section (response model)")
    if not ldr and cfg.camera is not None:
        raise ValueError("camera: only LDR targets (PNG/JPEG or a synthetic camera) use a camera")
    return _Prepared(scene, paths, init, bounds, truth, target_spec, ldr)


# -------------------------------------------------------------------------------------------
# the loss: render → (camera) → loss, one jitted program per configuration


def _build_scene(scene, paths, scene_params):
    for path in paths:
        scene = scene.replace(path, scene_params[path])
    return scene


def _camera_blend(img, exposure, gamma, weights):
    """``Σ_m weights[m] · apply_camera(img, exposure, gamma, model=m)`` over
    :data:`RESPONSE_MODELS` (a one-hot ``weights`` selects a model without recompiling)."""
    out = 0.0
    for i, m in enumerate(RESPONSE_MODELS):
        out = out + weights[i] * apply_camera(img, exposure, gamma, model=m)
    return out


def camera_to_linear(z, exposure, gamma, *, model: str):
    """Inverse of :func:`apply_camera`: linear radiance for display values ``z`` in [0, 1]."""
    import jax.numpy as jnp

    from jaxgfx.hdr import CameraResponse

    z = jnp.clip(jnp.asarray(z), 0.0, 1.0)
    if model == "linear":
        return z / exposure
    if model == "gamma":
        resp = CameraResponse.gamma(jnp.reshape(gamma, (1,)), anchor="unit")
    else:
        resp = CameraResponse.analytic(model, anchor="unit")
    return resp.to_linear_normalized(z) / exposure


def _censored_linear_loss(img, codes, exposure, gamma, weights, code_max):
    """Censored L2 in linear radiance: each code ``q`` is linearised through the current camera
    (``T = f⁻¹(q / c) / exposure``, a blend over :data:`RESPONSE_MODELS` by ``weights``) and
    compared with the *linear* render, so the loss is quadratic in the Monte Carlo image and its
    expectation is unbiased (in code space, ``E f(Î) ≠ f(E Î)`` for a curved response: a
    noisy render through a concave response is darker on average, and the camera parameters
    absorb that). Clipped codes bound the radiance from one side (``q = c``: ``Î ≥
    f⁻¹((c - ½)/c)/e``; ``q = 0``: ``Î ≤ f⁻¹(½/c)/e``). Normalised by the mean linearised
    target so that its scale does not drift with the exposure."""
    import jax
    import jax.numpy as jnp

    def inv(z):
        out = 0.0
        for i, m in enumerate(RESPONSE_MODELS):
            out = out + weights[i] * camera_to_linear(z, exposure, gamma, model=m)
        return out

    c = code_max
    t_mid = inv(codes / c)
    t_lo = inv((c - 0.5) / c)
    t_hi = inv(0.5 / c)
    e = jnp.where(
        codes >= c,
        jnp.maximum(t_lo - img, 0.0),
        jnp.where(codes <= 0, jnp.maximum(img - t_hi, 0.0), img - t_mid),
    )
    scale = jax.lax.stop_gradient(jnp.mean(t_mid)) + 1e-6
    return jnp.mean(e * e) / (scale * scale)


def _freeze(x, free):
    """``x`` with its gradient kept where ``free`` (1.0) and removed where 0.0."""
    import jax

    return free * x + (1.0 - free) * jax.lax.stop_gradient(x)


def make_loss(cfg: FitConfig, paths, ldr: bool):
    """The fit's loss ``loss(params, key, (scene, target, camera_args))`` for
    :func:`jaxgfx.optim.fit`.

    ``params = {"scene": {path: value}, "camera": {"exposure": e, "gamma": g}}``; for LDR
    targets ``camera_args = {"weights": one-hot over RESPONSE_MODELS, "free": [exposure free,
    gamma free]}`` (arrays, so that every camera variant of a scene shares one compiled
    program; a frozen camera parameter has a zero gradient and Adam leaves it unchanged)."""

    from jaxgfx.optim import censored_l2_loss, decorrelated_loss, image_loss
    from jaxgfx.render import render

    r = cfg.render
    code_max = float(2 ** (cfg.camera.bits if cfg.camera else 8) - 1)
    paths = tuple(paths)
    kind, space = cfg.loss.kind, cfg.loss.space
    code_space = cfg.camera is not None and cfg.camera.space == "code"

    def image(scene, p, key, spp):
        s = _build_scene(scene, paths, p["scene"])
        return render(s, key, spp=spp, integrator=r.integrator, max_depth=r.max_depth)

    def per_image_loss(img, target, p, cam_args):
        if not ldr:
            return image_loss(img, target, kind=kind, space=space)
        e = _freeze(p["camera"]["exposure"], cam_args["free"][0])
        g = _freeze(p["camera"]["gamma"], cam_args["free"][1])
        if code_space:
            v = _camera_blend(img, e, g, cam_args["weights"])
            return censored_l2_loss(v, target, code_max=code_max)
        return _censored_linear_loss(img, target, e, g, cam_args["weights"], code_max)

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


def _cached_loss(cfg, paths, ldr):
    """One loss object (hence one compiled fit step) per render / loss configuration and
    parameter set; camera choices are arguments, not part of the program."""
    cam = (cfg.camera.bits, cfg.camera.space) if cfg.camera else None
    key = (cfg.render, cfg.loss, cam, tuple(paths), ldr)
    if key not in _LOSS_CACHE:
        _LOSS_CACHE[key] = make_loss(cfg, paths, ldr)
    return _LOSS_CACHE[key]


# -------------------------------------------------------------------------------------------
# outputs


def _srgb8(img, scale=1.0):
    from jaxgfx.color import linear_to_srgb

    v = np.asarray(linear_to_srgb(np.clip(np.asarray(img, np.float32) * scale, 0.0, 1.0)))
    return np.round(np.clip(v, 0, 1) * 255).astype(np.uint8)


def _plain(x):
    a = np.asarray(x, np.float64)
    return float(a) if a.ndim == 0 else a.tolist()


def _plot_curves(path, res, names, truth):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = 1 + len(names)
    fig, axes = plt.subplots(n, 2, figsize=(9, 2.3 * n), squeeze=False)
    steps = np.arange(res.n_steps + 1)
    t = np.concatenate([[0.0], np.cumsum(res.seconds)])
    for col, (xs, xl) in enumerate(((steps, "step"), (t, "seconds (after compilation)"))):
        ax = axes[0, col]
        ax.semilogy(xs[:-1], np.maximum(res.loss, 1e-30), color="k", lw=1)
        ax.set_ylabel("loss")
        ax.grid(alpha=0.3)
        for row, (group, name) in enumerate(names, start=1):
            ax = axes[row, col]
            hist = np.asarray(res.history[group][name], np.float64).reshape(len(xs), -1)
            colors = ("tab:red", "tab:green", "tab:blue") if hist.shape[1] == 3 else [None] * 99
            for c in range(min(hist.shape[1], 12)):
                ax.plot(xs, hist[:, c], color=colors[c], lw=1.2)
                if truth is not None and name in truth:
                    tv = np.asarray(truth[name], np.float64).reshape(-1)
                    ax.axhline(tv[min(c, tv.size - 1)], color=colors[c] or "k", ls="--", lw=0.8)
            ax.set_ylabel(
                name.split(".")[-2] + "." + name.split(".")[-1] if "." in name else name, fontsize=8
            )
            ax.grid(alpha=0.3)
        axes[-1, col].set_xlabel(xl)
    fig.suptitle("fit: loss and parameters (dashed: truth)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# -------------------------------------------------------------------------------------------
# the job


OUTPUT_NAMES = ("result.json", "curves.png", "before.png", "after.png", "target.png")


@dataclasses.dataclass(frozen=True)
class FitJob:
    """A fit job: the config, the output folder (None: write nothing), ``overwrite`` and the
    folder relative config paths are also looked up in (``base_dir``, e.g. the config's)."""

    config: FitConfig
    out: str | None = "out/fit"
    overwrite: bool = False
    base_dir: str | None = None


def run_fit(
    cfg: FitJob | FitConfig | dict | str,
    out_dir: str | None = None,
    *,
    base_dir: str | None = None,
    overwrite: bool = False,
) -> dict:
    """Run the fit described by ``cfg`` (a :class:`FitJob`, or a :class:`FitConfig`, a mapping
    or a YAML path with ``out_dir``, ``base_dir``, ``overwrite``) and
    write the outputs (module doc) to ``out_dir`` (None: nothing written). Everything is checked
    before rendering (:func:`prepare_fit`); an ``out_dir`` that holds a previous run's results
    is refused unless ``overwrite`` (outputs are staged and moved into place only when the job
    succeeded, :mod:`jaxgfx.pipelines._output`). Relative paths in the config (scene, target)
    are looked up in the working directory, then in ``base_dir``. Returns the ``result.json``
    dictionary (plus ``"outputs"``: ``{name: path}`` when written)."""
    import contextlib

    from jaxgfx.pipelines._output import StagedDir

    if isinstance(cfg, FitJob):
        cfg, out_dir, overwrite, base_dir = cfg.config, cfg.out, cfg.overwrite, cfg.base_dir
    if isinstance(cfg, (str, os.PathLike)):
        base_dir = base_dir or os.path.dirname(os.path.abspath(cfg))
        cfg = load_config(FitConfig, cfg)
    elif not isinstance(cfg, FitConfig):
        cfg = load_config(FitConfig, cfg)
    stage = (
        StagedDir(out_dir, OUTPUT_NAMES, overwrite=overwrite)
        if out_dir is not None
        else contextlib.nullcontext()
    )
    prep = prepare_fit(cfg, base_dir=base_dir)
    with stage:
        out = _fit_and_write(cfg, prep, None if out_dir is None else stage.path)
    if out_dir is not None:
        out["outputs"] = {n: os.path.join(os.fspath(out_dir), n) for n in OUTPUT_NAMES}
    return out


def _fit_and_write(cfg: FitConfig, prep: _Prepared, out_dir: str | None) -> dict:
    import jax
    import jax.numpy as jnp

    from jaxgfx.optim import fit
    from jaxgfx.render import render

    cam = cfg.camera
    r = cfg.render
    key = jax.random.key(cfg.seed)
    k_target, k_fit, k_show = jax.random.split(key, 3)

    # the target
    t0 = time.perf_counter()
    target_linear = None
    if isinstance(prep.target_spec, dict):
        t = prep.target_spec
        tscene = _build_scene(prep.scene, list(prep.truth), prep.truth)
        tkey = jax.random.key(int(t.get("seed", 1)))
        target_linear = np.asarray(
            render(
                tscene,
                tkey,
                spp=int(t.get("spp", 256)),
                integrator=r.integrator,
                max_depth=r.max_depth,
            )
        )
        if prep.ldr:
            tc = t["camera"]
            v = apply_camera(
                target_linear,
                float(tc.get("exposure", 1.0)),
                float(tc.get("gamma", 2.2)),
                model=tc.get("response", "gamma"),
            )
            target = _quantise(v, int(tc.get("bits", 8))).astype(np.float32)
        else:
            target = target_linear
    else:
        from jaxgfx.io import read_any

        path = prep.target_spec
        if prep.ldr:
            from PIL import Image

            with Image.open(path) as im:
                arr = np.asarray(im.convert("RGB"))
            target = arr.astype(np.float32)  # 8-bit codes 0..255
        else:
            target = np.load(path) if path.endswith(".npy") else read_any(path)
            target = np.asarray(target, np.float32)[..., :3]
    target_seconds = time.perf_counter() - t0

    params = {"scene": {p: jnp.asarray(prep.init[p]) for p in prep.paths}, "camera": {}}
    bounds = {"scene": {p: prep.bounds[p] for p in prep.paths}, "camera": {}}
    cam_args = None
    if cam is not None:
        params["camera"] = {
            "exposure": jnp.asarray(cam.exposure.init, jnp.float32),
            "gamma": jnp.asarray(cam.response.init, jnp.float32),
        }
        bounds["camera"] = {
            "exposure": (cam.exposure.min, cam.exposure.max),
            "gamma": (cam.response.min, cam.response.max),
        }
        cam_args = {
            "weights": jnp.asarray(
                [float(m == cam.response.model) for m in RESPONSE_MODELS], jnp.float32
            ),
            "free": jnp.asarray([float(cam.exposure.fit), float(cam.response.fit)], jnp.float32),
        }
    fitted_camera = (
        []
        if cam is None
        else [n for n, f in (("exposure", cam.exposure.fit), ("gamma", cam.response.fit)) if f]
    )

    loss = _cached_loss(cfg, prep.paths, prep.ldr)
    o = cfg.optimizer
    res = fit(
        loss,
        params,
        optimizer=o.name,
        learning_rate=o.schedule(),
        steps=o.steps,
        key=k_fit,
        args=(prep.scene, jnp.asarray(target), cam_args),
        bounds=bounds,
        progress=cfg.progress,
        tol=o.tol,
    )

    fitted = {p: _plain(res.params["scene"][p]) for p in prep.paths}
    camera_out = None
    if cam is not None:
        camera_out = {
            "model": cam.response.model,
            "exposure": _plain(res.params["camera"]["exposure"]),
            "gamma": _plain(res.params["camera"]["gamma"])
            if cam.response.model == "gamma"
            else None,
            "fitted": fitted_camera,
        }
    out = {
        "params": fitted,
        "init": {p: _plain(prep.init[p]) for p in prep.paths},
        "camera": camera_out,
        "loss": [float(v) for v in res.loss],
        "seconds": float(np.sum(res.seconds)),
        "compile_seconds": float(res.compile_seconds),
        "seconds_per_step": float(np.median(res.seconds)),
        "target_seconds": float(target_seconds),
        "n_steps": int(res.n_steps),
        "stop_reason": res.stop_reason,
        "history": {
            p: np.asarray(res.history["scene"][p], np.float64).tolist()
            for p in prep.paths
            if np.size(prep.init[p]) <= 16
        },
        "seconds_history": [float(v) for v in res.seconds],
        "config": config_to_dict(cfg),
    }
    if prep.truth is not None:
        out["truth"] = {p: _plain(v) for p, v in prep.truth.items()}
        out["errors"] = {
            p: float(np.max(np.abs(np.asarray(fitted[p]) - prep.truth[p])))
            for p in prep.paths
            if p in prep.truth
        }
        if prep.ldr:
            tc = prep.target_spec["camera"]
            out["truth_camera"] = {
                "model": tc.get("response", "gamma"),
                "exposure": float(tc.get("exposure", 1.0)),
                "gamma": float(tc.get("gamma", 2.2)),
            }

    if out_dir is not None:
        from jaxgfx.io import write_png

        show_spp = max(r.spp, 64)

        def show(scene_params, cam_params):
            s = _build_scene(prep.scene, prep.paths, scene_params)
            img = np.asarray(
                render(s, k_show, spp=show_spp, integrator=r.integrator, max_depth=r.max_depth)
            )
            if cam is None:
                return img
            e = float(cam_params["exposure"])
            g = float(cam_params["gamma"])
            return _quantise(apply_camera(img, e, g, model=cam.response.model), 8) / 255.0

        before = show(params["scene"], params["camera"])
        after = show(res.params["scene"], res.params["camera"])
        if cam is None:
            scale = 1.0 / max(float(np.percentile(target, 99.5)), 1e-6)
            write_png(os.path.join(out_dir, "before.png"), _srgb8(before, scale))
            write_png(os.path.join(out_dir, "after.png"), _srgb8(after, scale))
            write_png(os.path.join(out_dir, "target.png"), _srgb8(target, scale))
        else:
            write_png(os.path.join(out_dir, "before.png"), before)
            write_png(os.path.join(out_dir, "after.png"), after)
            write_png(os.path.join(out_dir, "target.png"), target / (2**cam.bits - 1))
        names = [("scene", p) for p in prep.paths] + [("camera", c) for c in fitted_camera]
        truth_named = dict(prep.truth or {})
        if prep.ldr and prep.truth is not None:
            truth_named.update({k: out["truth_camera"][k] for k in ("exposure", "gamma")})
        _plot_curves(os.path.join(out_dir, "curves.png"), res, names, truth_named)
        with open(os.path.join(out_dir, "result.json"), "w", encoding="utf-8") as f:
            json.dump(out, f, indent=1)
    return out
