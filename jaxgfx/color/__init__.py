"""jaxgfx.color: transfer functions, colour spaces, colour differences, chromatic adaptation
and white balance (see docs/color.md).

All functions are pure, jittable, vmappable and differentiable; colours are channels-last
``(..., 3)`` and the dtype follows the input.
"""

from .adaptation import CAT_MATRICES as CAT_MATRICES
from .adaptation import __all__ as _adaptation_all
from .adaptation import chromatic_adaptation as chromatic_adaptation
from .adaptation import chromatic_adaptation_matrix as chromatic_adaptation_matrix
from .adaptation import rgb_to_rgb as rgb_to_rgb
from .difference import __all__ as _difference_all
from .difference import delta_e_1976 as delta_e_1976
from .difference import delta_e_2000 as delta_e_2000
from .difference import delta_e_2000_residuals as delta_e_2000_residuals
from .spaces import LUMINANCE_WEIGHTS as LUMINANCE_WEIGHTS
from .spaces import RGB_SPACES as RGB_SPACES
from .spaces import WHITEPOINTS as WHITEPOINTS
from .spaces import YIQ_MATRIX as YIQ_MATRIX
from .spaces import RGBSpace as RGBSpace
from .spaces import __all__ as _spaces_all
from .spaces import cmyk_to_rgb as cmyk_to_rgb
from .spaces import hsv_to_rgb as hsv_to_rgb
from .spaces import lab_to_xyz as lab_to_xyz
from .spaces import luminance as luminance
from .spaces import normalised_primary_matrix as normalised_primary_matrix
from .spaces import rgb_to_cmyk as rgb_to_cmyk
from .spaces import rgb_to_hsv as rgb_to_hsv
from .spaces import rgb_to_xyz as rgb_to_xyz
from .spaces import rgb_to_xyz_matrix as rgb_to_xyz_matrix
from .spaces import rgb_to_yiq as rgb_to_yiq
from .spaces import whitepoint_xyz as whitepoint_xyz
from .spaces import xy_to_xyz as xy_to_xyz
from .spaces import xyY_to_xyz as xyY_to_xyz
from .spaces import xyz_to_lab as xyz_to_lab
from .spaces import xyz_to_rgb as xyz_to_rgb
from .spaces import xyz_to_xyY as xyz_to_xyY
from .spaces import yiq_to_rgb as yiq_to_rgb
from .temperature import ROBERTSON1968 as ROBERTSON1968
from .temperature import cct_to_xy as cct_to_xy
from .temperature import xy_to_cct as xy_to_cct
from .transfer import ACES_NARKOWICZ2015 as ACES_NARKOWICZ2015
from .transfer import ADOBE_RGB_GAMMA as ADOBE_RGB_GAMMA
from .transfer import TRANSFER_FUNCTIONS as TRANSFER_FUNCTIONS
from .transfer import __all__ as _transfer_all
from .transfer import aces_narkowicz2015 as aces_narkowicz2015
from .transfer import adobe_rgb_to_linear as adobe_rgb_to_linear
from .transfer import gamma_decode as gamma_decode
from .transfer import gamma_encode as gamma_encode
from .transfer import linear_to_adobe_rgb as linear_to_adobe_rgb
from .transfer import linear_to_prophoto as linear_to_prophoto
from .transfer import linear_to_rec709 as linear_to_rec709
from .transfer import linear_to_srgb as linear_to_srgb
from .transfer import prophoto_to_linear as prophoto_to_linear
from .transfer import rec709_to_linear as rec709_to_linear
from .transfer import srgb_to_linear as srgb_to_linear
from .transfer import transfer_decode as transfer_decode
from .transfer import transfer_encode as transfer_encode
from .white_balance import WHITE_BALANCE_METHODS as WHITE_BALANCE_METHODS
from .white_balance import __all__ as _white_balance_all
from .white_balance import apply_white_balance as apply_white_balance
from .white_balance import white_balance as white_balance
from .white_balance import white_balance_brightest_pixel as white_balance_brightest_pixel
from .white_balance import (
    white_balance_brightest_pixel_gains as white_balance_brightest_pixel_gains,
)
from .white_balance import white_balance_grey_world as white_balance_grey_world
from .white_balance import white_balance_grey_world_gains as white_balance_grey_world_gains
from .white_balance import white_balance_stretch as white_balance_stretch
from .white_balance import white_balance_stretch_limits as white_balance_stretch_limits
from .white_balance import white_balance_von_kries as white_balance_von_kries
from .white_balance import white_balance_von_kries_matrix as white_balance_von_kries_matrix
from .white_balance import white_balance_white_patch as white_balance_white_patch
from .white_balance import white_balance_white_patch_gains as white_balance_white_patch_gains

# the public names are those of the submodules (each lists its own), less temperature's
# uv1960 helpers
__all__ = [
    *_transfer_all,
    *_spaces_all,
    *_difference_all,
    *_adaptation_all,
    *_white_balance_all,
    "ROBERTSON1968",
    "xy_to_cct",
    "cct_to_xy",
]
