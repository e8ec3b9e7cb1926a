"""The config loader pinned: every refusal by its whole message, every conversion by type and
value, the plain form, and the shipped defaults layered under a user's file."""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path
from typing import Any

import pytest

from diffsense.config import from_dict, load, parse_toml, replace, to_dict
from diffsense.config._defaults import (
    default_text,
    list_defaults,
    load_default,
    load_layers,
    merge,
)
from diffsense.config._schema import _convert, _type_name
from diffsense.runtime._errors import InputError
from tests.test_config import Inner, Outer

ROOT = Path(__file__).resolve().parents[1]


@dataclasses.dataclass(frozen=True)
class Every:
    n: int = 0
    x: float = 0.0
    on: bool = False
    s: str = ""
    pair: tuple[int, str] = (0, "")
    many: tuple[float, ...] = ()
    items: list[int] = dataclasses.field(default_factory=list)
    table: dict[str, float] = dataclasses.field(default_factory=dict)
    maybe: float | None = None
    either: int | str = 0
    anything: Any = None
    inner: Inner = Inner()  # noqa: RUF009 (frozen: one shared default is safe)
    computed: int = dataclasses.field(default=0, init=False)


_KNOWN = "anything, either, inner, items, many, maybe, n, on, pair, s, table, x"  # sorted; not `computed`


def _refusal(data, cls=Every) -> str:
    with pytest.raises(InputError) as err:
        from_dict(cls, data)
    return str(err.value)


@pytest.mark.parametrize(("data", "message"), [
    ({"n": "3"}, "n: expected an integer, got '3'"),
    ({"n": True}, "n: expected an integer, got True"),
    ({"n": 2.0}, "n: expected an integer, got 2.0"),
    ({"x": "1"}, "x: expected a number, got '1'"),
    ({"x": False}, "x: expected a number, got False"),
    ({"x": float("inf")}, "x: expected a finite number, got inf"),
    ({"x": float("nan")}, "x: expected a finite number, got nan"),
    ({"on": 1}, "on: expected true/false, got 1"),
    ({"s": 3}, "s: expected a string, got 3"),
    ({"pair": [1]}, "pair: expected 2 values, got 1"),
    ({"pair": [1, "a", 2]}, "pair: expected 2 values, got 3"),
    ({"pair": ["1", "a"]}, "pair[0]: expected an integer, got '1'"),
    ({"pair": [1, 2]}, "pair[1]: expected a string, got 2"),
    ({"pair": "ab"}, "pair: expected a list, got str 'ab'"),
    ({"many": [1.0, "b"]}, "many[1]: expected a number, got 'b'"),
    ({"items": {"a": 1}}, "items: expected a list, got dict {'a': 1}"),
    ({"items": [1, 2, 3.5]}, "items[2]: expected an integer, got 3.5"),
    ({"table": [1]}, "table: expected a table, got list [1]"),
    ({"table": {"k": "v"}}, "table.k: expected a number, got 'v'"),
    ({"maybe": "x"}, "maybe: expected a number, got 'x'"),
    ({"either": 1.5}, "either: expected a string, got 1.5"),
    ({"inner": 3}, "inner: expected a table, got int 3"),
    ({"inner": {"name": "c"}}, "inner.name: 'c' is not one of 'a', 'b'"),
    ({"inner": {"gain_db": "x"}}, "inner.gain_db: expected a number, got 'x'"),
    ({"inner": {"gain": 1}}, "unknown key 'inner.gain' (known keys: gain_db, name)"),
    ({"zz": 1, "aa": 2}, f"unknown key 'aa' (known keys: {_KNOWN})"),
    ({"computed": 1}, f"unknown key 'computed' (known keys: {_KNOWN})"),
])
def test_refusals_by_whole_message(data, message):
    assert _refusal(data) == message


def test_missing_keys_and_tables():
    assert _refusal({}, Outer) == "missing key 'count'"
    assert _refusal([1], Outer) == "Outer: expected a table, got [1]"
    with pytest.raises(InputError) as err:
        from_dict(Inner, 3, "radar.inner")
    assert str(err.value) == "radar.inner: expected a table, got 3"

    @dataclasses.dataclass(frozen=True)
    class Nested:
        outer: Outer

    assert _refusal({"outer": {}}, Nested) == "missing key 'outer.count'"
    assert _refusal({"outer": {"count": -1}}, Nested) == "count must be >= 0, got -1"


def test_conversions_by_type_and_value():
    got = from_dict(Every, {"n": 3, "x": 2, "on": True, "s": "a", "pair": [1, "b"], "many": [1, 2.5], "items": [4, 5],
                            "table": {"k": 1}, "maybe": 7, "either": "e", "anything": [1, "z"], "inner": {"gain_db": 3}})
    assert got == Every(n=3, x=2.0, on=True, s="a", pair=(1, "b"), many=(1.0, 2.5), items=[4, 5], table={"k": 1.0},
                        maybe=7.0, either="e", anything=[1, "z"], inner=Inner(gain_db=3.0))
    assert type(got.x) is float and type(got.maybe) is float and type(got.table["k"]) is float
    assert type(got.pair) is tuple and type(got.many) is tuple and type(got.items) is list
    assert type(got.inner.gain_db) is float
    assert from_dict(Every, {"maybe": None}).maybe is None
    assert from_dict(Every, {"either": 4}).either == 4  # the first type that takes it
    assert from_dict(Every, {"pair": (2, "t")}).pair == (2, "t")
    assert from_dict(Every, {}) == Every()


