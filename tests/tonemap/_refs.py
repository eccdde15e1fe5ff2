"""Shared test inputs and reference runners (OpenCV, Debian's pfstmo command-line operators)."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile

import numpy as np


def synthetic_hdr(H=32, W=48, *, seed=0, zeros=False, dynamic_range=1e4):
    """A smooth HDR scene: sky gradient, a bright disc ("sun"), textured ground, coloured
    patches; ``dynamic_range`` ~ max / min of the non-zero pixels."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    yy /= max(H - 1, 1)
    xx /= max(W - 1, 1)
    sky = np.exp(np.log(dynamic_range) * 0.35 * (1.0 - yy))[..., None] * np.array([0.6, 0.8, 1.0])
    ground = (0.05 + 0.04 * np.sin(40 * xx) * np.cos(30 * yy))[..., None] * np.array(
        [0.7, 0.55, 0.35]
    )
    img = np.where((yy > 0.55)[..., None], ground, sky)
    d2 = (yy - 0.25) ** 2 + (xx - 0.7) ** 2
    img += (d2 < 0.01)[..., None] * dynamic_range * 0.3 * np.array([1.0, 0.95, 0.8])
    img *= np.exp(0.1 * rng.standard_normal((H, W, 1)))
    if zeros:
        img[-max(H // 6, 1) :, : max(W // 3, 1)] = 0.0
    return img.astype(np.float32)


def hard_scenes(n=96, block=16, seed=0):
    """Issue 27: HDR scenes with exact-zero backgrounds, ~10^9:1 range and a 10^6 sun, built
    from ``block``-sized regions (for block-mean order checks); positions scale with ``n``.
    ``{name: (n, n, 3) float32}``."""
    rng = np.random.default_rng(seed)
    nb = n // block
    yy, xx = np.mgrid[0:n, 0:n] * (96.0 / n)  # layout drawn on a 96 x 96 canvas
    r2 = (96.0 / n) ** 2  # one pixel, squared, in canvas units
    out = {}
    # 1: patchwork of flat regions 1e-3..1e3 (a third exactly zero) and a sun
    lev = 10.0 ** rng.uniform(-3, 3, (nb, nb))
    lev[rng.random((nb, nb)) < 0.33] = 0.0
    img = np.kron(lev, np.ones((block, block)))
    img = img * np.exp(0.05 * rng.standard_normal((n, n)))
    img[(yy - 40) ** 2 + (xx - 56) ** 2 < max(25, 2 * r2)] = 1e6
    out["patches_sun"] = img
    # 2: black sky with stars (3 x 3 canvas-px dots 1..1e5) and a moon
    img = np.zeros((n, n))
    for _ in range(24):
        y, x = rng.integers(2, 93, 2)
        img[(np.abs(yy - y) <= max(1, 0.5 * 96 / n)) & (np.abs(xx - x) <= max(1, 0.5 * 96 / n))] = (
            10.0 ** rng.uniform(0, 5)
        )
    img[(yy - 20) ** 2 + (xx - 70) ** 2 < max(36, 2 * r2)] = 1e6
    out["stars"] = img
    # 3: zero background, a lit room (1e-2..1) with a window (1e2) and a sun (1e6)
    img = np.zeros((n, n))
    room = (yy >= 16) & (yy < 80) & (xx >= 8) & (xx < 88)
    img[room] = 0.02 * np.exp(3.0 * xx[room] / 96.0)
    img[(yy >= 24) & (yy < 56) & (xx >= 48) & (xx < 80)] = 100.0
    img[(yy - 40) ** 2 + (xx - 64) ** 2 < max(16, 2 * r2)] = 1e6
    out["room"] = img * np.exp(0.05 * rng.standard_normal((n, n)))
    col = np.array([1.0, 0.9, 0.7])
    return {k: (v[..., None] * col).astype(np.float32) for k, v in out.items()}


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
