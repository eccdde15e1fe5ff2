"""The fit job's configuration: frozen dataclasses that validate themselves on construction
(``__post_init__``), so a config built in Python, read from YAML or assembled by the CLI gets
the same checks and the same messages. Choices are checked against the library's own
registries (:data:`jaxgfx.optim.OPTIMIZERS`, :data:`jaxgfx.optim.LOSSES`,
:data:`RESPONSE_MODELS`, ...), never against a retyped list."""

from __future__ import annotations

import dataclasses
from typing import Any

from jaxgfx._checks import check_choice
from jaxgfx.config import load_config
from jaxgfx.hdr import ANALYTIC_RESPONSES, RESPONSE_METHODS, check_response_options
from jaxgfx.optim import FAST_COMPILE_OPTIONS, LOSS_SPACES, LOSSES, OPTIMIZERS
from jaxgfx.render.integrators import INTEGRATORS
from jaxgfx.render.integrators.path import ADJOINTS

from .camera import RESPONSE_MODELS

JPEG_CHROMA = {"none": None, "4:2:0": (2, 2), "4:2:2": (1, 2)}
"""``loss.jpeg_chroma``: the codec's chroma block (rows, columns) of each subsampling."""

__all__ = [
    "FitParam",
    "ResponseSpec",
    "ExposureSpec",
    "WhiteBalanceSpec",
    "ColorMatrixSpec",
    "ToneSpec",
    "PRIOR_KINDS",
    "CameraConfig",
    "OptimizerConfig",
    "RenderConfig",
    "LossConfig",
    "FitConfig",
    "ESTIMATORS",
    "LOSS_COMPARE_SPACES",
]

ESTIMATORS = ("independent", "correlated")
"""Monte Carlo gradient estimators of the fit (module doc of :mod:`jaxgfx.pipelines.fit`)."""

LOSS_COMPARE_SPACES = ("linear", "code")
"""Where an LDR target is compared: linearised radiance (unbiased) or display codes."""


def _positive_int(v, where):
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise ValueError(f"{where}: expected a positive integer, got {v!r}")


PRIOR_KINDS = ("tv", "laplacian")
"""Smoothness priors of texel-grid parameters (``params.X.prior: {tv: weight}``): total
variation ``mean |∇x|`` (Charbonnier, ε = 1e-3) or the squared Laplacian ``mean (Δx)²``."""


@dataclasses.dataclass(frozen=True)
class FitParam:
    """One fitted parameter: ``init`` (None: the scene's value), bounds ``min``/``max``,
    its own learning rate ``lr`` (None: ``optimizer.lr``; with a schedule, scaled alike) and a
    smoothness ``prior`` ``{tv | laplacian: weight}`` (texel grids only)."""

    init: float | tuple[float, ...] | None = None
    min: float | None = None
    max: float | None = None
    lr: float | None = None
    prior: dict | None = None

    def __post_init__(self):
        if self.lr is not None and not self.lr > 0:
            raise ValueError(f"lr: expected a positive number, got {self.lr}")
        if self.prior is not None:
            if not self.prior:
                raise ValueError("prior: expected {tv: weight} or {laplacian: weight}")
            for k, v in self.prior.items():
                check_choice(k, "prior", PRIOR_KINDS)
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0:
                    raise ValueError(f"prior.{k}: expected a weight >= 0, got {v!r}")


