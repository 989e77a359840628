"""The mechanism that turns TOML tables into frozen, checked dataclasses.

A section is a frozen dataclass whose fields are declared with `setting(...)` (a scalar, a path, a tuple
of numbers, with range, choices and a help line) or `subsection(...)` (a nested table, or an array of
tables). `parse_section` checks every key against the dataclass: unknown keys (with a did-you-mean),
wrong types, values out of range or not among the choices, and paths that do not exist, each reported
as one line naming the key, the value and what is allowed. Nothing after this boundary sees a raw dict.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import types
import typing
from dataclasses import MISSING, dataclass, field
from pathlib import Path
from typing import Any

from arsim.core.errors import ArsimError

__all__ = ["PathResolver", "ScenarioError", "parse_section", "section_to_dict", "setting", "subsection"]


class ScenarioError(ArsimError):
    """A scenario that cannot be used as written."""


def setting(
    default: Any,
    *,
    help: str,
    min: float | None = None,
    max: float | None = None,
    choices: tuple[Any, ...] | None = None,
    must_exist: bool = False,
    unit: str = "",
    check: Any = None,
) -> Any:
    """Declare a scenario key: its default, a one-line help, and what values are allowed; check(value) returns
    what is wrong with a value and how to fix it (None: nothing), for rules beyond a range or choices."""
    meta = {"help": help, "min": min, "max": max, "choices": choices, "must_exist": must_exist, "unit": unit,
            "check": check}
    if isinstance(default, list):
        raise TypeError("use a tuple for sequence defaults, so the dataclass stays immutable")
    return field(default=default, metadata=meta)


def subsection(cls: type, *, help: str, array: bool = False, default: Any = None) -> Any:
    """Declare a nested table (`[a.b]`), or with array=True an array of tables (`[[a.b]]`).

    default: an instance of cls whose values stand for the keys a scenario leaves out, so that one
    section class can serve several tables with different defaults (the IMU's three sensors); for an
    array, a tuple of instances used when the scenario has no such array."""
    factory = (lambda: default) if default is not None else (tuple if array else cls)
    return field(default_factory=factory, metadata={"help": help, "section": cls, "array": array, "default": default})


@dataclass(frozen=True)
class PathResolver:
    """Resolves relative paths: first against the scenario file's folder, then the packaged assets."""

    scenario_dir: Path | None
    assets_dir: Path

    def resolve(self, value: str) -> tuple[Path, list[Path]]:
        """The resolved path (the first that exists, else the first candidate) and every candidate."""
        p = Path(value).expanduser()
        if p.is_absolute():
            return p, [p]
        bases = [b for b in (self.scenario_dir, self.assets_dir) if b is not None]
        candidates = [(b / p).resolve() for b in bases]
        return next((c for c in candidates if c.exists()), candidates[0]), candidates


def _printable(text: str) -> str:
    """text with its control characters escaped: an error naming it stays one line."""
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


def _describe(value: Any) -> str:
    if isinstance(value, str):
        return f'"{_printable(value)}"'
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "a table"
    return repr(value)


def _type_name(tp: Any) -> str:
    names = {bool: "true or false", int: "an integer", float: "a finite number", str: "a string", Path: "a path (string)"}
    if typing.get_origin(tp) is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"an array of {_type_name(args[0]).removeprefix('an ').removeprefix('a ')}s"
        return f"an array of {len(args)} {_type_name(args[0]).removeprefix('an ').removeprefix('a ')}s"
    return names.get(tp, getattr(tp, "__name__", str(tp)))


def _coerce_scalar(tp: Any, value: Any) -> Any:
    """The value as type tp, or raise TypeError. Integers are accepted for floats, never bools."""
    if tp is bool:
        if isinstance(value, bool):
            return value
    elif tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if isinstance(value, int) and abs(value) > 1e308:
                raise TypeError  # an integer no float holds (400 digits): not a number arsim can take
            if not math.isfinite(value):
                raise TypeError
            return float(value)
    elif tp in (str, Path):
        if isinstance(value, str):
            return value
    raise TypeError


def _coerce(tp: Any, value: Any) -> Any:
    if typing.get_origin(tp) is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, list):
            raise TypeError
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce_scalar(args[0], v) for v in value)
        if len(value) != len(args):
            raise TypeError
        return tuple(_coerce_scalar(a, v) for a, v in zip(args, value))
    if isinstance(tp, types.UnionType) or typing.get_origin(tp) is typing.Union:
        for option in typing.get_args(tp):
            if option is type(None):
                continue
            try:
                return _coerce(option, value)
            except TypeError:
                pass
        raise TypeError
    return _coerce_scalar(tp, value)


def _allowed(meta: dict) -> str:
    lo, hi, unit = meta["min"], meta["max"], f" {meta['unit']}" if meta["unit"] else ""
    if lo is not None and hi is not None:
        return f"from {lo} to {hi}{unit}"
    if lo is not None:
        return f"at least {lo}{unit}"
    return f"at most {hi}{unit}"


