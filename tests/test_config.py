"""Config loading: types coerced, unknown/missing/wrong-typed keys rejected with their path."""

import dataclasses
from typing import Literal

import pytest

from jaxgfx.config import config_to_dict, load_config


@dataclasses.dataclass(frozen=True)
class Inner:
    lam: float = 10.0
    method: Literal["debevec", "robertson"] = "debevec"


@dataclasses.dataclass(frozen=True)
class Outer:
    name: str
    times: tuple[float, ...] = (1.0,)
    inner: Inner = Inner()
    seed: int | None = None

    def validate(self):
        if any(t <= 0 for t in self.times):
            raise ValueError("times: expected positive exposure times")


def test_load_from_dict_and_yaml(tmp_path):
    cfg = load_config(Outer, {"name": "a", "times": [1, 2], "inner": {"lam": 3}})
    assert cfg == Outer(name="a", times=(1.0, 2.0), inner=Inner(lam=3.0))
    assert isinstance(cfg.times[0], float)
    p = tmp_path / "c.yaml"
    p.write_text("name: b\ninner:\n  method: robertson\nseed: 3\n")
    cfg = load_config(Outer, p)
    assert cfg.inner.method == "robertson" and cfg.seed == 3
    assert config_to_dict(cfg)["inner"] == {"lam": 10.0, "method": "robertson"}


@pytest.mark.parametrize(
    "data, match",
    [
        ({"name": "a", "tims": [1]}, "tims"),
        ({"name": "a", "inner": {"lamda": 1}}, "inner.lamda"),
        ({"times": [1]}, "name"),
        ({"name": "a", "inner": {"method": "mitsunaga"}}, "inner.method"),
        ({"name": "a", "inner": {"lam": "big"}}, "inner.lam"),
        ({"name": "a", "times": [1, -2]}, "times"),
        ({"name": 3}, "name"),
    ],
)
def test_bad_configs_name_the_field(data, match):
    with pytest.raises(ValueError, match=match):
        load_config(Outer, data)


def test_bad_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_config(Outer, tmp_path / "nope.yaml")
    p = tmp_path / "bad.yaml"
    p.write_text("name: [unclosed\n")
    with pytest.raises(ValueError, match="bad.yaml"):
        load_config(Outer, p)
    p.write_text("- 1\n- 2\n")
    with pytest.raises(ValueError, match="mapping"):
        load_config(Outer, p)
