"""Everything a fit checks before it renders: the scene file, each parameter path, init and
bounds, and the target (a photo or radiance file, or a synthetic target rendered here).

A target file is read once, here, and checked for what would otherwise fail after the compile
or silently change the fit: its size against the camera's, its bit depth against
``camera.bits``, non-finite radiance, a photo with no unclipped pixel. Grey targets (``(H, W)``
files, 2-D arrays or one channel) are compared with the render's luminance; the alpha channel
of an RGBA photo is a mask (pixels with alpha 0 do not count)."""

from __future__ import annotations

import dataclasses
import os
from typing import Any

import numpy as np

from jaxgfx.config import load_config, read_yaml
from jaxgfx.hdr import ANALYTIC_RESPONSES

from .camera import RESPONSE_MODELS
from .config import FitConfig, FitParam

__all__ = [
    "Prepared",
    "Target",
    "prepare_fit",
    "resolve_path",
    "load_fit_scene",
    "build_scene",
    "is_texel_grid",
    "check_synthetic_camera",
    "fixed_response_of",
    "bracket_photos",
    "color_matrix_of",
    "scene_camera_desc",
    "build_view",
]

TARGET_CAMERA_KEYS = (
    "response", "gamma", "exposure", "exposures", "bits", "white_balance", "noise", "jpeg",
    "color_matrix", "tonemap",
)
SYNTHETIC_TARGET_KEYS = ("synthetic", "spp", "seed", "camera", "views")
PHOTO_KEYS = ("file", "exposure", "view")


@dataclasses.dataclass
class Target:
    """A target as the loss sees it: ``pixels`` ``(H, W, C)`` float32 (integer codes for
    photos, radiance otherwise), ``grey`` (compare with the render's luminance), ``mask``
    ``(H, W, 1)`` float32 weights or None, ``bits`` of a photo (None for radiance), and
    ``path`` (None for a synthetic target)."""

    pixels: np.ndarray
    grey: bool = False
    mask: np.ndarray | None = None
    bits: int | None = None
    path: str | None = None
    exposure: float | None = None  # relative exposure (seconds or a ratio) of a photo


@dataclasses.dataclass
class Prepared:
    scene: Any
    paths: list
    init: dict
    bounds: dict
    truth: dict | None
    target_spec: Any
    ldr: bool
    target: Target | None = None  # the first file target (all of them: ``targets``)
    targets: list | None = None  # file targets, read and checked; synthetic ones are rendered
    exposures: np.ndarray | None = None  # (N,) exposure of each photo relative to the first
    fixed_response: Any = None  # the camera's fixed CameraResponse (analytic or loaded)
    texture_paths: tuple = ()  # fitted parameters that are texel grids
    # several views (None: the scene's camera only): one camera per distinct pose, the view
    # of each photo (N,) and the pose each view was given as ({}: the scene's camera)
    views: tuple | None = None
    view_of: np.ndarray | None = None
    view_poses: list | None = None
    color_matrix: np.ndarray | None = None  # (3, 3) the camera's matrix (init or profile's)
    curve_init: dict | None = None  # camera.response.init: bracket: how the curve started

    @property
    def n_targets(self) -> int:
        if self.view_of is not None:
            return len(self.view_of)
        return len(self.exposures) if self.exposures is not None else 1

    @property
    def n_views(self) -> int:
        return 1 if self.views is None else len(self.views)


def resolve_path(path: str, base: str | None, what: str) -> str:
    """``path`` as given when absolute; a relative path is looked up in ``base`` (the config's
    folder) first, then in the working directory. ``FileNotFoundError`` names ``what`` and
    every place looked in."""
    path = os.fspath(path)
    if os.path.isabs(path) or base is None:
        if not os.path.exists(path):
            raise FileNotFoundError(f"{what}: file not found: {path}")
        return path
    candidates = [os.path.join(base, path), path]
    for c in candidates:
        if os.path.exists(c):
            return c
    raise FileNotFoundError(
        f"{what}: file not found: {path} (looked in {os.path.abspath(base)} and "
        f"{os.getcwd()})"
    )


