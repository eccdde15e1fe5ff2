"""DNG writer read back by rawpy (bit-exact mosaic, metadata) and the RawImage reader."""

import numpy as np
import pytest
import rawpy

from jaxgfx.io import RawImage, read_raw, read_raw_linear_rgb, write_dng

CM = np.array([[0.6, -0.1, -0.05], [-0.4, 1.3, 0.1], [-0.1, 0.2, 0.7]])


def _site_letters(pattern, h, w):
    """Letter of every pixel from the 2x2 pattern string (independent of LibRaw)."""
    tile = np.array(list(pattern)).reshape(2, 2)
    return np.tile(tile, (h // 2, w // 2))


@pytest.mark.parametrize("pattern", ["RGGB", "BGGR", "GRBG", "GBRG"])
def test_dng_bit_exact_and_metadata(tmp_path, rng, pattern):
    m = rng.integers(0, 4096, (24, 36)).astype(np.uint16)
    p = tmp_path / "a.dng"
    black = [60, 61, 62, 63]  # per CFA site, pattern order
    write_dng(
        p,
        m,
        cfa_pattern=pattern,
        black_level=black,
        white_level=4095,
        exposure_time=1 / 250,
        iso=200,
        f_number=5.6,
        camera_whitebalance=[2.0, 1.0, 1.5],
        color_matrix=CM,
    )
    with rawpy.imread(str(p)) as r:  # the oracle: LibRaw itself
        np.testing.assert_array_equal(r.raw_image, m)
        desc = r.color_desc.decode()
        assert "".join(desc[i] for i in r.raw_pattern.ravel()) == pattern
    img = read_raw(p)
    assert isinstance(img, RawImage)
    np.testing.assert_array_equal(img.mosaic, m)
    assert img.mosaic.flags.owndata or img.mosaic.base is None or img.mosaic.base.flags.owndata
    assert img.cfa_pattern == pattern and img.white_level == 4095
    letters = _site_letters(pattern, 24, 36)
    assert np.all(np.array(list(img.color_desc))[img.raw_colors] == letters)
    np.testing.assert_array_equal(img.black_level, black)  # per site, pattern order
    for k in range(4):  # per colour index: site k has colour raw_colors[k // 2, k % 2]
        yy, xx = divmod(k, 2)
        assert img.black_level_per_color[img.raw_colors[yy, xx]] == black[k]
    np.testing.assert_allclose(img.camera_whitebalance[:3], [2.0, 1.0, 1.5], rtol=1e-6)
    np.testing.assert_allclose(img.rgb_xyz_matrix[:3], CM, atol=1e-6)
    assert img.exposure_time == pytest.approx(1 / 250) and img.iso == 200
    assert img.f_number == pytest.approx(5.6)
    assert img.exif_fields == ("exposure_time", "iso", "f_number")
    assert (img.make, img.model) == ("jaxgfx", "synthetic")
    # normalised mosaic from first principles
    blk = np.choose(
        np.array([[0, 1], [2, 3]])[np.arange(24)[:, None] % 2, np.arange(36) % 2], black
    )
    np.testing.assert_allclose(img.normalized(), (m - blk) / (4095.0 - blk), rtol=1e-6)
    assert img.normalized().dtype == np.float32


def test_no_exif_and_defaults(tmp_path):
    m = np.full((22, 24), 1000, np.uint16)
    write_dng(tmp_path / "b.dng", m)
    img = read_raw(tmp_path / "b.dng")
    assert img.exposure_time is None and img.iso is None and img.f_number is None
    assert img.exif_fields == ()
    np.testing.assert_array_equal(img.black_level, 0)
    assert img.white_level == 65535
    np.testing.assert_allclose(img.normalized(), 1000 / 65535, rtol=1e-6)


def test_linear_rgb_of_flat_patch(tmp_path):
    """Flat colour: LibRaw's linear output equals (x - black) / (white - black) per channel."""
    vals = {"R": 1000, "G": 2000, "B": 3000}
    m = np.vectorize(vals.get)(_site_letters("RGGB", 32, 32)).astype(np.uint16)
    write_dng(tmp_path / "f.dng", m, black_level=64, white_level=4095)
    rgb = read_raw_linear_rgb(tmp_path / "f.dng")
    assert rgb.shape == (32, 32, 3) and rgb.dtype == np.float32
    expected = (np.array([1000, 2000, 3000]) - 64) / (4095 - 64)
    np.testing.assert_allclose(rgb[4:-4, 4:-4].reshape(-1, 3).mean(0), expected, rtol=2e-3)


def test_corrupt_files(tmp_path, rng):
    with pytest.raises(FileNotFoundError):
        read_raw(tmp_path / "missing.dng")
    (tmp_path / "g.dng").write_bytes(b"garbage" * 100)
    with pytest.raises(ValueError, match="g.dng"):
        read_raw(tmp_path / "g.dng")
    write_dng(tmp_path / "v.dng", rng.integers(0, 4096, (64, 64)).astype(np.uint16))
    data = (tmp_path / "v.dng").read_bytes()
    for cut in (len(data) // 2, len(data) - 100, 200):
        (tmp_path / "t.dng").write_bytes(data[:cut])
        with pytest.raises(ValueError, match="t.dng"):
            read_raw(tmp_path / "t.dng")
        with pytest.raises(ValueError, match="t.dng"):
            read_raw_linear_rgb(tmp_path / "t.dng")


def test_write_dng_bad_args(tmp_path):
    m = np.zeros((24, 24), np.uint16)
    with pytest.raises(TypeError, match="mosaic"):
        write_dng(tmp_path / "x.dng", m.astype(np.float32))
    with pytest.raises(ValueError, match="mosaic"):
        write_dng(tmp_path / "x.dng", np.zeros((23, 24), np.uint16))
    with pytest.raises(ValueError, match="22"):
        write_dng(tmp_path / "x.dng", np.zeros((8, 8), np.uint16))
    with pytest.raises(ValueError, match="cfa_pattern"):
        write_dng(tmp_path / "x.dng", m, cfa_pattern="RGBX")
    with pytest.raises(ValueError, match="black_level"):
        write_dng(tmp_path / "x.dng", m, black_level=[1, 2])
    with pytest.raises(ValueError, match="white_level"):
        write_dng(tmp_path / "x.dng", m, black_level=100, white_level=50)
    with pytest.raises(ValueError, match="exposure_time"):
        write_dng(tmp_path / "x.dng", m, exposure_time=-1)
    with pytest.raises(ValueError, match="color_matrix"):
        write_dng(tmp_path / "x.dng", m, color_matrix=np.eye(4))