@dataclasses.dataclass(frozen=True)
class ResponseSpec:
    """The fit camera's response: ``model`` (:data:`RESPONSE_MODELS`), or ``source`` (YAML
    key ``from``: a response file of :func:`jaxgfx.hdr.save_response` or a calibrate
    ``report.json``). ``fit``: fit it (``gamma``: the exponent; ``table``: a free-form
    monotone curve of ``knots`` knots and ``channels`` 1 or 3 curves, started from ``init`` —
    a gamma exponent, an analytic curve's name, or the ``from`` curve — with a
    ``smoothness`` prior on its second differences). A loaded curve with ``fit: true`` starts
    a free-form fit. ``init: bracket`` starts the free-form table from the curve that
    :func:`jaxgfx.hdr.recover_response` (``init_method``, default Debevec) recovers from the
    target photos themselves: photos of one view at several exposures (EXIF or given) are a
    registered bracket; ``init_options`` are the method's options. ``start_prior`` keeps a
    free-form curve near its start, most where the photos hold few pixels
    (:func:`jaxgfx.pipelines.fit.job.start_prior_args`)."""

    model: str = "srgb"
    source: str | None = None
    fit: bool = False
    init: float | str = 2.2
    min: float = 0.2
    max: float = 6.0
    knots: int = 33
    channels: int = 1
    smoothness: float = 1e-3
    init_method: str = "debevec"  # init: bracket: the recovery method (hdr.RESPONSE_METHODS)
    # init: bracket: the method's options (hdr.recover_response keywords, e.g. subspace's
    # n_poly); checked with hdr.check_response_options before anything renders
    init_options: dict | None = None
    # the free-form curve's own learning rate (None: optimizer.lr): fitted as v, u = k v with
    # k = lr / optimizer.lr (the params.X.lr scheme)
    lr: float | None = None
    # a prior that keeps the free-form curve near its start where the photos hold few pixels:
    # weight x mean over knots of w_k (ln x_k - ln x0_k)^2, w_k = 1 / (n_k / n_mean + 0.01)
    # (n_k: the photos' pixels nearest knot k; 0: none, the program of before)
    start_prior: float = 0.0

    def __post_init__(self):
        check_choice(self.model, "camera.response.model", RESPONSE_MODELS)
        if self.init == "bracket":
            if self.source is not None:
                raise ValueError(
                    "camera.response.init: 'bracket' recovers the starting curve from the "
                    "target photos; it cannot be combined with 'from' (a loaded curve)"
                )
            if self.model != "table":
                raise ValueError(
                    "camera.response.init: 'bracket' starts a free-form curve; expected "
                    f"model: table (fit: true), got model {self.model!r}"
                )
            check_choice(self.init_method, "camera.response.init_method",
                         tuple(RESPONSE_METHODS))
        if self.init_options is not None:
            if self.init != "bracket":
                raise ValueError(
                    "camera.response.init_options: options of the bracket's recovery method; "
                    f"expected init: bracket, got init {self.init!r}"
                )
            check_response_options(self.init_method, self.init_options,
                                   name="camera.response.init_options")
        if self.source is not None:
            if not isinstance(self.source, str) or not self.source:
                raise ValueError(f"camera.response.from: expected a file path, got "
                                 f"{self.source!r}")
            if self.fit:  # a loaded curve that is refined: the free-form table starts from it
                object.__setattr__(self, "model", "table")
        if self.fit and self.model not in ("gamma", "table"):
            raise ValueError(
                "camera.response.fit: only 'gamma' (an exponent) and 'table' (a free-form "
                f"curve) have parameters, got {self.model!r}"
            )
        if self.model == "gamma" and not self.min < float(self.init) < self.max:
            raise ValueError(
                f"camera.response: init {self.init} outside the bounds ({self.min}, {self.max})"
            )
        if self.model == "table":
            init = self.init
            if isinstance(init, str):
                check_choice(init, "camera.response.init", (*ANALYTIC_RESPONSES, "bracket"))
            elif not init > 0:
                raise ValueError(f"camera.response.init: expected a gamma > 0, got {init}")
        if self.lr is not None:
            lr = self.lr
            if isinstance(lr, bool) or not isinstance(lr, (int, float)) or not lr > 0:
                raise ValueError(f"camera.response.lr: expected a positive number, got {lr!r}")
            if self.model != "table":
                raise ValueError(
                    "camera.response.lr: only a free-form curve (model: table) has its own "
                    f"learning rate; got model {self.model!r}"
                )
        sp = self.start_prior
        if isinstance(sp, bool) or not isinstance(sp, (int, float)) or not sp >= 0:
            raise ValueError(f"camera.response.start_prior: expected a number >= 0, got {sp!r}")
        if sp and self.model != "table":
            raise ValueError(
                "camera.response.start_prior: only a free-form curve (model: table, fit: true) "
                f"has a start to stay near; got model {self.model!r}"
            )
        _positive_int(self.knots, "camera.response.knots")
        if self.knots < 4:
            raise ValueError(f"camera.response.knots: expected >= 4, got {self.knots}")
        if self.channels not in (1, 3):
            raise ValueError(f"camera.response.channels: expected 1 or 3, got {self.channels}")
        if not self.smoothness >= 0:
            raise ValueError(f"camera.response.smoothness: expected >= 0, got {self.smoothness}")

    @property
    def curve_kind(self) -> str:
        """The slot of the fit's level table (:data:`CURVE_KINDS`)."""
        if self.model == "gamma":
            return "gamma"
        if self.model == "table":
            return "free"
        return "fixed"


