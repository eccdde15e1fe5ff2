"""Exposure from shutter time, aperture and ISO (issue 26): a bracket differing in more than
time, written as DNGs and as JPEGs with EXIF, read back by jaxgfx.io."""

import numpy as np
import pytest
from PIL import Image

from jaxgfx import io


def test_exposure_values_closed_form():
    # EV arithmetic: f/4 -> f/2.8 is (4/2.8)^2 = 2.04x, ISO 100 -> 400 is 4x
    t = io.exposure_values([0.5, 0.5, 0.25], [4.0, 2.8, 4.0], [100, 100, 400])
    np.testing.assert_allclose(t, [0.5, 0.5 * (4 / 2.8) ** 2, 1.0], rtol=1e-12)
    # a time-only bracket (equal or unknown apertures) is left as it is
    np.testing.assert_array_equal(io.exposure_values([1.0, 4.0], [8.0, 8.0], [None, 100]),
                                  [1.0, 4.0])  # fmt: skip
    with pytest.raises(ValueError, match="frame 1: f-number must be finite and > 0"):
        io.exposure_values([1.0, 1.0], [2.0, 0.0])


def test_raw_bracket_differing_in_iso_and_aperture(tmp_path):
    # same shutter time, three apertures/ISOs: true relative exposures 1, 2, 8
    rng = np.random.default_rng(0)
    scene = rng.uniform(0.002, 0.1, (24, 32))
    fnum = [5.6, 4.0, 4.0]
    iso = [100.0, 100.0, 400.0]
    true_h = np.array([1.0, (5.6 / 4.0) ** 2, (5.6 / 4.0) ** 2 * 4])
    paths = []
    for i in (2, 0, 1):  # file order != exposure order
        dn = 256 + np.clip(scene * true_h[i], 0, 1) * 3839 + rng.normal(0, 1.5, scene.shape)
        p = str(tmp_path / f"f{i}.dng")
        io.write_dng(p, np.clip(np.round(dn), 0, 4095).astype(np.uint16), black_level=256,
                     white_level=4095, exposure_time=1 / 60, iso=iso[i], f_number=fnum[i],
                     camera_whitebalance=(1.0, 1.0, 1.0))  # fmt: skip
        paths.append(p)
    raws, h = io.read_raw_stack(paths)
    assert [r.iso for r in raws] == iso and [r.f_number for r in raws] == fnum
    np.testing.assert_allclose(h / h[0], true_h, rtol=1e-6)
    # seconds at the first file's aperture and ISO (f2: f/4, ISO 400)
    np.testing.assert_allclose(h[-1], 1 / 60, rtol=1e-6)
    # the measured mosaic ratio agrees (an independent check of the direction of each factor)
    x = np.stack([r.normalized() for r in raws])
    meas = np.median(x[1:] / np.maximum(x[0], 1e-6), axis=(1, 2))
    np.testing.assert_allclose(meas, true_h[1:], rtol=0.02)
    # explicit times are taken as the exposures
    _, h2 = io.read_raw_stack(paths, exposure_times=[3.0, 1.0, 2.0])
    np.testing.assert_array_equal(h2, [1.0, 2.0, 3.0])


def test_ldr_bracket_exif_iso_and_aperture(tmp_path):
    paths = []
    for i, (t, fn, iso) in enumerate([(0.01, 8.0, 200), (0.01, 8.0, 800), (0.04, 4.0, 200)]):
        img = Image.fromarray(np.full((8, 8, 3), 40 * (i + 1), np.uint8))
        exif = Image.Exif()
        sub = exif.get_ifd(0x8769)
        sub[0x829A], sub[0x829D], sub[0x8827] = t, fn, iso
        p = str(tmp_path / f"f{i}.jpg")
        img.save(p, exif=exif)
        paths.append(p)
    _, h = io.read_ldr_stack(paths)
    np.testing.assert_allclose(h / h[0], [1.0, 4.0, 16.0], rtol=1e-6)
