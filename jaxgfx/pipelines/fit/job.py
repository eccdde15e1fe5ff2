"""The fit job: ``run_fit(FitJob)`` is check → target → fit → check the result → report."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time
import typing

import numpy as np

from jaxgfx.config import config_to_dict, load_config

from .config import FitConfig
from .loss import cached_loss
from .report import OUTPUT_NAMES, plain, srgb8, write_outputs
from .targets import Prepared, Target, build_scene, prepare_fit

__all__ = ["FitJob", "run_fit", "auto_exposure", "view_losses", "tile_views", "choose_adjoint"]


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

    @classmethod
    def load(cls, config, out: str | None = None, *, base_dir: str | None = None,
             overwrite: bool = False) -> FitJob:  # fmt: skip
        """A job from ``config``: a YAML path (its folder becomes ``base_dir`` unless given), a
        mapping, or a :class:`FitConfig`."""
        if isinstance(config, (str, os.PathLike)):
            base_dir = base_dir or os.path.dirname(os.path.abspath(config))
            config = load_config(FitConfig, config)
        elif not isinstance(config, FitConfig):
            config = load_config(FitConfig, config)
        return cls(config, out, overwrite, base_dir)


def run_fit(job: FitJob) -> dict:
    """Run the fit ``job`` (a :class:`FitJob`; :meth:`FitJob.load` builds one from a YAML path,
    a mapping or a :class:`FitConfig`) and write the outputs (:data:`OUTPUT_NAMES`) to
    ``job.out`` (None: nothing written). Everything is checked before rendering
    (:func:`prepare_fit`); an ``out`` that holds a previous run's results is refused unless
    ``job.overwrite`` (outputs are staged and moved into place only when the job succeeded,
    :mod:`jaxgfx.pipelines._output`). Relative paths in the config (scene, target) are looked up
    in ``job.base_dir`` (a YAML path's folder), then in the working directory. Returns the
    ``result.json`` dictionary (plus ``"outputs"``: ``{name: path}`` when written).
    """
    if not isinstance(job, FitJob):
        raise TypeError(
            f"job: expected a FitJob (FitJob.load(config, out=...)), got {type(job).__name__}"
        )
    from jaxgfx.pipelines._output import StagedDir

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


def _fitted_mask(scene, path, value):
    """A tree of bools shaped like ``scene``: ``True`` at the leaves the parameter ``path``
    changes (the leaves with a nonzero tangent when ``path`` moves; integer leaves ``False``)."""
    import jax
    import jax.tree_util as jtu

    x = jax.numpy.asarray(value)

    def leaves(v):
        return jtu.tree_leaves(scene.replace(path, v))

    _, tangents = jax.jvp(leaves, (x,), (jax.numpy.ones_like(x),))
    flags = [t.dtype != jax.dtypes.float0 and bool(np.any(np.asarray(t) != 0)) for t in tangents]
    return jtu.tree_unflatten(jtu.tree_structure(scene), flags)


def choose_adjoint(cfg: FitConfig, prep: Prepared) -> dict:
    """``{"adjoint": "ad" | "replay", "why": ...}``: ``render.adjoint`` as given, or for
    ``"auto"`` path replay where the integrator is path or direct and every fitted scene
    parameter is one replay differentiates (materials, emitters, textures, environment:
    :func:`jaxgfx.render.integrators.replay_refusal`), AD otherwise (geometry, camera, the
    ``eta`` of a smooth dielectric, ...), with the first parameter that ruled replay out."""
    from jaxgfx.render.integrators import replay_refusal

    r = cfg.render
    if r.adjoint != "auto":
        return {"adjoint": r.adjoint, "why": "render.adjoint"}
    if r.integrator not in ("path", "direct"):
        return {"adjoint": "ad", "why": f"auto: integrator {r.integrator!r} has no replay"}
    for p in prep.paths:
        mask = _fitted_mask(prep.scene, p, prep.init[p])
        why = replay_refusal(prep.scene, (mask, False, False))
        if why is not None:
            return {"adjoint": "ad", "why": f"auto: params.{p}: {why}"}
    return {"adjoint": "replay", "why": "auto: every fitted parameter is one replay covers"}



def show_spp(cfg: FitConfig) -> int:
    """The spp of the report's renders (previews, each view's loss): ``max(render.spp, 64)``;
    also the spp of the one forward program that renders a synthetic target (:func:`_render`)."""
    return max(cfg.render.spp, 64)


def _flag(name: str) -> bool:
    """An on-by-default switch of the cold-start work (``NAME=0`` turns it off: the old route,
    for ``benchmarks/fit_cold.py``'s A/B runs)."""
    return os.environ.get(name, "1") != "0"


def _render(cfg: FitConfig, scene, key, spp):
    """``scene`` rendered at ``spp``. When ``spp`` is a multiple ``n k`` of the report's
    ``k = show_spp(cfg)`` (the 256-spp synthetic target: 4 × 64), the mean of ``n`` renders of
    ``k`` spp with the keys ``fold_in(key, i)``, ``i < n``: the same estimator at ``spp``
    samples per pixel (other random numbers than one ``spp`` call, equal within Monte Carlo
    error), made by the program the report's renders use, so a cold fit compiles one forward
    render instead of one per spp (``JAXGFX_FIT_SHARED_RENDER=0``: one call at ``spp``)."""
    import jax

    from jaxgfx.render import render

    r = cfg.render

    def one(k, n):
        return render(scene, k, spp=n, integrator=r.integrator_spec, max_depth=r.max_depth)

    k = show_spp(cfg)
    if spp > k and spp % k == 0 and _flag("JAXGFX_FIT_SHARED_RENDER"):
        n = spp // k
        imgs = [np.asarray(one(jax.random.fold_in(key, i), k)) for i in range(n)]
        return (np.sum(imgs, axis=0, dtype=np.float64) / n).astype(imgs[0].dtype)
    return np.asarray(one(key, spp))


def _render_views(cfg: FitConfig, prep: Prepared, scene, key, spp) -> np.ndarray:
    """``(V, H, W, 3)``: ``scene`` through each view's camera (one view: the scene's), view
    ``v`` with the key ``fold_in(key, v)``."""
    import equinox as eqx
    import jax

    if prep.views is None:
        return _render(cfg, scene, key, spp)[None]
    return np.stack([
        _render(cfg, eqx.tree_at(lambda s: s.camera, scene, cam), jax.random.fold_in(key, v),
                spp)
        for v, cam in enumerate(prep.views)
    ])


def _target_camera(tc: dict, exposure: float, channels: int):
    """The :class:`~jaxgfx.hdr.Camera` that takes a synthetic target's photo."""
    import jax.numpy as jnp

    from jaxgfx.hdr import Camera, CameraResponse, NoiseModel, ToneCurve

    model = tc.get("response", "gamma")
    if model == "gamma":
        resp = CameraResponse.gamma(float(tc.get("gamma", 2.2)), anchor="unit")
    else:
        resp = CameraResponse.analytic(model, anchor="unit")
    noise = None
    if tc.get("noise"):
        n = tc["noise"]
        noise = NoiseModel(
            jnp.full((channels,), float(n.get("gain", 0.0))),
            jnp.full((channels,), float(n.get("read_sigma", 0.0)) ** 2),
        )
    wb = tc.get("white_balance")
    tone = None
    if tc.get("tonemap") is not None:
        from .config import ToneSpec

        t = dict(tc["tonemap"])
        spec = ToneSpec(t.pop("op"), t)
        tone = ToneCurve(spec.op, {k: jnp.asarray(v, jnp.float32)
                                   for k, v in spec.params.items()})
    m = tc.get("color_matrix")
    return Camera(
        resp,
        jnp.asarray(exposure, jnp.float32),
        white_balance=None if wb is None else jnp.asarray(wb, jnp.float32)[:channels],
        noise=noise,
        bits=int(tc.get("bits", 8)),
        clip=True,
        color_matrix=None if m is None else jnp.asarray(m, jnp.float32),
        tone=tone,
    )


def _target(cfg: FitConfig, prep: Prepared, key=None) -> tuple[Target, np.ndarray | None]:
    """The target the loss compares with (photos stacked ``(N, H, W, C)``), and its linear
    radiance when synthetic."""
    import jax

    if prep.targets is not None:
        ts = prep.targets
        if not prep.ldr and len(ts) == 1:
            return ts[0], None
        pixels = np.stack([t.pixels for t in ts])
        mask = None
        if any(t.mask is not None for t in ts):
            mask = np.stack([
                np.ones(t.pixels.shape[:2] + (1,), np.float32) if t.mask is None else t.mask
                for t in ts
            ])
        return Target(pixels, grey=ts[0].grey, mask=mask, bits=ts[0].bits), None
    t = prep.target_spec
    tscene = build_scene(prep.scene, list(prep.truth), prep.truth)
    key = jax.random.key(int(t.get("seed", 1)))
    spp = int(t.get("spp", 256))
    if prep.views is None:
        linear = _render(cfg, tscene, key, spp)
        per_photo = None
    else:  # (V, H, W, C) and each photo's view
        linear = _render_views(cfg, prep, tscene, key, spp)
        per_photo = linear[prep.view_of]
    if not prep.ldr:
        return Target(linear if per_photo is None else per_photo), linear
    tc = t["camera"]
    bits = int(tc.get("bits", 8))
    e0 = float(tc.get("exposure", 1.0))
    noise_key = jax.random.fold_in(jax.random.key(int(t.get("seed", 1))), 1)
    ratios = list(tc.get("exposures", [1.0]))
    photos = []
    for j in range(prep.n_targets):  # a view at every exposure, the views in turn
        img = linear if per_photo is None else per_photo[j]
        cam = _target_camera(tc, e0 * float(ratios[j % len(ratios)]), img.shape[-1])
        photos.append(np.asarray(cam.capture(img, jax.random.fold_in(noise_key, j))))
    photos = np.stack(photos)
    if tc.get("jpeg") is not None:
        from jaxgfx.hdr import jpeg_roundtrip

        photos = jpeg_roundtrip(photos, quality=int(tc["jpeg"]))
    return Target(photos.astype(np.float32), bits=bits), linear


def auto_exposure(img, codes, table, ratios, code_max: float) -> float:
    """The first photo's exposure ``e`` that maps a render ``img`` ``(H, W, C)`` onto photos
    ``codes`` ``(N, H, W, C)`` (``img`` may be ``(N, H, W, C)``: each photo's view) of relative
    exposures ``ratios`` ``(N,)`` through a camera of
    level table ``table`` (``ln f⁻¹``, :func:`~jaxgfx.pipelines.fit.camera.level_table`):
    the median of ``f⁻¹(q) / (r_j · img)`` over the uncensored codes (``0 < q < c``) of
    pixels with ``img > 0``. Robust to clipping and to a material that is still wrong over
    part of the image; a start for ``camera.exposure.auto``."""
    img = np.asarray(img, np.float64)
    codes = np.asarray(codes)
    c = int(round(code_max))
    q = np.clip(codes, 0, c).astype(np.int64)
    g = np.broadcast_to(np.asarray(table, np.float64), (c + 1, codes.shape[-1]))
    x = np.exp(np.take_along_axis(g, q.reshape(-1, codes.shape[-1]), 0)).reshape(codes.shape)
    r = np.asarray(ratios, np.float64).reshape(-1, 1, 1, 1)
    imgs = img if img.ndim == 4 else img[None]
    ok = (q > 0) & (q < c) & (imgs > 1e-8)
    if not ok.any():
        raise ValueError("camera.exposure.auto: no pixel is both measured and lit in the render")
    ri = np.broadcast_to(r * imgs, codes.shape)
    return float(np.median(x[ok] / ri[ok]))


def _prior_specs(cfg: FitConfig, prep: Prepared):
    """``((path, kind), ...)`` and ``{path: {kind: weight}}`` of the texel-grid priors, and
    ``{path: k}`` the learning-rate factors (``params.X.lr / optimizer.lr``)."""
    from .targets import _param_spec

    priors, weights, scales = [], {}, {}
    for path in prep.paths:
        spec = _param_spec(path, cfg.params[path])
        if spec.prior:
            weights[path] = {}
            for kind, w in spec.prior.items():
                priors.append((path, kind))
                weights[path][kind] = np.float32(w)
        if spec.lr is not None and spec.lr != cfg.optimizer.lr:
            scales[path] = float(spec.lr / cfg.optimizer.lr)
    return tuple(priors), weights, scales


def bracket_start(cfg: FitConfig, prep: Prepared, target: Target):
    """The starting curve of ``camera.response.init: bracket``: the response that
    :func:`jaxgfx.hdr.recover_response` (``camera.response.init_method`` with its
    ``init_options``) recovers from the
    target photos of one view (:func:`~jaxgfx.pipelines.fit.targets.bracket_photos`) with
    their relative exposures as times. Returns the response and a record for the report."""
    from jaxgfx.hdr import recover_response

    from .targets import bracket_photos

    idx = bracket_photos(prep.exposures, prep.view_of)
    codes = np.asarray(target.pixels)[idx]
    dtype = np.uint16 if cfg.camera.bits > 8 else np.uint8
    times = np.asarray(prep.exposures, np.float64)[idx]
    spec = cfg.camera.response
    options = dict(spec.init_options or {})
    resp = recover_response(codes.astype(dtype), times, method=spec.init_method, **options)
    view = 0 if prep.view_of is None else int(np.asarray(prep.view_of)[idx[0]])
    record = {"from": "bracket", "method": spec.init_method,
              **({"options": options} if options else {}),
              "photos": [int(i) for i in idx], "view": view,
              "exposures": [float(t) for t in times]}
    return resp, record


def _initial(cfg: FitConfig, prep: Prepared, target: Target | None = None):
    """Initial parameters, bounds and camera arguments of :func:`jaxgfx.optim.fit`
    (``target``: the photos, needed by ``camera.response.init: bracket`` only)."""
    import jax.numpy as jnp

    from jaxgfx.hdr import CameraResponse
    from jaxgfx.optim import Interval

    from .camera import CURVE_KINDS, free_init, level_table

    cam = cfg.camera
    _, weights, scales = _prior_specs(cfg, prep)
    params = {"scene": {}, "camera": {}}
    bounds = {"scene": {}, "camera": {}}
    for p in prep.paths:
        x0 = jnp.asarray(prep.init[p])
        if p in scales:  # its own learning rate: fitted as v, x = bounds.forward(k v)
            iv = Interval(*[_static_bound(b) for b in prep.bounds[p]])
            params["scene"][p] = jnp.asarray(iv.inverse(x0) / scales[p], jnp.float32)
            bounds["scene"][p] = None
        else:
            params["scene"][p] = x0
            bounds["scene"][p] = prep.bounds[p]
    cam_args = None
    if weights:
        cam_args = {"priors": {p: {k: jnp.asarray(w) for k, w in d.items()}
                               for p, d in weights.items()}}
    if cam is not None:
        spec = cam.response
        kind = spec.curve_kind
        n = prep.n_targets
        ratios = np.asarray(prep.exposures, np.float32)
        nch = 1 if prep.targets and prep.targets[0].grey else 3
        if kind == "free":
            if prep.fixed_response is not None:
                start = prep.fixed_response
            elif spec.init == "bracket":
                if target is None:
                    raise ValueError("camera.response.init: 'bracket' needs the target photos")
                start, prep.curve_init = bracket_start(cfg, prep, target)
            elif isinstance(spec.init, str):
                start = CameraResponse.analytic(spec.init, anchor="unit")
            else:
                start = CameraResponse.gamma(float(spec.init), anchor="unit")
            curve0 = free_init(start, spec.knots, spec.channels)
        else:  # unused: a small placeholder of the default shape
            curve0 = free_init(CameraResponse.gamma(2.2, anchor="unit"), spec.knots,
                               spec.channels)
        gamma0 = float(spec.init) if kind == "gamma" else 2.2
        gb = (spec.min, spec.max) if kind == "gamma" else (0.2, 6.0)
        params["camera"] = {
            "exposure": jnp.asarray(cam.exposure.init, jnp.float32),
            "photo_exposure": jnp.asarray(ratios),
            "white_balance": jnp.asarray(cam.white_balance.init, jnp.float32),
            "gamma": jnp.asarray(gamma0, jnp.float32),
            "curve": jnp.asarray(curve0),
        }
        # lower bounds only (softplus: exp-like near the bound): a sigmoid over (1e-3, 1e3)
        # moves every init below 1e-3 of its width (1.0) to the margin, 1.001
        bounds["camera"] = {
            "exposure": (cam.exposure.min, None),
            "photo_exposure": (ratios / 32.0, None),
            "white_balance": (cam.white_balance.min, cam.white_balance.max),
            "gamma": gb,
            "curve": None,
        }
        bits = cam.bits
        if kind == "fixed":
            fixed = level_table(prep.fixed_response, bits)
        else:
            fixed = jnp.zeros((2**bits, 1), jnp.float32)
        fixed = jnp.broadcast_to(fixed, (2**bits, nch)) if fixed.shape[1] == 1 else fixed
        per_photo = np.zeros(n, np.float32)
        if cam.exposure.per_photo:
            per_photo[1:] = 1.0
        cam_args = {
            **(cam_args or {}),
            "weights": jnp.asarray([float(k == kind) for k in CURVE_KINDS], jnp.float32),
            "fixed": fixed,
            "free": {
                "exposure": jnp.asarray(float(cam.exposure.fit), jnp.float32),
                "photo_exposure": jnp.asarray(per_photo),
                "white_balance": jnp.asarray(
                    [1.0, 0.0, 1.0] if cam.white_balance.fit else [0.0, 0.0, 0.0], jnp.float32
                ),
                "gamma": jnp.asarray(float(kind == "gamma" and spec.fit), jnp.float32),
                "curve": jnp.asarray(float(kind == "free"), jnp.float32),
            },
            "smoothness": jnp.asarray(spec.smoothness if kind == "free" else 0.0, jnp.float32),
            "clip_code": jnp.asarray(
                2**bits - 1 if cam.clip_code is None else cam.clip_code, jnp.int32
            ),
            "unmeasured": jnp.asarray(float(cam.clipped == "unmeasured"), jnp.float32),
        }
        # the picture style: present only when configured (a config without it keeps the
        # parameter tree, hence the program, it had before)
        if kind == "free" and spec.start_prior and target is not None:
            cam_args["curve_prior"] = start_prior_args(spec, curve0, target, cam_args,
                                                       2**bits - 1)
        if cam.has_matrix:
            params["camera"]["color_matrix"] = jnp.asarray(prep.color_matrix, jnp.float32)
            bounds["camera"]["color_matrix"] = None
            cam_args["free"]["color_matrix"] = jnp.asarray(float(cam.color_matrix.fit),
                                                           jnp.float32)
            cam_args["white_preserving"] = jnp.asarray(float(cam.color_matrix.fit),
                                                       jnp.float32)
        if cam.tonemap is not None:
            tm = cam.tonemap
            params["camera"]["tone"] = {k: jnp.asarray(v, jnp.float32)
                                        for k, v in tm.params.items()}
            bounds["camera"]["tone"] = {
                k: (1e-3, None) if tm.constraint(k) == "positive" else None for k in tm.params
            }
            cam_args["free"]["tone"] = {k: jnp.asarray(float(k in tm.fit), jnp.float32)
                                        for k in tm.params}
    if prep.views is not None:
        from .loss import stack_cameras

        cam_args = {**(cam_args or {}), "views": stack_cameras(prep.views),
                    "view_of": jnp.asarray(prep.view_of, jnp.int32)}
    return params, bounds, cam_args


def knot_counts(codes, knots: int, clip_code: int, code_max: int = 255) -> np.ndarray:
    """``(knots, C)``: the pixels of the photos ``codes`` ``(..., C)`` whose code is nearest
    each of the free curve's ``knots`` uniform knots, per channel; black (0) and clipped
    (``>= clip_code``) codes measure no level and are left out."""
    c = np.asarray(codes).reshape(-1, np.shape(codes)[-1]).astype(np.int64)
    k = np.rint(c * (knots - 1) / code_max).astype(np.int64)
    ok = (c > 0) & (c < clip_code)
    return np.stack(
        [np.bincount(k[ok[:, j], j], minlength=knots)[:knots] for j in range(c.shape[1])], 1
    ).astype(np.float64)


def start_prior_args(spec, curve0, target: Target, cam_args, code_max: int = 255) -> dict:
    """``camera_args["curve_prior"]`` of ``camera.response.start_prior``: the start's ``ln x``
    knots ``g0`` ``(K, C)`` and the per-knot weights ``start_prior · w_k``, ``w_k = 1 / (n_k /
    n̄ + 0.01)`` (:func:`knot_counts` of the target photos, ``n̄`` their mean over the knots:
    ~1 where the photos hold an average count, up to 100 where they hold none)."""
    import jax.numpy as jnp

    from .camera import free_response

    g0 = np.asarray(free_response(jnp.asarray(curve0)).params, np.float64)
    n = knot_counts(np.asarray(target.pixels)[..., :3], spec.knots,
                    int(np.asarray(cam_args["clip_code"])), code_max)
    if g0.shape[1] == 1:
        n = n.sum(axis=1, keepdims=True)
    w = 1.0 / (n / np.maximum(n.mean(axis=0, keepdims=True), 1.0) + 0.01)
    return {"g0": jnp.asarray(g0, jnp.float32),
            "w": jnp.asarray(float(spec.start_prior) * w, jnp.float32)}


def _curve_lr(cfg: FitConfig) -> float | None:
    """``camera.response.lr / optimizer.lr`` of a free-form curve with its own learning rate,
    else None."""
    cam = cfg.camera
    if cam is None or cam.response.lr is None or cam.response.curve_kind != "free":
        return None
    return float(cam.response.lr / cfg.optimizer.lr)


def _static_bound(b):
    """A bound as an :class:`~jaxgfx.optim.Interval` field: None, a float when every element
    is equal (a texel grid's ``min: 0``), else nested tuples (hashable: the loss cache's key
    holds the intervals; lists are not)."""
    if b is None:
        return None
    a = np.asarray(b, np.float64)
    if a.size and np.all(a == a.flat[0]):
        return float(a.flat[0])
    return _nested_tuple(a) if a.ndim else float(a)


def _nested_tuple(a: np.ndarray):
    """Nested tuples of floats of an array (hashable, for the loss cache's static key)."""
    return tuple(_nested_tuple(r) for r in a) if a.ndim > 1 else tuple(float(v) for v in a)


def _scaled_intervals(cfg: FitConfig, prep: Prepared):
    """``((path, (k, Interval)), ...)`` of the parameters with their own learning rate."""
    from jaxgfx.optim import Interval

    _, _, scales = _prior_specs(cfg, prep)
    out = []
    for p in prep.paths:
        if p in scales:
            lo, hi = prep.bounds[p]
            iv = Interval(_static_bound(lo), _static_bound(hi))
            out.append((p, (scales[p], iv)))
    return tuple(out)


def _unscale(tree: dict, scaled) -> dict:
    """Scene values from the fitted leaves (``x = Interval.forward(k · v)``)."""
    out = dict(tree)
    for p, (k, iv) in scaled:
        out[p] = np.asarray(iv.forward(k * np.asarray(tree[p])))
    return out


def _fitted_camera_names(cam) -> list:
    if cam is None:
        return []
    names = [("exposure", cam.exposure.fit), ("gamma", cam.response.fit and
                                              cam.response.curve_kind == "gamma"),
             ("photo_exposure", cam.exposure.per_photo), ("white_balance",
                                                          cam.white_balance.fit)]
    return [n for n, f in names if f]


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


def _result(cfg: FitConfig, prep: Prepared, res, target_seconds, scene_params) -> dict:
    cam = cfg.camera
    fitted = {p: plain(scene_params[p]) for p in prep.paths}
    camera_out = None
    if cam is not None:
        cp = res.params["camera"]
        kind = cam.response.curve_kind
        camera_out = {
            "model": "file" if cam.response.source and kind == "fixed" else cam.response.model,
            "from": cam.response.source,
            "curve": kind,
            "exposure": plain(cp["exposure"]),
            "photo_exposure": plain(cp["photo_exposure"]),
            "white_balance": plain(cp["white_balance"]),
            "gamma": plain(cp["gamma"]) if kind == "gamma" else None,
            "fitted": _fitted_camera_names(cam) + (["curve"] if kind == "free" else []),
        }
        if prep.curve_init is not None:
            camera_out["curve_init"] = prep.curve_init
        if cam.has_matrix:
            from .camera import white_preserving

            camera_out["color_matrix"] = plain(white_preserving(
                np.asarray(cp["color_matrix"], np.float64), float(cam.color_matrix.fit)))
            if cam.color_matrix.fit:
                camera_out["fitted"].append("color_matrix")
        if cam.tonemap is not None:
            camera_out["tonemap"] = {"op": cam.tonemap.op,
                                     **{k: plain(v) for k, v in cp["tone"].items()}}
            camera_out["fitted"] += [f"tonemap.{k}" for k in cam.tonemap.fit]
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
        "n_targets": prep.n_targets,
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
                "exposures": [float(v) for v in tc.get("exposures", [1.0])],
            }
    return out


