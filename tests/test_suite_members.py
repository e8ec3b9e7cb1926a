"""Suites of named members: two sensors of one kind, each with its own name, constants, mounting
defaults and envelope. Their qualified parameters, bounds and cost per member; a blind member
leaving the others' fusion as it was; the design objective's gradient against central
differences; a two-radar suite file run end to end through the command line (on the toy
objective); the shipped d = 28 suite; and every malformed suite file refused in one line.

Every member names its detection law (the threshold law, whose hard detections are 0 or 1),
so nothing here depends on which law a profile defaults to.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sensor_scenes import make_scene

import diffsense as ds
from diffsense.cli import optimise, run
from diffsense.metrics import (
    cost_breakdown,
    load_costs,
    make_cost,
    make_objective,
    member_costs,
)
from diffsense.sensors import (
    MOUNT_DOMAINS,
    MOUNT_NAMES,
    Radar,
    Suite,
    measurement_noise,
)
from diffsense.solve import BoxConfig
from diffsense.study import problem_config
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, toy_scenes

ROOT = Path(__file__).resolve().parents[1]
LAWS = ROOT / "configs" / "sensors" / "laws"
RADAR_LAW, CAMERA_LAW = str(LAWS / "radar_threshold.toml"), str(LAWS / "camera_threshold.toml")
KEY = jax.random.key(3, impl="rbg")
# A front radar, a front-left corner radar and a camera.
CORNER = {"kind": "radar", "sensor_config": RADAR_LAW, "yaw_deg": 40.0, "mount_x_m": 2.1, "mount_y_m": 0.75,
          "envelope": {"yaw_deg": (20.0, 75.0), "mount_y_m": (0.5, 0.9)}}
MEMBERS = {"front": {"kind": "radar", "sensor_config": RADAR_LAW}, "corner": CORNER,
           "cam": {"kind": "camera", "sensor_config": CAMERA_LAW}}
PARAMS = {"front.hfov": (20.0, 120.0), "corner.yaw": (20.0, 75.0), "cam.width": (640.0, 3840.0)}
LAMBDA = 0.01  # [m per EUR]
TINY = BoxConfig(samples=4, starts=1, tau_schedule=(1.0,), max_steps=2, max_soft=3)


def _problem(**changes) -> ds.Problem:
    return ds.Problem(**{"sensor": MEMBERS, "params": PARAMS, "scenarios": ["sc01"], "variants": 1} | changes)


def _toy_objective(problem: ds.Problem):
    """E(r) of the problem's suite on one tiny toy scene and the toy predictor (no network)."""
    scenes, scenario = toy_scenes(1)
    return make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:3], problem.sensing.built,
                          ToyPredictor(jnp.asarray(TOY_GAIN)), names=tuple(problem.params),
                          key=jax.random.key(2, impl="rbg"))


def test_named_members_qualify_their_parameters_and_carry_their_mounting():
    p = _problem()
    assert p.params == {"front.hfov_deg": (20.0, 120.0), "corner.yaw_deg": (20.0, 75.0),
                        "cam.width_px": (640.0, 3840.0)}
    suite = p.sensing.built
    assert suite.names == ("front", "corner", "cam") and p.sensor_kind == "front+corner+cam"
    yaw, y, x = (suite.spec(f"corner.{n}") for n in ("yaw_deg", "mount_y_m", "mount_x_m"))
    assert (yaw.lower, yaw.upper, yaw.default) == (20.0, 75.0, 40.0)  # the member's envelope and default
    assert (y.lower, y.upper, y.default) == (0.5, 0.9, 0.75)
    assert (x.lower, x.upper, x.default) == (*MOUNT_DOMAINS["mount_x_m"][1:3], 2.1)  # the global envelope
    assert suite.spec("front.mount_x_m").default == Radar.from_toml().mount_x_m  # the sensor's own
    assert [m.config.detection.law for m in suite.members] == ["threshold"] * 3
    # frozen specs that round-trip, the sensor built once
    assert ds.Problem(**p.keywords()) == p and p.replace(variants=2).sensing is p.sensing
    assert ds.Problem.from_specs(sensing=p.sensing, traffic=p.traffic).sensing == p.sensing
    config = problem_config(p)["sensor"]
    assert list(config) == ["front", "corner", "cam"] and config["corner"]["envelope"]["yaw_deg"] == [20.0, 75.0]
    assert config["corner"]["yaw_deg"] == 40.0 and config["cam"] == {"kind": "camera", "sensor_config": CAMERA_LAW}
    two = ds.Problem(**p.keywords() | {"sensor": p.sensing.sensor[:2], "params": {"corner.yaw": (20, 75)}})
    assert two.sensing.built.names == ("front", "corner")  # `Member`s themselves are taken too


