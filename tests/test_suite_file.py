"""Suite files (configs/suites/*.toml): the shipped ones load through `ds.Problem.from_suite`, a
member's constants come from a TOML beside the file, and every malformed one is refused in one
line naming the file."""

from __future__ import annotations

from pathlib import Path

import pytest

import diffsense as ds
from diffsense.study import checked

ROOT = Path(__file__).resolve().parents[1]
SUITES = ROOT / "configs" / "suites"
GOOD = 'sensors = ["radar", "camera"]\ncost_weight = 0.002\n[params]\n"radar.hfov_deg" = [20.0, 120.0]\n'


@pytest.mark.parametrize("name, d", [("radar_camera_d4", 4), ("radar_camera_d8", 8), ("radar_camera_mounted_d14", 14)])
def test_the_shipped_suites_load(name, d):
    problem = ds.Problem.from_suite(SUITES / f"{name}.toml", variants=1)
    assert len(problem.params) == d and problem.sensor_kind == "radar+camera"
    assert problem.question.cost_weight == 0.002 and problem.traffic.variants == 1  # the override
    assert all(n.split(".")[0] in ("radar", "camera") for n in problem.params)
    if "mounted" in name:
        assert {f"{s}.{m}" for s in ("radar", "camera") for m in ds.sensors.MOUNT_NAMES} <= set(problem.params)


def test_a_suite_file_is_read_as_utf8_and_its_cost_weight_defaults_to_0(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('description = "Radar vorn, Kamera: 20–120°"\n' + GOOD.replace("cost_weight = 0.002\n", ""),
                    encoding="utf-8")
    assert ds.Problem.from_suite(path) == ds.Problem(sensor=["radar", "camera"], params={"radar.hfov": (20, 120)})


def test_a_suite_file_gives_members_their_own_constants(tmp_path):
    problem = ds.Problem.from_suite(SUITES / "radar_camera_laws_d2.toml", variants=1)
    laws = [m.config.detection.law for m in problem.sensing.built.members]
    assert laws == ["swerling1", "confidence"] and problem.question.cost_weight == 0.0
    assert all(Path(p).is_file() for p in problem.sensing.sensor_config.values())
    # A copy elsewhere reads its configs beside itself: a member left out keeps its profile's.
    (tmp_path / "laws").mkdir()
    (tmp_path / "laws" / "r.toml").write_text((ROOT / "configs/sensors/laws/radar_swerling1.toml").read_text())
    (tmp_path / "s.toml").write_text(GOOD + '[sensor_config]\nradar = "laws/r.toml"\n')
    radar, camera = ds.Problem.from_suite(tmp_path / "s.toml").sensing.built.members
    assert radar.config.detection.law == "swerling1" and camera.config == ds.sensors.Camera.from_toml().config


@pytest.mark.parametrize("text, culprit", [
    (GOOD + "bogus = 1\n", "params bogus must be two numbers [LO, HI]"),  # after [params]: one of them
    ("colour = 'red'\n" + GOOD, "unknown key 'colour'"),
    (GOOD.replace("0.002", '"a lot"'), "cost_weight must be a finite number"),
    ("description = 5\n" + GOOD, "description must be a string"),
    (GOOD.replace('["radar", "camera"]', '"radar"'), "sensors must be a list"),
    (GOOD.replace('"camera"', "5"), "sensors must be a list"),
    (GOOD.replace('"camera"', '""'), "sensors must be a list"),
    (GOOD.replace("[20.0, 120.0]", '["20", 120.0]'), "params radar.hfov_deg must be two numbers"),
    (GOOD.replace("[20.0, 120.0]", "[20.0]"), "params radar.hfov_deg must be two numbers"),
    (GOOD.replace('"radar.hfov_deg"', "radar.hfov_deg"), 'quote the qualified name: "radar.hfov_deg"'),
    ('sensors = ["radar"]\nparams = 5\n', "[params] must be a table"),
    ('sensors = ["radar"]\n[params]\n', "[params] must be a table"),
    (GOOD.split("[params]")[0], "no [params]"),
    ("sensors = [\n", "malformed TOML"),
    (GOOD + "[sensor_config]\n", "[sensor_config] must be a table"),
    (GOOD.replace("[params]", "sensor_config = 5\n[params]"), "[sensor_config] must be a table"),
    (GOOD + "[sensor_config]\nradar = 3\n", "sensor_config radar must be a TOML path"),
    (GOOD + '[sensor_config]\nradar = "absent.toml"\n', "sensor_config radar: "),
    # what Problem refuses, named with the file
    (GOOD.replace("[20.0, 120.0]", "[0.0, 120.0]"), "outside the domain of radar.hfov_deg"),
    (GOOD.replace("[20.0, 120.0]", "[120.0, 20.0]"), "lo < hi"),
    (GOOD + '"radar.hfov" = [30.0, 60.0]\n', "parameter radar.hfov_deg is named twice"),
    (GOOD + '"lidar.hfov_deg" = [30.0, 60.0]\n', "names sensor 'lidar', not in the suite"),
    (GOOD + '"radar.mount_y_m" = [-1.5, 0.0]\n', "outside the domain of radar.mount_y_m"),
    (GOOD.replace('"camera"', '"sonar"'), "unknown sensor 'sonar'"),
    (GOOD + '[sensor_config]\nlidar = "suite.toml"\n', "sensor_config names 'lidar', not a member"),
])
def test_a_malformed_suite_is_refused_in_one_line_naming_the_file(tmp_path, text, culprit):
    path = tmp_path / "suite.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ds.InputError) as e:
        ds.Problem.from_suite(path)
    message = str(e.value)
    assert message.startswith(f"suite {path}: ") and culprit in message and "\n" not in message, message
    assert message.count(str(path)) == 1  # once


def test_checked_names_the_file_once(tmp_path):
    path = tmp_path / "suite.toml"

    def refuse(message):
        def build():
            raise ds.InputError(message)
        return build

    for message in ("lo < hi", f"suite {path}: no [params]"):
        with pytest.raises(ds.InputError) as e:
            checked(path, refuse(message))
        assert str(e.value) in (f"suite {path}: {message}", message) and str(e.value).count(f"suite {path}") == 1
    assert checked(path, lambda: 42) == 42
