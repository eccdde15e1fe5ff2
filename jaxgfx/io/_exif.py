"""EXIF exposure tags from camera raw containers, parsed directly (no LibRaw, no exiftool).

TIFF-based raws (NEF, CR2, ARW, DNG, PEF, ORF, RW2, ...): the IFD0 chain is walked and, from
every IFD, the EXIF IFD (tag 34665) and the SubIFDs (tag 330) are followed, so tags stored
in any of them are found (Nikon and Sony keep ExposureTime in the EXIF IFD, the raw data in a
SubIFD; Canon CR2 has a TIFF header with "CR" at byte 8 and the EXIF IFD under IFD0). Canon
CR3 is an ISO base-media file: its ``moov/uuid`` box holds ``CMT1`` (IFD0) and ``CMT2``
(EXIF IFD) boxes, each a complete little TIFF, which are parsed the same way.
Reference: TIFF 6.0 (Adobe 1992), EXIF 2.32 (CIPA DC-008-2019), ISO/IEC 14496-12.
"""

from __future__ import annotations

import struct
from pathlib import Path

__all__ = ["read_raw_exif"]

_TAGS = {33434: "exposure_time", 33437: "f_number", 34855: "iso", 271: "make", 272: "model"}
_SIZES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 10: 8, 11: 4, 12: 8, 13: 4}
_CR3_UUID = bytes.fromhex("85c0b687820f11e08111f4ce462b6a48")


class _Tiff:
    def __init__(self, buf: bytes):
        self.buf = buf
        if buf[:2] == b"II":
            self.e = "<"
        elif buf[:2] == b"MM":
            self.e = ">"
        else:
            raise ValueError("not a TIFF header")
        # magic: 42 (TIFF, CR2, NEF, ARW, DNG), 0x4F52 / 0x5352 (ORF), 0x55 (RW2)
        magic = struct.unpack_from(self.e + "H", buf, 2)[0]
        if magic not in (42, 0x4F52, 0x5352, 0x55):
            raise ValueError(f"unknown TIFF magic {magic:#x}")
        self.ifd0 = struct.unpack_from(self.e + "I", buf, 4)[0]

    def entries(self, off):
        e, buf = self.e, self.buf
        if off <= 0 or off + 2 > len(buf):
            return [], 0
        n = struct.unpack_from(e + "H", buf, off)[0]
        if n > 4096 or off + 2 + 12 * n + 4 > len(buf):
            return [], 0
        out = []
        for i in range(n):
            tag, typ, cnt = struct.unpack_from(e + "HHI", buf, off + 2 + 12 * i)
            size = _SIZES.get(typ, 1) * cnt
            vo = off + 2 + 12 * i + 8
            if size > 4:
                vo = struct.unpack_from(e + "I", buf, vo)[0]
            if vo + size > len(buf):
                continue
            out.append((tag, typ, cnt, vo))
        nxt = struct.unpack_from(e + "I", buf, off + 2 + 12 * n)[0]
        return out, nxt

    def value(self, typ, cnt, vo):
        e, buf = self.e, self.buf
        if typ in (5, 10):
            fmt = "I" if typ == 5 else "i"
            num, den = struct.unpack_from(e + fmt + fmt, buf, vo)
            return num / den if den else None
        if typ == 3:
            return float(struct.unpack_from(e + "H", buf, vo)[0])
        if typ in (4, 13):
            return [struct.unpack_from(e + "I", buf, vo + 4 * k)[0] for k in range(cnt)]
        if typ == 2:
            return buf[vo : vo + cnt].split(b"\x00")[0].decode("ascii", "replace").strip()
        return None


def _walk_tiff(buf: bytes, out: dict) -> None:
    t = _Tiff(buf)
    seen: set[int] = set()
    todo = [(t.ifd0, True, 0)]
    while todo:
        off, chain, depth = todo.pop(0)
        if off in seen or depth > 4 or len(seen) > 64:
            continue
        seen.add(off)
        ents, nxt = t.entries(off)
        for tag, typ, cnt, vo in ents:
            if tag in _TAGS and _TAGS[tag] not in out:
                v = t.value(typ, cnt, vo)
                if isinstance(v, list):
                    v = float(v[0]) if v else None
                if v is not None and v != "":
                    out[_TAGS[tag]] = v
            elif tag in (34665, 330) and typ in (4, 13):
                for sub in t.value(typ, cnt, vo):
                    todo.append((sub, False, depth + 1))
        if chain and nxt:
            todo.append((nxt, True, depth))


def _walk_bmff(buf: bytes, out: dict, start=0, end=None, depth=0) -> None:
    end = len(buf) if end is None else end
    pos = start
    while pos + 8 <= end and depth < 6:
        size, kind = struct.unpack_from(">I4s", buf, pos)
        hdr = 8
        if size == 1:
            size = struct.unpack_from(">Q", buf, pos + 8)[0]
            hdr = 16
        elif size == 0:
            size = end - pos
        if size < hdr or pos + size > end:
            return
        body = pos + hdr
        if kind == b"uuid":
            if buf[body : body + 16] == _CR3_UUID:
                _walk_bmff(buf, out, body + 16, pos + size, depth + 1)
        elif kind == b"moov":
            _walk_bmff(buf, out, body, pos + size, depth + 1)
        elif kind in (b"CMT1", b"CMT2"):
            try:
                _walk_tiff(buf[body : pos + size], out)
            except (ValueError, struct.error):
                pass
        pos += size


def read_raw_exif(path) -> dict:
    """Exposure metadata of a camera raw file: a dict with any of ``exposure_time`` (s),
    ``f_number``, ``iso``, ``make``, ``model`` that were found (missing keys: not present).

    Works on TIFF-based raws (NEF, CR2, ARW, DNG, PEF, ORF, RW2: IFD0 chain, EXIF IFD and
    SubIFDs) and Canon CR3 (``CMT1``/``CMT2`` boxes); anything else gives ``{}``.
    Host-only; reads the file once.

    Example: a Nikon-style NEF with ExposureTime 1/60 in its EXIF IFD →
    ``{"exposure_time": 0.016666…, ...}`` (``tests/io/test_raw_exif.py``).
    """
    p = Path(path)
    buf = p.read_bytes()
    out: dict = {}
    try:
        if buf[4:8] == b"ftyp":
            _walk_bmff(buf, out)
        else:
            _walk_tiff(buf, out)
    except (ValueError, struct.error):
        return out
    return out
