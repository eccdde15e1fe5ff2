"""Inverse rendering from a config: fit scene parameters (and an unknown camera) to a target.

The package is the job's stages: ``config`` (the frozen, self-validating dataclasses),
``targets`` (scene, parameters and target, checked before rendering), ``camera`` (the
:class:`jaxgfx.hdr.Camera` between render and photo), ``loss``, ``report`` (result.json,
plots, previews) and ``job`` (``run_fit``: check → target → fit → check → report).

``run_fit(FitJob.load(cfg, out_dir))`` loads the initial scene, the target (a linear
EXR/HDR, an 8-bit PNG/JPEG "photo", or a synthetic target rendered here at known parameter
values), checks every parameter path, size and bound *before* rendering, fits with
:func:`jaxgfx.optim.fit` and writes::

    result.json   fitted params {path: value}, camera, loss per step, seconds, truth and errors,
                  the parameter history per step (parameters of <= 16 values)
    curves.png    loss and each parameter against steps and against seconds
    before.png    the initial scene (through the fitted camera for LDR targets), every view
    after.png     the fitted scene
    target.png    the target

Config (YAML, see configs/inverse_material.yaml and docs/inverse.md)::

    scene: configs/scenes/inverse.yaml     # any parameter path of Scene.replace
    target: path/to/target.exr             # or target.png, or {synthetic: {...}} (below), or
                                           # a list of photos [{file, exposure, view}, ...]
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

Several views (docs/inverse.md, "Several views"): each entry of a ``target`` list may carry
its own pose, ``{file: photos/left.png, exposure: 0.01, view: {origin: [...], target: [...],
up: [...], fov: 40}}`` in the scene file's ``camera`` keys (the size stays the scene
camera's); a synthetic target takes ``views: [{}, {origin: [...]}, ...]`` (every view at every
exposure of ``target.camera``). Photos of one pose share one render; the distinct views'
cameras are stacked and rendered by ``jax.vmap`` inside the one jitted step, and the photos'
losses are summed (the scene's lights and materials and the photo camera are shared).
``result.json`` then lists each view's loss before and after (``views``), and the previews
show the views side by side.

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
``∇ Var(I)``); ``correlated`` uses one image for both. ``render.adjoint``: ``ad`` (default),
``replay`` (path replay backpropagation) or ``auto`` (replay where every fitted parameter is
one replay covers, :func:`~jaxgfx.pipelines.fit.job.choose_adjoint`; ``result.json``'s
``"adjoint"`` records the choice).
"""

from __future__ import annotations

from jaxgfx._jaxcache import enable_compilation_cache as enable_compilation_cache

from .camera import RESPONSE_MODELS as RESPONSE_MODELS
from .camera import apply_camera as apply_camera
from .camera import camera_to_linear as camera_to_linear
from .camera import fit_camera as fit_camera
from .camera import free_response as free_response
from .camera import level_table as level_table
from .config import CameraConfig as CameraConfig
from .config import ExposureSpec as ExposureSpec
from .config import FitConfig as FitConfig
from .config import FitParam as FitParam
from .config import LossConfig as LossConfig
from .config import OptimizerConfig as OptimizerConfig
from .config import RenderConfig as RenderConfig
from .config import ResponseSpec as ResponseSpec
from .config import WhiteBalanceSpec as WhiteBalanceSpec
from .job import FitJob as FitJob
from .job import fitted_camera as fitted_camera
from .job import run_fit as run_fit
from .loss import make_loss as make_loss
from .report import OUTPUT_NAMES as OUTPUT_NAMES
from .targets import Prepared as Prepared
from .targets import Target as Target
from .targets import build_scene as build_scene
from .targets import prepare_fit as prepare_fit

__all__ = [
    "FitJob",
    "FitConfig",
    "FitParam",
    "CameraConfig",
    "ResponseSpec",
    "ExposureSpec",
    "WhiteBalanceSpec",
    "OptimizerConfig",
    "RenderConfig",
    "LossConfig",
    "RESPONSE_MODELS",
    "OUTPUT_NAMES",
    "Prepared",
    "Target",
    "apply_camera",
    "camera_to_linear",
    "fit_camera",
    "fitted_camera",
    "free_response",
    "level_table",
    "build_scene",
    "make_loss",
    "prepare_fit",
    "run_fit",
    "enable_compilation_cache",
]
