"""jaxgfx.image (see docs/)."""

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
# --- end convolution, filters, edges (other blocks: extend __all__ with `__all__ += [...]`) ---
