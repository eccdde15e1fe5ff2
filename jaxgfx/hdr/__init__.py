"""jaxgfx.hdr: camera response recovery, HDR radiance merging and synthetic bracketed stacks.

See ``docs/hdr.md``.
"""

from ._curves import ANALYTIC_RESPONSES as ANALYTIC_RESPONSES
from ._metrics import radiance_error as radiance_error
from ._metrics import response_curve_error as response_curve_error
from ._model import RESPONSE_KINDS as RESPONSE_KINDS
from ._model import CameraResponse as CameraResponse
from .camera import CAMERA_BITS as CAMERA_BITS
from .camera import TONE_CURVES as TONE_CURVES
from .camera import Camera as Camera
from .camera import ToneCurve as ToneCurve
from .merge import SLOPE_NOISE_RATIO as SLOPE_NOISE_RATIO
from .merge import merge_radiance as merge_radiance
from .merge import slope_weights as slope_weights
from .response import MIN_USABLE_PIXELS as MIN_USABLE_PIXELS
from .response import RESPONSE_METHODS as RESPONSE_METHODS
from .response import check_response_options as check_response_options
from .response import recover_response as recover_response
from .response_io import RESPONSE_FILE_FORMAT as RESPONSE_FILE_FORMAT
from .response_io import load_response as load_response
from .response_io import save_response as save_response
from .synthetic import CANON_EOS_5D_MARK_II as CANON_EOS_5D_MARK_II
from .synthetic import SYNTHETIC_RESPONSES as SYNTHETIC_RESPONSES
from .synthetic import BracketedStack as BracketedStack
from .synthetic import colorchecker_scene as colorchecker_scene
from .synthetic import jpeg_roundtrip as jpeg_roundtrip
from .synthetic import make_bracketed_stack as make_bracketed_stack
from .synthetic import make_jpeg_stack as make_jpeg_stack
from .synthetic import read_dorf_curves as read_dorf_curves
from .synthetic import response_from_curve as response_from_curve
from .synthetic import synthetic_radiance as synthetic_radiance
from .synthetic import synthetic_response as synthetic_response
from .synthetic import write_dng_bracket as write_dng_bracket
from .weighting import WEIGHTINGS as WEIGHTINGS
from .weighting import weight_gaussian as weight_gaussian
from .weighting import weight_hat as weight_hat
from .weighting import weight_linear as weight_linear

__all__ = [
    "CameraResponse",
    "RESPONSE_KINDS",
    "ANALYTIC_RESPONSES",
    "RESPONSE_METHODS",
    "WEIGHTINGS",
    "SYNTHETIC_RESPONSES",
    "write_dng_bracket",
    "CANON_EOS_5D_MARK_II",
    "colorchecker_scene",
    "BracketedStack",
    "Camera",
    "ToneCurve",
    "TONE_CURVES",
    "CAMERA_BITS",
    "recover_response",
    "save_response",
    "load_response",
    "RESPONSE_FILE_FORMAT",
    "check_response_options",
    "MIN_USABLE_PIXELS",
    "merge_radiance",
    "slope_weights",
    "SLOPE_NOISE_RATIO",
    "response_curve_error",
    "radiance_error",
    "synthetic_radiance",
    "synthetic_response",
    "make_bracketed_stack",
    "make_jpeg_stack",
    "read_dorf_curves",
    "response_from_curve",
    "jpeg_roundtrip",
    "weight_hat",
    "weight_gaussian",
    "weight_linear",
]

# --- pixel encodings (docs/io.md); noise, RAW calibration, alignment (docs/raw_calibration.md)
from .align import ALIGN_METHODS as ALIGN_METHODS
from .align import SHIFT_MODES as SHIFT_MODES
from .align import align_raw_stack as align_raw_stack
from .align import align_stack as align_stack
from .align import mtb_align as mtb_align
from .align import phase_correlation as phase_correlation
from .align import shift_image as shift_image
from .encodings import ENCODINGS as ENCODINGS
from .encodings import half_roundtrip as half_roundtrip
from .encodings import logluv24_decode as logluv24_decode
from .encodings import logluv24_encode as logluv24_encode
from .encodings import logluv32_decode as logluv32_decode
from .encodings import logluv32_encode as logluv32_encode
from .encodings import rgbe_decode as rgbe_decode
from .encodings import rgbe_encode as rgbe_encode
from .noise import NoiseModel as NoiseModel
from .noise import fit_photon_transfer as fit_photon_transfer
from .raw import RawCalibration as RawCalibration
from .raw import calibrate_raw_stack as calibrate_raw_stack
from .raw import estimate_black_level as estimate_black_level
from .raw import estimate_exposure_ratios as estimate_exposure_ratios
from .raw import estimate_white_level as estimate_white_level
from .raw import linearity_check as linearity_check
from .selfcheck import LOO_BANDS as LOO_BANDS
from .selfcheck import LeaveOneOut as LeaveOneOut
from .selfcheck import leave_one_out as leave_one_out

__all__ += [
    "ALIGN_METHODS",
    "SHIFT_MODES",
    "align_stack",
    "align_raw_stack",
    "mtb_align",
    "phase_correlation",
    "shift_image",
    "ENCODINGS",
    "half_roundtrip",
    "logluv24_decode",
    "logluv24_encode",
    "logluv32_decode",
    "logluv32_encode",
    "rgbe_decode",
    "rgbe_encode",
    "NoiseModel",
    "fit_photon_transfer",
    "RawCalibration",
    "calibrate_raw_stack",
    "estimate_black_level",
    "estimate_exposure_ratios",
    "estimate_white_level",
    "linearity_check",
]

__all__ += ["LOO_BANDS", "LeaveOneOut", "leave_one_out"]

# --- camera profiles: the fitted camera as one file (docs/raw_calibration.md)
from .camera_profile import CAMERA_PROFILE_FORMAT as CAMERA_PROFILE_FORMAT  # noqa: E402
from .camera_profile import CameraProfile as CameraProfile  # noqa: E402
from .camera_profile import load_camera_profile as load_camera_profile  # noqa: E402
from .camera_profile import save_camera_profile as save_camera_profile  # noqa: E402

__all__ += ["CAMERA_PROFILE_FORMAT", "CameraProfile", "load_camera_profile", "save_camera_profile"]

# --- exposure fusion (docs/tonemap.md; owner: tonemap)
from .fusion import exposure_fusion as exposure_fusion  # noqa: E402

__all__ += ["exposure_fusion"]

# --- ghost-free merge of brackets of moving scenes (docs/hdr.md)
from .deghost import DeghostResult as DeghostResult  # noqa: E402
from .deghost import merge_deghosted as merge_deghosted  # noqa: E402

__all__ += ["DeghostResult", "merge_deghosted"]
