"""The fit job: ``run_fit(FitJob)`` is check → target → fit → check the result → report."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time

import numpy as np

from jaxgfx.config import config_to_dict, load_config

from .camera import RESPONSE_MODELS, photo_camera
from .config import FitConfig
from .loss import cached_loss
from .report import OUTPUT_NAMES, plain, srgb8, write_outputs
from .targets import Prepared, Target, build_scene, prepare_fit

__all__ = ["FitJob", "run_fit"]


@dataclasses.dataclass(frozen=True)
class FitJob:
    """A fit job: the config, the output folder (None: write nothing), ``overwrite`` and the
    folder relative config paths are looked up in first (``base_dir``, e.g. the config's)."""

    config: FitConfig
    out: str | None = "out/fit"
    overwrite: bool = False
    base_dir: str | None = None

    def __post_init__(self):
        if not isinstance(self.config, FitConfig):
            raise TypeError(f"config: expected a FitConfig, got {type(self.config).__name__}")


def _as_job(cfg, out_dir, base_dir, overwrite) -> FitJob:
    if isinstance(cfg, FitJob):
        return cfg
    if isinstance(cfg, (str, os.PathLike)):
        base_dir = base_dir or os.path.dirname(os.path.abspath(cfg))
        cfg = load_config(FitConfig, cfg)
    elif not isinstance(cfg, FitConfig):
        cfg = load_config(FitConfig, cfg)
    return FitJob(cfg, out_dir, overwrite, base_dir)


def run_fit(
    cfg: FitJob | FitConfig | dict | str,
    out_dir: str | None = None,
    *,
    base_dir: str | None = None,
    overwrite: bool = False,
) -> dict:
    """Run the fit described by ``cfg`` (a :class:`FitJob`, or a :class:`FitConfig`, a mapping
    or a YAML path with ``out_dir``, ``base_dir``, ``overwrite``) and write the outputs
    (:data:`OUTPUT_NAMES`) to ``out_dir`` (None: nothing written). Everything is checked before
    rendering (:func:`prepare_fit`); an ``out_dir`` that holds a previous run's results is
    refused unless ``overwrite`` (outputs are staged and moved into place only when the job
    succeeded, :mod:`jaxgfx.pipelines._output`). Relative paths in the config (scene, target)
    are looked up in ``base_dir`` (a YAML path's folder), then in the working directory.
    Returns the ``result.json`` dictionary (plus ``"outputs"``: ``{name: path}`` when written).
    """
    from jaxgfx.pipelines._output import StagedDir

    job = _as_job(cfg, out_dir, base_dir, overwrite)
    stage = (
        StagedDir(job.out, OUTPUT_NAMES, overwrite=job.overwrite)
        if job.out is not None
        else contextlib.nullcontext()
    )
    prep = prepare_fit(job.config, base_dir=job.base_dir)
    with stage:
        out = _fit_and_write(job.config, prep, None if job.out is None else stage.path)
    if job.out is not None:
        out["outputs"] = {n: os.path.join(os.fspath(job.out), n) for n in OUTPUT_NAMES}
    return out


# ------------------------------------------------------------------------------------ stages


def _render(cfg: FitConfig, scene, key, spp):
    from jaxgfx.render import render

    r = cfg.render
    return np.asarray(render(scene, key, spp=spp, integrator=r.integrator, max_depth=r.max_depth))


def _target(cfg: FitConfig, prep: Prepared) -> tuple[Target, np.ndarray | None]:
    """The target the loss compares with, and its linear radiance when synthetic."""
    import jax

    if prep.target is not None:
        return prep.target, None
    t = prep.target_spec
    tscene = build_scene(prep.scene, list(prep.truth), prep.truth)
    linear = _render(cfg, tscene, jax.random.key(int(t.get("seed", 1))), int(t.get("spp", 256)))
    if not prep.ldr:
        return Target(linear), linear
    tc = t["camera"]
    bits = int(tc.get("bits", 8))
    cam = photo_camera(
        float(tc.get("exposure", 1.0)),
        float(tc.get("gamma", 2.2)),
        model=tc.get("response", "gamma"),
        bits=bits,
    )
    codes = np.asarray(cam.capture(linear)).astype(np.float32)
    return Target(codes, bits=bits), linear


def _initial(cfg: FitConfig, prep: Prepared):
    """Initial parameters, bounds and camera arguments of :func:`jaxgfx.optim.fit`."""
    import jax.numpy as jnp

    cam = cfg.camera
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
    return params, bounds, cam_args


def _fitted_camera_names(cam) -> list:
    if cam is None:
        return []
    return [n for n, f in (("exposure", cam.exposure.fit), ("gamma", cam.response.fit)) if f]


def _check_fitted(prep: Prepared, fitted_scene, cfg: FitConfig):
    """The fitted values must make a valid scene; an unbounded parameter that the optimiser
    drove out of its domain is named with its value (before any preview is rendered)."""
    for p in prep.paths:
        v = np.asarray(fitted_scene[p])
        if not np.all(np.isfinite(v)):
            raise FloatingPointError(f"params.{p}: the fit ended at a non-finite value {v}")
        try:
            prep.scene.replace(p, fitted_scene[p])
        except (ValueError, TypeError) as e:
            raise ValueError(
                f"params.{p}: the fit drove it to {plain(v)}, outside its valid range ({e}); "
                f"give params.{p} bounds (min/max) or a smaller optimizer.lr "
                f"({cfg.optimizer.lr})"
            ) from None


def _result(cfg: FitConfig, prep: Prepared, res, target_seconds) -> dict:
    cam = cfg.camera
    fitted = {p: plain(res.params["scene"][p]) for p in prep.paths}
    camera_out = None
    if cam is not None:
        camera_out = {
            "model": cam.response.model,
            "exposure": plain(res.params["camera"]["exposure"]),
            "gamma": plain(res.params["camera"]["gamma"])
            if cam.response.model == "gamma"
            else None,
            "fitted": _fitted_camera_names(cam),
        }
    out = {
        "params": fitted,
        "init": {p: plain(prep.init[p]) for p in prep.paths},
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
        out["truth"] = {p: plain(v) for p, v in prep.truth.items()}
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
    return out


def _previews(cfg: FitConfig, prep: Prepared, target: Target, params, res, key):
    """(before, after, target) preview images: linear fits as sRGB scaled to the target's
    99.5th percentile, LDR fits through the initial / fitted camera at 8 bits."""
    cam = cfg.camera
    show_spp = max(cfg.render.spp, 64)

    def show(scene_params, cam_params):
        img = _render(cfg, build_scene(prep.scene, prep.paths, scene_params), key, show_spp)
        if cam is None:
            return img
        pc = photo_camera(
            float(cam_params["exposure"]),
            float(cam_params["gamma"]),
            model=cam.response.model,
            bits=8,
        )
        return np.asarray(pc.capture(img)) / 255.0

    before = show(params["scene"], params["camera"])
    after = show(res.params["scene"], res.params["camera"])
    pixels = target.pixels
    if cam is None:
        scale = 1.0 / max(float(np.percentile(pixels, 99.5)), 1e-6)
        return srgb8(before, scale), srgb8(after, scale), srgb8(pixels, scale)
    return before, after, pixels / (2**target.bits - 1)


def _fit_and_write(cfg: FitConfig, prep: Prepared, out_dir: str | None) -> dict:
    import jax
    import jax.numpy as jnp

    from jaxgfx.optim import fit

    key = jax.random.key(cfg.seed)
    _k_target, k_fit, k_show = jax.random.split(key, 3)

    t0 = time.perf_counter()
    target, _ = _target(cfg, prep)
    target_seconds = time.perf_counter() - t0

    params, bounds, cam_args = _initial(cfg, prep)
    masked = target.mask is not None
    loss = cached_loss(cfg, prep.paths, prep.ldr, target.grey, masked)
    pixels = jnp.asarray(target.pixels)
    target_arg = (pixels, jnp.asarray(target.mask)) if masked else pixels
    o = cfg.optimizer
    res = fit(
        loss,
        params,
        optimizer=o.name,
        learning_rate=o.schedule(),
        steps=o.steps,
        key=k_fit,
        args=(prep.scene, target_arg, cam_args),
        bounds=bounds,
        progress=cfg.progress,
        tol=o.tol,
    )
    _check_fitted(prep, res.params["scene"], cfg)
    out = _result(cfg, prep, res, target_seconds)

    if out_dir is not None:
        before, after, tgt = _previews(cfg, prep, target, params, res, k_show)
        names = [("scene", p) for p in prep.paths]
        names += [("camera", c) for c in _fitted_camera_names(cfg.camera)]
        truth_named = dict(prep.truth or {})
        if prep.ldr and prep.truth is not None:
            truth_named.update({k: out["truth_camera"][k] for k in ("exposure", "gamma")})
        write_outputs(
            out_dir, out, res, before=before, after=after, target=tgt, names=names,
            truth=truth_named,
        )
    return out
