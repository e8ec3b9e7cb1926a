"""Suite files (configs/suites/*.toml): the shipped ones load through `ds.Problem.from_suite` and the
CLI's --suite alike, and every malformed one is refused in one line naming the file (exit 2 from the
CLI, nothing written)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import diffsense as ds
from diffsense.cli.optimise import _parser, problems

ROOT = Path(__file__).resolve().parents[1]
SUITES = ROOT / "configs" / "suites"


@pytest.mark.parametrize("name, d", [("radar_camera_d4", 4), ("radar_camera_d8", 8), ("radar_camera_mounted_d14", 14)])
def test_the_shipped_suites_load_alike_from_the_api_and_the_cli(name, d):
    path = SUITES / f"{name}.toml"
    problem = ds.Problem.from_suite(path, variants=1)
    assert len(problem.params) == d and problem.sensor_kind == "radar+camera" and problem.cost_weight == 0.002
    assert all(n.split(".")[0] in ("radar", "camera") for n in problem.params)
    (cli,) = problems(_parser().parse_args(["--suite", str(path), "--variants", "1"]))
    assert cli.params == problem.params and cli.cost_weight == problem.cost_weight and cli.sensor == problem.sensor
    (heavier,) = problems(_parser().parse_args(["--suite", str(path), "--cost-weight", "0.01"]))
    assert heavier.cost_weight == 0.01  # the flag replaces the file's weight


def test_a_suite_file_gives_members_their_own_constants(tmp_path):
    # The shipped suite under the probabilistic laws: paths relative to the file, one TOML per member.
    path = SUITES / "radar_camera_laws_d2.toml"
    problem = ds.Problem.from_suite(path, variants=1)
    laws = [m.config.detection.law for m in problem.make_sensor().members]
    assert laws == ["swerling1", "confidence"] and problem.cost_weight == 0.0
    assert all(Path(p).is_file() for p in problem.sensor_config.values())
    (cli,) = problems(_parser().parse_args(["--suite", str(path), "--variants", "1"]))
    assert cli.sensor_config == problem.sensor_config and cli.params == problem.params
    # A copy elsewhere reads its configs beside itself: a member left out keeps its profile's.
    (tmp_path / "laws").mkdir()
    (tmp_path / "laws" / "r.toml").write_text((ROOT / "configs/sensors/laws/radar_swerling1.toml").read_text())
    (tmp_path / "s.toml").write_text(GOOD + '[sensor_config]\nradar = "laws/r.toml"\n')
    radar, camera = ds.Problem.from_suite(tmp_path / "s.toml").make_sensor().members
    assert radar.config.detection.law == "swerling1" and camera.config.detection.law == "threshold"


def test_the_mounted_suite_frees_every_sensors_mounting():
    problem = ds.Problem.from_suite(SUITES / "radar_camera_mounted_d14.toml")
    assert {f"{s}.{m}" for s in ("radar", "camera") for m in ds.sensors.MOUNT_NAMES} <= set(problem.params)


GOOD = 'sensors = ["radar", "camera"]\ncost_weight = 0.002\n[params]\n"radar.hfov_deg" = [20.0, 120.0]\n'


@pytest.mark.parametrize("text, needle", [
    (GOOD + "bogus = 1\n", "params bogus must be two numbers [LO, HI], got 1"),  # after [params]: one of them
    ("colour = 'red'\n" + GOOD, "unknown key 'colour'"),
    (GOOD.replace("0.002", '"a lot"'), "cost_weight must be a finite number"),
    (GOOD.replace('["radar", "camera"]', '"radar"'), "sensors must be a list"),
    (GOOD.replace("[20.0, 120.0]", '["20", 120.0]'), "params radar.hfov_deg must be two numbers"),
    (GOOD.replace("[20.0, 120.0]", "[20.0]"), "params radar.hfov_deg must be two numbers"),
    (GOOD.replace('"radar.hfov_deg"', "radar.hfov_deg"), 'quote the qualified name: "radar.hfov_deg"'),
    (GOOD.replace("[20.0, 120.0]", "[0.0, 120.0]"), "outside the domain of radar.hfov_deg"),
    (GOOD.replace("[20.0, 120.0]", "[120.0, 20.0]"), "lo < hi"),
    (GOOD + '"radar.hfov" = [30.0, 60.0]\n', "parameter radar.hfov_deg is named twice"),
    (GOOD + '"lidar.hfov_deg" = [30.0, 60.0]\n', "names sensor 'lidar', not in the suite"),
    (GOOD + '"radar.mount_y_m" = [-1.5, 0.0]\n', "outside the domain of radar.mount_y_m"),
    (GOOD.replace('"camera"', '"sonar"'), "unknown sensor 'sonar'"),
    (GOOD.split("[params]")[0], "no [params]"),
    ("sensors = [\n", "not valid TOML"),
    (GOOD + "[sensor_config]\n", "[sensor_config] must be a table"),
    (GOOD + "[sensor_config]\nradar = 3\n", "sensor_config radar must be a TOML path"),
    (GOOD + '[sensor_config]\nradar = "absent.toml"\n', "sensor_config radar: "),
    (GOOD + '[sensor_config]\nlidar = "suite.toml"\n', "sensor_config names 'lidar', not a member"),
])
def test_a_malformed_suite_is_refused_in_one_line_naming_the_file(tmp_path, text, needle):
    path = tmp_path / "suite.toml"
    path.write_text(text)
    for load in (lambda: ds.Problem.from_suite(path), lambda: problems(_parser().parse_args(["--suite", str(path)]))):
        with pytest.raises(ds.InputError) as e:
            load()
        message = str(e.value)
        assert message.startswith(f"suite {path}: ") and needle in message and "\n" not in message, message


@pytest.mark.parametrize("extra, needle", [
    ([], "unknown key 'colour'"),
    (["--param", "radar.hfov_deg=20:60"], "give no --param with it"),
])
def test_a_bad_suite_on_the_cli_is_one_line_exit_2_nothing_written(tmp_path, extra, needle):
    path = tmp_path / "suite.toml"
    path.write_text(("colour = 'red'\n" if not extra else "") + GOOD)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "diffsense.optimise", "--suite", str(path), *extra, "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and needle in lines[0], proc.stderr
    assert not out.exists()


def test_a_sensor_config_by_member_is_refused_where_it_cannot_apply():
    law = str(ROOT / "configs/sensors/laws/radar_swerling1.toml")
    with pytest.raises(ds.InputError, match="is for a suite"):
        ds.Problem(sensor="radar", sensor_config={"radar": law})
    radar = ds.sensors.Radar.from_toml()
    with pytest.raises(ds.InputError, match="carries its own constants"):
        ds.Problem(sensor=[radar, "camera"], params={"camera.hfov_deg": (30.0, 60.0)}, sensor_config={"radar": law})
