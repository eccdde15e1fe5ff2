"""jaxgfx.hdr: camera response recovery, HDR radiance merging and synthetic bracketed stacks.

See ``docs/hdr.md``.
"""

from ._metrics import radiance_error as radiance_error
from ._metrics import response_curve_error as response_curve_error
from ._model import CameraResponse as CameraResponse
from .merge import merge_radiance as merge_radiance
from .response import RESPONSE_METHODS as RESPONSE_METHODS
from .response import recover_response as recover_response
from .synthetic import SYNTHETIC_RESPONSES as SYNTHETIC_RESPONSES
from .synthetic import BracketedStack as BracketedStack
from .synthetic import NoiseParams as NoiseParams
from .synthetic import make_bracketed_stack as make_bracketed_stack
from .synthetic import synthetic_radiance as synthetic_radiance
from .synthetic import synthetic_response as synthetic_response
from .weighting import WEIGHTINGS as WEIGHTINGS
from .weighting import weight_gaussian as weight_gaussian
from .weighting import weight_hat as weight_hat
from .weighting import weight_linear as weight_linear

__all__ = [
    "CameraResponse",
    "RESPONSE_METHODS",
    "WEIGHTINGS",
    "SYNTHETIC_RESPONSES",
    "BracketedStack",
    "NoiseParams",
    "recover_response",
    "merge_radiance",
    "response_curve_error",
    "radiance_error",
    "synthetic_radiance",
    "synthetic_response",
    "make_bracketed_stack",
    "weight_hat",
    "weight_gaussian",
    "weight_linear",
]
