"""Radiance .hdr: RGBE formulas, RLE/flat/old-style scanlines, OpenCV as oracle, bad files."""

import cv2
import numpy as np
import pytest

from jaxgfx.io import read_hdr, write_hdr
from jaxgfx.io.hdr_rgbe import float_from_rgbe, read_hdr_header, rgbe_from_float

CV_FLAGS = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR


def _cv_read(path):
    return cv2.imread(str(path), CV_FLAGS)[..., ::-1]  # BGR -> RGB


@pytest.fixture
def hdr_image(rng):
    img = np.exp(rng.normal(0.0, 4.0, (40, 70, 3))).astype(np.float32)
    img[5:12] = [2.0, 1.0, 0.25]  # long runs
    img[20] = 0.0  # black row
    img[25, 3:40] = 3e4
    return img


def test_rgbe_known_values():
    # Ward 1991: 1.0 -> frexp = 0.5 * 2**1 -> (128, E=129); 0.5 -> 128 * 2**-8 at E=129 = 64.
    np.testing.assert_array_equal(rgbe_from_float([1.0, 0.5, 0.0]), [128, 64, 0, 129])
    np.testing.assert_array_equal(rgbe_from_float([0.0, 0.0, 0.0]), [0, 0, 0, 0])
    np.testing.assert_array_equal(rgbe_from_float([1e-40, 0, 0]), [0, 0, 0, 0])
    np.testing.assert_array_equal(rgbe_from_float([1e39, 0, 0]), [255, 255, 255, 255])
    np.testing.assert_array_equal(rgbe_from_float([-1.0, np.nan, 3.0]), [0, 0, 192, 130])
    np.testing.assert_allclose(float_from_rgbe([128, 64, 0, 129], offset=0.0), [1.0, 0.5, 0.0])
    np.testing.assert_allclose(
        float_from_rgbe([128, 64, 0, 129]), [1.00390625, 0.50390625, 0.00390625]
    )
    np.testing.assert_array_equal(float_from_rgbe([7, 7, 7, 0]), [0.0, 0.0, 0.0])


def test_quantisation_bound(rng):
    x = np.exp(rng.uniform(np.log(1e-30), np.log(1e30), (20000, 3)))
    mx = x.max(-1)
    for offset, bound in [(0.5, 2.0**-8), (0.0, 2.0**-7)]:
        y = float_from_rgbe(rgbe_from_float(x), offset=offset).max(-1)
        assert np.max(np.abs(y / mx - 1)) <= bound * (1 + 1e-6)
    # Every channel: absolute error below one mantissa step of the shared exponent.
    y = float_from_rgbe(rgbe_from_float(x))
    assert np.all(np.abs(y - x) <= mx[:, None] * 2.0**-7)


@pytest.mark.parametrize("rle", [True, False])
def test_roundtrip_and_opencv_reads_ours(tmp_path, hdr_image, rle):
    p = tmp_path / "ours.hdr"
    write_hdr(p, hdr_image, rle=rle)
    ours0 = read_hdr(p, offset=0.0)
    np.testing.assert_array_equal(ours0, _cv_read(p))  # bit-identical to OpenCV's reader
    np.testing.assert_array_equal(read_hdr(p), float_from_rgbe(rgbe_from_float(hdr_image)))
    mx = hdr_image.max(-1)
    nz = mx > 0
    rel = np.abs(read_hdr(p).max(-1)[nz] / mx[nz] - 1)
    assert rel.max() <= 2.0**-8 * (1 + 1e-6)
    assert np.all(read_hdr(p)[~nz] == 0)


def test_we_read_opencv_files(tmp_path, hdr_image):
    for w in (70, 5):  # RLE (width >= 8) and flat scanlines
        p = tmp_path / f"cv{w}.hdr"
        img = np.ascontiguousarray(hdr_image[:, :w, ::-1])
        assert cv2.imwrite(str(p), img)
        ours = read_hdr(p, offset=0.0)
        np.testing.assert_array_equal(ours, _cv_read(p))
        # OpenCV's encoder and ours produce the same RGBE bytes
        np.testing.assert_array_equal(rgbe_from_float(ours), rgbe_from_float(img[..., ::-1]))


def test_rle_compresses_constant_image(tmp_path):
    write_hdr(tmp_path / "c.hdr", np.full((16, 300, 3), 0.7, np.float32))
    size = (tmp_path / "c.hdr").stat().st_size
    assert size < 16 * 4 * 8 + 100  # 3 run codes of 2 bytes per component per scanline
    np.testing.assert_allclose(read_hdr(tmp_path / "c.hdr"), 0.7, rtol=2**-8)


def _raw_file(res: bytes, pixels: bytes) -> bytes:
    return b"#?RGBE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=2.0\n\n" + res + b"\n" + pixels


