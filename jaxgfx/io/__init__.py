"""jaxgfx.io: host-only NumPy readers and writers (OpenEXR, Radiance .hdr, RAW/DNG, LDR)."""

from .exr import read_exr as read_exr
from .exr import read_exr_header as read_exr_header
from .exr import write_exr as write_exr
from .hdr_rgbe import read_hdr as read_hdr
from .hdr_rgbe import read_hdr_header as read_hdr_header
from .hdr_rgbe import write_hdr as write_hdr

__all__ = ["read_exr", "read_exr_header", "write_exr", "read_hdr", "read_hdr_header", "write_hdr"]