@dataclasses.dataclass(frozen=True)
class ExposureSpec:
    """The exposure of the first photo (``init``, ``fit``, bounds); the others are at their
    given exposure ratios (EXIF or ``target[i].exposure``), each fitted too with
    ``per_photo``."""

    init: float = 1.0
    fit: bool = False
    min: float = 1e-3
    max: float = 1e3
    per_photo: bool = False
    # auto: start from the exposure that best maps the initial render onto the linearised
    # photos (median ratio over measured pixels, :func:`jaxgfx.pipelines.fit.job.auto_exposure`)
    # instead of init: a calibrated curve's scale is arbitrary (x = 1 at its extrapolated top)
    auto: bool = False

    def __post_init__(self):
        if not 0 < self.min < self.init < self.max:
            raise ValueError(
                f"camera.exposure: expected 0 < min < init < max, got init {self.init} and "
                f"bounds ({self.min}, {self.max})"
            )


@dataclasses.dataclass(frozen=True)
class WhiteBalanceSpec:
    """Per-channel gains before the response (``fit``: red and blue; green is the
    reference that the exposure scales)."""

    init: tuple[float, float, float] = (1.0, 1.0, 1.0)
    fit: bool = False
    min: float = 0.1
    max: float = 10.0

    def __post_init__(self):
        if not all(self.min < float(v) < self.max for v in self.init):
            raise ValueError(
                f"camera.white_balance: init {list(self.init)} outside the bounds "
                f"({self.min}, {self.max})"
            )


def _matrix3(v, where):
    import numpy as np

    try:
        m = np.asarray(v, np.float64)
    except (TypeError, ValueError):
        m = None
    if m is None or m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise ValueError(f"{where}: expected a 3x3 matrix of numbers (rows: output R, G, B), "
                         f"got {v!r}")
    if abs(np.linalg.det(m)) < 1e-9:
        raise ValueError(f"{where}: the matrix is singular (det {np.linalg.det(m):.3g})")
    return tuple(tuple(float(x) for x in row) for row in m)


@dataclasses.dataclass(frozen=True)
class ColorMatrixSpec:
    """The camera → output colour matrix ``y = M · (white balance · exposure · radiance)``:
    ``init`` a 3×3 matrix (rows: output R, G, B; default identity) or ``source`` (YAML
    ``from``: a ``camera.json`` profile of ``jaxgfx calibrate``, its ``matrix``); ``fit``:
    fitted with each row summing to 1 (white preserved: the neutral axis stays the white
    balance's and exposure's), as ``M = P + diag(1 − P·1)`` — the six off-diagonal entries
    are free, the diagonal follows."""

    init: Any = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    source: str | None = None
    fit: bool = False

    def __post_init__(self):
        import numpy as np

        if not isinstance(self.fit, bool):
            raise ValueError(f"camera.color_matrix.fit: expected true or false, got {self.fit!r}")
        if self.source is not None:
            if not isinstance(self.source, str) or not self.source:
                raise ValueError(f"camera.color_matrix.from: expected a camera profile path, "
                                 f"got {self.source!r}")
            if self.fit:
                raise ValueError(
                    "camera.color_matrix: a profile's matrix includes its white-balance gains "
                    "(rows need not sum to 1), so it is used fixed; to fit a matrix give "
                    "init: [[...]] with rows summing to 1"
                )
        m = _matrix3(self.init, "camera.color_matrix.init")
        object.__setattr__(self, "init", m)
        rows = np.sum(np.asarray(m), axis=1)
        if self.fit and not np.allclose(rows, 1.0, atol=1e-6):
            raise ValueError(
                "camera.color_matrix.init: a fitted matrix keeps white (each row sums to 1); "
                f"the rows sum to {[round(float(r), 6) for r in rows]}"
            )


