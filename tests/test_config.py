"""Strict config loading (diffsense.config): every field type converted or refused in one line
naming the key, the plain form, TOML files named in their errors, and the shipped defaults
layered under a user's file, found in the installed package or else in the checkout."""

from __future__ import annotations

import dataclasses
import importlib.resources
import re
import typing
from pathlib import Path
from typing import Any, Literal

import pytest

from diffsense import config
from diffsense.runtime import InputError

ROOT = Path(__file__).resolve().parents[1]


@dataclasses.dataclass(frozen=True)
class Inner:
    gain_db: float = 1.0
    name: Literal["a", "b"] = "a"


@dataclasses.dataclass(frozen=True)
class Outer:
    count: int
    steps: tuple[float, ...] = (1.0, 2.0)
    inner: Inner = Inner()  # noqa: RUF009 (frozen: one shared default is safe)
    flag: bool = False

    def __post_init__(self):
        if self.count < 0:
            raise InputError(f"count must be >= 0, got {self.count}")


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
    first_none: None | float = None
    anything: Any = None
    inner: Inner = Inner()  # noqa: RUF009
    computed: int = dataclasses.field(default=0, init=False)


def _refusal(data, cls=Every) -> str:
    with pytest.raises(InputError) as err:
        config.from_dict(cls, data)
    assert "\n" not in str(err.value)
    return str(err.value)


@pytest.mark.parametrize(("data", "culprit"), [
    ({"n": "3"}, "n"), ({"n": True}, "n"), ({"n": 2.0}, "n"),
    ({"x": "1"}, "x"), ({"x": False}, "x"), ({"x": float("inf")}, "x"), ({"x": float("nan")}, "x"),
    ({"on": 1}, "on"), ({"s": 3}, "s"),
    ({"pair": [1]}, "pair"), ({"pair": [1, "a", 2]}, "pair"), ({"pair": ["1", "a"]}, "pair[0]"),
    ({"pair": [1, 2]}, "pair[1]"), ({"pair": "ab"}, "pair"), ({"many": [1.0, "b"]}, "many[1]"),
    ({"items": {"a": 1}}, "items"), ({"items": [1, 2, 3.5]}, "items[2]"), ({"table": [1]}, "table"),
    ({"table": {"k": "v"}}, "table.k"), ({"maybe": "x"}, "maybe"), ({"either": 1.5}, "either"),
    ({"either": None}, "either"), ({"inner": 3}, "inner"), ({"inner": {"name": "c"}}, "inner.name"),
    ({"inner": {"gain_db": "x"}}, "inner.gain_db"),
])
def test_a_wrong_type_is_refused_naming_the_key(data, culprit):
    assert _refusal(data).startswith(f"{culprit}: ")


def test_unknown_and_missing_keys_are_refused_naming_them():
    message = _refusal({"zz": 1, "aa": 2})
    assert "'aa'" in message and "anything, either, first_none, inner, items, many" in message  # the known, sorted
    assert "computed" not in message  # not an init field: not a key
    assert "'computed'" in _refusal({"computed": 1})
    assert "'inner.gain'" in _refusal({"inner": {"gain": 1}}) and "gain_db, name" in _refusal({"inner": {"gain": 1}})
    assert "'count'" in _refusal({}, Outer)
    assert _refusal([1], Outer).startswith("Outer: ")
    with pytest.raises(InputError, match="^radar.inner: "):
        config.from_dict(Inner, 3, "radar.inner")

    @dataclasses.dataclass(frozen=True)
    class Nested:
        outer: Outer

    assert "'outer.count'" in _refusal({"outer": {}}, Nested)
    assert "count must be >= 0" in _refusal({"outer": {"count": -1}}, Nested)  # the dataclass's own check


