"""Config loading: types coerced, unknown/missing/wrong-typed keys rejected with their path."""

import dataclasses
from typing import Literal

import pytest

from jaxgfx.config import config_to_dict, load_config, read_yaml


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


# -- duplicate keys, dotted paths (issue 28) ---------------------------------------------------


@pytest.mark.parametrize(
    "text, needle",
    [
        ("name: a\nseed: 1\nseed: 2\n", "c.yaml:3: duplicate key 'seed' (first given on line 2)"),
        (
            "name: a\ninner:\n  lam: 1\n  method: debevec\n  lam: 2\n",
            "c.yaml:5: duplicate key 'lam' (first given on line 3)",
        ),
        (
            "name: a\ninner: {lam: 1, lam: 2}\n",
            "c.yaml:2: duplicate key 'lam' (first given on line 2)",
        ),
        ("name: a\ntimes: [1, {x: 1, x: 2}]\n", "c.yaml:2: duplicate key 'x'"),
    ],
)
def test_duplicate_yaml_keys_are_refused_at_every_level(tmp_path, text, needle):
    # PyYAML keeps the last of two equal keys silently; read_yaml names the key, file and line
    p = tmp_path / "c.yaml"
    p.write_text(text)
    with pytest.raises(ValueError) as e:
        load_config(Outer, p)
    assert needle in str(e.value)


def test_fit_config_with_optimizer_twice_is_refused(tmp_path):
    # issue 28's case: `optimizer:` twice in a `jaxgfx fit` config kept the last one silently
    from jaxgfx.pipelines.fit.config import FitConfig

    p = tmp_path / "fit.yaml"
    p.write_text(
        "scene: scene.yaml\ntarget: photo.exr\nparams: {materials.m.alpha: {init: 0.1}}\n"
        "optimizer: {name: adam, lr: 0.01}\noptimizer: {name: sgd, lr: 0.5}\n"
    )
    with pytest.raises(ValueError) as e:
        load_config(FitConfig, p)
    assert "fit.yaml:5: duplicate key 'optimizer' (first given on line 4)" in str(e.value)


def test_yaml_merge_keys_are_not_duplicates(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("name: a\nbase: &b {lam: 1.0, method: robertson}\n")
    assert read_yaml(p)["base"] == {"lam": 1.0, "method": "robertson"}
    p.write_text("name: a\ninner:\n  <<: {lam: 1.0, method: robertson}\n  lam: 2.0\n")
    assert load_config(Outer, p).inner == Inner(lam=2.0, method="robertson")


@dataclasses.dataclass(frozen=True)
class Checked:
    spp: int = 4

    def validate(self):
        if self.spp < 1:
            raise ValueError(f"spp: expected >= 1, got {self.spp}")


@dataclasses.dataclass(frozen=True)
class Holder:
    target: Checked = Checked()
    other: Checked | None = None


@pytest.mark.parametrize(
    "data, where, message",
    [
        ({"target": {"spp": 0}}, "", "target.spp: expected >= 1, got 0"),
        ({"other": {"spp": -1}}, "", "other.spp: expected >= 1, got -1"),
        ({"target": {"spp": 0}}, "job", "job.target.spp: expected >= 1, got 0"),
        ({"target": {"spp": "x"}}, "job", "job.target.spp: expected an integer, got 'x'"),
        (
            {"target": {"sp": 1}},
            "job",
            "unknown config key(s) job.target.sp; expected some of: spp",
        ),
        ({1: 2}, "", "unknown config key(s) 1; expected some of: other, target"),
    ],
)
def test_errors_name_the_full_dotted_path(data, where, message):
    with pytest.raises(ValueError) as e:
        load_config(Holder, data, where=where)
    assert str(e.value) == message


def test_union_error_names_the_path_once():
    with pytest.raises(ValueError) as e:
        load_config(Outer, {"name": "a", "seed": "x"}, where="fit")
    assert str(e.value) == "fit.seed: expected an integer, got 'x'"

    @dataclasses.dataclass(frozen=True)
    class Either:
        value: float | tuple[float, ...] | None = None

    with pytest.raises(ValueError) as e:
        load_config(Either, {"value": "abc"}, where="params.p")
    assert str(e.value) == (
        "params.p.value: 'abc' matches none of float | tuple[float, ...] | None "
        "(expected a number, got 'abc'; expected a list, got str; or null)"
    )


@dataclasses.dataclass(frozen=True)
class Fixed:
    gains: tuple[float, float, float] = (1.0, 1.0, 1.0)
    pair: tuple[int, str] = (0, "a")


def test_fixed_length_tuples_coerce_each_item_by_its_type():
    """``tuple[float, float, float]`` (e.g. the fit's ``camera.white_balance.init``): each item
    coerced by its own type, and a config round-trips through :func:`config_to_dict`."""
    cfg = load_config(Fixed, {"gains": [2, 1, 0.5], "pair": [3, "b"]})
    assert cfg == Fixed(gains=(2.0, 1.0, 0.5), pair=(3, "b"))
    assert all(isinstance(g, float) for g in cfg.gains)
    assert load_config(Fixed, config_to_dict(cfg)) == cfg
    with pytest.raises(ValueError, match=r"pair\[1\]"):
        load_config(Fixed, {"pair": [1, 2]})
    with pytest.raises(ValueError, match="gains: expected 3 items, got 2"):
        load_config(Fixed, {"gains": [1, 2]})
