"""Where the shipped default configs live.

`configs/` at the repository top is the one source of defaults. An installed package carries it
as `diffsense._configs` (see pyproject.toml); a source checkout reads it in place.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path
from typing import TypeVar

from diffsense.config._schema import from_dict, parse_toml
from diffsense.errors import InputError

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


def load_default(cls: type[C], relpath: str) -> C:
    """Load a shipped config into the dataclass `cls`."""
    try:
        return from_dict(cls, parse_toml(default_text(relpath), f"configs/{relpath}"))
    except InputError as e:
        raise InputError(f"configs/{relpath}: {e}") from None
