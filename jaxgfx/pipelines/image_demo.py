"""Image-processing demo: a procedural test image through the lecture-1 operations.

``run_image_demo(ImageDemoJob(out, size=...))`` writes PNGs and a histogram plot to ``out``
and returns a dict of output paths and timings. Used by ``make demo`` (``experiments/demo.py``).
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

from jaxgfx._checks import check_positive_int

__all__ = ["procedural_image", "ImageDemoJob", "run_image_demo"]


def procedural_image(height: int = 256, width: int = 256, *, seed: int = 0) -> np.ndarray:
    """A deterministic colourful test image in [0, 1]: gradients, discs, a checker and text-like
    bars, with a slight colour cast and low contrast (so white balance / stretching show)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    u, v = x / (width - 1), y / (height - 1)
    img = np.stack([0.3 + 0.4 * u, 0.25 + 0.35 * v, 0.35 + 0.2 * (1 - u)], axis=-1)
    for cy, cx, r, col in [
        (0.3, 0.3, 0.15, (1.0, 0.45, 0.4)),
        (0.6, 0.7, 0.2, (0.1, 0.55, 0.1)),
        (0.75, 0.3, 0.1, (0.05, 0.1, 0.6)),
    ]:
        m = (u - cx) ** 2 + (v - cy) ** 2 < r**2
        img[m] = col
    checker = ((x // 16 + y // 16) % 2 == 0) & (v > 0.85)
    img[checker] = 0.95
    bars = (np.sin(2 * np.pi * u * 12) > 0.6) & (v < 0.1)
    img[bars] = 0.05
    img = 0.25 + 0.5 * img  # low contrast
    img = img * np.array([1.1, 1.0, 0.8], np.float32)  # warm colour cast
    img = img + rng.normal(0, 0.01, img.shape)
    return np.clip(img, 0, 1).astype(np.float32)


@dataclasses.dataclass(frozen=True)
class ImageDemoJob:
    """One run of the image demo: ``out`` (the folder the PNGs and ``histograms.png`` are
    written to, created if needed; existing files of the same names are replaced) and ``size``
    (side of the square procedural test image, pixels)."""

    out: str = "out/image"
    size: int = 256

    def validate(self):
        check_positive_int(self.size, "size")


def run_image_demo(job: ImageDemoJob) -> dict:
    """Run the demo ``job``. Returns ``{"paths": {name: path}, "seconds": {name: float}}``
    (one PNG per operation, plus ``"histograms"``)."""
    if not isinstance(job, ImageDemoJob):
        raise TypeError(f"job: expected an ImageDemoJob, got {type(job).__name__}")
    job.validate()
    out_dir, size = os.fspath(job.out), job.size

    import jax
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxgfx import color, image, io

    os.makedirs(out_dir, exist_ok=True)
    img = procedural_image(size, size)
    key = jax.random.key(0)
    noisy = np.asarray(image.add_salt_and_pepper(key, img, amount=0.05))
    ops = {
        "00_input": lambda: img,
        "01_grey_world": lambda: color.white_balance_grey_world(img),
        "02_stretch": lambda: image.stretch_contrast(img, low=0.02, high=0.98),
        "03_equalized": lambda: image.equalize_histogram(img),
        "04_gamma_0.6": lambda: image.gamma_correct(img, 0.6),
        "05_gaussian_s3": lambda: image.gaussian_blur(img, 3.0),
        "06_salt_pepper": lambda: noisy,
        "07_median_3x3": lambda: image.median_filter(noisy, 3),
        "08_bilateral": lambda: image.bilateral_filter(img, 4.0, 0.1),
        "09_unsharp": lambda: image.unsharp_mask(img, 2.0, 1.5),
        "10_canny": lambda: np.asarray(image.canny(img, 1.5, 0.05, 0.15), np.float32),
        "11_demosaic_malvar": lambda: image.demosaic(image.bayer_mosaic(img, "RGGB"), "RGGB"),
        "12_lowpass": lambda: image.fourier_lowpass(img, 0.05),
    }
    paths, timings = {}, {}
    for name, fn in ops.items():
        t0 = time.perf_counter()
        out = np.asarray(jax.block_until_ready(fn()))
        timings[name] = time.perf_counter() - t0
        path = os.path.join(out_dir, f"{name}.png")
        io.write_png(path, np.clip(out, 0, 1))
        paths[name] = path

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
    for ax, (title, im) in zip(
        axes,
        [("input", img), ("equalised", np.asarray(image.equalize_histogram(img)))],
        strict=True,
    ):
        lum = np.asarray(color.luminance(im))
        ax.hist(lum.ravel(), bins=64, range=(0, 1), color="0.3")
        ax.set_title(f"luminance histogram: {title}")
        ax.set_xlabel("value")
    fig.tight_layout()
    plot = os.path.join(out_dir, "histograms.png")
    fig.savefig(plot, dpi=100)
    plt.close(fig)
    paths["histograms"] = plot
    return {"paths": paths, "seconds": timings}