def load_fit_scene(cfg: FitConfig, base: str | None):
    """The scene of ``cfg``, a YAML or Mitsuba 3 XML file (``render.width/height`` override
    the camera's resolution)."""
    from jaxgfx.render import load_scene

    spath = resolve_path(cfg.scene, base, "scene")
    if spath.lower().endswith(".xml"):  # Mitsuba 3 XML (absolute file paths in the desc)
        from jaxgfx.render.scene.mitsuba_xml import read_xml

        desc = read_xml(spath).desc
    else:
        desc = read_yaml(spath)
    if cfg.render.width is not None or cfg.render.height is not None:
        cam = dict(desc.get("camera", {}))
        if cfg.render.width is not None:
            cam["width"] = cfg.render.width
        if cfg.render.height is not None:
            cam["height"] = cfg.render.height
        desc["camera"] = cam
    return load_scene(desc, base_dir=os.path.dirname(os.path.abspath(spath)))


def build_scene(scene, paths, values):
    """``scene`` with each parameter path in ``paths`` replaced by ``values[path]``."""
    for path in paths:
        scene = scene.replace(path, values[path])
    return scene


def scene_camera_desc(cam) -> dict:
    """The ``camera`` description (the scene file's keys) of a loaded camera: ``origin``,
    ``target``, ``up``, ``fov``, ``fov_axis`` of a look-at camera, ``view_proj_inverse`` of a
    matrix camera, and ``width``, ``height``."""
    from jaxgfx.render.camera import MatrixCamera

    d = {"width": cam.width, "height": cam.height}
    if isinstance(cam, MatrixCamera):
        d["view_proj_inverse"] = np.asarray(cam.view_proj_inverse, np.float64).tolist()
        return d
    for k in ("origin", "target", "up"):
        d[k] = np.asarray(getattr(cam, k), np.float64).tolist()
    d["fov"] = float(np.asarray(cam.fov))
    d["fov_axis"] = cam.fov_axis
    return d


def build_view(scene, pose, where: str):
    """The camera of one view: the scene's camera with the keys of ``pose`` replaced (the
    scene file's ``camera`` keys but the size: ``origin``, ``target``, ``up``, ``fov``,
    ``fov_axis``, or ``view_proj_inverse`` for a matrix camera; ``{}``: the scene's camera).
    Errors name ``where`` (``target[1].view.fov: ...``)."""
    from jaxgfx.render.scene.schema import build_camera

    base = scene_camera_desc(scene.camera)
    keys = tuple(k for k in base if k not in ("width", "height"))
    if not isinstance(pose, dict):
        raise ValueError(f"{where}: expected a mapping of camera keys {list(keys)}, got {pose!r}")
    bad = sorted(set(pose) - set(keys))
    if bad:
        size = [k for k in bad if k in ("width", "height")]
        raise ValueError(
            f"{where}: unknown key(s) {bad}; a view takes the scene camera's keys {list(keys)}"
            + ("; its size is the scene camera's (render.width/height)" if size else "")
        )
    if pose.get("fov_axis", base.get("fov_axis")) != base.get("fov_axis"):
        raise ValueError(
            f"{where}.fov_axis: every view of a fit has the scene camera's fov_axis "
            f"({base['fov_axis']!r}), got {pose['fov_axis']!r}"
        )
    return build_camera({**base, **pose}, where)


def _view_key(cam) -> tuple:
    import jax

    return tuple(tuple(np.asarray(x, np.float64).ravel().tolist())
                 for x in jax.tree.leaves(cam))


def _views(scene, poses):
    """``(cameras, view_of, given poses)`` of ``[(where, pose or None)]``: photos of one
    pose share one view (and one render)."""
    cams, keys, given, view_of = [], [], [], []
    for where, pose in poses:
        cam = scene.camera if pose is None else build_view(scene, pose, where)
        k = _view_key(cam)
        if k not in keys:
            keys.append(k)
            cams.append(cam)
            given.append({} if pose is None else dict(pose))
        view_of.append(keys.index(k))
    return tuple(cams), np.asarray(view_of, np.int32), given