def test_two_radars_cost_two_radars_each_at_its_own_parameters():
    suite, model = _problem().sensing.built, load_costs()
    # At the defaults a radar costs 45 + 15 + 10 + 10 + 5 = 85 EUR and a camera 25 + 10 + 5 + 2 + 5 = 47.
    assert member_costs(model, suite, {}) == pytest.approx({"front": 85.0, "corner": 85.0, "cam": 47.0}, abs=1e-9)
    # The corner radar at 60 deg: its HFOV term 10 EUR x 60 / 30 = 20 EUR; the front radar's stays 10.
    r = {"corner.hfov_deg": 60.0}
    assert member_costs(model, suite, r) == pytest.approx({"front": 85.0, "corner": 95.0, "cam": 47.0}, abs=1e-9)
    assert float(make_cost(model, suite)(r)) == pytest.approx(85.0 + 95.0 + 47.0, abs=1e-9)
    parts = cost_breakdown(model, suite, r)
    assert parts["corner.hfov_deg"] == pytest.approx(20.0) and parts["front.hfov_deg"] == pytest.approx(10.0)


def _cars():
    """Ego plus cars 20-60 m away at 0-60 deg left and right of the ego's heading, two frames."""
    az = np.radians([0.0, 10.0, -25.0, 45.0, -50.0, 60.0])
    rng = np.array([40.0, 30.0, 25.0, 20.0, 22.0, 60.0])
    x = np.r_[0.0, 4.2 + rng * np.cos(az)]
    y = np.r_[0.0, rng * np.sin(az)]
    return make_scene(np.stack([x, x + 0.5]), np.stack([y, y]))


# Compiled once per suite: eager JAX compiles every primitive on its own, far slower here.
detect = eqx.filter_jit(lambda s, sc, r, noise: s.detect(sc, r, noise, mode="hard"))
views = eqx.filter_jit(lambda s, sc, r, noise: s.member_views(sc, r, noise, mode="hard"))


def test_a_blind_member_leaves_the_other_members_fusion_as_it_was():
    three = _problem().sensing.built
    front, _, cam = three.members
    two = Suite((front, cam), names=("front", "cam"))
    sc = _cars()
    noise = jnp.stack([measurement_noise(k, sc) for k in jax.random.split(KEY, 3)])  # [3, 2, T, V]: the members'
    blind = {"corner.range_m": 0.5}  # nothing within half a metre of it
    corner_sees = lambda r: np.asarray(views(three, sc, r, noise)[1][0].p_detect)[:, 1:]
    assert corner_sees({}).any() and not corner_sees(blind).any()
    got, want = detect(three, sc, blind, noise), detect(two, sc, {}, noise[jnp.array([0, 2])])
    np.testing.assert_array_equal(np.asarray(got.p_detect), np.asarray(want.p_detect))
    # The position of a track that exists (where no member detects, the fused position is a
    # placeholder that no track reads: its weight p is 0).
    tracked = np.asarray(want.p_detect) > 0
    assert tracked[:, 1:].sum() >= 4
    for a in ("x_m", "y_m"):
        np.testing.assert_allclose(np.asarray(getattr(got, a))[tracked], np.asarray(getattr(want, a))[tracked],
                                   rtol=1e-12, atol=1e-12)
    assert not np.array_equal(np.asarray(got.p_detect), np.asarray(detect(three, sc, {}, noise).p_detect))


def test_a_member_is_handed_its_mounting_defaults():
    suite, sc = _problem().sensing.built, _cars()
    noise = jnp.stack([measurement_noise(k, sc) for k in jax.random.split(KEY, 3)])
    corner = suite.members[1]
    (got, _) = views(suite, sc, {}, noise)[1]
    mounted = {"yaw_deg": 40.0, "mount_x_m": 2.1, "mount_y_m": 0.75}
    want = detect(corner, sc, mounted, noise[1])
    for a in ("p_detect", "x_m", "y_m"):
        np.testing.assert_array_equal(np.asarray(getattr(got, a)), np.asarray(getattr(want, a)))
    assert not np.array_equal(np.asarray(got.p_detect), np.asarray(detect(corner, sc, {}, noise[1]).p_detect))


GRAD_POINT = {"corner.hfov_deg": 100.0, "cam.width_px": 900.0, "corner.yaw_deg": 35.0}


