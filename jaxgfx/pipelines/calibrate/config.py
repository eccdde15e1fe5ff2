"""The calibration job's configuration: frozen dataclasses that validate themselves on
construction (``__post_init__``), so a config built in Python, read from YAML
(``configs/calibrate.yaml``) or assembled by the CLI gets the same checks and messages.
Choices are checked with :func:`jaxgfx._checks.check_choice` against the library's own
registries (:data:`jaxgfx.hdr.RESPONSE_METHODS`, :data:`jaxgfx.hdr.merge.MERGE_WEIGHTINGS`,
:data:`jaxgfx.hdr.ALIGN_METHODS`, :data:`jaxgfx.image.DEMOSAIC_METHODS`,
:data:`jaxgfx.tonemap.TONEMAP_METHODS`, :data:`jaxgfx.hdr.SYNTHETIC_RESPONSES`,
:data:`jaxgfx.hdr.raw.COLORSPACES`, :data:`jaxgfx.hdr.raw.RAW_WHITE_BALANCES`,
:data:`jaxgfx.hdr.raw.CHART_MODELS`), never against a retyped list."""

from __future__ import annotations

import dataclasses

import numpy as np

from jaxgfx._checks import check_choice
from jaxgfx.hdr.align import ALIGN_METHODS
from jaxgfx.hdr.merge import MERGE_WEIGHTINGS
from jaxgfx.hdr.raw.chart import CHART_MODELS, CORNER_ORDER
from jaxgfx.hdr.raw.color import COLORSPACES, RAW_WHITE_BALANCES
from jaxgfx.hdr.response import RESPONSE_METHODS, check_response_options
from jaxgfx.hdr.synthetic import SYNTHETIC_RESPONSES
from jaxgfx.image.bayer import DEMOSAIC_METHODS
from jaxgfx.tonemap import TONEMAP_METHODS

__all__ = [
    "SyntheticConfig",
    "ResponseConfig",
    "MergeConfig",
    "AlignConfig",
    "CalibrateConfig",
]


@dataclasses.dataclass(frozen=True)
class SyntheticConfig:
    """The embedded default stack: known radiance, response and noise."""

    seed: int = 0
    height: int = 240
    width: int = 320
    dynamic_range: float = 1.0e4
    response: str = "filmic"
    exposure_times: tuple[float, ...] = (0.5, 4.0, 32.0, 256.0, 2048.0)
    bits: int = 8
    gain: float = 2.0e-4
    read_sigma: float = 1.0e-3

    def __post_init__(self):
        for name in ("height", "width"):
            if getattr(self, name) < 8:
                raise ValueError(
                    f"synthetic.{name}: expected at least 8 pixels, got {getattr(self, name)}"
                )
        if len(self.exposure_times) < 2 or any(t <= 0 for t in self.exposure_times):
            raise ValueError("synthetic.exposure_times: expected >= 2 positive times")
        if self.bits not in (8, 16):
            raise ValueError(f"synthetic.bits: expected 8 or 16, got {self.bits}")
        if self.seed < 0:
            raise ValueError(f"synthetic.seed: expected an integer >= 0, got {self.seed}")
        if not (np.isfinite(self.dynamic_range) and self.dynamic_range > 1):
            raise ValueError(
                f"synthetic.dynamic_range: expected a finite value > 1, got {self.dynamic_range}"
            )
        for name in ("gain", "read_sigma"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"synthetic.{name}: expected a finite value >= 0, got {v}")
        if any(not np.isfinite(t) for t in self.exposure_times):
            raise ValueError("synthetic.exposure_times: expected finite times")
        check_choice(self.response, "synthetic.response", SYNTHETIC_RESPONSES)