def _tone_params(op):
    from jaxgfx.tonemap import TONEMAP_PARAMETERS

    return {k: v for k, v in TONEMAP_PARAMETERS[op].items() if k != "saturation"}


@dataclasses.dataclass(frozen=True)
class ToneSpec:
    """A global tone curve in the camera (:class:`jaxgfx.hdr.ToneCurve`): ``op`` one of
    :data:`jaxgfx.hdr.TONE_CURVES`, its curve parameters (``reinhard``: ``key``, ``white``;
    ``filmic``: ``exposure``; defaults: the operator's, :data:`jaxgfx.tonemap.
    TONEMAP_PARAMETERS`), and ``fit``: true (all), false, or a list of parameter names."""

    op: str = "filmic"
    params: Any = None
    fit: Any = False

    def __post_init__(self):
        from jaxgfx.hdr import TONE_CURVES

        check_choice(self.op, "camera.tonemap.op", TONE_CURVES)
        specs = _tone_params(self.op)
        given = dict(self.params or {})
        bad = set(given) - set(specs)
        if bad:
            raise ValueError(
                f"camera.tonemap: unknown parameter(s) {sorted(bad)} of {self.op!r}; expected "
                f"some of {sorted(specs)}"
            )
        vals = {}
        for k, spec in specs.items():
            v = given.get(k, spec.initial)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or v != v or (
                spec.constraint == "positive" and not v > 0
            ):
                what = "a number > 0" if spec.constraint == "positive" else "a number"
                raise ValueError(f"camera.tonemap.{k}: expected {what}, got {v!r}")
            vals[k] = float(v)
        object.__setattr__(self, "params", vals)
        fit = self.fit
        if isinstance(fit, bool):
            fit = tuple(specs) if fit else ()
        elif isinstance(fit, (list, tuple)) and all(isinstance(n, str) for n in fit):
            for n in fit:
                check_choice(n, "camera.tonemap.fit", tuple(specs))
            fit = tuple(fit)
        else:
            raise ValueError(
                f"camera.tonemap.fit: expected true, false or a list of {sorted(specs)}, got "
                f"{fit!r}"
            )
        object.__setattr__(self, "fit", fit)

    def constraint(self, name: str) -> str:
        return _tone_params(self.op)[name].constraint