def fitted_camera(cfg: FitConfig, prep: Prepared, cam_p, photo: int = 0, bits: int = 8):
    """The :class:`~jaxgfx.hdr.Camera` of photo ``photo`` with camera parameters ``cam_p``
    (the response the fit ended with, its exposure and white balance), clipped and quantised
    to ``bits`` as a photo is taken."""
    import jax.numpy as jnp

    from jaxgfx.hdr import Camera

    from .camera import response_of, with_channels

    cam = cfg.camera
    nch = 1 if prep.targets and prep.targets[0].grey else 3
    resp = with_channels(response_of(cam.response.curve_kind, cam_p, prep.fixed_response), nch)
    e = float(np.asarray(cam_p["exposure"])) * float(np.asarray(cam_p["photo_exposure"])[photo])
    wb = jnp.asarray(cam_p["white_balance"], jnp.float32)[:nch] if nch == 3 else None
    m = tone = None
    if cam.has_matrix:
        from .camera import white_preserving

        m = white_preserving(jnp.asarray(cam_p["color_matrix"], jnp.float32),
                             float(cam.color_matrix.fit))
    if cam.tonemap is not None:
        from .camera import tone_curve

        tone = tone_curve(cam.tonemap.op, cam_p["tone"])
    return Camera(resp, jnp.asarray(e, jnp.float32), white_balance=wb, bits=bits, clip=True,
                  color_matrix=m, tone=tone)