def _param_spec(path, raw) -> FitParam:
    if isinstance(raw, FitParam):
        return raw
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ValueError(f"params.{path}: expected a mapping with init/min/max, got {raw!r}")
    try:
        return load_config(FitParam, raw, where=f"params.{path}")
    except ValueError as e:
        msg = str(e)
        raise ValueError(msg if msg.startswith("params.") else f"params.{path}.{msg}") from None


def is_texel_grid(value) -> bool:
    """A parameter that a smoothness prior can act on: an ``(H, W, C)`` texel grid (bitmap
    texture or environment map) with ``H, W >= 2``."""
    shape = np.shape(value)
    return len(shape) == 3 and shape[0] >= 2 and shape[1] >= 2


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


# ------------------------------------------------------------------------------ target files


def _read_target_file(path: str) -> Target:
    """Read and check a target file (module doc)."""
    from jaxgfx import io

    kind = io.kind_of(path)
    if kind == "ldr":
        codes = io.read_image(path)
        if not np.issubdtype(codes.dtype, np.integer):
            raise ValueError(
                f"target: {path}: a float TIFF holds radiance or display values, not camera "
                "codes; save the photo as 8/16-bit, or the radiance as .exr"
            )
        bits = 16 if codes.dtype == np.uint16 else 8
        mask = None
        if codes.ndim == 3 and codes.shape[-1] in (2, 4):  # grey + alpha, RGB + alpha
            alpha = codes[..., -1:].astype(np.float32)
            mask = (alpha > 0).astype(np.float32)
            codes = codes[..., :-1]
            if not mask.any():
                raise ValueError(f"target: {path}: the alpha channel is 0 everywhere")
        pixels = codes.astype(np.float32)
        if pixels.ndim == 2:
            pixels = pixels[..., None]
        code_max = float(2**bits - 1)
        w = np.ones(pixels.shape[:2] + (1,), np.float32) if mask is None else mask
        informative = ((pixels > 0) & (pixels < code_max)) * w
        if not informative.any():
            level = "0 (black)" if pixels.max() <= 0 else f"clipped ({int(code_max)})"
            raise ValueError(
                f"target: {path}: every pixel is {level}; a fit needs pixels between black "
                "and the clip level"
            )
        return Target(pixels, grey=pixels.shape[-1] == 1, mask=mask, bits=bits, path=path)
    if kind in ("hdr", "npy"):
        arr = np.load(path) if kind == "npy" else io.read_any(path)
        arr = np.asarray(arr)
        if not np.issubdtype(arr.dtype, np.number) or arr.ndim not in (2, 3):
            raise ValueError(
                f"target: {path}: expected an (H, W) or (H, W, C) array of numbers, got "
                f"{arr.dtype} {arr.shape}"
            )
        arr = arr.astype(np.float32)
        if arr.ndim == 2:
            arr = arr[..., None]
        if arr.shape[-1] not in (1, 3, 4):
            raise ValueError(f"target: {path}: expected 1, 3 or 4 channels, got {arr.shape[-1]}")
        mask = None
        if arr.shape[-1] == 4:
            mask = (arr[..., 3:] > 0).astype(np.float32)
            arr = arr[..., :3]
        bad = ~np.isfinite(arr)
        if bad.any():
            n = int(bad.any(axis=-1).sum())
            raise ValueError(f"target: {path}: {n} pixel(s) are NaN or infinite")
        if (arr < 0).any():
            n = int((arr < 0).any(axis=-1).sum())
            raise ValueError(f"target: {path}: {n} pixel(s) have negative radiance")
        return Target(arr, grey=arr.shape[-1] == 1, mask=mask, path=path)
    raise ValueError(
        f"target: {path}: unsupported file type {os.path.splitext(path)[1]!r}; expected a photo "
        f"({', '.join(sorted(io.FILE_KINDS['ldr']))}) or radiance "
        f"({', '.join(sorted(io.FILE_KINDS['hdr'] | io.FILE_KINDS['npy']))})"
    )


