"""Suite files refused by their whole one-line message (`diffsense.study._suite_file`): the file's name
once, then what is wrong and what is expected, for each malformation the reader checks itself."""

from __future__ import annotations

import pytest

from diffsense.study._suite_file import checked, load_suite
from diffsense.runtime._errors import InputError

SENSORS = 'sensors must be a list of sensor names, e.g. ["radar", "camera"], '
GOOD = 'sensors = ["radar", "camera"]\ncost_weight = 0.002\n[params]\n"radar.hfov_deg" = [20.0, 120.0]\n'


@pytest.mark.parametrize("text, message", [
    ('sensors = ["radar"]\nparams = 5\n',
     '[params] must be a table naming at least one parameter, e.g. "radar.hfov_deg" = [20, 120]'),
    ('sensors = ["radar"]\n[params]\n',
     '[params] must be a table naming at least one parameter, e.g. "radar.hfov_deg" = [20, 120]'),
    ('sensors = ["radar"]\n[params]\nradar = {}\n', 'quote the qualified name: "radar." = [LO, HI]'),
    ('colour = "red"\n' + GOOD,
     "unknown key 'colour' (known: sensors, cost_weight, description, params, sensor_config)"),
    (GOOD.replace('"camera"', "5"), SENSORS + "got ['radar', 5]"),
    (GOOD.replace('"camera"', '""'), SENSORS + "got ['radar', '']"),
    (GOOD.split("[params]")[0], "no [params]: name the free parameters and their bounds"),
    ("description = 5\n" + GOOD, "description must be a string, got 5"),
    (GOOD + "[sensor_config]\n",
     '[sensor_config] must be a table of member name = "TOML path", e.g. radar = "radar.toml"'),
    (GOOD.replace("[params]", "sensor_config = 5\n[params]"),
     '[sensor_config] must be a table of member name = "TOML path", e.g. radar = "radar.toml"'),
])
def test_a_malformed_suite_is_refused_by_its_whole_message(tmp_path, text, message):
    path = tmp_path / "suite.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError) as info:
        load_suite(path)
    assert str(info.value) == f"suite {path}: {message}"


def test_a_suite_file_is_read_as_utf8(tmp_path):
    path = tmp_path / "suite.toml"
    path.write_text('description = "Radar vorn, Kamera hinter der Windschutzscheibe: 20–120°"\n' + GOOD,
                    encoding="utf-8")
    assert load_suite(path)["params"] == {"radar.hfov_deg": (20.0, 120.0)}


def test_checked_names_the_file_once(tmp_path):
    path = tmp_path / "suite.toml"

    def refuse(message):
        def build():
            raise InputError(message)
        return build

    with pytest.raises(InputError) as other:
        checked(path, refuse("bounds of radar.hfov_deg must have lo < hi, got 120 20"))
    assert str(other.value) == f"suite {path}: bounds of radar.hfov_deg must have lo < hi, got 120 20"
    with pytest.raises(InputError) as own:
        checked(path, refuse(f"suite {path}: no [params]: name the free parameters and their bounds"))
    assert str(own.value) == f"suite {path}: no [params]: name the free parameters and their bounds"
    assert checked(path, lambda: 42) == 42
