"""Every reader turns truncated files (cut anywhere) into ValueError naming the file.

Byte flips inside pixel data are not detectable in EXR, Radiance or DNG (no checksums) and are
not tested; PNG has CRCs and is.
"""

import numpy as np
import pytest

from jaxgfx.io import (
    read_exr,
    read_hdr,
    read_image,
    read_raw,
    write_dng,
    write_exr,
    write_hdr,
    write_png,
)


def _make(kind, path, rng):
    img = rng.random((32, 40, 3)).astype(np.float32)
    if kind == "exr":
        write_exr(path, img)
        return read_exr
    if kind == "hdr":
        write_hdr(path, img * 10)
        return read_hdr
    if kind == "dng":
        write_dng(path, (img[:32, :32, 0] * 4000).astype(np.uint16))
        return read_raw
    write_png(path, img)
    return read_image


@pytest.mark.parametrize("kind", ["exr", "hdr", "dng", "png"])
def test_truncated_anywhere(tmp_path, rng, kind):
    src = tmp_path / f"src.{kind}"
    reader = _make(kind, src, rng)
    data = src.read_bytes()
    cuts = sorted(set(rng.integers(1, len(data), 12).tolist()) | {1, 8, len(data) - 1})
    for cut in cuts:
        p = tmp_path / f"cut{cut}.{kind}"
        p.write_bytes(data[:cut])
        with pytest.raises(ValueError, match=f"cut{cut}"):
            reader(p)


def test_png_bit_flips_detected(tmp_path, rng):
    src = tmp_path / "src.png"
    _make("png", src, rng)
    data = bytearray(src.read_bytes())
    for pos in rng.integers(60, len(data) - 12, 10).tolist():
        d = bytearray(data)
        d[pos] ^= 0x5A
        (tmp_path / "f.png").write_bytes(bytes(d))
        with pytest.raises(ValueError, match="f.png"):
            read_image(tmp_path / "f.png")
