"""jaxgfx.io: host-only NumPy readers and writers (OpenEXR, Radiance .hdr, RAW/DNG, LDR)."""

from .dng import write_dng as write_dng
from .exr import read_exr as read_exr
from .exr import read_exr_header as read_exr_header
from .exr import write_exr as write_exr
from .hdr_rgbe import read_hdr as read_hdr
from .hdr_rgbe import read_hdr_header as read_hdr_header
from .hdr_rgbe import write_hdr as write_hdr
from .raw import RawImage as RawImage
from .raw import read_raw as read_raw
from .raw import read_raw_linear_rgb as read_raw_linear_rgb

__all__ = [
    "read_exr",
    "read_exr_header",
    "write_exr",
    "read_hdr",
    "read_hdr_header",
    "write_hdr",
    "RawImage",
    "read_raw",
    "read_raw_linear_rgb",
    "write_dng",
]
