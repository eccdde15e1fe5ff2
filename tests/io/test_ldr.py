"""LDR images: PNG/JPEG/TIFF reading and writing (OpenCV as oracle), EXIF stacks, dispatch."""

import json

import cv2
import numpy as np
import pytest
import tifffile
from PIL import Image, TiffImagePlugin

from jaxgfx.io import (
    exif_exposure_time,
    read_any,
    read_image,
    read_ldr_stack,
    write_any,
    write_exr,
    write_png,
)


def _cv(path):
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    return img[..., ::-1] if img.ndim == 3 else img


@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("c", [0, 3, 4])
def test_png_roundtrip_vs_opencv(tmp_path, rng, bits, c):
    shape = (13, 17) if c == 0 else (13, 17, c)
    dtype = np.uint8 if bits == 8 else np.uint16
    img = rng.integers(0, 2**bits, shape).astype(dtype)
    p = tmp_path / "a.png"
    write_png(p, img, bits=bits)
    ours = read_image(p)
    assert ours.dtype == dtype
    np.testing.assert_array_equal(ours, img)
    cv = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if c:  # OpenCV returns BGR / BGRA
        cv = cv[..., [2, 1, 0, 3][:c]]
    np.testing.assert_array_equal(cv, img)  # independent decoder reads our file
    # and we read OpenCV's files
    q = tmp_path / "cv.png"
    cv2.imwrite(str(q), img if c == 0 else img[..., [2, 1, 0, 3][:c]])
    np.testing.assert_array_equal(read_image(q), img)


def test_png_float_quantisation(tmp_path):
    x = np.array([[0.0, 0.5, 1.0, 1.7, -0.2, 1 / 255]], np.float32)
    write_png(tmp_path / "f.png", x)
    np.testing.assert_array_equal(read_image(tmp_path / "f.png"), [[0, 128, 255, 255, 0, 1]])
    write_png(tmp_path / "g.png", x, bits=16)
    np.testing.assert_array_equal(
        read_image(tmp_path / "g.png"), [[0, 32768, 65535, 65535, 0, 257]]
    )
    f = read_image(tmp_path / "g.png", as_float=True)
    assert f.dtype == np.float32 and f[0, 2] == 1.0 and f[0, 5] == pytest.approx(1 / 255)
    with pytest.raises(ValueError, match="NaN"):
        write_png(tmp_path / "n.png", np.full((2, 2), np.nan))
    with pytest.raises(ValueError, match="bits"):
        write_png(tmp_path / "n.png", np.zeros((2, 2)), bits=12)
    with pytest.raises(ValueError, match="integer values"):
        write_png(tmp_path / "n.png", np.full((2, 2), 300))


def test_tiff_16bit_and_float(tmp_path, rng):
    img = rng.integers(0, 65536, (9, 11, 3)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "a.tif", img, photometric="rgb")
    np.testing.assert_array_equal(read_image(tmp_path / "a.tif"), img)
    np.testing.assert_allclose(read_image(tmp_path / "a.tif", as_float=True), img / 65535)


def _jpeg_with_exif(path, img, exposure):
    exif = Image.Exif()
    if exposure is not None:
        exif.get_ifd(0x8769)[0x829A] = TiffImagePlugin.IFDRational(*exposure)
    Image.fromarray(img).save(path, format="JPEG", quality=95, exif=exif)


def test_stack_from_exif_sorted(tmp_path, rng):
    base = rng.integers(0, 200, (16, 24, 3)).astype(np.uint8)
    exps = [(1, 30), (1, 250), (1, 2)]
    paths = []
    for i, e in enumerate(exps):
        paths.append(tmp_path / f"img{i}.jpg")
        _jpeg_with_exif(paths[-1], base + 20 * i, e)
    assert exif_exposure_time(paths[1]) == pytest.approx(1 / 250)
    imgs, times, order = read_ldr_stack(paths, return_order=True)
    imgs2, times2 = read_ldr_stack(paths, exposure_times=[])  # empty = not given
    np.testing.assert_array_equal(imgs2, imgs)
    np.testing.assert_array_equal(times2, times)
    np.testing.assert_allclose(times, [1 / 250, 1 / 30, 1 / 2])
    np.testing.assert_array_equal(order, [1, 0, 2])
    assert imgs.shape == (3, 16, 24, 3) and imgs.dtype == np.uint8
    # JPEG is lossy: compare each slot with its own file decoded by OpenCV
    for k, i in enumerate(order):
        np.testing.assert_array_equal(imgs[k], _cv(paths[i]))


