"""RAW sensor calibration (compatibility module): the implementation lives in
:mod:`jaxgfx.hdr.raw` (step functions with typed results); every public name of this module
is re-exported from there."""

from __future__ import annotations

from jaxgfx.hdr.raw import *  # noqa: F403
from jaxgfx.hdr.raw import __all__ as __all__  # noqa: F401