def test_the_design_objectives_gradient_matches_central_differences():
    """J = E + lambda cost in float64, for a radar, a camera and a mounting parameter."""
    problem = _problem(params={n: (lo, hi) for n, (lo, hi) in
                               {"corner.hfov_deg": (60.0, 150.0), "cam.width_px": (640.0, 3840.0),
                                "corner.yaw_deg": (20.0, 75.0)}.items()})
    E, cost = _toy_objective(problem), make_cost(load_costs(), problem.sensing.built)
    J = jax.jit(lambda r: E(r, tau=2.0) + LAMBDA * cost(r))
    grad = jax.jit(jax.grad(lambda r: E(r, tau=2.0) + LAMBDA * cost(r)))(GRAD_POINT)
    grad_cost = jax.grad(cost)(GRAD_POINT)
    for name, value in GRAD_POINT.items():
        h = 1e-4 * abs(value)
        fd = (float(J(GRAD_POINT | {name: value + h})) - float(J(GRAD_POINT | {name: value - h}))) / (2 * h)
        np.testing.assert_allclose(float(grad[name]), fd, rtol=1e-5, atol=1e-10, err_msg=name)
        assert abs(float(grad[name]) - LAMBDA * float(grad_cost[name])) > 1e-7, name  # E moves too, not only the cost


SUITE_FILE = """description = "two radars and a camera"
cost_weight = 0.01
[members.front]
kind = "radar"
sensor_config = "{radar}"
[members.corner]
kind = "radar"
sensor_config = "{radar}"
yaw_deg = 40.0
mount_x_m = 2.1
mount_y_m = 0.75
[members.corner.envelope]
yaw_deg = [20.0, 75.0]
mount_y_m = [0.5, 0.9]
[members.cam]
kind = "camera"
sensor_config = "{camera}"
[params]
"front.range_m" = [30.0, 200.0]
"corner.yaw_deg" = [20.0, 75.0]
"""


def _suite_file(folder: Path, text: str = SUITE_FILE) -> Path:
    path = folder / "suite.toml"
    path.write_text(text.format(radar=RADAR_LAW, camera=CAMERA_LAW))
    return path


