"""jaxgfx.image: convolution, filters, edges, point operators, noise, Fourier filters, Bayer.

Images are channels-last ``(..., H, W, C)`` or single-channel ``(..., H, W)`` float arrays;
every function is jittable, vmappable and differentiable in its continuous parameters.
See docs/image_filters.md and docs/image_point.md.
"""

# --- convolution, filters, edges (docs/image_filters.md) ---
from ._padding import PADDING_MODES, pad_image
from .convolve import (
    CONVOLVE_METHODS,
    convolve,
    convolve_separable,
    separable_factors,
)
from .edges import (
    EDGE_OPERATORS,
    canny,
    gradient_magnitude_direction,
    image_gradients,
    prewitt,
    roberts,
    sobel,
    soft_canny,
)
from .filters import (
    BILATERAL_METHODS,
    bilateral_Chen2007,
    bilateral_filter,
    bilateral_Tomasi1998,
    box_blur,
    gaussian_blur,
    gaussian_kernel1d,
    laplacian_of_gaussian,
    median_filter,
    sharpen,
    unsharp_mask,
)

__all__ = [
    "PADDING_MODES",
    "pad_image",
    "CONVOLVE_METHODS",
    "convolve",
    "convolve_separable",
    "separable_factors",
    "BILATERAL_METHODS",
    "gaussian_kernel1d",
    "gaussian_blur",
    "box_blur",
    "median_filter",
    "bilateral_filter",
    "bilateral_Tomasi1998",
    "bilateral_Chen2007",
    "unsharp_mask",
    "laplacian_of_gaussian",
    "sharpen",
    "EDGE_OPERATORS",
    "roberts",
    "prewitt",
    "sobel",
    "image_gradients",
    "gradient_magnitude_direction",
    "canny",
    "soft_canny",
]
# --- end convolution, filters, edges ---

# --- imgpoint block: point operators, noise, Fourier filters, Bayer (owner: imgpoint) ---
from .bayer import BAYER_PATTERNS as BAYER_PATTERNS
from .bayer import DEMOSAIC_METHODS as DEMOSAIC_METHODS
from .bayer import bayer_masks as bayer_masks
from .bayer import bayer_mosaic as bayer_mosaic
from .bayer import demosaic as demosaic
from .bayer import demosaic_bilinear as demosaic_bilinear
from .bayer import demosaic_Malvar2004 as demosaic_Malvar2004
from .fourier import FOURIER_FILTER_KINDS as FOURIER_FILTER_KINDS
from .fourier import FOURIER_PADDINGS as FOURIER_PADDINGS
from .fourier import fft_filter as fft_filter
from .fourier import fourier_bandpass as fourier_bandpass
from .fourier import fourier_highpass as fourier_highpass
from .fourier import fourier_lowpass as fourier_lowpass
from .fourier import frequency_grid as frequency_grid
from .fourier import lowpass_transfer as lowpass_transfer
from .noise import POISSON_GAUSSIAN_METHODS as POISSON_GAUSSIAN_METHODS
from .noise import TEMPORAL_AVERAGE_METHODS as TEMPORAL_AVERAGE_METHODS
from .noise import add_gaussian_noise as add_gaussian_noise
from .noise import add_impulse_noise as add_impulse_noise
from .noise import add_poisson_gaussian_noise as add_poisson_gaussian_noise
from .noise import add_salt_and_pepper as add_salt_and_pepper
from .noise import temporal_average as temporal_average
from .point import adjust_brightness_contrast as adjust_brightness_contrast
from .point import cumulative_histogram as cumulative_histogram
from .point import equalize_histogram as equalize_histogram
from .point import equalize_histogram_soft as equalize_histogram_soft
from .point import gamma_correct as gamma_correct
from .point import histogram as histogram
from .point import stretch_contrast as stretch_contrast
from .point import tone_curve_linear as tone_curve_linear
from .point import tone_curve_spline as tone_curve_spline

_IMGPOINT_ALL = [
    "BAYER_PATTERNS",
    "DEMOSAIC_METHODS",
    "bayer_masks",
    "bayer_mosaic",
    "demosaic",
    "demosaic_bilinear",
    "demosaic_Malvar2004",
    "FOURIER_FILTER_KINDS",
    "FOURIER_PADDINGS",
    "fft_filter",
    "fourier_bandpass",
    "fourier_highpass",
    "fourier_lowpass",
    "frequency_grid",
    "lowpass_transfer",
    "POISSON_GAUSSIAN_METHODS",
    "TEMPORAL_AVERAGE_METHODS",
    "add_gaussian_noise",
    "add_impulse_noise",
    "add_poisson_gaussian_noise",
    "add_salt_and_pepper",
    "temporal_average",
    "adjust_brightness_contrast",
    "cumulative_histogram",
    "equalize_histogram",
    "equalize_histogram_soft",
    "gamma_correct",
    "histogram",
    "stretch_contrast",
    "tone_curve_linear",
    "tone_curve_spline",
]
__all__ += _IMGPOINT_ALL
# --- end imgpoint block ---
