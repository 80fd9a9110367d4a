"""One configuration mechanism for every tunable dataclass of the toolkit.

A configuration class is a frozen dataclass that inherits `Config`:

    @dataclass(frozen=True)
    class DatabaseParams(Config):
        PRESETS = {"strict": {"confirmations": 2}}   # no annotation: a class attribute, not a field

        shortlist: int = setting(5, range="[1, inf)", doc="candidates verified by local matching")
        min_overlap: float | None = setting(None, range="[0, 1]", doc="...")

and gets, with no code of its own:

- construction that converts and checks every field (`__post_init__`): strings become enums, lists tuples, integral
  floats ints, "1e-5" a float; a wrong type, a value outside the field's `range`, a value not in its `choices` or NaN
  is a `ConfigError`. Infinity is accepted only where the range includes it (`[0, inf]`). Rules that involve
  several fields go in an optional `check(self)` method that raises `ConfigError` naming the keys (a subclass
  does not define `__post_init__`).
- `Cls.from_dict(mapping, source=..., base=...)`: nested mappings become nested configs, unknown keys are errors
  (with a suggestion), missing keys keep the value of `base` (default: the class defaults).
- `Cls.load(path)`: a YAML (.yaml/.yml), TOML (.toml) or JSON (.json) file.
- `obj.to_dict()`, `obj.dumps()` (YAML text) and `obj.dump(path)` (YAML or JSON by suffix, written atomically).
- `obj.replace(**changes)`: a validated copy with some fields changed (a nested field may be given as a mapping of
  its own changes).
- `Cls.preset(name, **changes)`: `PRESETS` maps a name to the changes it makes to the defaults.
- `obj.with_overrides(["loops.mode=5", "graph.robust=huber"])`: command-line style dotted assignments, each value
  read as a YAML scalar (`5`, `1e-5`, `true`, `null`, `[8, 6]`, `huber`).
- `Cls.describe()`: a plain-text table of every dotted key with its default, range or choices, unit and doc.
- `SHORTHAND = "method"` (class attribute): a scalar given where this config is expected, as a nested field, sets
  that one field (`graph.robust=none` for `graph.robust.method=none`), on top of the base when replacing.
- `MOVED = {"old_key": "group.new_key"}` (class attribute): a key that moved into a nested config is a ConfigError
  naming its new dotted key, not an unknown setting.
- `REMOVED = {"old_key": "why"}` (class attribute): a key whose setting was removed is a ConfigError saying so and
  why, not an unknown setting.

Tunables are documented where they are declared, with `setting(default, range=..., unit=..., doc=...)`: the
range is an interval written as text ("[1, inf)", "(0, 1]", "(0.5, 1)") or a (low, high) pair, closed, None for
unbounded; for a tuple field it applies to each element. Comments next to a field explain why; `doc` says what.

Every error names where the value came from and the dotted key: a type problem names the key itself
("c.yaml: vo.max_features: expected an integer, got 'many'"), a value rule names the section and the rule
("c.yaml: loops.database: shortlist must be >= 1, got -5"; "FusionConfig: gyro_sigma must be >= 0, got -1.0"
when built in code).
"""
from __future__ import annotations

import dataclasses
import difflib
import enum
import functools
import json
import math
import numbers
import re
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import yaml

from odometry.shared.atomic_io import atomic_write_text
from odometry.shared.errors import ConfigError

try:
    import tomllib
except ModuleNotFoundError:   # Python 3.10: the tomli backport (a declared dependency there)
    import tomli as tomllib

__all__ = ["Config", "ConfigError", "Interval", "setting"]

_FLOAT_TEXT = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")   # "1e-5": YAML 1.1 reads it as a string