def _shown_photos(prep: Prepared) -> list:
    """The photo each view's preview shows: the middle photo of the view's bracket."""
    if prep.views is None:
        return [prep.n_targets // 2]
    out = []
    for v in range(prep.n_views):
        idx = np.flatnonzero(prep.view_of == v)
        out.append(int(idx[len(idx) // 2]))
    return out


def tile_views(images, gap: int = 2):
    """The views ``(V, H, W, C)`` side by side, ``gap`` columns of white between them."""
    images = np.asarray(images)
    white = 255 if images.dtype == np.uint8 else 1.0
    cols = []
    for v, im in enumerate(images):
        if v:
            cols.append(np.full(im.shape[:1] + (gap,) + im.shape[2:], white, images.dtype))
        cols.append(im)
    return np.concatenate(cols, axis=1)


def _previews(cfg: FitConfig, prep: Prepared, target: Target, params, res, key, scene_after,
              renders=None):
    """(before, after, target) preview images, every view side by side: linear fits as sRGB
    scaled to the target's 99.5th percentile, LDR fits through the initial / fitted camera at
    8 bits (the middle photo of each view's bracket). ``renders``: the ``(V, H, W, 3)``
    renders ``{"before", "after"}`` when already made."""
    cam = cfg.camera
    spp = show_spp(cfg)
    shown = _shown_photos(prep)
    renders = renders or {}

    def show(scene_params, cam_params, imgs):
        if imgs is None:
            scene = build_scene(prep.scene, prep.paths, scene_params)
            imgs = _render_views(cfg, prep, scene, key, spp)
        if cam is None:
            return imgs
        return np.stack([
            np.asarray(fitted_camera(cfg, prep, cam_params, photo=j).capture(imgs[v])) / 255.0
            for v, j in enumerate(shown)
        ])

    before = show(prep.init, params["camera"], renders.get("before"))
    after = show(scene_after, res.params["camera"], renders.get("after"))
    pixels = target.pixels if target.pixels.ndim == 4 else target.pixels[None]
    pixels = pixels[shown]
    if cam is None:
        scale = 1.0 / max(float(np.percentile(pixels, 99.5)), 1e-6)
        return (tile_views(srgb8(before, scale)), tile_views(srgb8(after, scale)),
                tile_views(srgb8(pixels, scale)))
    return tile_views(before), tile_views(after), tile_views(pixels / (2**target.bits - 1))


def view_losses(cfg: FitConfig, prep: Prepared, target: Target, renders, cam_p, cam_args):
    """Each view's loss ``(V,)``: the sum of its photos' terms
    (:func:`~jaxgfx.pipelines.fit.loss.photo_losses`, priors not included) with the renders
    ``(V, H, W, 3)`` of each view and camera parameters ``cam_p``."""
    import jax.numpy as jnp

    from .camera import fit_level_table
    from .loss import photo_losses, to_target_channels

    imgs = to_target_channels(jnp.asarray(renders), target.grey)
    view_of = np.zeros(prep.n_targets, np.int64) if prep.views is None else prep.view_of
    if target.pixels.ndim == 4:
        imgs = imgs[jnp.asarray(view_of)]
    else:
        imgs = imgs[0]
    table = (fit_level_table(cam_p, cam_args, cfg.camera.bits, cfg.camera.tone_op)
             if prep.ldr else None)
    pixels = jnp.asarray(target.pixels)
    masked = target.mask is not None
    t = (pixels, jnp.asarray(target.mask)) if masked else pixels
    terms = np.asarray(photo_losses(cfg, prep.ldr, imgs, t, cam_p, cam_args, table, masked),
                       np.float64)
    return np.bincount(view_of[: terms.size], weights=terms, minlength=prep.n_views)


class _FitInputs(typing.NamedTuple):
    params: dict
    bounds: dict
    args: tuple  # (scene, target pixels or (pixels, mask), camera args)
    k_curve: float | None
    scaled: tuple
    loss: object


def _fit_inputs(cfg: FitConfig, prep: Prepared, target: Target, k_show) -> _FitInputs:
    """The fit's parameters, bounds, ``args`` (scene, target, camera arguments) and loss for
    ``target``: what :func:`jaxgfx.optim.fit` gets (``benchmarks/fit_cold.py`` compiles the
    step from them)."""
    import jax.numpy as jnp

    params, bounds, cam_args = _initial(cfg, prep, target)
    if prep.ldr and cfg.camera.exposure.auto:
        from .camera import fit_level_table

        bits = cfg.camera.bits
        img = _render_views(cfg, prep, build_scene(prep.scene, prep.paths, prep.init), k_show,
                            max(cfg.render.spp, 16))
        img = img[prep.view_of] if prep.views is not None else img[0]
        if target.grey:
            from .loss import to_target_channels

            img = np.asarray(to_target_channels(jnp.asarray(img), True))
        table = fit_level_table(params["camera"], cam_args, bits, cfg.camera.tone_op)
        if cfg.camera.has_matrix:  # compare in the camera's output space
            from .camera import photo_matrix

            img = img @ np.asarray(photo_matrix(params["camera"], cam_args)).T
        e0 = auto_exposure(img, target.pixels, table, prep.exposures, float(2**bits - 1))
        lo = cfg.camera.exposure.min
        params["camera"]["exposure"] = jnp.asarray(max(e0, 1.01 * lo), jnp.float32)
    k_curve = _curve_lr(cfg)
    if k_curve is not None:  # fitted as v = u / k (the loss multiplies back)
        params["camera"]["curve"] = params["camera"]["curve"] / k_curve
        cam_args["curve_lr"] = jnp.asarray(k_curve, jnp.float32)
    priors, _, _ = _prior_specs(cfg, prep)
    scaled = _scaled_intervals(cfg, prep)
    masked = target.mask is not None
    loss = cached_loss(cfg, prep.paths, prep.ldr, target.grey, masked, priors, scaled,
                       views=prep.views is not None)
    pixels = jnp.asarray(target.pixels)
    target_arg = (pixels, jnp.asarray(target.mask)) if masked else pixels
    return _FitInputs(params, bounds, (prep.scene, target_arg, cam_args), k_curve, scaled, loss)


def _fit_and_write(cfg: FitConfig, prep: Prepared, out_dir: str | None) -> dict:
    import jax

    from jaxgfx.optim import fit

    key = jax.random.key(cfg.seed)
    _k_target, k_fit, k_show = jax.random.split(key, 3)
    given = cfg
    adjoint = choose_adjoint(cfg, prep)
    if cfg.render.adjoint != adjoint["adjoint"]:  # "auto", resolved
        render_cfg = dataclasses.replace(cfg.render, adjoint=adjoint["adjoint"])
        cfg = dataclasses.replace(cfg, render=render_cfg)

    o = cfg.optimizer
    t0 = time.perf_counter()
    # (compiling the step in a thread while the target renders did not shorten the cold run:
    # XLA's compile holds the GIL; docs/performance.md, "The cold jaxgfx fit")
    target, _ = _target(cfg, prep)
    target_seconds = time.perf_counter() - t0
    inputs = _fit_inputs(cfg, prep, target, k_show)
    params, bounds, cam_args = inputs.params, inputs.bounds, inputs.args[2]
    k_curve, scaled = inputs.k_curve, inputs.scaled
    res = fit(
        inputs.loss,
        params,
        optimizer=o.name,
        learning_rate=o.schedule(),
        steps=o.steps,
        key=k_fit,
        args=inputs.args,
        bounds=bounds,
        progress=cfg.progress,
        tol=o.tol,
        compiler_options=o.compiler_options(),
        average_from=o.average_from(),
    )
    if k_curve is not None:
        params["camera"]["curve"] = params["camera"]["curve"] * k_curve
        res.params["camera"]["curve"] = k_curve * np.asarray(res.params["camera"]["curve"])
    if scaled and res.history is not None:  # fitted leaves of own-lr parameters -> values
        res.history["scene"] = _unscale(res.history["scene"], scaled)
    scene_after = _unscale(res.params["scene"], scaled)
    _check_fitted(prep, scene_after, cfg)
    out = _result(given, prep, res, target_seconds, scene_after)
    out["adjoint"] = adjoint
    if o.average:  # optimizer.average: the result is a mean of iterates (fit's average_from)
        out["average"] = {"fraction": o.average, "from_step": o.average_from(),
                          "iterates": res.n_averaged}
    renders = None
    if prep.views is not None:  # each view's loss before and after (one render per view)
        spp = show_spp(cfg)
        renders = {
            "before": _render_views(cfg, prep, build_scene(prep.scene, prep.paths, prep.init),
                                    k_show, spp),
            "after": _render_views(cfg, prep, build_scene(prep.scene, prep.paths, scene_after),
                                   k_show, spp),
        }
        out["views"] = {
            "poses": prep.view_poses,
            "photo_view": [int(v) for v in prep.view_of],
            "loss_before": view_losses(cfg, prep, target, renders["before"],
                                       params["camera"], cam_args).tolist(),
            "loss_after": view_losses(cfg, prep, target, renders["after"],
                                      res.params["camera"], cam_args).tolist(),
            "loss_spp": spp,
        }

    if out_dir is not None:
        before, after, tgt = _previews(cfg, prep, target, params, res, k_show, scene_after,
                                       renders)
        names = [("scene", p) for p in prep.paths]
        names += [("camera", c) for c in _fitted_camera_names(cfg.camera)
                  if np.size(res.params["camera"][c]) <= 16]
        truth_named = dict(prep.truth or {})
        if prep.ldr and prep.truth is not None:
            truth_named.update({k: out["truth_camera"][k] for k in ("exposure", "gamma")})
        write_outputs(
            out_dir, out, res, before=before, after=after, target=tgt, names=names,
            truth=truth_named,
        )
        if cfg.camera is not None:
            from jaxgfx.hdr import save_response

            from .camera import response_of

            save_response(
                os.path.join(out_dir, "response.json"),
                response_of(cfg.camera.response.curve_kind, res.params["camera"],
                            prep.fixed_response),
            )
    return out
