"""OpenEXR round trips, channel order, metadata, strided inputs and corrupt files."""

import numpy as np
import OpenEXR
import pytest

from jaxgfx.io import read_exr, read_exr_header, write_exr


@pytest.mark.parametrize("c", [1, 3, 4, 5])
@pytest.mark.parametrize("half", [False, True])
def test_roundtrip_channels_and_types(tmp_path, rng, c, half):
    img = (rng.random((17, 23, c)) * 1000).astype(np.float32)
    names = ["R", "G", "B", "A", "Z"][:c] if c == 5 else None
    path = tmp_path / "x.exr"
    write_exr(path, img, half=half, channels=names)
    out = read_exr(path)
    assert out.dtype == np.float32 and out.shape == (17, 23, c)
    expected = img.astype(np.float16).astype(np.float32) if half else img
    np.testing.assert_array_equal(out, expected)  # half rounding is exactly NumPy's
    hdr = read_exr_header(path)
    assert (hdr["width"], hdr["height"]) == (23, 17)
    assert {v["type"] for v in hdr["channels"].values()} == {"half" if half else "float"}


def test_gray_2d_is_Y(tmp_path, rng):
    img = rng.random((8, 9)).astype(np.float32)
    write_exr(tmp_path / "y.exr", img)
    assert list(read_exr_header(tmp_path / "y.exr")["channels"]) == ["Y"]
    np.testing.assert_array_equal(read_exr(tmp_path / "y.exr")[..., 0], img)


def test_channel_order_and_selection(tmp_path, rng):
    img = rng.random((6, 7, 5)).astype(np.float32)
    write_exr(tmp_path / "o.exr", img, channels=["Z", "B", "depth", "R", "G"])
    hdr = read_exr_header(tmp_path / "o.exr")
    assert list(hdr["channels"]) == ["R", "G", "B", "Z", "depth"]
    out = read_exr(tmp_path / "o.exr")
    np.testing.assert_array_equal(out, img[..., [3, 4, 1, 0, 2]])
    sel = read_exr(tmp_path / "o.exr", channels=["depth", "R"])
    np.testing.assert_array_equal(sel, img[..., [2, 3]])
    with pytest.raises(ValueError, match="not in file"):
        read_exr(tmp_path / "o.exr", channels=["A"])


def test_metadata_and_compression(tmp_path, rng):
    img = rng.random((16, 16, 3)).astype(np.float32)
    for comp in ["none", "rle", "zips", "zip", "piz"]:
        p = tmp_path / f"{comp}.exr"
        write_exr(p, img, compression=comp, header={"owner": "jaxgfx", "exposure": 2.5, "n": 7})
        hdr = read_exr_header(p)
        assert hdr["compression"] == comp
        assert hdr["attributes"]["owner"] == "jaxgfx"
        assert hdr["attributes"]["n"] == 7
        assert hdr["attributes"]["exposure"] == pytest.approx(2.5)
        np.testing.assert_array_equal(read_exr(p), img)  # lossless codecs


def test_mixed_pixel_types_written_by_openexr(tmp_path, rng):
    """A file written directly with the OpenEXR package: half + float + uint channels."""
    r = rng.random((5, 4)).astype(np.float16)
    z = rng.random((5, 4)).astype(np.float32)
    idx = np.arange(20, dtype=np.uint32).reshape(5, 4)
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(hdr, {"R": r, "Z": z, "id": idx}).write(str(tmp_path / "m.exr"))
    types = {k: v["type"] for k, v in read_exr_header(tmp_path / "m.exr")["channels"].items()}
    assert types == {"R": "half", "Z": "float", "id": "uint"}
    out = read_exr(tmp_path / "m.exr")
    np.testing.assert_array_equal(out[..., 0], r.astype(np.float32))
    np.testing.assert_array_equal(out[..., 1], z)
    np.testing.assert_array_equal(out[..., 2], idx.astype(np.float32))


