"""The fit job's configuration: frozen dataclasses that validate themselves on construction
(``__post_init__``), so a config built in Python, read from YAML or assembled by the CLI gets
the same checks and the same messages. Choices are checked against the library's own
registries (:data:`jaxgfx.optim.OPTIMIZERS`, :data:`jaxgfx.optim.LOSSES`,
:data:`RESPONSE_MODELS`, ...), never against a retyped list."""

from __future__ import annotations

import dataclasses
from typing import Any

from jaxgfx._checks import check_choice
from jaxgfx.optim import LOSS_SPACES, LOSSES, OPTIMIZERS
from jaxgfx.render.integrators import INTEGRATORS

from .camera import RESPONSE_MODELS

__all__ = [
    "FitParam",
    "ResponseSpec",
    "ExposureSpec",
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


@dataclasses.dataclass(frozen=True)
class FitParam:
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

    def __post_init__(self):
        check_choice(self.model, "camera.response.model", RESPONSE_MODELS)
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

    def __post_init__(self):
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

    def __post_init__(self):
        if self.bits not in (8, 16):
            raise ValueError(f"camera.bits: expected 8 or 16, got {self.bits}")
        check_choice(self.space, "camera.space", LOSS_COMPARE_SPACES)


# first-order optimisers only: a fit renders with a fresh key per step, which least-squares
# solvers (jaxgfx.optim.LEAST_SQUARES_SOLVERS) cannot use (they need a deterministic residual)
FIT_OPTIMIZERS = tuple(OPTIMIZERS)


@dataclasses.dataclass(frozen=True)
class OptimizerConfig:
    name: str = "adam"
    lr: float = 0.02
    steps: int = 200
    tol: float | None = None
    lr_final: float | None = None  # exponential decay from lr to lr_final over the steps

    def __post_init__(self):
        check_choice(self.name, "optimizer.name", FIT_OPTIMIZERS)
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

    def __post_init__(self):
        check_choice(self.estimator, "render.estimator", ESTIMATORS)
        check_choice(self.integrator, "render.integrator", tuple(INTEGRATORS))
        _positive_int(self.spp, "render.spp")
        if self.estimator == "independent" and self.spp < 2:
            raise ValueError(f"render.spp: expected >= 2 (two half-spp images), got {self.spp}")
        _positive_int(self.max_depth, "render.max_depth")
        for name in ("width", "height"):
            v = getattr(self, name)
            if v is not None:
                _positive_int(v, f"render.{name}")


@dataclasses.dataclass(frozen=True)
class LossConfig:
    kind: str = "l2"  # l2 | relative_l2 | l1 (linear targets); LDR targets use censored L2
    space: str = "linear"  # linear | log | lab

    def __post_init__(self):
        check_choice(self.kind, "loss.kind", tuple(LOSSES))
        check_choice(self.space, "loss.space", LOSS_SPACES)


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

    def __post_init__(self):
        if not isinstance(self.scene, str) or not self.scene:
            raise ValueError(f"scene: expected a scene file path, got {self.scene!r}")
        if not isinstance(self.params, dict) or not self.params:
            raise ValueError("params: expected a mapping {parameter path: {init, min, max}}")
        if not isinstance(self.target, (str, dict)):
            raise ValueError("target: expected a file path or {synthetic: {...}}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise ValueError(f"seed: expected an integer, got {self.seed!r}")
