"""Defects found by issue 12's probe, in typed configs (jaxgfx.config, pipeline config dataclasses):
one test each (every one failed before its fix), grouped by the code they exercise (the
D-numbers are the probe's).

References: scikit-image (``canny``, ``equalize_hist``), SciPy (``gaussian_laplace``), the
closed-form derivative of the LoG kernel at a vanishing sigma, the project's own readers for
files written by the CLI (format by content, not by name).
"""

from __future__ import annotations

import re

import pytest

from jaxgfx.config import load_config
from jaxgfx.pipelines.calibrate import CalibrateConfig

from ._util import read_only_sys

READ_ONLY = "/sys/jaxgfx-reliability"  # sysfs: not writable, even by root


def _read_only_available() -> bool:
    return read_only_sys()


# --------------------------------------------------------------- D4 config values checked


@pytest.mark.parametrize(
    "data, needle",
    [
        ({"demosaic": "fancy"}, "demosaic: expected one of ('bilinear', 'malvar')"),
        ({"preview_key": -1.0}, "preview_key: expected a finite value > 0"),
        ({"preview_key": 0.0}, "preview_key"),
        ({"response": {"options": {"n_samples": 0}}}, "n_samples: expected an integer >= 32"),
        ({"response": {"options": {"n_samples": 31}}}, "n_samples"),
        ({"response": {"options": {"smoothness": 50.0}}}, "has no option 'smoothness'"),
        ({"align": {"method": "sift"}}, "align.method: expected one of ('phase', 'mtb')"),
        ({"merge": {"weighting": "box"}}, "merge.weighting"),
        ({"response": {"method": "magic"}}, "response.method"),
        ({"response": {"compare": ["debevec", "nope"]}}, "response.compare[1]"),
        ({"exposure_times": [1.0, 0.0]}, "exposure_times[1]"),
    ],
)
def test_d04_config_values_are_checked(data, needle):
    with pytest.raises(ValueError) as e:
        load_config(CalibrateConfig, data)
    assert needle in str(e.value)


def test_d04_the_config_comment_example_loads():
    # the example in configs/calibrate.yaml's comment must be a valid options mapping
    with open("configs/calibrate.yaml", encoding="utf-8") as f:
        text = f.read()
    example = re.search(r"options: \{\}.*e\.g\. (\{.*\})", text).group(1)
    import yaml

    opts = yaml.safe_load(example)
    cfg = load_config(CalibrateConfig, {"response": {"options": opts}})
    assert cfg.response.options == opts and "lam" in opts
