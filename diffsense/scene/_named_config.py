"""Load a config by its shipped name (configs/<folder>/<name>.toml) or by a file path."""

from __future__ import annotations

from pathlib import Path
from typing import TypeVar

from diffsense.config import list_defaults, load, load_default
from diffsense.runtime import InputError

C = TypeVar("C")


def load_named(cls: type[C], folder: str, name_or_path: str | Path, what: str) -> C:
    """A shipped config of `folder` by name, or a TOML file by path; else one line naming the
    known names."""
    text = str(name_or_path)
    known = list_defaults(folder)
    if text in known:
        return load_default(cls, f"{folder}/{text}.toml")
    if text.endswith(".toml") or Path(text).exists():
        return load(cls, text)
    raise InputError(f"unknown {what} {text!r} (known: {', '.join(known)}; or a .toml path)")