def _synthetic_spec(t: dict, scene):
    unknown = set(t) - set(SYNTHETIC_TARGET_KEYS)
    if unknown or "synthetic" not in t:
        raise ValueError(
            "target: expected a file path or {synthetic: {path: value}, spp, seed, camera, "
            "views}"
            + (f"; unknown keys {sorted(unknown)}" if unknown else "")
        )
    for key in ("spp", "seed"):
        if key in t:
            v = t[key]
            if isinstance(v, bool) or not isinstance(v, int) or v < (1 if key == "spp" else 0):
                raise ValueError(f"target.{key}: expected a positive integer, got {v!r}")
    truth = {}
    synth = t["synthetic"] or {}
    if not isinstance(synth, dict):
        raise ValueError(f"target.synthetic: expected a mapping {{path: value}}, got {synth!r}")
    for path, value in synth.items():
        try:
            current = scene.get(path)
        except (ValueError, IndexError, AttributeError) as e:
            raise ValueError(f"target.synthetic.{path}: unknown parameter path ({e})") from None
        truth[path] = np.broadcast_to(
            _check_value(path, current, value, "synthetic value"), current.shape
        ).astype(np.float32)
    ldr = t.get("camera") is not None
    if ldr:
        check_synthetic_camera(t["camera"])
    views = t.get("views")
    if views is not None and (not isinstance(views, (list, tuple)) or not views):
        raise ValueError(
            "target.views: expected a list of camera poses ({origin, target, up, fov}: the "
            f"scene camera's keys), got {views!r}"
        )
    return truth, ldr


def _number(v, where, *, positive=True):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or (
        positive and not v > 0
    ):
        raise ValueError(f"{where}: expected a positive number, got {v!r}")
    return float(v)


def check_synthetic_camera(cam) -> None:
    """Check ``target.camera`` of a synthetic target: the camera that takes the photos
    (``response`` a gamma / analytic name, ``gamma``, ``exposure``, ``exposures`` — a bracket
    of several photos, relative to ``exposure`` —, ``bits``, ``white_balance``, ``noise``
    ``{gain, read_sigma}`` in normalised units, ``jpeg`` quality, the picture style
    ``color_matrix`` (3×3) and ``tonemap`` ``{op, <parameter>: value}``, checked as the fit
    camera's ``camera.color_matrix`` / ``camera.tonemap``)."""
    if not isinstance(cam, dict):
        raise ValueError(f"target.camera: expected a mapping, got {cam!r}")
    bad = set(cam) - set(TARGET_CAMERA_KEYS)
    if bad:
        raise ValueError(
            f"target.camera: unknown keys {sorted(bad)}; expected some of {TARGET_CAMERA_KEYS}"
        )
    from jaxgfx._checks import check_choice

    check_choice(cam.get("response", "gamma"), "target.camera.response",
                 tuple(m for m in RESPONSE_MODELS if m != "table"))
    if cam.get("bits", 8) not in (8, 16):
        raise ValueError(f"target.camera.bits: expected 8 or 16, got {cam.get('bits')!r}")
    for key in ("gamma", "exposure"):
        _number(cam.get(key, 1.0), f"target.camera.{key}")
    ex = cam.get("exposures")
    if ex is not None:
        if not isinstance(ex, (list, tuple)) or not ex:
            raise ValueError(f"target.camera.exposures: expected a list of numbers, got {ex!r}")
        for i, v in enumerate(ex):
            _number(v, f"target.camera.exposures[{i}]")
    wb = cam.get("white_balance")
    if wb is not None:
        if not isinstance(wb, (list, tuple)) or len(wb) != 3:
            raise ValueError(f"target.camera.white_balance: expected 3 gains, got {wb!r}")
        for i, v in enumerate(wb):
            _number(v, f"target.camera.white_balance[{i}]")
    noise = cam.get("noise")
    if noise is not None:
        if not isinstance(noise, dict) or set(noise) - {"gain", "read_sigma"}:
            raise ValueError(
                f"target.camera.noise: expected {{gain, read_sigma}}, got {noise!r}"
            )
        for k, v in noise.items():
            _number(v, f"target.camera.noise.{k}", positive=False)
            if v < 0:
                raise ValueError(f"target.camera.noise.{k}: expected >= 0, got {v!r}")
    q = cam.get("jpeg")
    if q is not None:
        if isinstance(q, bool) or not isinstance(q, int) or not 1 <= q <= 100:
            raise ValueError(f"target.camera.jpeg: expected a quality 1..100, got {q!r}")
        if cam.get("bits", 8) != 8:
            raise ValueError("target.camera.jpeg: JPEG photos are 8-bit (set bits: 8)")
    from .config import ToneSpec, _matrix3

    if cam.get("color_matrix") is not None:
        _matrix3(cam["color_matrix"], "target.camera.color_matrix")
    tm = cam.get("tonemap")
    if tm is not None:
        if not isinstance(tm, dict) or "op" not in tm or "fit" in tm:
            raise ValueError(f"target.camera.tonemap: expected {{op, <parameter>: value}}, got "
                             f"{tm!r}")
        try:
            ToneSpec(tm["op"], {k: v for k, v in tm.items() if k != "op"})
        except ValueError as e:
            raise ValueError(f"target.{e}") from None