# ---------------------------------------------------------------------------------------------------- ranges
@dataclasses.dataclass(frozen=True)
class Interval:
    """A range of allowed numbers; None for an unbounded side (always open there: infinity is outside)."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    @classmethod
    def parse(cls, spec: "str | tuple | Interval") -> "Interval":
        """'[1, inf)', '(0, 1]', '[-inf, inf]' or a closed (low, high) pair with None for unbounded."""
        if isinstance(spec, Interval):
            return spec
        if isinstance(spec, tuple):
            low, high = spec
            return cls(low, high, low is None, high is None)
        m = re.fullmatch(r"\s*([\[(])\s*([^,\s]+)\s*,\s*([^,\s]+)\s*([\])])\s*", spec)
        if not m:
            raise ValueError(f"bad range {spec!r}: write it as an interval such as '[0, 1]' or '(0, inf)'")
        low, high = float(m.group(2)), float(m.group(3))
        return cls(None if low == -math.inf and m.group(1) == "(" else low,
                   None if high == math.inf and m.group(4) == ")" else high,
                   m.group(1) == "(", m.group(4) == ")")

    def __contains__(self, v: float) -> bool:
        if math.isnan(v):
            return False
        if self.low is None:
            ok_low = v > -math.inf
        else:
            ok_low = v > self.low if self.low_open else v >= self.low
        if self.high is None:
            ok_high = v < math.inf
        else:
            ok_high = v < self.high if self.high_open else v <= self.high
        return ok_low and ok_high

    def __str__(self) -> str:
        low = "-inf" if self.low is None else f"{self.low:g}"
        high = "inf" if self.high is None else f"{self.high:g}"
        return f"{'(' if self.low_open else '['}{low}, {high}{')' if self.high_open else ']'}"

    def rule(self) -> str:
        """The rule in words: '>= 0', '> 1', 'in [0, 1]', 'a finite number'."""
        if self.low is None and self.high is None:
            return "a finite number"
        if self.high is None:
            return f"{'>' if self.low_open else '>='} {self.low:g}"
        if self.low is None:
            return f"{'<' if self.high_open else '<='} {self.high:g}"
        return f"in {self}"


ANY_FINITE = Interval()


def setting(default: Any = dataclasses.MISSING, *, default_factory: Any = dataclasses.MISSING,
            range: "str | tuple | None" = None, choices: Iterable | None = None, unit: str | None = None,
            doc: str | None = None) -> Any:
    """A dataclass field with its allowed range (or choices), unit and one-line description."""
    meta: dict[str, Any] = {}
    if range is not None:
        meta["range"] = Interval.parse(range)
    if choices is not None:
        meta["choices"] = tuple(choices)
    if unit is not None:
        meta["unit"] = unit
    if doc is not None:
        meta["doc"] = doc
    return dataclasses.field(default=default, default_factory=default_factory, metadata=meta)


# ---------------------------------------------------------------------------------------------------- errors
class _Problem(Exception):
    """A bad value at a dotted location `where` (relative to the object being built); the public entry points
    turn it into a ConfigError prefixed with the source."""

    def __init__(self, where: str, message: str):
        super().__init__(f"{where}: {message}" if where else message)
        self.where, self.message = where, message


class _InvalidConfig(ConfigError):
    """Raised by construction; from_dict re-reads `where` and `message` to place it in the file's key path."""

    def __init__(self, owner: str, where: str, message: str):
        super().__init__(f"{owner}: {where}: {message}" if where else f"{owner}: {message}")
        self.where, self.message = where, message


def _join(where: str, key: str) -> str:
    if not key:
        return where
    return f"{where}.{key}" if where else str(key)


