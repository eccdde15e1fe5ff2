"""jaxgfx: differentiable image processing, HDR camera calibration and rendering in JAX.

Subpackages (imported lazily so that ``import jaxgfx`` stays cheap):

- :mod:`jaxgfx.color`   colour spaces, transfer functions, white balance
- :mod:`jaxgfx.image`   convolution, filters, edges, Fourier filters, noise, Bayer
- :mod:`jaxgfx.io`      EXR / Radiance HDR / RAW / LDR stacks (host-side NumPy)
- :mod:`jaxgfx.hdr`     response-curve recovery, radiance merge, HDR encodings
- :mod:`jaxgfx.tonemap` tone-mapping operators
- :mod:`jaxgfx.render`  Monte Carlo renderer
- :mod:`jaxgfx.optim`   losses, constraints, optimisation loops
- :mod:`jaxgfx.testing` chi^2, finite differences, furnace tests (public)
"""

import importlib

__version__ = "0.1.0"

_SUBPACKAGES = ("color", "image", "io", "hdr", "tonemap", "render", "optim", "testing")
__all__ = ["__version__", *_SUBPACKAGES]


def __getattr__(name):
    if name in _SUBPACKAGES:
        return importlib.import_module(f"jaxgfx.{name}")
    raise AttributeError(f"module 'jaxgfx' has no attribute {name!r}")
