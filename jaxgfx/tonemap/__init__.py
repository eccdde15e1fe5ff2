"""jaxgfx.tonemap: displaying HDR images (lecture 2) -- global and local tone-mapping
operators, colour handling, video smoothing, inverse tone mapping and parameter fitting.

Operators map linear relative radiance ``(..., H, W, 3)`` (or luminance ``(..., H, W)``) to
display values in [0, 1], sRGB-encoded by default (``encode="linear"`` to skip). All are pure,
jittable, vmappable and differentiable in their continuous parameters. See docs/tonemap.md.
Exposure fusion (Mertens et al. 2007) lives in :func:`jaxgfx.hdr.exposure_fusion`.
"""

from ._common import ENCODINGS as ENCODINGS
from ._common import AdaptationStats as AdaptationStats
from ._common import image_stats as image_stats
from ._fit import FIT_LOSSES as FIT_LOSSES
from ._fit import TonemapFit as TonemapFit
from ._fit import fit_tonemap as fit_tonemap
from ._global import tonemap_ACES_Narkowicz2015 as tonemap_ACES_Narkowicz2015
from ._global import tonemap_Drago2003 as tonemap_Drago2003
from ._global import tonemap_exposure as tonemap_exposure
from ._global import tonemap_Hable2010 as tonemap_Hable2010
from ._global import tonemap_Reinhard2002 as tonemap_Reinhard2002
from ._global import tonemap_Reinhard2005 as tonemap_Reinhard2005
from ._inverse import inverse_tonemap as inverse_tonemap
from ._local import tonemap_contrast_inversion as tonemap_contrast_inversion
from ._local import tonemap_Durand2002 as tonemap_Durand2002
from ._local import tonemap_Fattal2002 as tonemap_Fattal2002
from ._local import tonemap_Reinhard2002_local as tonemap_Reinhard2002_local
from ._mantiuk import mantiuk_transducer as mantiuk_transducer
from ._mantiuk import mantiuk_transducer_inverse as mantiuk_transducer_inverse
from ._mantiuk import tonemap_Mantiuk2006 as tonemap_Mantiuk2006
from ._poisson import solve_poisson_neumann as solve_poisson_neumann
from ._registry import GLOBAL_METHODS as GLOBAL_METHODS
from ._registry import TONEMAP_METHODS as TONEMAP_METHODS
from ._registry import TONEMAP_PARAMETERS as TONEMAP_PARAMETERS
from ._registry import ParamSpec as ParamSpec
from ._registry import tonemap as tonemap
from ._temporal import flicker as flicker
from ._temporal import smooth_adaptation as smooth_adaptation
from ._temporal import smoothed_stats as smoothed_stats

__all__ = [
    "ENCODINGS",
    "AdaptationStats",
    "image_stats",
    "TONEMAP_METHODS",
    "TONEMAP_PARAMETERS",
    "GLOBAL_METHODS",
    "ParamSpec",
    "tonemap",
    "tonemap_exposure",
    "tonemap_Drago2003",
    "tonemap_Reinhard2002",
    "tonemap_Reinhard2005",
    "tonemap_ACES_Narkowicz2015",
    "tonemap_Hable2010",
    "tonemap_Reinhard2002_local",
    "tonemap_contrast_inversion",
    "tonemap_Durand2002",
    "tonemap_Fattal2002",
    "tonemap_Mantiuk2006",
    "mantiuk_transducer",
    "mantiuk_transducer_inverse",
    "solve_poisson_neumann",
    "smooth_adaptation",
    "smoothed_stats",
    "flicker",
    "inverse_tonemap",
    "fit_tonemap",
    "TonemapFit",
    "FIT_LOSSES",
]