def test_strided_inputs_written_correctly(tmp_path, rng):
    """The OpenEXR binding scrambles non-contiguous arrays; write_exr must not."""
    base = rng.random((20, 30, 4)).astype(np.float64)
    for img in [base.transpose(1, 0, 2), base[::2, 1::3, :3], base[..., ::-1]]:
        write_exr(tmp_path / "s.exr", img)
        np.testing.assert_array_equal(read_exr(tmp_path / "s.exr"), img.astype(np.float32))


def test_half_range(tmp_path):
    img = np.array([[1e-8, 6.1e-5, 1.0, 65504.0, 1e6]], np.float32)
    write_exr(tmp_path / "h.exr", img, half=True)
    out = read_exr(tmp_path / "h.exr")[0, :, 0]
    assert out[0] == 0.0  # underflow below the smallest subnormal 2**-24
    assert out[1] == pytest.approx(6.1e-5, rel=2**-10)
    assert out[2] == 1.0 and out[3] == 65504.0 and np.isposinf(out[4])


def test_errors(tmp_path, rng):
    with pytest.raises(FileNotFoundError):
        read_exr(tmp_path / "missing.exr")
    (tmp_path / "g.exr").write_bytes(b"garbage" * 50)
    with pytest.raises(ValueError, match="g.exr"):
        read_exr(tmp_path / "g.exr")
    write_exr(tmp_path / "v.exr", rng.random((64, 64, 3)).astype(np.float32), compression="none")
    data = (tmp_path / "v.exr").read_bytes()
    (tmp_path / "t.exr").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="t.exr"):
        read_exr(tmp_path / "t.exr")
    with pytest.raises(ValueError, match="t.exr"):
        read_exr_header(tmp_path / "t.exr")
    with pytest.raises(ValueError, match="channels"):
        write_exr(tmp_path / "x.exr", np.zeros((4, 4, 2)))
    with pytest.raises(ValueError, match="compression"):
        write_exr(tmp_path / "x.exr", np.zeros((4, 4, 3)), compression="jpeg")
    with pytest.raises(ValueError, match="ndim"):
        write_exr(tmp_path / "x.exr", np.zeros(4))
    with pytest.raises(TypeError, match="image"):
        write_exr(tmp_path / "x.exr", "abc")


def test_tiled_and_offset_data_window(tmp_path, rng):
    """Files written by OpenEXR itself: tiled storage; data window not at the origin."""
    a = rng.random((40, 50)).astype(np.float32)
    td = OpenEXR.TileDescription()
    td.xSize, td.ySize, td.mode = 16, 16, OpenEXR.ONE_LEVEL
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.tiledimage, "tiles": td}
    OpenEXR.File(hdr, {"R": a, "G": 2 * a, "B": 3 * a}).write(str(tmp_path / "t.exr"))
    assert read_exr_header(tmp_path / "t.exr")["storage"] == "tiled"
    np.testing.assert_array_equal(read_exr(tmp_path / "t.exr"), np.stack([a, 2 * a, 3 * a], -1))
    dw = (np.array([10, 20], np.int32), np.array([59, 59], np.int32))
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, "dataWindow": dw}
    OpenEXR.File(hdr, {"Y": a}).write(str(tmp_path / "d.exr"))
    h = read_exr_header(tmp_path / "d.exr")
    assert h["data_window"] == ((10, 20), (59, 59)) and (h["width"], h["height"]) == (50, 40)
    np.testing.assert_array_equal(read_exr(tmp_path / "d.exr")[..., 0], a)  # data window only


def test_jax_array_input(tmp_path):
    import jax.numpy as jnp

    img = jnp.linspace(0.0, 2.0, 4 * 6 * 3).reshape(4, 6, 3)
    write_exr(tmp_path / "j.exr", img.T.transpose(2, 1, 0))  # a JAX array, shape (4, 6, 3)
    np.testing.assert_array_equal(read_exr(tmp_path / "j.exr"), np.asarray(img))