def test_stack_errors(tmp_path, rng):
    img = rng.integers(0, 255, (8, 8, 3)).astype(np.uint8)
    _jpeg_with_exif(tmp_path / "a.jpg", img, (1, 100))
    _jpeg_with_exif(tmp_path / "b.jpg", img, None)
    with pytest.raises(ValueError, match="b.jpg"):
        read_ldr_stack([tmp_path / "a.jpg", tmp_path / "b.jpg"])
    write_png(tmp_path / "c.png", np.zeros((8, 9, 3), np.uint8))
    with pytest.raises(ValueError, match=r"sizes.*\(8, 8\).*\(8, 9\)"):
        read_ldr_stack([tmp_path / "a.jpg", tmp_path / "c.png"], exposure_times=[1, 2])
    with pytest.raises(ValueError, match="exposure_times"):
        read_ldr_stack([tmp_path / "a.jpg"], exposure_times=[1, 2])
    with pytest.raises(ValueError, match="paths"):
        read_ldr_stack([])


@pytest.mark.parametrize("kind", ["txt", "yaml", "json", "json_map"])
def test_stack_sidecar(tmp_path, rng, kind):
    paths = []
    for i in range(3):
        paths.append(tmp_path / f"p{i}.png")
        write_png(paths[-1], rng.integers(0, 65535, (8, 8, 3)).astype(np.uint16), bits=16)
    times = ["1/4", "1/1000", "0.0625"]
    if kind == "txt":
        side = tmp_path / "times.txt"
        side.write_text("\n".join(times))
    elif kind == "yaml":
        side = tmp_path / "times.yaml"
        side.write_text("exposure_times: [0.25, 0.001, 0.0625]\n")
    elif kind == "json":
        side = tmp_path / "times.json"
        side.write_text(json.dumps([0.25, 0.001, 0.0625]))
    else:
        side = tmp_path / "times.json"
        side.write_text(json.dumps({"p0.png": 0.25, "p1.png": "1/1000", "p2.png": 0.0625}))
    imgs, t, order = read_ldr_stack(paths, sidecar=side, return_order=True)
    np.testing.assert_allclose(t, [0.001, 0.0625, 0.25])
    np.testing.assert_array_equal(order, [1, 2, 0])
    assert imgs.dtype == np.uint16
    np.testing.assert_array_equal(imgs[0], read_image(paths[1]))
    side.write_text("[1, 2]" if kind.startswith("json") else "1\n2\n")
    with pytest.raises(ValueError, match="times"):
        read_ldr_stack(paths, sidecar=side)


def test_corrupt_ldr(tmp_path, rng):
    with pytest.raises(FileNotFoundError):
        read_image(tmp_path / "missing.png")
    (tmp_path / "g.png").write_bytes(b"garbage" * 20)
    with pytest.raises(ValueError, match="g.png"):
        read_image(tmp_path / "g.png")
    write_png(tmp_path / "v.png", rng.integers(0, 255, (64, 64, 3)).astype(np.uint8))
    data = (tmp_path / "v.png").read_bytes()
    (tmp_path / "t.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="t.png"):
        read_image(tmp_path / "t.png")
    _jpeg_with_exif(tmp_path / "v.jpg", rng.integers(0, 255, (64, 64, 3)).astype(np.uint8), None)
    data = (tmp_path / "v.jpg").read_bytes()
    (tmp_path / "t.jpg").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="t.jpg"):
        read_image(tmp_path / "t.jpg")
    (tmp_path / "t.tif").write_bytes(b"II*\x00garbage")
    with pytest.raises(ValueError, match="t.tif"):
        read_image(tmp_path / "t.tif")


def test_dispatch(tmp_path, rng):
    hdr = (rng.random((10, 12, 3)) * 50).astype(np.float32)
    for ext in ("exr", "hdr", "tif"):
        write_any(tmp_path / f"x.{ext}", hdr)
    np.testing.assert_array_equal(read_any(tmp_path / "x.exr"), hdr)
    np.testing.assert_array_equal(read_any(tmp_path / "x.tif"), hdr)
    err = np.abs(read_any(tmp_path / "x.hdr") - hdr)
    assert np.all(err <= hdr.max(-1, keepdims=True) * 2.0**-8)  # shared-exponent step / 2
    ldr = rng.random((10, 12, 3)).astype(np.float32)
    write_any(tmp_path / "x.png", ldr)
    np.testing.assert_allclose(read_any(tmp_path / "x.png"), ldr, atol=0.5 / 255 + 1e-7)
    smooth = np.broadcast_to(np.linspace(0.1, 0.9, 12)[None, :, None], (10, 12, 3))
    write_any(tmp_path / "x.jpg", smooth)
    assert np.abs(read_any(tmp_path / "x.jpg") - smooth).max() < 0.03  # lossy (quality 95)
    write_exr(tmp_path / "y.EXR", hdr)  # extension case is ignored
    np.testing.assert_array_equal(read_any(tmp_path / "y.EXR"), hdr)
    with pytest.raises(ValueError, match="unsupported extension"):
        (tmp_path / "z.xyz").write_bytes(b"abc")
        read_any(tmp_path / "z.xyz")
    with pytest.raises(ValueError, match="write_dng"):
        write_any(tmp_path / "z.dng", hdr)
