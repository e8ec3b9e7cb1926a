"""Strict config loading: unknown keys, wrong types and malformed TOML give one clear line."""

from __future__ import annotations

import dataclasses
from typing import Literal

import pytest

from diffsense.config import from_dict, load, parse_toml, replace, to_dict
from diffsense.runtime._errors import InputError


@dataclasses.dataclass(frozen=True)
class Inner:
    gain_db: float = 1.0
    name: Literal["a", "b"] = "a"


@dataclasses.dataclass(frozen=True)
class Outer:
    count: int
    steps: tuple[float, ...] = (1.0, 2.0)
    inner: Inner = Inner()
    flag: bool = False

    def __post_init__(self):
        if self.count < 0:
            raise InputError(f"count must be >= 0, got {self.count}")


def test_round_trip_and_int_to_float():
    cfg = from_dict(Outer, {"count": 3, "steps": [1, 2.5], "inner": {"gain_db": 2}})
    assert cfg == Outer(count=3, steps=(1.0, 2.5), inner=Inner(gain_db=2.0))
    assert from_dict(Outer, to_dict(cfg)) == cfg


@pytest.mark.parametrize(
    "data, needle",
    [
        ({"count": 1, "cout": 2}, "unknown key 'cout'"),
        ({"count": 1, "inner": {"gain": 1}}, "unknown key 'inner.gain'"),
        ({"count": "3"}, "count: expected an integer"),
        ({"count": True}, "count: expected an integer"),
        ({"count": 1, "inner": {"gain_db": "x"}}, "inner.gain_db: expected a number"),
        ({"count": 1, "inner": {"name": "c"}}, "inner.name: 'c' is not one of"),
        ({"count": 1, "steps": 3}, "steps: expected a list"),
        ({}, "missing key 'count'"),
        ({"count": -1}, "count must be >= 0"),
    ],
)
def test_rejects_with_one_line(data, needle):
    with pytest.raises(InputError) as e:
        from_dict(Outer, data)
    assert needle in str(e.value)
    assert "\n" not in str(e.value)


def test_malformed_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("count = [1,\n")
    with pytest.raises(InputError, match="bad.toml: malformed TOML"):
        load(Outer, bad)
    with pytest.raises(InputError, match="config file not found"):
        load(Outer, tmp_path / "nope.toml")
    with pytest.raises(InputError, match="malformed TOML"):
        parse_toml("a = ", "x")


def test_replace_checks_types():
    cfg = Outer(count=1)
    assert replace(cfg, count=2).count == 2
    with pytest.raises(InputError):
        replace(cfg, count=-5)