def test_old_style_rle_flat_and_orientation(tmp_path):
    a, b = bytes((128, 64, 32, 129)), bytes((10, 20, 30, 130))
    # old-style: pixel a, then (1,1,1,3) repeats it 3 times, then b; second row flat.
    pix = a + bytes((1, 1, 1, 3)) + b + b + a + a + a + b
    (tmp_path / "o.hdr").write_bytes(_raw_file(b"-Y 2 +X 5", pix))
    img = read_hdr(tmp_path / "o.hdr", offset=0.0)
    va, vb = float_from_rgbe(np.frombuffer(a + b, np.uint8).reshape(2, 4), offset=0.0)
    expected = np.array([[va, va, va, va, vb], [vb, va, va, va, vb]])
    np.testing.assert_array_equal(img, expected)
    hdr = read_hdr_header(tmp_path / "o.hdr")
    assert hdr["exposure"] == 2.0 and (hdr["height"], hdr["width"]) == (2, 5)
    # '+Y' stores the bottom row first; '-X' right to left; '+X .. -Y' stores columns.
    (tmp_path / "f.hdr").write_bytes(_raw_file(b"+Y 2 -X 5", pix))
    np.testing.assert_array_equal(read_hdr(tmp_path / "f.hdr", offset=0.0), img[::-1, ::-1])
    flat = np.frombuffer(b + a + a + b + a + b, np.uint8).reshape(3, 2, 4)  # 3 columns of 2
    (tmp_path / "t.hdr").write_bytes(_raw_file(b"+X 3 -Y 2", flat.tobytes()))
    np.testing.assert_array_equal(
        read_hdr(tmp_path / "t.hdr", offset=0.0),
        float_from_rgbe(flat, offset=0.0).transpose(1, 0, 2),
    )


def test_bad_files(tmp_path, hdr_image):
    with pytest.raises(FileNotFoundError):
        read_hdr(tmp_path / "missing.hdr")
    (tmp_path / "g.hdr").write_bytes(b"\x00garbage" * 30)
    with pytest.raises(ValueError, match="g.hdr"):
        read_hdr(tmp_path / "g.hdr")
    write_hdr(tmp_path / "v.hdr", hdr_image)
    data = (tmp_path / "v.hdr").read_bytes()
    (tmp_path / "t.hdr").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="t.hdr.*truncated"):
        read_hdr(tmp_path / "t.hdr")
    (tmp_path / "f.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_xyz\n\n-Y 1 +X 1\n0000")
    with pytest.raises(ValueError, match="FORMAT"):
        read_hdr(tmp_path / "f.hdr")
    (tmp_path / "r.hdr").write_bytes(b"#?RADIANCE\n\n-Y 1 Q 1\n0000")
    with pytest.raises(ValueError, match="resolution"):
        read_hdr(tmp_path / "r.hdr")
    bad_run = _raw_file(b"-Y 1 +X 8", bytes((2, 2, 0, 8, 200, 1)))
    (tmp_path / "b.hdr").write_bytes(bad_run)
    with pytest.raises(ValueError, match="b.hdr"):
        read_hdr(tmp_path / "b.hdr")
    with pytest.raises(ValueError, match="image"):
        write_hdr(tmp_path / "x.hdr", np.zeros((4, 4, 2)))


@pytest.mark.parametrize("w", [8, 9, 131, 300])
def test_rle_edge_runs_read_by_opencv(tmp_path, rng, w):
    """Runs of length 1..6 and > 127, literals > 128, at both ends of each scanline."""
    lengths = rng.integers(1, 7, 400)
    lengths[::17] = 140
    vals = np.repeat(rng.integers(1, 4, lengths.size), lengths)[: 6 * w].reshape(6, w)
    img = np.stack([vals, vals[::-1], np.roll(vals, 3, axis=1)], -1).astype(np.float32) / 4
    p = tmp_path / "e.hdr"
    write_hdr(p, img)
    np.testing.assert_array_equal(read_hdr(p, offset=0.0), _cv_read(p))
    np.testing.assert_array_equal(read_hdr(p), float_from_rgbe(rgbe_from_float(img)))


def test_xyze_format_and_missing_format_line(tmp_path):
    px = bytes((128, 64, 32, 129)) * 2
    (tmp_path / "x.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 2\n" + px)
    assert read_hdr_header(tmp_path / "x.hdr")["format"] == "32-bit_rle_xyze"
    np.testing.assert_array_equal(read_hdr(tmp_path / "x.hdr", offset=0.0), [[[1, 0.5, 0.25]] * 2])
    (tmp_path / "n.hdr").write_bytes(b"#?RADIANCE\n\n-Y 1 +X 2\n" + px)  # FORMAT is optional
    np.testing.assert_array_equal(read_hdr(tmp_path / "n.hdr", offset=0.0), [[[1, 0.5, 0.25]] * 2])
