"""Mitsuba 3's tensor file: a small binary container of named, typed N-d arrays (host, NumPy).

Layout (little endian), as Mitsuba's ``TensorFile`` reads it: the 12 bytes ``tensor_file\\0``,
a version ``(major, minor)`` of two bytes (``(1, 0)``; Mitsuba accepts a minor version of 0),
the field count (``uint32``), then per field its name length (``uint16``), the UTF-8 name, the
number of axes (``uint16``), the dtype code (``uint8``: 1 uint8, 2 int8, 3 uint16, 4 int16,
5 uint32, 6 int32, 7 uint64, 8 int64, 9 float16, 10 float32, 11 float64), the byte offset of
its data (``uint64``) and its shape (``uint64`` per axis). The data are C-ordered arrays at
their offsets. The RGL material database's ``.bsdf`` files (Mitsuba's ``measured`` BSDF) are
such files.
"""

from __future__ import annotations

import os
import struct

import numpy as np

__all__ = ["read_tensor_file", "write_tensor_file", "TENSOR_DTYPES"]

_MAGIC = b"tensor_file\0"
TENSOR_DTYPES = {
    1: np.uint8,
    2: np.int8,
    3: np.uint16,
    4: np.int16,
    5: np.uint32,
    6: np.int32,
    7: np.uint64,
    8: np.int64,
    9: np.float16,
    10: np.float32,
    11: np.float64,
}
"""dtype code -> NumPy dtype (Mitsuba's ``struct_jit`` type ids)."""
_CODES = {np.dtype(v): k for k, v in TENSOR_DTYPES.items()}


def read_tensor_file(path) -> dict[str, np.ndarray]:
    """The fields of a tensor file as ``{name: array}`` (read-only copies, in file order).

    ``FileNotFoundError`` for a missing file; ``ValueError`` naming the file for a bad header
    or version, an unknown dtype code, or a field table or field data running past the end
    of the file (truncated).
    """
    path = os.fspath(path)
    with open(path, "rb") as f:
        buf = f.read()
    n = len(buf)
    if n < 12 + 2 + 4:
        raise ValueError(f"{path}: invalid tensor file: {n} bytes, too small (truncated?)")
    if buf[:12] != _MAGIC:
        raise ValueError(f"{path}: invalid tensor file: header {buf[:12]!r}, expected {_MAGIC!r}")
    if buf[13] != 0:
        raise ValueError(f"{path}: invalid tensor file: unknown version {buf[12]}.{buf[13]}")
    (count,) = struct.unpack_from("<I", buf, 14)
    pos = 18

    def take(fmt, what):
        nonlocal pos
        size = struct.calcsize(fmt)
        if pos + size > n:
            raise ValueError(f"{path}: invalid tensor file: field table truncated in {what}")
        out = struct.unpack_from(fmt, buf, pos)
        pos += size
        return out

    table = []
    for i in range(count):
        (name_len,) = take("<H", f"field {i}")
        name = bytes(take(f"<{name_len}s", f"field {i}")[0]).decode("utf-8", "replace")
        ndim, code, offset = take("<HBQ", f"field {name!r}")
        shape = take(f"<{ndim}Q", f"field {name!r}")
        if code not in TENSOR_DTYPES:
            raise ValueError(f"{path}: invalid tensor file: field {name!r} has unknown dtype "
                             f"code {code}")  # fmt: skip
        table.append((name, np.dtype(TENSOR_DTYPES[code]), offset, tuple(int(s) for s in shape)))
    out = {}
    for name, dt, offset, shape in table:
        nbytes = dt.itemsize * int(np.prod(shape, dtype=np.int64))
        if offset + nbytes > n:
            raise ValueError(f"{path}: invalid tensor file: field {name!r} ({dt}, shape {shape}) "
                             f"runs past the end of the file (truncated?)")  # fmt: skip
        arr = np.frombuffer(buf, dtype=dt.newbyteorder("<"), count=nbytes // dt.itemsize,
                            offset=offset).reshape(shape)  # fmt: skip
        out[name] = arr.astype(dt)
    return out


def write_tensor_file(path, fields: dict, *, align: int = 8) -> None:
    """Write ``fields`` (``{name: array or str}``; a ``str`` is stored as ``uint8`` UTF-8) as a
    tensor file, each field's data aligned to ``align`` bytes (as Mitsuba's ``tensor_io``).
    ``ValueError`` naming the field for a dtype the format lacks."""
    arrays = {}
    for k, v in fields.items():
        a = np.frombuffer(v.encode("utf-8"), np.uint8) if isinstance(v, str) else np.asarray(v)
        if a.dtype not in _CODES:
            raise ValueError(f"fields[{k!r}]: dtype {a.dtype} has no tensor file code")
        arrays[k] = np.ascontiguousarray(a, a.dtype.newbyteorder("<"))
    head = [_MAGIC, struct.pack("<BBI", 1, 0, len(arrays))]
    size = sum(len(b) for b in head)
    for k, a in arrays.items():
        size += 2 + len(k.encode("utf-8")) + 2 + 1 + 8 + 8 * a.ndim
    offsets, pos = {}, size
    for k, a in arrays.items():
        pos = (pos + align - 1) // align * align
        offsets[k] = pos
        pos += a.nbytes
    for k, a in arrays.items():
        label = k.encode("utf-8")
        head.append(struct.pack("<H", len(label)) + label)
        head.append(struct.pack("<HBQ", a.ndim, _CODES[a.dtype], offsets[k]))
        head.append(struct.pack(f"<{a.ndim}Q", *a.shape))
    out = bytearray(b"".join(head))
    for k, a in arrays.items():
        out.extend(b"\0" * (offsets[k] - len(out)))
        out.extend(a.tobytes())
    with open(os.fspath(path), "wb") as f:
        f.write(bytes(out))
