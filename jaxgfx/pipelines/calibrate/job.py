"""The job: :class:`CalibrateJob` and :func:`run_calibrate`, a short sequence of stages
(inputs -> LDR or RAW path -> outputs -> report) inside an output staging folder."""

from __future__ import annotations

import dataclasses
import os
import time

from jaxgfx.pipelines._output import StagedDir

from . import ldr, raw, report
from .config import CalibrateConfig
from .inputs import collect_inputs, find_sidecar, stack_kind

__all__ = ["CalibrateJob", "run_calibrate"]


@dataclasses.dataclass(frozen=True)
class CalibrateJob:
    """One run of the calibration job: the config plus where to read and write.

    ``inputs``: image files or one folder (empty: the embedded synthetic stack);
    ``out``: the results folder (see :mod:`jaxgfx.pipelines._output` for the guarantees);
    ``overwrite``: replace the results of a previous run in ``out`` (else refused).
    """

    config: CalibrateConfig = CalibrateConfig()
    inputs: tuple[str, ...] = ()
    out: str = "out/calibrate"
    overwrite: bool = False
    progress: bool = True


class _Steps:
    """Progress reporting (tqdm) plus per-step wall-clock timings for the report."""

    def __init__(self, total: int, enabled: bool):
        from tqdm.auto import tqdm

        self.bar = tqdm(total=total, disable=not enabled, desc="calibrate", unit="step")
        self.timings: dict[str, float] = {}
        self._t = time.perf_counter()
        self._name = None

    def start(self, name: str):
        self._close_step()
        self._name = name
        self.bar.set_postfix_str(name)
        self._t = time.perf_counter()

    def _close_step(self):
        if self._name is not None:
            self.timings[self._name] = round(time.perf_counter() - self._t, 4)
            self.bar.update(1)
            self._name = None

    def close(self):
        self._close_step()
        self.bar.close()


def _compute(job: CalibrateJob, files, kind: str, steps) -> report.CalibrateResult:
    """The LDR or RAW path (module attributes, so tests can replace a stage)."""
    cfg = job.config
    if kind == "raw":
        return raw._fit_raw(cfg, files, steps)
    result_kw: dict = {}
    images, times, truth = ldr._load_ldr(cfg, files, find_sidecar(job.inputs), steps, result_kw)
    return ldr._fit_ldr(cfg, images, times, truth, steps, result_kw)


def run_calibrate(job: CalibrateJob) -> dict:
    """Run the calibration ``job`` (a :class:`CalibrateJob`: config, inputs, out, overwrite,
    progress); returns the report dict (also written to ``report.json``). Inputs and the output
    folder are checked before any computation; results appear in ``out`` only when the whole
    run succeeded (see :mod:`jaxgfx.pipelines._output`). The returned dict also has
    ``"replaced"``: the previous results that were replaced.
    """
    if not isinstance(job, CalibrateJob):
        raise TypeError(f"job: expected a CalibrateJob, got {type(job).__name__}")
    job = dataclasses.replace(
        job, inputs=tuple(os.fspath(i) for i in job.inputs or ()), out=os.fspath(job.out)
    )
    files = collect_inputs(job.inputs)
    kind = stack_kind(files)
    ff = job.config.flat_field
    if ff is not None:
        if kind != "raw":
            raise ValueError(f"flat_field: a RAW flat-field frame needs RAW inputs, not {kind}")
        if not os.path.isfile(ff):
            raise FileNotFoundError(f"flat_field: file not found: {ff}")
    if job.config.chart is not None and kind != "raw":
        raise ValueError(f"chart: the colour-chart fit needs RAW inputs, not {kind}")
    t_all = time.perf_counter()
    with StagedDir(job.out, report.OUTPUT_NAMES, overwrite=job.overwrite) as stage:
        steps = _Steps(total=5 if files else 6, enabled=job.progress)
        try:
            result = _compute(job, files, kind, steps)
            steps.start("write outputs")
            names = report.write_outputs(stage.path, result, job.config)
        finally:
            steps.close()
        outputs = report.output_paths(job.out, [*names, "report.json"])
        timings = {**steps.timings, "total": round(time.perf_counter() - t_all, 4)}
        rep = report.build_report(job, files, result, timings, outputs)
        report.write_report(stage.path, rep)
    return {**rep, "replaced": stage.replaced}