@dataclasses.dataclass(frozen=True)
class CameraConfig:
    """The camera between the rendered radiance and LDR targets (``response`` a mapping with
    the keys of :class:`ResponseSpec`, ``from`` for ``source``, or a model name)."""

    response: Any = ResponseSpec()
    exposure: ExposureSpec = ExposureSpec()
    white_balance: WhiteBalanceSpec = WhiteBalanceSpec()
    bits: int = 8
    space: str = "linear"  # where the loss compares: linear (unbiased) | code (see module doc)
    # codes >= clip_code only bound the radiance from below, like the clip level (None: only
    # 2^bits - 1): JPEG rings a clipped highlight down to ~235-254, and a calibrated curve is
    # trusted only up to some level (docs/inverse.md section 2b)
    clip_code: int | None = None
    # bound: every clipped (or black) code bounds the radiance; unmeasured: only where no
    # other photo of the bracket measures the pixel (the hinge of a bound is biased by the
    # render's Monte Carlo noise; a measured pixel does not need it)
    clipped: str = "bound"
    # the picture style between the sensor and the response (None: none; a config without
    # them compiles to the program it compiled to before they existed)
    color_matrix: Any = None
    tonemap: Any = None

    def __post_init__(self):
        cm = self.color_matrix
        if cm is not None and not isinstance(cm, ColorMatrixSpec):
            if isinstance(cm, dict):
                cm = dict(cm)
                if "from" in cm:
                    cm["source"] = cm.pop("from")
                cm = load_config(ColorMatrixSpec, cm, where="camera.color_matrix")
            else:  # a bare matrix: fixed
                cm = ColorMatrixSpec(init=cm)
            object.__setattr__(self, "color_matrix", cm)
        tm = self.tonemap
        if tm is not None and not isinstance(tm, ToneSpec):
            if isinstance(tm, str):
                tm = {"op": tm}
            if not isinstance(tm, dict) or "op" not in tm:
                raise ValueError(
                    f"camera.tonemap: expected {{op: reinhard | filmic, <parameter>: value, fit: "
                    f"...}}, got {tm!r}"
                )
            tm = dict(tm)
            op, fit = tm.pop("op"), tm.pop("fit", False)
            tm = ToneSpec(op, tm, fit)
            object.__setattr__(self, "tonemap", tm)
        r = self.response
        if isinstance(r, str):
            r = {"model": r}
        if isinstance(r, dict):
            r = dict(r)
            if "from" in r:
                if "source" in r:
                    raise ValueError("camera.response: give 'from' or 'source', not both")
                r["source"] = r.pop("from")
            r = load_config(ResponseSpec, r, where="camera.response")
        if not isinstance(r, ResponseSpec):
            raise ValueError(f"camera.response: expected a mapping, got {self.response!r}")
        object.__setattr__(self, "response", r)
        if self.bits not in (8, 16):
            raise ValueError(f"camera.bits: expected 8 or 16, got {self.bits}")
        c = 2**self.bits - 1
        k = self.clip_code
        if k is not None and (isinstance(k, bool) or not isinstance(k, int) or not 1 < k <= c):
            raise ValueError(
                f"camera.clip_code: expected an integer code in 2..{c} (camera.bits "
                f"{self.bits}), got {k!r}"
            )
        check_choice(self.space, "camera.space", LOSS_COMPARE_SPACES)
        check_choice(self.clipped, "camera.clipped", ("bound", "unmeasured"))

    @property
    def tone_op(self) -> str | None:
        """The tone curve's operator (None: no tone curve): static, part of the program."""
        return None if self.tonemap is None else self.tonemap.op

    @property
    def has_matrix(self) -> bool:
        """A colour matrix in the chain (static, part of the program)."""
        return self.color_matrix is not None


# first-order optimisers only: a fit renders with a fresh key per step, which least-squares
# solvers (jaxgfx.optim.LEAST_SQUARES_SOLVERS) cannot use (they need a deterministic residual)
FIT_OPTIMIZERS = tuple(OPTIMIZERS)

FIT_ADJOINTS = (*ADJOINTS, "auto")
"""``render.adjoint``: the integrators' adjoints and ``"auto"`` (the fit chooses)."""


