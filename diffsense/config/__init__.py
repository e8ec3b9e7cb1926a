"""Configs: strict TOML loading into frozen dataclasses, and the shipped defaults."""

from diffsense.config._defaults import (
    default_text,
    list_defaults,
    load_default,
    load_layers,
    merge,
)
from diffsense.config._schema import from_dict, load, parse_toml, replace, to_dict

__all__ = [
    "default_text",
    "from_dict",
    "list_defaults",
    "load",
    "load_default",
    "load_layers",
    "merge",
    "parse_toml",
    "replace",
    "to_dict",
]
