"""Strict TOML -> frozen dataclass loading.

A config is a frozen dataclass whose fields carry type annotations. `from_dict` builds one from
a parsed TOML table and refuses, with one line naming the key, any unknown key, missing key
(a field without a default), or value of the wrong type. Domain checks (a range that must be
positive, ...) belong in the dataclass's own `__post_init__`, raising `InputError`.

Supported field types: bool, int, float (an int is accepted and converted), str,
`Literal[...]`, `tuple[T, ...]`, `list[T]`, `dict[str, T]`, `X | None`, and nested config dataclasses.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

from diffsense.runtime import InputError, read_text_file

C = TypeVar("C")


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")


def _convert(value: Any, tp: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(value, arg, where)
            except InputError as e:
                errors.append(str(e))
        raise InputError(errors[-1] if errors else f"{where}: unexpected value {value!r}")
    if origin is typing.Literal:
        if value not in args:
            choices = ", ".join(repr(a) for a in args)
            raise InputError(f"{where}: {value!r} is not one of {choices}")
        return value
    if origin is dict:
        if not isinstance(value, dict):
            raise InputError(f"{where}: expected a table, got {type(value).__name__} {value!r}")
        key_tp, item_tp = args if args else (str, Any)
        if key_tp is not str:
            raise TypeError(f"unsupported config dict key type {_type_name(key_tp)} at {where}")
        return {str(k): _convert(v, item_tp, f"{where}.{k}") for k, v in value.items()}
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise InputError(f"{where}: expected a list, got {type(value).__name__} {value!r}")
        if origin is tuple and not (len(args) == 2 and args[1] is Ellipsis):
            if len(value) != len(args):
                raise InputError(f"{where}: expected {len(args)} values, got {len(value)}")
            items = [_convert(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args))]
        else:
            item_tp = args[0] if args else Any
            items = [_convert(v, item_tp, f"{where}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise InputError(f"{where}: expected a table, got {type(value).__name__} {value!r}")
        return from_dict(tp, value, where)
    if tp is Any:
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise InputError(f"{where}: expected true/false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"{where}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise InputError(f"{where}: expected a finite number, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise InputError(f"{where}: expected a string, got {value!r}")
        return value
    raise TypeError(f"unsupported config field type {_type_name(tp)} at {where}")


def from_dict(cls: type[C], data: dict[str, Any], where: str = "") -> C:
    """Build the config dataclass `cls` from `data`, refusing unknown keys and wrong types."""
    if not isinstance(data, dict):
        raise InputError(f"{where or cls.__name__}: expected a table, got {data!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    prefix = f"{where}." if where else ""
    unknown = sorted(set(data) - set(fields))
    if unknown:
        known = ", ".join(sorted(fields))
        raise InputError(f"unknown key '{prefix}{unknown[0]}' (known keys: {known})")
    kwargs = {}
    for name, f in fields.items():
        if name in data:
            kwargs[name] = _convert(data[name], hints[name], f"{prefix}{name}")
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise InputError(f"missing key '{prefix}{name}'")
    return cls(**kwargs)


def to_dict(config: Any) -> Any:
    """The plain (TOML/JSON-ready) form of a config dataclass, recursively."""
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        return {f.name: to_dict(getattr(config, f.name)) for f in dataclasses.fields(config)}
    if isinstance(config, (list, tuple)):
        return [to_dict(v) for v in config]
    if isinstance(config, dict):
        return {k: to_dict(v) for k, v in config.items()}
    return config


def replace(config: C, **changes: Any) -> C:
    """`dataclasses.replace` with the same checks as loading (types, domains)."""
    merged = to_dict(config) | {k: to_dict(v) for k, v in changes.items()}
    return from_dict(type(config), merged)


MAX_TOML_DEPTH = 32  # arrays, inline tables and dotted-key parts; the shipped configs nest 2 deep


def _nesting(text: str) -> int:
    """How deep `text` nests, counted in one pass before parsing (strings and comments skipped):
    the deepest nesting of arrays and inline tables, or the most parts of one dotted key, each a
    table level. tomllib recurses once per nesting level, and a dotted key costs it time quadratic
    in its parts."""
    stack: list[str] = []  # the arrays and inline tables open at i
    deepest = parts = 0
    in_key, after_equals = True, False  # where a key may stand; whether this line has had its "="
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch == "#":
            i = text.find("\n", i)
            i = n if i < 0 else i
            continue
        if ch in "\"'":
            quote = text[i:i + 3] if text[i:i + 3] in ('"""', "'''") else ch
            i += len(quote)
            while i < n and not text.startswith(quote, i):
                i += 2 if ch == '"' and text[i] == "\\" else 1
            i += len(quote) - 1
        elif ch == "\n" and not stack:
            in_key, after_equals, parts = True, False, 0
        elif ch == "=" and in_key:
            in_key, after_equals = False, True
        elif ch == "." and in_key:
            parts += 1
            deepest = max(deepest, len(stack) + parts + 1)
        elif ch == "{" or (ch == "[" and (stack or after_equals)):  # else "[" opens a table header
            stack.append(ch)
            deepest = max(deepest, len(stack))
            in_key, parts = ch == "{", 0
        elif ch == "," and stack and stack[-1] == "{":
            in_key, parts = True, 0
        elif ch in "]}" and stack:
            stack.pop()
        i += 1
    return deepest


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """Parse TOML text, turning a syntax error into one `InputError` line naming `source`; nesting
    deeper than MAX_TOML_DEPTH is refused before parsing, an integer beyond 64 bits after it."""
    if _nesting(text) > MAX_TOML_DEPTH:
        raise InputError(f"{source}: TOML nested more than {MAX_TOML_DEPTH} levels deep")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{source}: malformed TOML: {e}") from None
    except ValueError:  # tomllib's int() of an integer over Python's 4300-digit limit
        raise InputError(f"{source}: malformed TOML: an integer with too many digits") from None
    except RecursionError:  # a nesting the count above missed: still one line, never a traceback
        raise InputError(f"{source}: TOML nested too deeply") from None
    _check_integers(data, source)
    return data


INT64 = (-(2**63), 2**63 - 1)


def _check_integers(data: dict[str, Any], source: str) -> None:
    """Refuse an integer outside 64 bits, as the TOML spec requires (tomllib keeps any size, and
    a float() of one past 1e308 overflows). Iterative, with each key path kept as a link to its
    parent's: tables nest as deep as a header's dotted key says."""
    stack: list[tuple[Any, tuple | None]] = [(data, None)]
    while stack:
        value, trail = stack.pop()
        if isinstance(value, dict):
            stack.extend((v, (str(k), trail)) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((v, (f"[{i}]", trail)) for i, v in enumerate(value))
        elif isinstance(value, int) and not isinstance(value, bool) and not INT64[0] <= value <= INT64[1]:
            keys = []
            while trail is not None:
                keys.append(trail[0])
                trail = trail[1]
            where = ".".join(reversed(keys)).replace(".[", "[")
            raise InputError(f"{source}: {where[:200]}: an integer beyond TOML's 64-bit range")


def load(cls: type[C], path: str | Path) -> C:
    """Load a config dataclass from a TOML file; every error names the file."""
    path = Path(path)
    text = read_text_file(path, "config file")
    try:
        return from_dict(cls, parse_toml(text, str(path)))
    except InputError as e:
        msg = str(e)
        raise InputError(msg if msg.startswith(str(path)) else f"{path}: {msg}") from None
