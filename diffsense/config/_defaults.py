"""Where the shipped default configs live.

`configs/` at the repository top is the one source of defaults. An installed package carries it
as `diffsense._configs` (see pyproject.toml); a source checkout reads it in place.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path
from typing import Any, TypeVar

from diffsense.config._schema import from_dict, parse_toml
from diffsense.runtime import InputError, read_text_file

C = TypeVar("C")


def _configs_root():
    try:
        root = importlib.resources.files("diffsense._configs")
        if root.is_dir():
            return root
    except ModuleNotFoundError:
        pass
    return Path(__file__).resolve().parents[2] / "configs"


def default_text(relpath: str) -> str:
    """The text of a shipped config, e.g. `default_text("sensors/radar.toml")`."""
    node = _configs_root()
    for part in relpath.split("/"):
        node = node / part
    try:
        return node.read_text()
    except FileNotFoundError:
        raise InputError(f"no shipped config named {relpath!r}") from None


def list_defaults(folder: str) -> list[str]:
    """Names (without .toml) of the shipped configs in `folder`, sorted."""
    node = _configs_root() / folder
    return sorted(p.name[:-5] for p in node.iterdir() if p.name.endswith(".toml"))


def merge(base: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    """`base` with the keys of `extra` replacing its, tables merged key by key (recursively)."""
    out = dict(base)
    for key, value in extra.items():
        out[key] = merge(base[key], value) if isinstance(value, dict) and isinstance(base.get(key), dict) else value
    return out


def load_layers(cls: type[C], shipped: list[str], user: str | Path | None = None) -> C:
    """`cls` from shipped configs merged in order (a later one's keys replace earlier ones'), then
    the user's TOML at `user` (any subset of the keys). Unknown keys and wrong types are refused
    with one line naming the file they came from."""
    data: dict[str, Any] = {}
    for relpath in shipped:
        data = merge(data, parse_toml(default_text(relpath), f"configs/{relpath}"))
    where = f"configs/{shipped[-1]}"
    if user is not None:
        path = Path(user)
        text = read_text_file(path, "config file")
        data, where = merge(data, parse_toml(text, str(path))), str(path)
    try:
        return from_dict(cls, data)
    except InputError as e:
        raise InputError(f"{where}: {e}") from None


def load_default(cls: type[C], relpath: str) -> C:
    """Load a shipped config into the dataclass `cls`."""
    data = parse_toml(default_text(relpath), f"configs/{relpath}")  # its refusal names the file itself
    try:
        return from_dict(cls, data)
    except InputError as e:
        raise InputError(f"configs/{relpath}: {e}") from None
