"""EXIF exposure tags from raw containers: small fixtures with the tag layout of NEF (big-endian,
EXIF IFD + SubIFDs), CR2 ("CR" header, IFD chain), ARW (SubIFDs) and CR3 (ISO-BMFF CMT1/CMT2).
tifffile, an independent TIFF reader, confirms where the tags sit in the TIFF fixtures."""

import struct

import numpy as np
import pytest
import tifffile

from jaxgfx import io


def _ifd(e, entries, base, next_off=0):
    """Serialise one IFD at ``base``: entries ``(tag, type, count, payload bytes)``; payloads
    longer than 4 bytes go after the IFD. Returns the bytes."""
    entries = sorted(entries, key=lambda x: x[0])
    n = len(entries)
    data_off = base + 2 + 12 * n + 4
    head, tail = [struct.pack(e + "H", n)], b""
    for tag, typ, cnt, payload in entries:
        if len(payload) <= 4:
            head.append(struct.pack(e + "HHI", tag, typ, cnt) + payload.ljust(4, b"\0"))
        else:
            head.append(struct.pack(e + "HHII", tag, typ, cnt, data_off + len(tail)))
            tail += payload + (b"\0" if len(payload) % 2 else b"")
    head.append(struct.pack(e + "I", next_off))
    return b"".join(head) + tail


def _rat(e, num, den):
    return struct.pack(e + "II", num, den)


def _tiff(e, ifds, header_extra=b""):
    """``ifds``: list of callables ``f(offsets) -> entries``; IFDs laid out in order after the
    header; ``offsets[i]`` is IFD i's position. IFD 0 is the first in the chain; ``chain``
    links consecutive ones when the entry list says so."""
    start = 8 + len(header_extra)
    # two passes: sizes first (offsets do not change the sizes)
    offs = [0] * len(ifds)
    for _ in range(2):
        pos, blobs = start, []
        for i, f in enumerate(ifds):
            offs[i] = pos
            entries, nxt = f(offs)
            b = _ifd(e, entries, pos, nxt)
            blobs.append(b)
            pos += len(b) + (len(b) % 2)
    hdr = (b"II" if e == "<" else b"MM") + struct.pack(e + "HI", 42, start) + header_extra
    return hdr + b"".join(b + (b"\0" if len(b) % 2 else b"") for b in blobs)


def _ascii(s):
    return s.encode() + b"\0"


def _exif_entries(e, exposure, iso=None, fnum=None):
    ent = [(33434, 5, 1, _rat(e, *exposure))]
    if fnum:
        ent.append((33437, 5, 1, _rat(e, *fnum)))
    if iso:
        ent.append((34855, 3, 1, struct.pack(e + "H", iso)))
    return ent


def nef_like(e=">"):
    # IFD0 (thumbnail): Make, Model, SubIFDs -> [raw IFD], ExifIFD -> exif IFD
    return _tiff(
        e,
        [
            lambda o: (
                [
                    (271, 2, 17, _ascii("NIKON CORPORATION")),
                    (272, 2, 10, _ascii("NIKON D850")),
                    (254, 4, 1, struct.pack(e + "I", 1)),
                    (330, 4, 1, struct.pack(e + "I", o[1])),
                    (34665, 4, 1, struct.pack(e + "I", o[2])),
                ],
                0,
            ),
            lambda o: ([(254, 4, 1, struct.pack(e + "I", 0)), (256, 4, 1, b"\0\0\0\x10")], 0),
            lambda o: (_exif_entries(e, (1, 60), iso=400, fnum=(56, 10)), 0),
        ],
    )


def cr2_like():
    e = "<"
    # "CR" 2.0 at byte 8 and the raw IFD offset at 12; IFD0 (JPEG) has the EXIF IFD; IFD chain
    return _tiff(
        e,
        [
            lambda o: (
                [
                    (271, 2, 6, _ascii("Canon")),
                    (272, 2, 14, _ascii("Canon EOS 5D")),
                    (34665, 4, 1, struct.pack(e + "I", o[2])),
                ],
                o[1],
            ),
            lambda o: ([(259, 3, 1, struct.pack(e + "H", 6))], 0),
            lambda o: (_exif_entries(e, (1, 8), iso=100), 0),
        ],
        header_extra=b"CR\x02\x00" + struct.pack(e + "I", 0),
    )


def arw_like():
    e = "<"
    return _tiff(
        e,
        [
            lambda o: (
                [
                    (271, 2, 5, _ascii("SONY")),
                    (330, 4, 2, struct.pack(e + "II", o[1], o[2])),
                    (34665, 4, 1, struct.pack(e + "I", o[3])),
                ],
                0,
            ),
            lambda o: ([(254, 4, 1, struct.pack(e + "I", 1))], 0),
            lambda o: ([(254, 4, 1, struct.pack(e + "I", 0))], 0),
            lambda o: (_exif_entries(e, (2, 1), fnum=(8, 1)), 0),
        ],
    )


def cr3_like():
    def box(kind, payload):
        return struct.pack(">I4s", 8 + len(payload), kind) + payload

    e = "<"
    cmt1 = _tiff(e, [lambda o: ([(271, 2, 6, _ascii("Canon"))], 0)])
    cmt2 = _tiff(e, [lambda o: (_exif_entries(e, (1, 250), iso=800), 0)])
    uuid = bytes.fromhex("85c0b687820f11e08111f4ce462b6a48")
    moov = box(b"moov", box(b"uuid", uuid + box(b"CMT1", cmt1) + box(b"CMT2", cmt2)))
    return box(b"ftyp", b"crx \x00\x00\x00\x01crx isom") + moov + box(b"mdat", b"\0" * 32)


@pytest.mark.parametrize(
    "name,maker,expected",
    [
        ("x.nef", nef_like, {"exposure_time": 1 / 60, "iso": 400.0, "f_number": 5.6}),
        ("x.cr2", cr2_like, {"exposure_time": 1 / 8, "iso": 100.0}),
        ("x.arw", arw_like, {"exposure_time": 2.0, "f_number": 8.0}),
        ("x.cr3", cr3_like, {"exposure_time": 1 / 250, "iso": 800.0}),
    ],
)
def test_raw_exif_layouts(tmp_path, name, maker, expected):
    p = tmp_path / name
    p.write_bytes(maker())
    got = io.read_raw_exif(p)
    for k, v in expected.items():
        assert got[k] == pytest.approx(v, rel=1e-12), (k, got)
    if name != "x.cr3":  # an independent TIFF reader finds the EXIF IFD where we wrote it
        with tifffile.TiffFile(p) as tif:
            exif = tif.pages[0].tags[34665].value
            num, den = exif["ExposureTime"]
            assert num / den == pytest.approx(expected["exposure_time"])


def test_raw_exif_make_model_and_garbage(tmp_path):
    p = tmp_path / "a.nef"
    p.write_bytes(nef_like("<"))
    got = io.read_raw_exif(p)
    assert got["make"] == "NIKON CORPORATION" and got["model"] == "NIKON D850"
    q = tmp_path / "junk.cr2"
    q.write_bytes(b"II*\x00" + np.random.default_rng(0).bytes(200))
    assert isinstance(io.read_raw_exif(q), dict)  # no exception on garbage
    r = tmp_path / "empty.cr3"
    r.write_bytes(b"")
    assert io.read_raw_exif(r) == {}