def _photo_entries(target) -> list:
    """``[(where, path, exposure or None, pose or None)]`` of a file target (a path,
    ``{file, exposure, view}`` or a list of those)."""
    items = list(target) if isinstance(target, (list, tuple)) else [target]
    out = []
    for i, item in enumerate(items):
        where = f"target[{i}]" if isinstance(target, (list, tuple)) else "target"
        if isinstance(item, str):
            out.append((where, item, None, None))
        elif isinstance(item, dict) and "file" in item and "synthetic" not in item:
            bad = set(item) - set(PHOTO_KEYS)
            if bad:
                raise ValueError(f"{where}: unknown keys {sorted(bad)}; expected {PHOTO_KEYS}")
            ex = item.get("exposure")
            if ex is not None and ex != "exif":
                ex = _number(ex, f"{where}.exposure")
            pose = item.get("view")
            if "view" in item and not isinstance(pose, dict):
                raise ValueError(
                    f"{where}.view: expected a mapping of camera keys (origin, target, up, "
                    f"fov), got {pose!r}"
                )
            out.append((where, item["file"], ex, pose))
        else:
            raise ValueError(
                f"{where}: expected a photo path or {{file: PATH, exposure: SECONDS | exif, "
                "view: {origin, target, up, fov}}"
                + (" (a synthetic target cannot be one of a list)"
                   if isinstance(item, dict) and "synthetic" in item else "")
            )
        if not isinstance(out[-1][1], str) or not out[-1][1]:
            raise ValueError(f"{where}.file: expected a file path, got {out[-1][1]!r}")
    return out


def _photo_exposure(where, path, given, n_photos):
    """The exposure of one photo of a bracket: the given number, else (``exif`` or not
    given) EXIF ExposureTime; a bracket of several photos needs one for each."""
    if given is not None and given != "exif":
        return given
    from jaxgfx import io

    t = io.exif_exposure_time(path)
    if t is None and (given == "exif" or n_photos > 1):
        raise ValueError(
            f"{where}: {path}: no exposure information (no EXIF ExposureTime); a bracket of "
            f"several photos needs each photo's exposure: give {where}.exposure (seconds or a "
            "ratio)"
        )
    return t


def fixed_response_of(cfg: FitConfig, base: str | None, channels: int):
    """The camera's fixed :class:`~jaxgfx.hdr.CameraResponse` (an analytic curve, or the
    ``from`` file checked against ``camera.bits``), or None; also the start of a free-form
    fit from a file."""
    from jaxgfx import hdr

    spec = cfg.camera.response
    if spec.source is not None:
        path = resolve_path(spec.source, base, "camera.response.from")
        resp = hdr.load_response(path, bits=cfg.camera.bits)
        if resp.channels not in (1, channels):
            raise ValueError(
                f"camera.response.from: {path}: a {resp.channels}-channel response cannot "
                f"linearise {channels}-channel targets"
            )
        return resp
    if spec.model in ANALYTIC_RESPONSES:
        return hdr.CameraResponse.analytic(spec.model, anchor="unit")
    return None


