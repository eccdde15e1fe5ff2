"""Host-side data of the ``sunsky`` emitter: the Hosek-Wilkie tables jaxgfx ships
(``jaxgfx/render/data/sunsky/sunsky_rgb.npz``, the RGB subset of Mitsuba 3.9.1's
``data/sunsky/*.bin``; see ORIGIN.md there) and a NumPy reader of Mitsuba's tensor-file format
(used by ``tools/make_sunsky_data.py`` and by the test that checks the subset against the
original files when Mitsuba's wheel is installed). NumPy only: no JAX, no Mitsuba.
"""

from __future__ import annotations

import functools
import os
import struct

import numpy as np

__all__ = ["DATA_DIR", "NPZ_PATH", "FIELDS", "read_tensor_file", "tables"]

DATA_DIR = os.path.join(os.path.dirname(__file__), "data", "sunsky")
NPZ_PATH = os.path.join(DATA_DIR, "sunsky_rgb.npz")

FIELDS = {
    # name in the npz: (Mitsuba file, field in it)
    "sky_params_rgb": ("sunsky_datasets.bin", "sky_params_rgb"),  # (10 T, 2 A, 6 eta, 3, 9)
    "sky_rad_rgb": ("sunsky_datasets.bin", "sky_rad_rgb"),  # (10 T, 2 A, 6 eta, 3)
    "sun_rad_rgb": ("sunsky_datasets.bin", "sun_rad_rgb"),  # (10 T, 45 seg, 3, 4 k, 6 j)
    "sun_irradiance": ("sampling_data.bin", "sun_irradiance"),  # (10 T, 30 elev, 11 lambda)
}
"""The arrays of the npz that are copies of Mitsuba's fields (the npz also holds ``cie_xyz``,
the CIE 1931 colour matching functions at the model's 11 wavelengths)."""

_DTYPES = {1: np.uint8, 2: np.int8, 3: np.uint16, 4: np.int16, 5: np.uint32, 6: np.int32,
           7: np.uint64, 8: np.int64, 9: np.float16, 10: np.float32, 11: np.float64}  # fmt: skip


def read_tensor_file(path) -> dict:
    """The fields of a Mitsuba 3 tensor file (``tensor_file\\0`` header, version 1.0, then per
    field its name, rank, dtype code, byte offset and shape; little-endian) as NumPy arrays."""
    with open(path, "rb") as f:
        blob = f.read()
    if blob[:12] != b"tensor_file\0":
        raise ValueError(f"{path}: not a Mitsuba tensor file (bad header)")
    if blob[12:14] != b"\x01\x00":
        raise ValueError(f"{path}: unknown tensor file version {tuple(blob[12:14])}")
    (n,) = struct.unpack_from("<I", blob, 14)
    pos, out = 18, {}
    for _ in range(n):
        (ln,) = struct.unpack_from("<H", blob, pos)
        name = blob[pos + 2 : pos + 2 + ln].decode("utf8")
        pos += 2 + ln
        ndim, code, offset = struct.unpack_from("<HBQ", blob, pos)
        pos += 11
        shape = struct.unpack_from("<" + "Q" * ndim, blob, pos)
        pos += 8 * ndim
        if code not in _DTYPES:
            raise ValueError(f"{path}: field {name!r} has an unknown dtype code {code}")
        dt = np.dtype(_DTYPES[code]).newbyteorder("<")
        count = int(np.prod(shape))
        out[name] = np.frombuffer(blob, dt, count, offset).reshape(shape).copy()
    return out


@functools.lru_cache(maxsize=1)
def tables() -> dict:
    """The shipped tables (float64 NumPy arrays, read once): the :data:`FIELDS` and
    ``cie_xyz`` ``(11, 3)``."""
    if not os.path.exists(NPZ_PATH):
        raise FileNotFoundError(f"{NPZ_PATH}: the sunsky data file is missing from the package")
    with np.load(NPZ_PATH) as z:
        out = {k: np.asarray(z[k], np.float64) for k in z.files}
    for k in (*FIELDS, "cie_xyz"):
        if k not in out:
            raise ValueError(f"{NPZ_PATH}: missing array {k!r}")
    for a in out.values():
        a.setflags(write=False)
    return out