@dataclasses.dataclass(frozen=True)
class OptimizerConfig:
    name: str = "adam"
    lr: float = 0.02
    steps: int = 200
    tol: float | None = None
    lr_final: float | None = None  # exponential decay from lr to lr_final over the steps
    # compile the step with jaxgfx.optim.FAST_COMPILE_OPTIONS (docs/performance.md)
    fast_compile: bool = False
    # Polyak-Ruppert averaging: the fit's result is the mean of the iterates of the last
    # `average` fraction of the steps (jaxgfx.optim.fit's average_from); 0: the last iterate
    average: float = 0.0

    def __post_init__(self):
        check_choice(self.name, "optimizer.name", FIT_OPTIMIZERS)
        f = self.average
        if isinstance(f, bool) or not isinstance(f, (int, float)) or not 0 <= f <= 1:
            raise ValueError(
                "optimizer.average: expected the fraction of the steps, at the end, whose "
                f"iterates are averaged into the result (0 <= average <= 1; 0: off), got {f!r}"
            )
        if not isinstance(self.fast_compile, bool):
            raise ValueError(
                f"optimizer.fast_compile: expected true/false, got {self.fast_compile!r}"
            )
        if not self.lr > 0:
            raise ValueError(f"optimizer.lr: expected a positive number, got {self.lr}")
        if self.lr_final is not None and not 0 < self.lr_final <= self.lr:
            raise ValueError(
                f"optimizer.lr_final: expected 0 < lr_final <= lr ({self.lr}) — the schedule "
                f"decays from lr to lr_final; got {self.lr_final}"
            )
        _positive_int(self.steps, "optimizer.steps")
        if self.tol is not None and not self.tol >= 0:
            raise ValueError(f"optimizer.tol: expected a number >= 0, got {self.tol}")

    def average_from(self) -> int | None:
        """:func:`jaxgfx.optim.fit`'s ``average_from``: the last ``round(average · steps)``
        iterates are averaged (None: off, or a fraction that rounds to no iterate)."""
        m = int(round(self.average * self.steps))
        return None if m == 0 else self.steps - m

    def compiler_options(self):
        """XLA options for the fit step: :data:`jaxgfx.optim.FAST_COMPILE_OPTIONS` or None."""
        return dict(FAST_COMPILE_OPTIONS) if self.fast_compile else None

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
    # how reverse mode differentiates the path / direct integrator: "ad" (JAX's reverse mode
    # of the bounce loop), "replay" (path replay backpropagation: material, texture and
    # emitter parameters only; docs/render_gradients.md) or "auto" (replay where every fitted
    # parameter is one replay covers and the integrator is path or direct, else ad; the
    # choice is in result.json's "adjoint": jaxgfx.pipelines.fit.job.choose_adjoint)
    adjoint: str = "ad"

    def __post_init__(self):
        check_choice(self.estimator, "render.estimator", ESTIMATORS)
        check_choice(self.integrator, "render.integrator", tuple(INTEGRATORS))
        check_choice(self.adjoint, "render.adjoint", FIT_ADJOINTS)
        if self.adjoint == "replay" and self.integrator not in ("path", "direct"):
            raise ValueError(
                f"render.adjoint: {self.adjoint!r} needs integrator path or direct, got "
                f"{self.integrator!r}"
            )
        _positive_int(self.spp, "render.spp")
        if self.estimator == "independent" and self.spp < 2:
            raise ValueError(f"render.spp: expected >= 2 (two half-spp images), got {self.spp}")
        _positive_int(self.max_depth, "render.max_depth")
        for name in ("width", "height"):
            v = getattr(self, name)
            if v is not None:
                _positive_int(v, f"render.{name}")

    @property
    def integrator_spec(self):
        """What ``render(..., integrator=...)`` takes: the name, or ``{type, adjoint}``
        (``"auto"`` not yet resolved: the name, whose renders have the same values)."""
        if self.adjoint in ("ad", "auto"):
            return self.integrator
        return {"type": self.integrator, "adjoint": self.adjoint}


@dataclasses.dataclass(frozen=True)
class LossConfig:
    kind: str = "l2"  # l2 | relative_l2 | l1 (linear targets); LDR targets use censored L2
    space: str = "linear"  # linear | log | lab
    # LDR colour photos that went through a JPEG codec's chroma subsampling: the residual's
    # chroma (the part outside the Rec. 601 luma axis) is averaged over the codec's chroma
    # blocks before it is squared (jaxgfx.pipelines.fit.loss.chroma_subsampled); "none": per
    # pixel (a config without it compiles to the program of before)
    jpeg_chroma: str = "none"  # none | 4:2:0 | 4:2:2

    def __post_init__(self):
        check_choice(self.kind, "loss.kind", tuple(LOSSES))
        check_choice(self.space, "loss.space", LOSS_SPACES)
        check_choice(self.jpeg_chroma, "loss.jpeg_chroma", tuple(JPEG_CHROMA))


@dataclasses.dataclass(frozen=True)
class FitConfig:
    scene: str
    target: Any  # path, {file, exposure}, a list of those, or {synthetic: ..., camera: ...}
    params: dict
    camera: CameraConfig | None = None
    optimizer: OptimizerConfig = OptimizerConfig()
    render: RenderConfig = RenderConfig()
    loss: LossConfig = LossConfig()
    seed: int = 0
    progress: bool = True

    def __post_init__(self):
        if not isinstance(self.scene, str) or not self.scene:
            raise ValueError(f"scene: expected a scene file path, got {self.scene!r}")
        if not isinstance(self.params, dict) or not self.params:
            raise ValueError("params: expected a mapping {parameter path: {init, min, max}}")
        if not isinstance(self.target, (str, dict, list, tuple)) or (
            isinstance(self.target, (list, tuple)) and not self.target
        ):
            raise ValueError(
                "target: expected a file path, {file: PATH, exposure: ...}, a list of those, "
                "or {synthetic: {...}}"
            )
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise ValueError(f"seed: expected an integer, got {self.seed!r}")