def bracket_photos(exposures, view_of) -> np.ndarray:
    """The indices of the photos that ``camera.response.init: bracket`` recovers the starting
    curve from: those of the view with the most distinct exposures (ties: the first view).
    ``ValueError`` naming ``camera.response.init`` when no view has photos at two distinct
    exposures (one photo, or no exposure information: neither EXIF ``ExposureTime`` nor
    ``target[i].exposure`` nor ``target.camera.exposures``)."""
    ex = np.ones(1) if exposures is None else np.asarray(exposures, np.float64)
    vo = np.zeros(ex.size, np.int64) if view_of is None else np.asarray(view_of, np.int64)
    best, n_best = None, 1
    for v in np.unique(vo):
        n = np.unique(ex[vo == v]).size
        if n > n_best:
            best, n_best = v, n
    if best is None:
        raise ValueError(
            "camera.response.init: 'bracket' recovers the starting curve from photos of one "
            f"view at two or more distinct exposures; the {ex.size} photo(s) give "
            f"{sorted(set(ex.tolist()))} (relative exposures) — give each photo's exposure "
            "(target[i].exposure, EXIF ExposureTime or target.camera.exposures) or another "
            "init"
        )
    return np.flatnonzero(vo == best)


def prepare_fit(cfg: FitConfig, *, base_dir: str | None = None) -> Prepared:
    """Load the scene and the target and check parameters, bounds, the target's size, kind and
    content (no rendering).

    Raises ``ValueError`` naming the offending config entry: an unknown parameter path, an init
    or bound of the wrong shape, bounds that exclude the init, a target whose size differs from
    the camera's, an LDR target without ``camera`` (or a linear one with it), a photo of
    another bit depth than ``camera.bits``, non-finite radiance; ``FileNotFoundError`` for a
    missing scene or target file (relative paths: the config's folder, then the working
    directory).
    """
    if not isinstance(cfg, FitConfig):
        raise TypeError(f"cfg: expected a FitConfig, got {type(cfg).__name__}")
    scene = load_fit_scene(cfg, base_dir)
    paths, init, bounds, textures = [], {}, {}, []
    for path, raw in cfg.params.items():
        spec = _param_spec(path, raw)
        try:
            current = scene.get(path)
        except (ValueError, IndexError, AttributeError) as e:
            raise ValueError(f"params.{path}: unknown parameter path ({e})") from None
        if spec.prior is not None:
            if not is_texel_grid(current):
                raise ValueError(
                    f"params.{path}.prior: a smoothness prior needs a texel grid (a bitmap "
                    f"texture or environment map, shape (H, W, C)); {path} has shape "
                    f"{tuple(np.shape(current))}"
                )
            if "laplacian" in spec.prior and min(np.shape(current)[:2]) < 3:
                raise ValueError(
                    f"params.{path}.prior.laplacian: needs a grid of at least 3x3 texels, got "
                    f"{tuple(np.shape(current))}; use tv"
                )
            textures.append(path)
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
    truth, targets, exposures = None, None, None
    views = view_of = view_poses = None
    if isinstance(cfg.target, dict) and "file" not in cfg.target:
        truth, ldr = _synthetic_spec(dict(cfg.target), scene)
        target_spec = dict(cfg.target)
        n_ex = 1
        if ldr:
            tc = target_spec["camera"]
            exposures = np.asarray(tc.get("exposures", [1.0]), np.float64)
            exposures = exposures / exposures[0]
            n_ex = len(exposures)
        if target_spec.get("views") is not None:  # photos: each view at every exposure
            poses = [(f"target.views[{i}]", v) for i, v in enumerate(target_spec["views"])]
            views, view_of, view_poses = _views(scene, poses)
            view_of = np.repeat(view_of, n_ex)
            if exposures is not None:
                exposures = np.tile(exposures, len(poses))
    else:
        entries = _photo_entries(cfg.target)
        if any(e[3] is not None for e in entries):
            views, view_of, view_poses = _views(scene, [(e[0] + ".view", e[3])
                                                        for e in entries])
        per_view = np.bincount(view_of) if views is not None else [len(entries)]
        targets, seconds = [], []
        for i, (where, given_path, given_exposure, _) in enumerate(entries):
            path = resolve_path(given_path, base_dir, where)
            t = _read_target_file(path)
            th, tw = t.pixels.shape[:2]
            if (th, tw) != (h, w):
                raise ValueError(
                    f"{where}: {path}: size {tw}x{th} (W x H) differs from the scene camera's "
                    f"{w}x{h}; set render.width/height or resize the target"
                )
            if targets and (t.bits, t.grey) != (targets[0].bits, targets[0].grey):
                raise ValueError(
                    f"{where}: {path}: a {t.bits or 'float'}-bit {'grey' if t.grey else 'RGB'}"
                    f" target among {targets[0].bits or 'float'}-bit "
                    f"{'grey' if targets[0].grey else 'RGB'} ones; all targets of a fit must "
                    "be of one kind"
                )
            if t.bits is not None:
                n_bracket = per_view[0 if views is None else view_of[i]]
                t.exposure = _photo_exposure(where, path, given_exposure, n_bracket)
                seconds.append(t.exposure)
            targets.append(t)
        ldr = targets[0].bits is not None
        if not ldr and len(targets) > 1 and max(per_view) > 1:
            raise ValueError(
                "target: several radiance targets must be of distinct views "
                "(target[i].view); only photos (8/16-bit) make a bracket"
            )
        target_spec = [t.path for t in targets] if len(targets) > 1 else targets[0].path
        if ldr:
            known = [s_ is not None for s_ in seconds]
            if any(known) and not all(known):
                i = known.index(False)
                raise ValueError(
                    f"{entries[i][0]}: {targets[i].path}: no exposure information (no EXIF "
                    f"ExposureTime) while other photos have one; give {entries[i][0]}.exposure"
                )
            s0 = seconds[0]
            exposures = np.asarray([1.0 if s0 is None else v / s0 for v in seconds])
        if ldr and cfg.camera is not None and cfg.camera.bits != targets[0].bits:
            raise ValueError(
                f"camera.bits: the target {targets[0].path} is a {targets[0].bits}-bit photo; "
                f"expected camera.bits: {targets[0].bits}, got {cfg.camera.bits}"
            )
    if ldr and cfg.camera is None:
        raise ValueError("camera: an LDR (8-bit) target needs a camera section (response model)")
    if not ldr and cfg.camera is not None:
        raise ValueError("camera: only LDR targets (PNG/JPEG or a synthetic camera) use a camera")
    fixed = None
    if ldr:
        channels = 1 if (targets and targets[0].grey) else 3
        fixed = fixed_response_of(cfg, base_dir, channels)
        if cfg.camera.white_balance.fit and channels == 1:
            raise ValueError("camera.white_balance.fit: a grey target has no colour balance")
    if cfg.loss.jpeg_chroma != "none":
        if not ldr:
            raise ValueError(
                "loss.jpeg_chroma: models a JPEG codec's chroma subsampling of 8-bit photos; "
                "the target is radiance"
            )
        if channels == 1:
            raise ValueError("loss.jpeg_chroma: a grey target has no chroma")
        if cfg.camera.space != "linear":
            raise ValueError("loss.jpeg_chroma: only with camera.space: linear")
    if ldr and cfg.camera.response.init == "bracket":
        bracket_photos(exposures, view_of)  # raises when no view has a bracket
    matrix = None
    if ldr and cfg.camera.color_matrix is not None:
        if channels == 1:
            raise ValueError("camera.color_matrix: a grey target has no colour to mix")
        matrix = color_matrix_of(cfg.camera.color_matrix, base_dir)
    return Prepared(
        scene, paths, init, bounds, truth, target_spec, ldr,
        targets[0] if targets else None, targets, exposures, fixed, tuple(textures),
        views, view_of, view_poses, matrix,
    )


def color_matrix_of(spec, base: str | None) -> np.ndarray:
    """The camera's colour matrix ``(3, 3)``: ``spec.init``, or the ``matrix`` of the camera
    profile ``spec.source`` (``camera.color_matrix.from``; errors name the file)."""
    if spec.source is None:
        return np.asarray(spec.init, np.float64)
    from jaxgfx import hdr

    path = resolve_path(spec.source, base, "camera.color_matrix.from")
    prof = hdr.load_camera_profile(path)
    if prof.matrix is None:
        raise ValueError(f"camera.color_matrix.from: {path}: the camera profile has no colour "
                         "matrix (a RAW calibration writes one)")
    return np.asarray(prof.matrix, np.float64)