def test_conversions_by_type_and_value():
    got = config.from_dict(Every, {"n": 3, "x": 2, "on": True, "s": "a", "pair": [1, "b"], "many": [1, 2.5], "items": [4, 5],
                            "table": {"k": 1}, "maybe": 7, "either": "e", "first_none": 2, "anything": [1, "z"],
                            "inner": {"gain_db": 3}})
    assert got == Every(n=3, x=2.0, on=True, s="a", pair=(1, "b"), many=(1.0, 2.5), items=[4, 5], table={"k": 1.0},
                        maybe=7.0, either="e", first_none=2.0, anything=[1, "z"], inner=Inner(gain_db=3.0))
    for value, kind in ((got.x, float), (got.maybe, float), (got.table["k"], float), (got.first_none, float),
                        (got.pair, tuple), (got.many, tuple), (got.items, list), (got.inner.gain_db, float)):
        assert type(value) is kind
    assert config.from_dict(Every, {"maybe": None}).maybe is None
    assert config.from_dict(Every, {"either": 4}).either == 4  # the first type that takes it
    assert config.from_dict(Every, {"pair": (2, "t")}).pair == (2, "t")
    assert config.from_dict(Every, {}) == Every()
    cfg = config.from_dict(Outer, {"count": 3, "steps": [1, 2.5], "inner": {"gain_db": 2}})
    assert cfg == Outer(count=3, steps=(1.0, 2.5), inner=Inner(gain_db=2.0)) and config.from_dict(Outer, config.to_dict(cfg)) == cfg


def test_unsupported_types_are_the_programmers_error():
    @dataclasses.dataclass(frozen=True)
    class Odd:
        keys: dict[int, float] = dataclasses.field(default_factory=dict)
        union_keys: dict[int | str, float] = dataclasses.field(default_factory=dict)
        raw: bytes = b""
        bare_dict: typing.Dict = dataclasses.field(default_factory=dict)  # noqa: UP006
        bare_list: typing.List = dataclasses.field(default_factory=list)  # noqa: UP006

    for data, names in (({"keys": {1: 2}}, ("int", "keys")), ({"raw": b"x"}, ("bytes", "raw")),
                        ({"union_keys": {1: 2}}, ("int | str", "union_keys"))):
        with pytest.raises(TypeError) as err:
            config.from_dict(Odd, data)
        assert all(name in str(err.value) for name in names) and "typing." not in str(err.value)
    # typing's generics without arguments: items as given
    got = config.from_dict(Odd, {"bare_dict": {"a": [1]}, "bare_list": (1, "a")})
    assert got.bare_dict == {"a": [1]} and got.bare_list == [1, "a"]


def test_to_dict_and_replace():
    cfg = Every(pair=(1, "b"), many=(1.0,), table={"k": 2.0}, inner=Inner(gain_db=3.0, name="b"))
    plain = config.to_dict(cfg)
    assert plain == {"n": 0, "x": 0.0, "on": False, "s": "", "pair": [1, "b"], "many": [1.0], "items": [],
                     "table": {"k": 2.0}, "maybe": None, "either": 0, "first_none": None, "anything": None,
                     "inner": {"gain_db": 3.0, "name": "b"}, "computed": 0}
    assert type(plain["pair"]) is list and type(plain["inner"]) is dict
    assert config.to_dict(Inner) is Inner  # a class is not a config
    assert config.replace(Outer(count=1), inner=Inner(gain_db=5)) == Outer(count=1, inner=Inner(gain_db=5.0))
    assert config.replace(Outer(count=1), steps=[3, 4]).steps == (3.0, 4.0)
    for bad in ("2", -5):  # the same checks as loading: types and the dataclass's own
        with pytest.raises(InputError, match="count"):
            config.replace(Outer(count=1), count=bad)


def test_toml_files_are_named_once_in_their_errors(tmp_path):
    with pytest.raises(InputError, match="^x.toml: ") as err:
        config.parse_toml("a = ", "x.toml")
    assert "\n" not in str(err.value)
    assert config.parse_toml("a = 1\n[t]\nb = 'c'\n", "x") == {"a": 1, "t": {"b": "c"}}
    good = tmp_path / "good.toml"
    good.write_text("count = 2\nsteps = [1, 3]\n")
    assert config.load(Outer, good) == config.load(Outer, str(good)) == Outer(count=2, steps=(1.0, 3.0))
    for text, culprit in (("count = -3\n", "count"), ("count = [1,\n", "TOML")):
        good.write_text(text)
        with pytest.raises(InputError, match=culprit) as err:
            config.load(Outer, good)
        assert str(err.value).startswith(f"{good}: ") and str(err.value).count(str(good)) == 1
    latin = tmp_path / "latin.toml"
    latin.write_bytes(b"count = 1 # \xff\n")
    for missing in (tmp_path / "nope.toml", tmp_path, latin):  # absent, a folder, not UTF-8
        with pytest.raises(InputError, match=re.escape(str(missing))):
            config.load(Outer, missing)


