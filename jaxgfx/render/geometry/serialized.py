"""Reader for Mitsuba's ``serialized`` mesh format (``.serialized``).

A file is a sequence of meshes, each: a 2-byte header ``0x041C``, a 2-byte version (3 or 4),
then a zlib stream holding ``flags`` (uint32: ``0x0001`` vertex normals, ``0x0002`` texture
coordinates, ``0x0008`` vertex colours, ``0x1000`` single precision, ``0x2000`` double), the
mesh name (version 4: a NUL-terminated string), the vertex count and triangle count (uint64),
then positions, normals, texture coordinates, colours (float32 or float64) and the triangle
indices (uint32, uint64 when there are more than 2^32 vertices). An end-of-file dictionary
gives each mesh's byte offset (version 4: uint64, version 3: uint32) and, last, the uint32
mesh count. Little-endian throughout. Host code (numpy); checked against Mitsuba 3.9.1's own
loader by tests/render/test_mitsuba_serialized.py.

Example: ``m = read_serialized("mesh.serialized", shape_index=0); m.vertices.shape``.
"""

from __future__ import annotations

import dataclasses
import struct
import zlib

import numpy as np

__all__ = ["SerializedMesh", "read_serialized", "serialized_mesh_count"]

_HEADER = 0x041C
_NORMALS, _UVS, _COLORS, _SINGLE, _DOUBLE = 0x0001, 0x0002, 0x0008, 0x1000, 0x2000


@dataclasses.dataclass(frozen=True)
class SerializedMesh:
    """One mesh of a ``.serialized`` file (numpy arrays; ``None`` where the file has none)."""

    name: str
    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int64
    normals: np.ndarray | None = None  # (V, 3)
    uvs: np.ndarray | None = None  # (V, 2)
    colors: np.ndarray | None = None  # (V, 3)


def _offsets(data: bytes, path) -> list[int]:
    if len(data) < 8:
        raise ValueError(f"{path}: not a Mitsuba serialized mesh file (too short)")
    (count,) = struct.unpack_from("<I", data, len(data) - 4)
    header, version = struct.unpack_from("<HH", data, 0)
    if header != _HEADER:
        raise ValueError(f"{path}: not a Mitsuba serialized mesh file (header 0x{header:04X})")
    if version not in (3, 4):
        raise ValueError(f"{path}: serialized format version {version} is not supported (3, 4)")
    size = 8 if version == 4 else 4
    start = len(data) - 4 - size * count
    if count == 0 or start < 0:
        raise ValueError(f"{path}: corrupt end-of-file dictionary (mesh count {count})")
    fmt = "<Q" if version == 4 else "<I"
    return [struct.unpack_from(fmt, data, start + size * i)[0] for i in range(count)]


def serialized_mesh_count(path) -> int:
    """The number of meshes in a ``.serialized`` file."""
    with open(path, "rb") as f:
        return len(_offsets(f.read(), path))


def read_serialized(path, shape_index: int = 0) -> SerializedMesh:
    """Mesh ``shape_index`` of the Mitsuba ``.serialized`` file ``path``; ``ValueError`` naming
    the file for a wrong header, version, index or a truncated stream."""
    with open(path, "rb") as f:
        data = f.read()
    offsets = _offsets(data, path)
    if not 0 <= shape_index < len(offsets):
        raise ValueError(f"{path}: shape_index {shape_index} out of range (the file has "
                         f"{len(offsets)} meshes)")  # fmt: skip
    off = offsets[shape_index]
    header, version = struct.unpack_from("<HH", data, off)
    if header != _HEADER or version not in (3, 4):
        raise ValueError(f"{path}: mesh {shape_index}: bad header 0x{header:04X} / version "
                         f"{version}")  # fmt: skip
    try:
        raw = zlib.decompressobj().decompress(data[off + 4 :])
    except zlib.error as e:
        raise ValueError(f"{path}: mesh {shape_index}: corrupt zlib stream ({e})") from None
    pos = 0

    def take(n):
        nonlocal pos
        if pos + n > len(raw):
            raise ValueError(f"{path}: mesh {shape_index}: truncated data")
        out = raw[pos : pos + n]
        pos += n
        return out

    (flags,) = struct.unpack("<I", take(4))
    name = ""
    if version == 4:
        end = raw.index(b"\0", pos)
        name = raw[pos:end].decode("utf-8", "replace")
        pos = end + 1
    nv, nf = struct.unpack("<QQ", take(16))
    if flags & _DOUBLE:
        dt = np.dtype("<f8")
    elif flags & _SINGLE:
        dt = np.dtype("<f4")
    else:
        raise ValueError(f"{path}: mesh {shape_index}: flags 0x{flags:X} gives no precision")

    def arr(k):
        return np.frombuffer(take(nv * k * dt.itemsize), dt).reshape(nv, k).astype(np.float64)

    v = arr(3)
    n = arr(3) if flags & _NORMALS else None
    uv = arr(2) if flags & _UVS else None
    c = arr(3) if flags & _COLORS else None
    it = np.dtype("<u8") if nv > 2**32 else np.dtype("<u4")
    f = np.frombuffer(take(nf * 3 * it.itemsize), it).reshape(nf, 3).astype(np.int64)
    if f.size and f.max() >= nv:
        raise ValueError(f"{path}: mesh {shape_index}: triangle index {int(f.max())} >= "
                         f"vertex count {nv}")  # fmt: skip
    return SerializedMesh(name, v, f, n, uv, c)
