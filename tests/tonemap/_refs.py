"""Shared test inputs and reference runners (OpenCV, Debian's pfstmo command-line operators)."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile

import numpy as np

from jaxgfx.hdr.synthetic import hard_hdr_scenes as hard_scenes  # noqa: F401
from jaxgfx.hdr.synthetic import smooth_hdr_scene as synthetic_hdr  # noqa: F401


def block_means(a, block=16):
    """Means of the ``block`` x ``block`` tiles of ``(H, W)`` ``a``, flattened."""
    H, W = a.shape
    return a.reshape(H // block, block, W // block, block).mean((1, 3)).ravel()


def psnr(a, b, peak=1.0):
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(peak**2 / mse)


def mean_delta_e2000(a_srgb, b_srgb):
    """Mean CIEDE2000 between two sRGB-encoded images in [0, 1] (colour-science)."""
    import colour

    def lab(v):
        lin = colour.models.eotf_sRGB(np.clip(np.asarray(v, np.float64), 0, 1))
        xyz = colour.RGB_to_XYZ(lin, colour.RGB_COLOURSPACES["sRGB"])
        return colour.XYZ_to_Lab(
            xyz, colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
        )

    return float(np.mean(colour.delta_E(lab(a_srgb), lab(b_srgb), method="CIE 2000")))


# ----------------------------------------------------------------------------- pfstmo

PFS_MISSING = "pfstmo not installed (apt-get install pfstools pfstmo)"


def have_pfstmo() -> bool:
    return all(shutil.which(c) for c in ("pfsinpfm", "pfsoutpfm", "pfstmo_drago03"))


def write_pfm(path, img):
    img = np.asarray(img, np.float32)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, -1)
    H, W, _ = img.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{W} {H}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(img[::-1]).astype("<f4").tobytes())


def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        W, H = map(int, f.readline().split())
        scale = float(f.readline())
        data = np.frombuffer(f.read(), "<f4" if scale < 0 else ">f4")
    c = 3 if kind == b"PF" else 1
    return data.reshape(H, W, c)[::-1].copy()


def run_pfstmo(img, cmd: list[str]):
    """Run ``pfsinpfm | <cmd> | pfsoutpfm`` on a linear RGB image; returns linear RGB."""
    with tempfile.TemporaryDirectory() as d:
        src, dst = os.path.join(d, "in.pfm"), os.path.join(d, "out.pfm")
        write_pfm(src, img)
        pipe = f"pfsinpfm {src} | {' '.join(cmd)} | pfsoutpfm {dst}"
        subprocess.run(pipe, shell=True, check=True, capture_output=True, timeout=120)
        return read_pfm(dst)