def test_merge_replaces_keys_and_merges_tables():
    base = {"a": 1, "t": {"x": 1, "y": {"p": 1, "q": 2}}, "u": {"k": 1}}
    got = config.merge(base, {"a": 2, "t": {"y": {"q": 3}, "z": 4}, "u": 5, "new": {"n": 1}})
    assert got == {"a": 2, "t": {"x": 1, "y": {"p": 1, "q": 3}, "z": 4}, "u": 5, "new": {"n": 1}}
    assert base == {"a": 1, "t": {"x": 1, "y": {"p": 1, "q": 2}}, "u": {"k": 1}}  # untouched
    assert config.merge({"a": 1}, {"a": {"b": 2}}) == {"a": {"b": 2}}


def test_the_shipped_defaults():
    assert config.default_text("sensors/radar.toml") == (ROOT / "configs" / "sensors" / "radar.toml").read_text()
    names = sorted(p.stem for p in (ROOT / "configs" / "scenarios").glob("*.toml"))
    assert config.list_defaults("scenarios") == names and "sc01" in names
    with pytest.raises(InputError, match="'sensors/lidar.toml'"):
        config.default_text("sensors/lidar.toml")


@dataclasses.dataclass(frozen=True)
class _Two:
    a: int
    b: float = 0.0


@pytest.fixture
def shipped(tmp_path, monkeypatch):
    """A folder of shipped configs, as an installed package holds them."""
    folder = tmp_path / "shipped"
    folder.mkdir()
    for name, text in {"one.toml": "a = 1\nb = 2\n", "two.toml": "b = 3\n", "bad.toml": "a = 'x'\n",
                       "broken.toml": "a = [\n"}.items():
        (folder / name).write_text(text)
    monkeypatch.setattr(importlib.resources, "files", lambda package: folder)
    return folder


def test_layers_merge_in_order_and_name_the_file_a_refusal_came_from(shipped, tmp_path):
    assert config.load_layers(_Two, ["one.toml", "two.toml"]) == _Two(a=1, b=3.0)
    assert config.load_default(_Two, "one.toml") == _Two(a=1, b=2.0)
    for call in (lambda: config.load_layers(_Two, ["one.toml", "bad.toml"]), lambda: config.load_default(_Two, "bad.toml")):
        with pytest.raises(InputError, match="^configs/bad.toml: a: "):
            call()
    for call in (lambda: config.load_layers(_Two, ["broken.toml"]), lambda: config.load_default(_Two, "broken.toml")):
        with pytest.raises(InputError, match="^configs/broken.toml: ") as err:
            call()
        assert str(err.value).count("broken.toml") == 1
    user = tmp_path / "mine.toml"
    user.write_text("b = 7\n")
    assert config.load_layers(_Two, ["one.toml", "two.toml"], user) == _Two(a=1, b=7.0)
    for text, culprit in (("c = 7\n", "'c'"), ("b = [\n", "TOML")):
        user.write_text(text)
        with pytest.raises(InputError, match=culprit) as err:
            config.load_layers(_Two, ["one.toml"], str(user))
        assert str(err.value).startswith(f"{user}: ") and str(err.value).count(str(user)) == 1
    (tmp_path / "latin.toml").write_bytes(b"b = 1 # \xff\n")
    for missing in (tmp_path / "none.toml", tmp_path, tmp_path / "latin.toml"):
        with pytest.raises(InputError, match=re.escape(str(missing))):
            config.load_layers(_Two, ["one.toml"], missing)


class _OneSegment:
    """A resource folder that takes one name at a time, as importlib's Traversable promises."""

    def __init__(self, path: Path):
        self.path = path

    def is_dir(self) -> bool:
        return self.path.is_dir()

    def __truediv__(self, name: str) -> _OneSegment:
        assert "/" not in name, name
        return _OneSegment(self.path / name)

    def read_text(self) -> str:
        return self.path.read_text()


def test_the_shipped_folder_is_the_installed_package_else_the_checkouts(shipped, monkeypatch):
    assert config.default_text("two.toml") == "b = 3\n" and config.list_defaults("") == ["bad", "broken", "one", "two"]
    radar = (ROOT / "configs" / "sensors" / "radar.toml").read_text()

    def missing(name):
        raise ModuleNotFoundError(name)

    for files in (lambda name: shipped / "not a folder", missing):
        monkeypatch.setattr(importlib.resources, "files", files)
        assert config.default_text("sensors/radar.toml") == radar
    # an installed package's folder is walked one name at a time
    monkeypatch.setattr(importlib.resources, "files", lambda name: _OneSegment(ROOT / "configs"))
    assert config.default_text("sensors/radar.toml") == radar