# ---------------------------------------------------------------------------------------------------- conversion
@functools.lru_cache(maxsize=None)
def _fields(cls: type) -> tuple[tuple[dataclasses.Field, Any], ...]:
    """The settable fields of a dataclass with their resolved type hints."""
    hints = typing.get_type_hints(cls)
    return tuple((f, hints[f.name]) for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_"))


def _field_names(cls: type) -> list[str]:
    return [f.name for f, _ in _fields(cls)]


def _convert(tp: Any, value: Any, where: str, base: Any = None) -> Any:
    """`value` as type `tp`, or a _Problem naming `where`. Mappings for dataclass types are built on `base`."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        return _convert_union(args, value, where, base)
    if origin is typing.Literal:
        for a in args:
            if value == a and type(value) is type(a):
                return a
        raise _Problem(where, f"{value!r} is not one of {', '.join(map(str, args))}")
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, Mapping) and getattr(tp, "SHORTHAND", None):
            value = {tp.SHORTHAND: value}    # `robust: none` for `robust: {method: none}`
        if not isinstance(value, Mapping):
            raise _Problem(where, f"expected a mapping of {tp.__name__} settings, got {value!r}")
        return _build(tp, value, where, base)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        try:
            return tp(value)
        except ValueError:
            raise _Problem(where, f"{value!r} is not one of {', '.join(str(m.value) for m in tp)}") from None
    if origin in (tuple, list):
        return _convert_sequence(origin, args, value, where)
    if origin is dict or tp is dict:
        if not isinstance(value, Mapping):
            raise _Problem(where, f"expected a mapping, got {value!r}")
        return dict(value)
    if tp in _SCALARS:
        return _SCALARS[tp](value, where)
    return value


def _convert_union(args: tuple, value: Any, where: str, base: Any) -> Any:
    """The first arm of `X | Y | None` that accepts the value (the first arm's complaint otherwise)."""
    if value is None and type(None) in args:
        return None
    problems = []
    for a in args:
        if a is type(None):
            continue
        try:
            return _convert(a, value, where, base if isinstance(a, type) and isinstance(base, a) else None)
        except _Problem as p:
            problems.append(p)
    raise problems[0] if problems else _Problem(where, f"bad value {value!r}")


def _convert_sequence(origin: type, args: tuple, value: Any, where: str) -> tuple | list:
    """tuple[int, int] (fixed length), tuple[float, ...] and list[X]; a 1-D numpy array counts as a list."""
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        raise _Problem(where, f"expected a list, got {value!r}")
    if origin is tuple and args and args[-1] is not Ellipsis:
        if len(value) != len(args):
            raise _Problem(where, f"expected {len(args)} values, got {len(value)}")
        return tuple(_convert(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    inner = args[0] if args else Any
    seq = [_convert(inner, v, f"{where}[{i}]") for i, v in enumerate(value)]
    return tuple(seq) if origin is tuple else seq


def _to_bool(value: Any, where: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise _Problem(where, f"expected true or false, got {value!r}")
    return bool(value)


def _to_int(value: Any, where: str) -> int:
    if isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, float) and value.is_integer():
        return int(value)
    raise _Problem(where, f"expected an integer, got {value!r}")


def _to_float(value: Any, where: str) -> float:
    if isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)):
        return float(value)
    if isinstance(value, str) and _FLOAT_TEXT.fullmatch(value.strip()):
        return float(value)
    raise _Problem(where, f"expected a number, got {value!r}")


def _to_str(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise _Problem(where, f"expected a string, got {value!r}")
    return value


_SCALARS = {bool: _to_bool, int: _to_int, float: _to_float, str: _to_str}


def _numbers_in(value: Any) -> Iterable[tuple[str, float, Any]]:
    """The numbers a range applies to: the value itself, or each element of a tuple/list (suffix '[i]')."""
    if isinstance(value, bool):
        return
    if isinstance(value, numbers.Real):
        yield "", float(value), value
    elif isinstance(value, (tuple, list)):
        for i, v in enumerate(value):
            if isinstance(v, numbers.Real) and not isinstance(v, bool):
                yield f"[{i}]", float(v), v


def _check_value(f: dataclasses.Field, value: Any) -> None:
    """The field's choices and range (NaN and infinities are outside every range unless it includes them)."""
    if value is None:
        return
    choices = f.metadata.get("choices")
    if choices is not None and value not in choices:
        raise _Problem("", f"{f.name} must be one of {', '.join(map(str, choices))}, got {value!r}")
    interval = f.metadata.get("range", ANY_FINITE)
    for suffix, number, given in _numbers_in(value):
        if number not in interval:
            raise _Problem("", f"{f.name}{suffix} must be {interval.rule()}, got {given!r}")


def _build(cls: type, data: Mapping, where: str, base: Any = None) -> Any:
    """An instance of dataclass `cls` from `data` (keys missing from it: from `base`, else the defaults)."""
    if not isinstance(data, Mapping):
        raise _Problem(where, f"expected a mapping of {cls.__name__} settings, got {data!r}")
    by_name = {f.name: (f, tp) for f, tp in _fields(cls)}
    kwargs = {}
    for key, value in data.items():
        path = _join(where, str(key))
        if key not in by_name:
            moved = getattr(cls, "MOVED", {}).get(key)
            if moved is not None:
                raise _Problem(path, f"this setting moved to {_join(where, moved)}")
            removed = getattr(cls, "REMOVED", {}).get(key)
            if removed is not None:
                raise _Problem(path, f"this setting was removed ({removed})")
            raise _Problem(path, _unknown(cls, str(key)))
        f, tp = by_name[key]
        kwargs[key] = _convert(tp, value, path, getattr(base, key, None))
    if base is None:
        missing = [f.name for f, _ in by_name.values() if f.name not in kwargs
                   and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
        if missing:
            raise _Problem(_join(where, missing[0]), "missing required setting")
    try:
        return dataclasses.replace(base, **kwargs) if base is not None else cls(**kwargs)
    except _InvalidConfig as exc:
        raise _Problem(_join(where, exc.where), exc.message) from None
    except ConfigError as exc:   # a nested class that validates without this mechanism
        raise _Problem(where, str(exc)) from None
    except (TypeError, ValueError) as exc:
        raise _Problem(where, str(exc)) from None


def _unknown(cls: type, key: str) -> str:
    names = _field_names(cls)
    close = difflib.get_close_matches(key, names, n=1)
    if close:
        return f"unknown setting (unknown {cls.__name__} field; did you mean {close[0]!r}?)"
    return f"unknown setting (unknown {cls.__name__} field; the known ones are {', '.join(sorted(names))})"


def _plain(obj: Any) -> Any:
    """Enums as their values, tuples as lists, nested configs as dicts: what YAML, TOML and JSON can hold."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _plain(getattr(obj, f.name)) for f, _ in _fields(type(obj))}
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, Mapping):
        return {k: _plain(v) for k, v in obj.items()}
    return obj


def read_mapping(path: str | Path) -> dict:
    """The top-level mapping of a YAML, TOML or JSON file (an empty file is an empty mapping)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: config file not found")
    text = path.read_text(encoding="utf-8")
    suffix = path.suffix.lower()
    try:
        if suffix == ".toml":
            data = tomllib.loads(text)
        elif suffix == ".json":
            data = json.loads(text) if text.strip() else None
        else:
            data = yaml.safe_load(text)
    except (yaml.YAMLError, tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"{path}: cannot parse ({exc})") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping of settings at the top level, got {type(data).__name__}")
    return data


def parse_assignments(assignments: Iterable[str], source: str = "--set") -> dict:
    """["loops.mode=5", "graph.robust=huber"] -> {"loops": {"mode": 5}, "graph": {"robust": "huber"}}."""
    out: dict = {}
    for item in assignments:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key or any(not part for part in key.split(".")):
            raise ConfigError(f"{source}: expected KEY=VALUE with a dotted KEY such as loops.mode=5, got {item!r}")
        try:
            value = yaml.safe_load(text) if text.strip() else None
        except yaml.YAMLError:
            value = text   # not a YAML scalar (e.g. "a: b"): kept as text; the field's type decides
        *parents, leaf = key.split(".")
        node = out
        for i, part in enumerate(parents):
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError(f"{source}: {'.'.join(parents[:i + 1])} is set both as a value and as a section")
        if isinstance(node.get(leaf), dict):
            raise ConfigError(f"{source}: {key} is set both as a value and as a section")
        node[leaf] = value
    return out


# ---------------------------------------------------------------------------------------------------- the mixin
class Config:
    """Mixin for frozen dataclasses of tunables; see the module docstring."""

    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {}
    LABEL: ClassVar[str | None] = None   # how preset errors name this kind of configuration (default: class name)
    SHORTHAND: ClassVar[str | None] = None   # a scalar given where this config is expected sets this field
    MOVED: ClassVar[Mapping[str, str]] = {}   # former keys -> their dotted key relative to this config (an error)
    REMOVED: ClassVar[Mapping[str, str]] = {}   # former keys -> why the setting was removed (an error)

    def __post_init__(self) -> None:
        owner = type(self).__name__
        for f, tp in _fields(type(self)):
            value = getattr(self, f.name)
            try:
                converted = _convert(tp, value, f.name)
                _check_value(f, converted)
            except _Problem as p:
                raise _InvalidConfig(owner, p.where, p.message) from None
            if converted is not value:
                object.__setattr__(self, f.name, converted)
        try:
            self.check()
        except _InvalidConfig:
            raise
        except ConfigError as exc:
            raise _InvalidConfig(owner, "", str(exc)) from None

    def check(self) -> None:
        """Rules between fields; raise ConfigError with a message that names the keys (e.g. "a must be <= b")."""

    # ------------------------------------------------------------------ reading
    @classmethod
    def from_dict(cls, data: Mapping, source: str | None = None, *, base: "Config | None" = None):
        """Build from a mapping (keys missing from it: from `base`, else the defaults). Errors start with
        `source` (a file name; default the class name) and name the dotted key."""
        try:
            return _build(cls, data, "", base)
        except _Problem as p:
            raise ConfigError(f"{source or cls.__name__}: {p}") from None

    @classmethod
    def load(cls, path: str | Path):
        """Read a YAML (.yaml/.yml), TOML (.toml) or JSON (.json) file; errors name the file and the key."""
        return cls.from_dict(read_mapping(path), str(path))

    @classmethod
    def preset(cls, name: str, **changes):
        """The named preset (`PRESETS[name]` applied to the defaults), with `changes` on top."""
        if name not in cls.PRESETS:
            raise ConfigError(f"unknown {cls.LABEL or cls.__name__} preset {name!r}; "
                              f"choose one of {', '.join(cls.PRESETS)}")
        obj = cls.from_dict(cls.PRESETS[name], f"{cls.__name__} preset {name!r}")
        return obj.replace(**changes) if changes else obj

    # ------------------------------------------------------------------ copies
    def replace(self, **changes):
        """A validated copy with some fields changed (values are converted as when loading; a nested config may
        be given as a mapping of its changes)."""
        return self.from_dict(changes, type(self).__name__, base=self)

    def with_overrides(self, assignments: Iterable[str], source: str = "--set"):
        """A copy with dotted command-line assignments applied, e.g. ["loops.mode=5", "vo.grid=[8, 6]"]; each
        value is read as a YAML scalar and then converted to the field's type. Errors start with `source`."""
        return self.from_dict(parse_assignments(assignments, source), source, base=self)

    # ------------------------------------------------------------------ writing
    def to_dict(self) -> dict:
        """Plain values (enums as their values, tuples as lists), nested configs as nested dicts."""
        return _plain(self)

    def dumps(self) -> str:
        """YAML text that `load` reads back to an equal object."""
        return yaml.safe_dump(self.to_dict(), sort_keys=False)

    def dump(self, path: str | Path) -> None:
        """Write YAML (or JSON for a .json path) atomically. TOML is read but not written (it has no null)."""
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix == ".json":
            text = json.dumps(self.to_dict(), indent=1) + "\n"
        elif suffix in (".yaml", ".yml"):
            text = self.dumps()
        else:
            raise ConfigError(f"{path}: write a config as .yaml, .yml or .json")
        atomic_write_text(path, text)

    # ------------------------------------------------------------------ documentation
    @classmethod
    def describe(cls) -> str:
        """One line per (dotted) key: type, default, range or choices, unit, doc."""
        rows = [("key", "default", "allowed", "unit", "doc")]
        rows += list(_describe_rows(cls, ""))
        widths = [max(len(r[i]) for r in rows) for i in range(4)]
        return "\n".join("  ".join(c.ljust(w) for c, w in zip(r[:4], widths)) + "  " + r[4] for r in rows) + "\n"


def _describe_rows(cls: type, where: str) -> Iterable[tuple[str, str, str, str, str]]:
    defaults = cls() if all(f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING
                            for f, _ in _fields(cls)) else None
    for f, tp in _fields(cls):
        key = _join(where, f.name)
        if dataclasses.is_dataclass(tp):
            yield from _describe_rows(tp, key)
            continue
        default = "" if defaults is None else json.dumps(_plain(getattr(defaults, f.name)))
        if "choices" in f.metadata:
            allowed = "one of " + ", ".join(map(str, f.metadata["choices"]))
        elif isinstance(tp, type) and issubclass(tp, enum.Enum):
            allowed = "one of " + ", ".join(str(m.value) for m in tp)
        elif "range" in f.metadata:
            allowed = str(f.metadata["range"])
        else:
            allowed = ""
        yield key, default, allowed, f.metadata.get("unit", ""), f.metadata.get("doc", "")
