"""The render job: a scene description file → an image file (and a preview).

``run_render(job)`` checks the arguments and the output paths, loads the scene
(:func:`jaxgfx.render.load_scene`), renders it (:func:`jaxgfx.render.render`) and writes:

* ``job.output`` in the format of its extension: ``.exr`` / ``.hdr`` / ``.tif`` hold the
  linear radiance (float); ``.png`` / ``.jpg`` hold the display image (sRGB-encoded,
  clipped to [0, 1]; no tone mapping); the 7-channel ``aov`` integrator needs ``.exr``;
* for an HDR ``output``, a display preview beside it (``<stem>.png``, or ``job.preview``;
  ``preview="none"`` for none). For a display ``output`` there is no separate preview unless
  ``job.preview`` names one. The two paths must differ.

Outputs are staged and moved into place only when the render succeeded
(:mod:`jaxgfx.pipelines._output`); an existing file is refused unless ``job.overwrite``.
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

from jaxgfx._checks import check_choice
from jaxgfx.io import DISPLAY_WRITE_EXTENSIONS, LINEAR_WRITE_EXTENSIONS
from jaxgfx.pipelines._output import StagedFiles, check_output_extension

__all__ = ["RenderJob", "run_render", "render_output_paths"]

# linear outputs hold the radiance (float); display outputs the sRGB image (jaxgfx.io's table)
_LINEAR_EXT = LINEAR_WRITE_EXTENSIONS
_DISPLAY_EXT = DISPLAY_WRITE_EXTENSIONS


@dataclasses.dataclass(frozen=True)
class RenderJob:
    """One render: ``scene`` (YAML path), ``output`` (image path), and the estimator's options
    (``spp``, ``integrator``, ``max_depth``, ``seed``). ``preview``: ``None`` (default per the
    module docstring), ``"none"``, or a path."""

    scene: str
    output: str
    spp: int = 64
    integrator: str = "path"
    max_depth: int | None = None  # None: the integrator's own default (path/whitted: 3)
    seed: int = 0
    preview: str | None = None
    overwrite: bool = False
    accel: str = "auto"  # mesh traversal backend (docs/render_backends.md)

    def validate(self):
        from jaxgfx.render import INTEGRATORS

        for name in ("spp", "max_depth"):
            v = getattr(self, name)
            if v is None and name == "max_depth":
                continue
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name}: expected a positive integer, got {v!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed: expected an integer >= 0, got {self.seed!r}")
        check_choice(self.integrator, "integrator", INTEGRATORS)
        from jaxgfx.render.geometry.accel import resolve_backend

        resolve_backend(self.accel)  # ValueError / ImportError naming `accel`
        if not os.path.isfile(self.scene):
            what = "is a directory" if os.path.isdir(self.scene) else "no such file"
            raise FileNotFoundError(2, f"scene: {what}", self.scene)


def render_output_paths(job: RenderJob) -> dict[str, str]:
    """``{"output": path, "preview": path}`` (no ``"preview"`` when there is none), checked:
    known extensions, channel counts the formats can hold, distinct paths."""
    from jaxgfx.render import AOV_CHANNELS

    ext = check_output_extension(job.output, "output", _LINEAR_EXT + _DISPLAY_EXT)
    channels = len(AOV_CHANNELS) if job.integrator == "aov" else 3
    if channels != 3 and ext != ".exr":
        raise ValueError(
            f"output: {job.output!r}: the {job.integrator} integrator gives {channels} "
            f"channels, which {ext} cannot hold; use .exr"
        )
    paths = {"output": os.fspath(job.output)}
    preview = job.preview
    if preview is None and ext in _LINEAR_EXT:
        preview = os.path.splitext(os.fspath(job.output))[0] + ".png"
    if preview is not None and preview.lower() != "none":
        check_output_extension(preview, "preview", _DISPLAY_EXT)
        paths["preview"] = os.fspath(preview)
    return paths


def _display(img: np.ndarray) -> np.ndarray:
    from jaxgfx.pipelines.tonemap import tonemap_image

    # AOV images: the display image shows the albedo channels. Exposure 0, per-channel clip,
    # sRGB (jaxgfx.tonemap.tonemap_exposure)
    return tonemap_image(img[..., :3], "exposure", per_channel=True)


def run_render(job: RenderJob) -> dict:
    """Run the render job. Returns ``{"outputs": {name: path}, "seconds": float,
    "compile_seconds": float, "samples_per_second": float, "shape": (H, W, C)}``:
    ``seconds`` is the render alone (the compiled program's run), ``compile_seconds`` the
    tracing, lowering and compilation before it, ``samples_per_second`` = H·W·spp / seconds."""
    import equinox as eqx
    import jax

    from jaxgfx import io
    from jaxgfx.render import load_scene, render

    if not isinstance(job, RenderJob):
        raise TypeError(f"job: expected a RenderJob, got {type(job).__name__}")
    job.validate()
    paths = render_output_paths(job)
    with StagedFiles(paths, overwrite=job.overwrite) as stage:
        scene = load_scene(job.scene, accel=job.accel)
        key = jax.random.key(job.seed)
        program = eqx.filter_jit(
            lambda scene, key: render(
                scene, key, spp=job.spp, integrator=job.integrator, max_depth=job.max_depth
            )
        )
        t0 = time.perf_counter()
        compiled = program.lower(scene, key).compile()
        t1 = time.perf_counter()
        img = np.asarray(jax.block_until_ready(compiled(scene, key)), np.float32)
        dt = time.perf_counter() - t1
        if not np.all(np.isfinite(img)):
            raise ValueError(
                f"scene: {job.scene!r} rendered {int(np.sum(~np.isfinite(img)))} non-finite "
                "values (NaN/Inf); nothing written"
            )
        ext = os.path.splitext(paths["output"])[1].lower()
        main = _display(img) if ext in _DISPLAY_EXT else np.ascontiguousarray(img)
        io.write_any(stage.staging["output"], main)
        if "preview" in paths:
            io.write_any(stage.staging["preview"], _display(img))
    n = img.shape[0] * img.shape[1] * job.spp
    return {
        "outputs": paths,
        "seconds": dt,
        "compile_seconds": t1 - t0,
        "samples_per_second": n / max(dt, 1e-9),
        "shape": img.shape,
    }