def _main(argv, capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as e:
        run(lambda: optimise.main(argv))
    out, err = capsys.readouterr()
    return e.value.code, out, err


@pytest.fixture
def toy_optimise(monkeypatch):
    """`diffsense.optimise` on the toy objective of each problem (the command line is real)."""
    asked, real = [], ds.optimise

    def solve(problem, **kw):
        asked.append(problem)
        return real(problem.replace(box=TINY), E=_toy_objective(problem), figures=False)

    monkeypatch.setattr(ds, "optimise", solve)
    return asked


def test_a_two_radar_suite_file_runs_end_to_end_on_the_command_line(tmp_path, capsys, toy_optimise):
    suite, out = _suite_file(tmp_path), tmp_path / "out"
    problem = ds.Problem.from_suite(suite)
    assert problem.sensing.sensor == _problem().sensing.sensor  # the file and the mapping: one problem
    small = ["--scenarios", "sc01", "--variants", "1", "--quiet"]
    code, printed, err = _main(["--suite", str(suite), "--out", str(out), *small[:-1]], capsys)
    assert code == 0, err
    # the line that says what was written lists the set the run published, no more
    written = json.loads((out / "manifest.json").read_text())["files"]
    assert f"wrote {out}/: {', '.join(written)}" in err and sorted(p.name for p in out.iterdir()) == sorted(
        [*written, "manifest.json"])
    (asked,) = toy_optimise
    assert asked.sensing == problem.sensing and asked.question.cost_weight == 0.01
    content = json.loads((out / "result.json").read_text())
    assert set(content["r_star"]) == set(content["box"]["gradient"]) == {"front.range_m", "corner.yaw_deg"}
    assert all(lo <= content["r_star"][n] <= hi for n, (lo, hi) in problem.params.items())
    assert list(content["config"]["sensor"]) == ["front", "corner", "cam"]
    by_member = content["box"]["cost_by_member"]
    assert list(by_member) == ["front", "corner", "cam"] and by_member["cam"] == pytest.approx(47.0)
    assert sum(by_member.values()) == pytest.approx(content["box"]["cost"], rel=1e-12)
    assert "corner.yaw_deg" in printed and "cost by member: front" in printed
    # --param qualified by a member's name replaces the file's [params]
    code, _, err = _main(["--suite", str(suite), "--param", "corner.hfov_deg=60:150", "--out", str(out), *small], capsys)
    assert code == 0, err
    assert toy_optimise[-1].params == {"corner.hfov_deg": (60.0, 150.0)}
    assert set(json.loads((out / "result.json").read_text())["r_star"]) == {"corner.hfov_deg"}


BAD = {
    "a member named twice": (SUITE_FILE.replace("[members.cam]", "[members.front]"), "twice"),
    "an unknown kind": (SUITE_FILE.replace('kind = "camera"', 'kind = "lidar"'), "unknown sensor 'lidar'"),
    "a parameter of a member not in the suite": (SUITE_FILE + '"rear.hfov_deg" = [20.0, 60.0]\n', "'rear'"),
    "a mounting default outside its envelope": (SUITE_FILE.replace("yaw_deg = 40.0", "yaw_deg = 10.0"),
                                                "outside its envelope [20, 75]"),
    "a mounting bound outside its envelope": (SUITE_FILE.replace('"corner.yaw_deg" = [20.0', '"corner.yaw_deg" = [5.0'),
                                              "corner.yaw_deg"),
    "an envelope outside the global one": (SUITE_FILE.replace("mount_y_m = [0.5, 0.9]", "mount_y_m = [0.5, 1.2]"),
                                           "mount_y_m"),
    "a member without a kind": (SUITE_FILE.replace('kind = "camera"\n', ""), "member cam: no kind"),
    "an unknown member key": (SUITE_FILE.replace("mount_x_m = 2.1", "pitch_deg = 2.1"), "'pitch_deg'"),
    "both forms": ('sensors = ["radar"]\n' + SUITE_FILE, "not both"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_suite_file_is_one_error_line_exit_2_nothing_written(tmp_path, capsys, toy_optimise, case):
    text, culprit = BAD[case]
    suite, out = _suite_file(tmp_path, text), tmp_path / "out"
    code, printed, err = _main(["--suite", str(suite), "--out", str(out)], capsys)
    assert (code, printed) == (2, "") and err.startswith(f"error: suite {suite}: ") and err.count("\n") == 1, err
    assert culprit in err and toy_optimise == [] and not out.exists()


def test_a_member_named_twice_in_a_real_process(tmp_path):
    suite, out = _suite_file(tmp_path, BAD["a member named twice"][0]), tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "diffsense.optimise", "--suite", str(suite), "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: ") and "twice" in lines[0]
    assert "Traceback" not in done.stderr and not out.exists()


D28 = ROOT / "configs" / "suites" / "corner_radars_camera_d28.toml"


def test_the_shipped_corner_radar_suite_keeps_every_member_in_its_envelope():
    p = ds.Problem.from_suite(D28, variants=1, scenarios=["sc01"])
    suite = p.sensing.built
    assert len(p.params) == 28 and suite.names == ("front_radar", "corner_left", "corner_right", "front_camera")
    assert [m.kind for m in suite.members] == ["radar", "radar", "radar", "camera"]
    for name in suite.names:
        for m in MOUNT_NAMES:
            spec, (_, lo, hi, _, _) = suite.spec(f"{name}.{m}"), MOUNT_DOMAINS[m]
            assert lo <= spec.lower <= spec.default <= spec.upper <= hi, (name, m)
            assert spec.lower <= p.params[f"{name}.{m}"][0] < p.params[f"{name}.{m}"][1] <= spec.upper
    # the corner radars look out to their own side, from the front corners
    assert suite.spec("corner_left.yaw_deg").lower >= 30.0 and suite.spec("corner_right.yaw_deg").upper <= -30.0
    assert suite.spec("corner_left.mount_y_m").lower > 0 > suite.spec("corner_right.mount_y_m").upper
    assert sum(member_costs(load_costs(), suite, {}).values()) == pytest.approx(3 * 85.0 + 47.0)


@pytest.mark.slow
def test_the_shipped_corner_radar_suite_evaluates_at_its_defaults():
    p = ds.Problem.from_suite(D28, variants=1, scenarios=["sc01"])
    E = ds.objective(p)
    r0 = {n: p.sensing.built.spec(n).default for n in p.params}
    value, grad = jax.jit(jax.value_and_grad(lambda r: E(r)))(r0)
    assert np.isfinite(float(value)) and set(grad) == set(p.params)
    assert all(np.isfinite(float(g)) for g in grad.values())
    assert sum(abs(float(g)) > 1e-9 for g in grad.values()) >= 10  # E moves with many of them
