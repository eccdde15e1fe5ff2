"""jaxgfx.io: host-only NumPy readers and writers (OpenEXR, Radiance .hdr, RAW/DNG, LDR).

Nothing here is traced by JAX: every function takes paths and NumPy arrays and returns NumPy
arrays. Missing files raise ``FileNotFoundError``; corrupt, truncated or unsupported files raise
``ValueError`` naming the file.
"""

from ._dispatch import DISPLAY_WRITE_EXTENSIONS as DISPLAY_WRITE_EXTENSIONS
from ._dispatch import FILE_KINDS as FILE_KINDS
from ._dispatch import HDR_EXTENSIONS as HDR_EXTENSIONS
from ._dispatch import HDR_WRITE_EXTENSIONS as HDR_WRITE_EXTENSIONS
from ._dispatch import LDR_EXTENSIONS as LDR_EXTENSIONS
from ._dispatch import LDR_WRITE_EXTENSIONS as LDR_WRITE_EXTENSIONS
from ._dispatch import LINEAR_WRITE_EXTENSIONS as LINEAR_WRITE_EXTENSIONS
from ._dispatch import RAW_EXTENSIONS as RAW_EXTENSIONS
from ._dispatch import WRITE_EXTENSIONS as WRITE_EXTENSIONS
from ._dispatch import kind_of as kind_of
from ._dispatch import read_any as read_any
from ._dispatch import write_any as write_any
from .dng import write_dng as write_dng
from .exr import read_exr as read_exr
from .exr import read_exr_header as read_exr_header
from .exr import write_exr as write_exr
from .hdr_rgbe import read_hdr as read_hdr
from .hdr_rgbe import read_hdr_header as read_hdr_header
from .hdr_rgbe import write_hdr as write_hdr
from .ldr import TIFF_EXTENSIONS as TIFF_EXTENSIONS
from .ldr import exif_exposure_time as exif_exposure_time
from .ldr import exposure_order as exposure_order
from .ldr import exposure_values as exposure_values
from .ldr import parse_exposure_time as parse_exposure_time
from .ldr import read_image as read_image
from .ldr import read_ldr_stack as read_ldr_stack
from .ldr import write_png as write_png
from .raw import RawImage as RawImage
from .raw import read_raw as read_raw
from .raw import read_raw_exif as read_raw_exif
from .raw import read_raw_linear_rgb as read_raw_linear_rgb
from .raw import read_raw_stack as read_raw_stack

__all__ = [
    "FILE_KINDS",
    "HDR_EXTENSIONS",
    "LDR_EXTENSIONS",
    "RAW_EXTENSIONS",
    "WRITE_EXTENSIONS",
    "HDR_WRITE_EXTENSIONS",
    "LDR_WRITE_EXTENSIONS",
    "LINEAR_WRITE_EXTENSIONS",
    "DISPLAY_WRITE_EXTENSIONS",
    "TIFF_EXTENSIONS",
    "kind_of",
    "read_exr",
    "read_exr_header",
    "write_exr",
    "read_hdr",
    "read_hdr_header",
    "write_hdr",
    "RawImage",
    "read_raw",
    "read_raw_linear_rgb",
    "read_raw_exif",
    "read_raw_stack",
    "write_dng",
    "read_image",
    "write_png",
    "read_ldr_stack",
    "exif_exposure_time",
    "parse_exposure_time",
    "exposure_order",
    "exposure_values",
    "read_any",
    "write_any",
]