def test_unsupported_types_are_the_programmers_error():
    with pytest.raises(TypeError) as err:
        _convert({1: 2}, dict[int, float], "t")
    assert str(err.value) == "unsupported config dict key type int at t"
    with pytest.raises(TypeError) as err:
        _convert(b"x", bytes, "b")
    assert str(err.value) == "unsupported config field type bytes at b"
    # typing's generics without arguments: items as given
    assert _convert({"a": [1]}, typing.Dict, "d") == {"a": [1]}  # noqa: UP006
    assert _convert((1, "a"), typing.List, "l") == [1, "a"]  # noqa: UP006
    assert _type_name(int) == "int" and _type_name(list[int]) == "list"
    assert _type_name(int | list[Any]) == "int | list[Any]"  # no __name__: its text, without "typing."
    with pytest.raises(InputError) as err:
        _convert(None, int | str, "u")  # None only where the type allows it; the last type's refusal
    assert str(err.value) == "u: expected a string, got None"
    assert _convert(None, float | None, "o") is None


def test_to_dict_and_replace():
    cfg = Every(pair=(1, "b"), many=(1.0,), table={"k": 2.0}, inner=Inner(gain_db=3.0, name="b"))
    plain = to_dict(cfg)
    assert plain == {"n": 0, "x": 0.0, "on": False, "s": "", "pair": [1, "b"], "many": [1.0], "items": [],
                     "table": {"k": 2.0}, "maybe": None, "either": 0, "anything": None,
                     "inner": {"gain_db": 3.0, "name": "b"}, "computed": 0}
    assert type(plain["pair"]) is list and type(plain["inner"]) is dict
    assert to_dict(Inner) is Inner  # a class is not a config
    assert replace(Outer(count=1), inner=Inner(gain_db=5)) == Outer(count=1, inner=Inner(gain_db=5.0))
    assert replace(Outer(count=1), steps=[3, 4]).steps == (3.0, 4.0)
    with pytest.raises(InputError) as err:
        replace(Outer(count=1), count="2")
    assert str(err.value) == "count: expected an integer, got '2'"


def test_toml_files(tmp_path):
    with pytest.raises(InputError) as err:
        parse_toml("a = ", "x.toml")
    assert str(err.value).startswith("x.toml: malformed TOML: ") and "\n" not in str(err.value)
    assert parse_toml("a = 1\n[t]\nb = 'c'\n", "x") == {"a": 1, "t": {"b": "c"}}
    good = tmp_path / "good.toml"
    good.write_text("count = 2\nsteps = [1, 3]\n")
    assert load(Outer, good) == Outer(count=2, steps=(1.0, 3.0))
    assert load(Outer, str(good)) == Outer(count=2, steps=(1.0, 3.0))
    good.write_text("count = -3\n")
    with pytest.raises(InputError) as err:
        load(Outer, good)
    assert str(err.value) == f"{good}: count must be >= 0, got -3"
    good.write_text("count = [1,\n")
    with pytest.raises(InputError) as err:
        load(Outer, good)
    assert str(err.value).startswith(f"{good}: malformed TOML: ") and not str(err.value).startswith(f"{good}: {good}")
    with pytest.raises(InputError) as err:
        load(Outer, tmp_path / "nope.toml")
    assert str(err.value) == f"config file not found: {tmp_path / 'nope.toml'}"
    with pytest.raises(InputError) as err:
        load(Outer, tmp_path)
    assert str(err.value).startswith(f"cannot read config {tmp_path}: ")
    (tmp_path / "latin.toml").write_bytes(b"count = 1 # \xff\n")
    with pytest.raises(InputError) as err:
        load(Outer, tmp_path / "latin.toml")
    assert str(err.value).startswith(f"cannot read config {tmp_path / 'latin.toml'}: ")


def test_merge_replaces_keys_and_merges_tables():
    base = {"a": 1, "t": {"x": 1, "y": {"p": 1, "q": 2}}, "u": {"k": 1}}
    got = merge(base, {"a": 2, "t": {"y": {"q": 3}, "z": 4}, "u": 5, "new": {"n": 1}})
    assert got == {"a": 2, "t": {"x": 1, "y": {"p": 1, "q": 3}, "z": 4}, "u": 5, "new": {"n": 1}}
    assert base == {"a": 1, "t": {"x": 1, "y": {"p": 1, "q": 2}}, "u": {"k": 1}}  # untouched
    assert merge({"a": 1}, {"a": {"b": 2}}) == {"a": {"b": 2}}