def _check_value(name: str, value: Any, meta: dict, where: str, written: Any) -> None:
    numbers = value if isinstance(value, tuple) else (value,)
    for v in numbers:
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            if (meta["min"] is not None and v < meta["min"]) or (meta["max"] is not None and v > meta["max"]):
                raise ScenarioError(f"{where} {name} = {_describe(written)} is out of range: allowed {_allowed(meta)}")
    for v in (value if isinstance(value, tuple) else (value,)) if meta["choices"] is not None else ():
        if v not in meta["choices"]:  # (an array's choices hold for each of its entries)
            options = ", ".join(_describe(c) for c in meta["choices"])
            hint = difflib.get_close_matches(str(v), [str(c) for c in meta["choices"]], n=1)
            mean = f"; did you mean {_describe(hint[0])}?" if hint else ""
            raise ScenarioError(f"{where} {name} = {_describe(value)} is not allowed: use one of {options}{mean}")
    problem = meta["check"](value) if meta.get("check") is not None else None
    if problem:
        raise ScenarioError(f"{where} {name} = {_describe(written)} {problem}")


def _unknown_key(key: str, known: list[str], where: str, top_level: bool) -> ScenarioError:
    hint = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
    if top_level:
        mean = f"did you mean [{hint[0]}]? " if hint else ""
        return ScenarioError(f"{where} unknown section [{key}]: {mean}(known sections: {', '.join(known)})")
    mean = f"did you mean '{hint[0]}'? " if hint else ""
    return ScenarioError(f"{where} unknown key '{key}': {mean}(known keys: {', '.join(known)})")


# Keys older versions wrote (a recording's meta.json keeps its scenario) that no longer mean anything: skipped on
# load so that those recordings still read. capture.correction_gain: the online drift correction's gain is now
# the Kalman filter's, from the device's noise figures (arsim/capture/drift.py).
RETIRED_KEYS = {"capture": ("correction_gain",)}


def parse_section(cls: type, table: Any, source: str, resolver: PathResolver, path: str = "",
                  defaults: Any = None) -> Any:
    """An instance of the section dataclass cls from a TOML table, every key checked.

    source names the file in messages; path is the table's dotted name ("" for the whole file);
    defaults, an instance of cls, replaces the class defaults for keys the table leaves out."""
    where = f"{source}: [{path}]" if path else f"{source}:"
    if not isinstance(table, dict):
        raise ScenarioError(f"{source}: '{path}' must be a table ([{path}]), got {_describe(table)}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    table = {k: v for k, v in table.items() if k not in RETIRED_KEYS.get(path, ())}
    for key in table:
        if key not in fields:
            raise _unknown_key(key, list(fields), where, top_level=not path)
    values: dict[str, Any] = {}
    for name, f in fields.items():
        sub = f.metadata.get("section")
        if name in table:
            raw = table[name]
        elif f.default is MISSING and f.default_factory is MISSING:
            raise ScenarioError(f"{where} {name} is missing: {f.metadata.get('help', 'required')}")
        elif isinstance(f.default, Path):
            raw = str(f.default)  # default paths resolve (and are checked) like written ones
        elif sub is not None and not f.metadata["array"]:
            raw = {}  # a section left out is parsed empty, so its default paths resolve too
        else:
            if defaults is not None:
                values[name] = getattr(defaults, name)
            continue
        if sub is not None:
            dotted = f"{path}.{name}" if path else name
            if f.metadata["array"]:
                if not isinstance(raw, list):
                    raise ScenarioError(f"{source}: '{dotted}' must be an array of tables ([[{dotted}]]), got {_describe(raw)}")
                values[name] = tuple(
                    parse_section(sub, item, source, resolver, f"{dotted}[{i}]") for i, item in enumerate(raw)
                )
            else:
                values[name] = parse_section(sub, raw, source, resolver, dotted, f.metadata.get("default"))
            continue
        tp = hints[name]
        try:
            value = _coerce(tp, raw)
        except TypeError:
            raise ScenarioError(f"{where} {name} = {_describe(raw)} has the wrong type: expected {_type_name(tp)}") from None
        _check_value(name, value, f.metadata, where, raw)
        if tp is Path or Path in typing.get_args(tp):
            try:
                resolved, candidates = resolver.resolve(value)
                found = resolved.is_file()
            except (RuntimeError, ValueError, OSError) as exc:  # ~nosuchuser, a NUL byte, a name too long
                raise ScenarioError(f"{where} {name} = {_describe(raw)[:80]}: is not a usable path ({_printable(str(exc))}); fix the path") from None
            if f.metadata["must_exist"] and not found:
                looked = _printable(" or ".join(str(c) for c in candidates))
                what = "a folder, not a file" if resolved.is_dir() else "no such file"
                raise ScenarioError(f"{where} {name} = {_describe(raw)[:80]}: {what} (looked for {looked[:300]}); fix the path")
            value = resolved
        values[name] = value
    section = cls(**values)
    problem = section.rules() if hasattr(section, "rules") else None  # cross-field rules, once the fields are checked
    if problem:
        raise ScenarioError(f"{where} {problem}")
    return section


def section_to_dict(obj: Any) -> dict[str, Any]:
    """A section as a TOML-ready dict (paths as strings, tuples as lists, nested sections as tables)."""

    def plain(v: Any) -> Any:
        if dataclasses.is_dataclass(v):
            return section_to_dict(v)
        if isinstance(v, tuple):
            return [plain(x) for x in v]
        if isinstance(v, Path):
            return str(v)
        return v

    return {f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj) if getattr(obj, f.name) is not None}
