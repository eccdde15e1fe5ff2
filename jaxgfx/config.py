"""Typed configuration loading: YAML / dict -> frozen dataclass, with strict validation.

Research scripts in ``experiments/`` describe their options as frozen dataclasses and load
them with :func:`load_config`. Unknown keys, wrong types and missing required fields raise
``ValueError`` naming the offending field (with its dotted path, also for the errors of a nested
dataclass's ``validate``), so a typo in a config file never silently falls back to a default.
:func:`read_yaml` refuses a key given twice in one mapping (YAML would keep the last one),
naming the key, the file and both lines.

Example::

    @dataclasses.dataclass(frozen=True)
    class Opts:
        sigma: float = 1.0
        method: str = "debevec"

    load_config(Opts, {"sigma": 2})  # -> Opts(sigma=2.0, method='debevec')
"""

from __future__ import annotations

import dataclasses
import os
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar

import yaml

__all__ = ["load_config", "config_to_dict", "read_yaml", "safe_load_yaml"]

T = TypeVar("T")


class _DuplicateKey(yaml.YAMLError):
    def __init__(self, key, line: int, first: int):
        super().__init__(f"duplicate key {key!r}")
        self.key, self.line, self.first = key, line, first


class _StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping (at any depth)."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen: dict = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue  # `<<: *anchor`: explicit keys override merged ones by design
                key = self.construct_object(key_node, deep=True)
                line = key_node.start_mark.line + 1
                try:  # compared as the dict compares them: 1, 1.0 and true are one key
                    if key in seen:
                        raise _DuplicateKey(key, line, seen[key])
                    seen[key] = line
                except TypeError:  # an unhashable key: the base class reports it
                    continue
        return super().construct_mapping(node, deep=deep)