def test_shipped_defaults():
    assert default_text("sensors/radar.toml") == (ROOT / "configs" / "sensors" / "radar.toml").read_text()
    names = sorted(p.stem for p in (ROOT / "configs" / "scenarios").glob("*.toml"))
    assert list_defaults("scenarios") == names and "sc01" in names
    with pytest.raises(InputError) as err:
        default_text("sensors/lidar.toml")
    assert str(err.value) == "no shipped config named 'sensors/lidar.toml'"


@dataclasses.dataclass(frozen=True)
class _Two:
    a: int
    b: float = 0.0


def test_layers_name_the_file_a_refusal_came_from(tmp_path, monkeypatch):
    from diffsense.config import _defaults

    texts = {"one.toml": "a = 1\nb = 2\n", "two.toml": "b = 3\n", "bad.toml": "a = 'x'\n"}
    monkeypatch.setattr(_defaults, "default_text", lambda rel: texts[rel])
    assert load_layers(_Two, ["one.toml", "two.toml"]) == _Two(a=1, b=3.0)
    with pytest.raises(InputError) as err:
        load_layers(_Two, ["one.toml", "bad.toml"])
    assert str(err.value) == "configs/bad.toml: a: expected an integer, got 'x'"
    user = tmp_path / "mine.toml"
    user.write_text("b = 7\n")
    assert load_layers(_Two, ["one.toml", "two.toml"], user) == _Two(a=1, b=7.0)
    user.write_text("c = 7\n")
    with pytest.raises(InputError) as err:
        load_layers(_Two, ["one.toml"], str(user))
    assert str(err.value) == f"{user}: unknown key 'c' (known keys: a, b)"
    with pytest.raises(InputError) as err:
        load_layers(_Two, ["one.toml"], tmp_path / "none.toml")
    assert str(err.value) == f"config file not found: {tmp_path / 'none.toml'}"
    with pytest.raises(InputError) as err:
        load_layers(_Two, ["one.toml"], tmp_path)
    assert str(err.value) == f"cannot read config {tmp_path}: Is a directory"
    (tmp_path / "latin.toml").write_bytes(b"b = 1 # \xff\n")
    with pytest.raises(InputError) as err:
        load_layers(_Two, ["one.toml"], tmp_path / "latin.toml")
    assert str(err.value).startswith(f"cannot read config {tmp_path / 'latin.toml'}: 'utf-8' codec")
    texts["broken.toml"] = "a = [\n"
    with pytest.raises(InputError) as err:
        load_layers(_Two, ["broken.toml"])
    assert str(err.value).startswith("configs/broken.toml: malformed TOML: ")
    with pytest.raises(InputError) as err:
        load_default(_Two, "bad.toml")
    assert str(err.value) == "configs/bad.toml: a: expected an integer, got 'x'"
    assert load_default(_Two, "one.toml") == _Two(a=1, b=2.0)


def test_the_shipped_folder_is_the_installed_package_else_the_checkouts(tmp_path, monkeypatch):
    from diffsense.config import _defaults

    def files(name):
        if name != "diffsense._configs":
            raise ModuleNotFoundError(name)
        return tmp_path

    monkeypatch.setattr(_defaults.importlib.resources, "files", files)
    assert _defaults._configs_root() == tmp_path
    monkeypatch.setattr(_defaults.importlib.resources, "files", lambda name: tmp_path / "not a folder")
    assert _defaults._configs_root() == ROOT / "configs"

    def missing(name):
        raise ModuleNotFoundError(name)

    monkeypatch.setattr(_defaults.importlib.resources, "files", missing)
    assert _defaults._configs_root() == ROOT / "configs"


class _OneSegment:
    """A resource folder that takes one name at a time, as importlib's Traversable promises."""

    def __init__(self, path: Path):
        self.path = path

    def __truediv__(self, name: str) -> _OneSegment:
        assert "/" not in name, name
        return _OneSegment(self.path / name)

    def read_text(self) -> str:
        return self.path.read_text()


def test_a_shipped_path_is_walked_one_folder_at_a_time(monkeypatch):
    from diffsense.config import _defaults

    monkeypatch.setattr(_defaults, "_configs_root", lambda: _OneSegment(ROOT / "configs"))
    assert default_text("sensors/radar.toml") == (ROOT / "configs" / "sensors" / "radar.toml").read_text()


def test_malformed_files_are_named_once(tmp_path, monkeypatch):
    from diffsense.config import _defaults

    monkeypatch.setattr(_defaults, "default_text", lambda rel: "a = [\n")
    with pytest.raises(InputError) as err:
        load_default(_Two, "broken.toml")
    assert str(err.value).startswith("configs/broken.toml: malformed TOML: ")
    user = tmp_path / "mine.toml"
    user.write_text("b = [\n")
    monkeypatch.setattr(_defaults, "default_text", lambda rel: "a = 1\n")
    with pytest.raises(InputError) as err:
        load_layers(_Two, ["one.toml"], user)
    assert str(err.value).startswith(f"{user}: malformed TOML: ")
    assert _convert(2, None | float, "o") == 2.0  # None first in the union: the other types still tried
