"""RAW sensor calibration from bracketed exposures: black/white levels, linearity, exposure
ratios, and a gathered, JSON-reportable :class:`RawCalibration`.

Modules: ``_common`` (CFA planes of :mod:`jaxgfx.image.bayer`, checks), ``levels`` (black,
white), ``linearity``, ``ratios`` (exposure ratios), ``calibration`` (the step functions with
their typed results, and :func:`calibrate_raw_stack` running them), ``color`` (white balance
and the camera matrix to a working colour space), ``chart`` (colour calibration from a
photographed ColorChecker: patch sampling from its corners, the matrix / root-polynomial fit on
CIEDE2000), ``vignetting`` (lens falloff from a flat field).

Conventions: a *mosaic* is a raw Bayer frame ``(..., H, W)`` in DN; ``cfa_channels`` splits it
into ``C = 4`` half-resolution planes ordered by position in the 2x2 tile
(``(0,0), (0,1), (1,0), (1,1)``; for ``"RGGB"``: R, G1, G2, B). Without a CFA pattern a stack
is ``(N, H, W)`` (one channel) or ``(N, H, W, C)``. Normalised signal is
``y = (raw - black) / (white - black)``. Every estimate comes with a standard error.
References: EMVA 1288 release 4.0 (2021) for black level, saturation and linearity; Janesick,
*Photon Transfer* (SPIE 2007); Robertson, Borman & Stevenson (2003) and Grossberg & Nayar
(2003) for exposure ratios from image pairs; Huber (1964) for the robust weights.
"""

from __future__ import annotations

from ._common import CFA_PATTERNS as CFA_PATTERNS
from ._common import cfa_channel_names as cfa_channel_names
from ._common import cfa_channels as cfa_channels
from .calibration import BlackLevelResult as BlackLevelResult
from .calibration import LinearityResult as LinearityResult
from .calibration import NoiseResult as NoiseResult
from .calibration import RawCalibration as RawCalibration
from .calibration import black_level_step as black_level_step
from .calibration import calibrate_raw_stack as calibrate_raw_stack
from .calibration import exposure_ratios_step as exposure_ratios_step
from .calibration import linearity_step as linearity_step
from .calibration import noise_step as noise_step
from .calibration import white_level_step as white_level_step
from .chart import CHART_MODELS as CHART_MODELS
from .chart import COLORCHECKER24 as COLORCHECKER24
from .chart import CORNER_ORDER as CORNER_ORDER
from .chart import ChartCalibration as ChartCalibration
from .chart import ChartReference as ChartReference
from .chart import apply_chart_calibration as apply_chart_calibration
from .chart import chart_delta_e as chart_delta_e
from .chart import chart_homography as chart_homography
from .chart import chart_patch_means as chart_patch_means
from .chart import chart_sample_points as chart_sample_points
from .chart import chart_terms as chart_terms
from .chart import colorchecker_reference as colorchecker_reference
from .chart import fit_chart_matrix as fit_chart_matrix
from .color import COLORSPACES as COLORSPACES
from .color import ILLUMINANT_CCT as ILLUMINANT_CCT
from .color import RAW_WHITE_BALANCES as RAW_WHITE_BALANCES
from .color import ColorTransform as ColorTransform
from .color import DngColorProfile as DngColorProfile
from .color import apply_color_transform as apply_color_transform
from .color import color_transform as color_transform
from .color import dng_camera_to_xyz_d50 as dng_camera_to_xyz_d50
from .color import dng_neutral_to_xy as dng_neutral_to_xy
from .color import dng_xyz_to_camera as dng_xyz_to_camera
from .color import exr_chromaticities as exr_chromaticities
from .color import xyz_d50_to_space_matrix as xyz_d50_to_space_matrix
from .levels import Measurement as Measurement
from .levels import WhiteLevel as WhiteLevel
from .levels import estimate_black_level as estimate_black_level
from .levels import estimate_white_level as estimate_white_level
from .linearity import Linearity as Linearity
from .linearity import linearity_check as linearity_check
from .ratios import ExposureRatios as ExposureRatios
from .ratios import estimate_exposure_ratios as estimate_exposure_ratios
from .ratios import pairwise_exposure_ratio as pairwise_exposure_ratio
from .vignetting import Vignetting as Vignetting
from .vignetting import devignette as devignette
from .vignetting import fit_vignetting as fit_vignetting

__all__ = [
    "CFA_PATTERNS",
    "cfa_channels",
    "cfa_channel_names",
    "Measurement",
    "WhiteLevel",
    "Linearity",
    "ExposureRatios",
    "RawCalibration",
    "estimate_black_level",
    "estimate_white_level",
    "linearity_check",
    "pairwise_exposure_ratio",
    "estimate_exposure_ratios",
    "calibrate_raw_stack",
    "BlackLevelResult",
    "LinearityResult",
    "NoiseResult",
    "white_level_step",
    "black_level_step",
    "linearity_step",
    "exposure_ratios_step",
    "noise_step",
    "COLORSPACES",
    "RAW_WHITE_BALANCES",
    "ILLUMINANT_CCT",
    "DngColorProfile",
    "ColorTransform",
    "dng_xyz_to_camera",
    "dng_neutral_to_xy",
    "dng_camera_to_xyz_d50",
    "xyz_d50_to_space_matrix",
    "color_transform",
    "apply_color_transform",
    "exr_chromaticities",
    "CHART_MODELS",
    "COLORCHECKER24",
    "CORNER_ORDER",
    "ChartReference",
    "ChartCalibration",
    "colorchecker_reference",
    "chart_homography",
    "chart_sample_points",
    "chart_patch_means",
    "chart_terms",
    "chart_delta_e",
    "fit_chart_matrix",
    "apply_chart_calibration",
    "Vignetting",
    "fit_vignetting",
    "devignette",
]