@dataclasses.dataclass(frozen=True)
class ResponseConfig:
    method: str = "debevec"
    options: dict = dataclasses.field(default_factory=dict)
    compare: tuple[str, ...] = ("debevec", "robertson", "polynomial", "spline")

    def __post_init__(self):
        check_choice(self.method, "response.method", RESPONSE_METHODS)
        for i, m in enumerate(self.compare):
            check_choice(m, f"response.compare[{i}]", RESPONSE_METHODS)
        check_response_options(self.method, self.options, name="response.options")


@dataclasses.dataclass(frozen=True)
class MergeConfig:
    weighting: str = "slope"
    deghost: bool = False  # hdr.merge_deghosted: frames inconsistent with a reference dropped

    def __post_init__(self):
        check_choice(self.weighting, "merge.weighting", MERGE_WEIGHTINGS)
        if not isinstance(self.deghost, bool):
            raise ValueError(f"merge.deghost: expected true/false, got {self.deghost!r}")


@dataclasses.dataclass(frozen=True)
class AlignConfig:
    enabled: bool = False
    method: str = "phase"

    def __post_init__(self):
        check_choice(self.method, "align.method", ALIGN_METHODS)


@dataclasses.dataclass(frozen=True)
class CalibrateConfig:
    """What to compute (the YAML of ``configs/calibrate.yaml``); every field checked when the
    object is built (from Python, YAML or the CLI alike)."""

    exposure_times: tuple[float, ...] | None = None
    synthetic: SyntheticConfig = SyntheticConfig()
    response: ResponseConfig = ResponseConfig()
    merge: MergeConfig = MergeConfig()
    align: AlignConfig = AlignConfig()
    demosaic: str = "malvar"
    preview_key: float = 0.18
    tonemap: tuple[str, ...] = ()
    colorspace: str = "rec709"
    white_balance: str = "as_shot"
    flat_field: str | None = None
    # a ColorChecker in view: its patch grid's corners x0,y0,...,x3,y3 (pixels of the merged
    # image; top-left, top-right, bottom-right, bottom-left), fitted by hdr.raw.fit_chart_matrix
    chart: tuple[float, ...] | None = None
    chart_model: str = "matrix"

    def __post_init__(self):
        if self.flat_field is not None and not isinstance(self.flat_field, str):
            raise ValueError(f"flat_field: expected a RAW file path, got {self.flat_field!r}")
        check_choice(self.chart_model, "chart_model", CHART_MODELS)
        if self.chart is not None:
            c = self.chart
            if (
                not isinstance(c, (tuple, list))
                or len(c) != 8
                or not all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
                    for v in c
                )
            ):
                raise ValueError(
                    "chart: expected 8 numbers x0,y0,x1,y1,x2,y2,x3,y3, the chart's corners in "
                    f"pixels ({', '.join(CORNER_ORDER)}), got {c!r}"
                )
            if self.colorspace == "camera":
                raise ValueError(
                    "chart: the chart fit maps camera RGB to a colour space; it does not go "
                    "with colorspace 'camera' (choose e.g. rec709)"
                )
        check_choice(self.demosaic, "demosaic", DEMOSAIC_METHODS)
        check_choice(self.colorspace, "colorspace", COLORSPACES)
        check_choice(self.white_balance, "white_balance", RAW_WHITE_BALANCES)
        for i, op in enumerate(self.tonemap):
            check_choice(op, f"tonemap[{i}]", TONEMAP_METHODS)
        if not (np.isfinite(self.preview_key) and self.preview_key > 0):
            raise ValueError(
                f"preview_key: expected a finite value > 0 (log-average maps to it), "
                f"got {self.preview_key!r}"
            )
        if self.exposure_times is not None:
            from jaxgfx.io import parse_exposure_time

            for i, t in enumerate(self.exposure_times):
                parse_exposure_time(t, f"exposure_times[{i}]")
        if self.merge.weighting == "noise":
            raise ValueError(
                "merge.weighting: 'noise' needs a noise model, which LDR calibration does not "
                "fit (RAW inputs use it automatically); expected hat, gaussian or linear"
            )
