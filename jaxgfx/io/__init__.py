"""jaxgfx.io: host-only NumPy readers and writers (OpenEXR, Radiance .hdr, RAW/DNG, LDR)."""

from .exr import read_exr as read_exr
from .exr import read_exr_header as read_exr_header
from .exr import write_exr as write_exr

__all__ = ["read_exr", "read_exr_header", "write_exr"]