def safe_load_yaml(stream, name: str = "<yaml>"):
    r"""``yaml.safe_load(stream)``, refusing duplicate keys: ``ValueError`` naming ``name``
    (the file), the line and the key; other YAML errors as ``ValueError`` naming ``name``.

    >>> safe_load_yaml("a: 1\nb: {c: 2, c: 3}\n", "x.yaml")
    Traceback (most recent call last):
    ...
    ValueError: x.yaml:2: duplicate key 'c' (first given on line 2)
    """
    try:
        return yaml.load(stream, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except _DuplicateKey as e:
        raise ValueError(
            f"{name}:{e.line}: duplicate key {e.key!r} (first given on line {e.first})"
        ) from None
    except yaml.YAMLError as e:
        raise ValueError(f"{name}: not valid YAML ({' '.join(str(e).split())})") from None


def read_yaml(path: str | os.PathLike) -> dict:
    """Read a YAML mapping from ``path``; clear errors for missing or malformed files and for
    a key given twice in one mapping (``ValueError`` naming the file, line and key)."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"config file not found: {path}")
    if os.path.isdir(path):
        raise IsADirectoryError(21, "config: is a folder, expected a YAML file", path)
    with open(path, encoding="utf-8") as f:
        try:
            data = safe_load_yaml(f, path)
        except UnicodeDecodeError:
            raise ValueError(f"{path}: not a UTF-8 text (YAML) file") from None
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise ValueError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    return dict(data)


def _coerce(value: Any, tp: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        if len(options) == 1:  # X | None: X's own error (a nested dataclass's names its key)
            return _coerce(value, options[0], where)
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(value, a, where)
            except (TypeError, ValueError) as e:
                errors.append(_strip_where(str(e), where))
        if type(None) in args:
            errors.append("or null")
        raise ValueError(f"{where}: {value!r} matches none of {tp} ({'; '.join(errors)})")
    if origin is typing.Literal:
        if value not in args:
            raise ValueError(f"{where}: expected one of {args}, got {value!r}")
        return value
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, Mapping):
            raise ValueError(f"{where}: expected a mapping, got {type(value).__name__}")
        return _build(tp, value, where)
    if origin in (tuple,):
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{where}: expected a list, got {type(value).__name__}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if args and len(args) != len(value):
            raise ValueError(f"{where}: expected {len(args)} items, got {len(value)}")
        return tuple(
            _coerce(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=True))
        )
    if origin in (list,):
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{where}: expected a list, got {type(value).__name__}")
        return [_coerce(v, args[0] if args else Any, f"{where}[{i}]") for i, v in enumerate(value)]
    if origin in (dict, Mapping) or tp in (dict,):
        if not isinstance(value, Mapping):
            raise ValueError(f"{where}: expected a mapping, got {type(value).__name__}")
        return dict(value)
    if tp is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{where}: expected true/false, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ValueError(f"{where}: expected a string, got {value!r}")
        return value
    return value


def _strip_where(message: str, where: str) -> str:
    """``message`` without its leading ``where: `` (for messages nested in another)."""
    return message[len(where) + 2 :] if where and message.startswith(f"{where}: ") else message


def _under(message: str, where: str) -> str:
    """``message`` of a nested ``validate`` under the path ``where``: unchanged when it already
    starts with ``where``, else ``where.KEY: ...`` (a message that names a key) or
    ``where: ...``."""
    if (
        not where
        or message == where
        or message.startswith((f"{where}.", f"{where}:", f"{where}[", f"{where} "))
    ):
        return message
    head = message.split(":", 1)[0]
    if (
        ":" in message
        and head
        and all(p.isidentifier() for p in head.replace("[", ".").split(".") if not p.endswith("]"))
    ):
        return f"{where}.{message}"
    return f"{where}: {message}"


def _build(cls: type[T], data: Mapping, where: str) -> T:
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted((k for k in data if k not in fields), key=str)
    if unknown:
        prefix = f"{where}." if where else ""
        raise ValueError(
            f"unknown config key(s) {', '.join(prefix + str(k) for k in unknown)}; "
            f"expected some of: {', '.join(sorted(fields))}"
        )
    kwargs = {}
    for name, f in fields.items():
        path = f"{where}.{name}" if where else name
        if name in data:
            kwargs[name] = _coerce(data[name], hints[name], path)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ValueError(f"missing required config key {path}")
    obj = cls(**kwargs)
    check = getattr(obj, "validate", None)
    if callable(check):
        try:
            check()
        except (ValueError, TypeError) as e:
            message = _under(str(e), where)
            if message == str(e):
                raise
            raise type(e)(message) from None
    return obj


def load_config(
    cls: type[T],
    source: str | os.PathLike | Mapping | None = None,
    *,
    where: str = "",
    **overrides,
) -> T:
    """Build the frozen dataclass ``cls`` from a YAML path, a mapping, or nothing (defaults).

    ``overrides`` are applied on top (dotted keys like ``fit__method`` are not supported;
    pass nested mappings instead). Nested dataclass fields are built recursively. If the class
    defines ``validate(self)``, it is called after construction. ``where``: the dotted path of
    this mapping inside a larger config (e.g. ``"params.materials.metal.alpha"``), prefixed to
    every error message (the keys of a nested dataclass are prefixed with their own path).

    >>> @dataclasses.dataclass(frozen=True)
    ... class Spec:
    ...     init: float = 0.0
    >>> load_config(Spec, {"init": "abc"}, where="params.alpha")
    Traceback (most recent call last):
    ...
    ValueError: params.alpha.init: expected a number, got 'abc'
    """
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise TypeError(f"cls: expected a dataclass type, got {cls!r}")
    if source is None:
        data: dict = {}
    elif isinstance(source, Mapping):
        data = dict(source)
    else:
        data = read_yaml(source)
    data.update(overrides)
    return _build(cls, data, where)


def config_to_dict(cfg) -> dict:
    """Plain-dict view of a (nested) config dataclass, for reports."""
    return dataclasses.asdict(cfg)
