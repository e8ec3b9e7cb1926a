"""Mounting as parameters: yaw_deg, mount_x_m and mount_y_m move the sensor's pose on the ego, the
FOV gate turns with the yaw, occlusion is seen from the mount point, the default mounting is the
unmounted sensor bit for bit, and a mounting outside its envelope is refused in one line."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_scenes import make_scene, traffic_scene

import diffsense as ds
from diffsense.sensors import Camera, Mount, Radar, load_config, make_params
from diffsense.sensors._mount import mount_of
from diffsense.sensors._geometry import Tracks, polar, vehicle_occlusion

ROOT = Path(__file__).resolve().parents[1]
KEY = jax.random.key(5, impl="rbg")


@pytest.mark.parametrize("make", [Radar.from_toml, Camera.from_toml])
def test_the_default_mounting_given_as_arrays_is_the_unmounted_sensor_bit_for_bit(make):
    sensor = make()
    scene = traffic_scene()
    scene = make_scene(scene.x_m, scene.y_m, heading_rad=0.3, kind=scene.kind, present=scene.present)
    mount = {"yaw_deg": jnp.asarray(0.0), "mount_x_m": jnp.asarray(sensor.mount_x_m), "mount_y_m": jnp.asarray(0.0)}
    for mode in ("soft", "hard"):
        plain = jax.jit(lambda s: sensor.detect(s, {}, KEY, mode=mode))(scene)
        given = jax.jit(lambda s, m: sensor.detect(s, m, KEY, mode=mode))(scene, mount)
        for a, b in zip(jax.tree.leaves(plain), jax.tree.leaves(given)):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("heading_rad", [0.0, 0.5])
def test_range_and_azimuth_are_measured_from_the_mount_point_and_the_yaw(heading_rad):
    # Mount 3 m ahead, 0.6 m left, boresight 20 deg left. In the ego frame the sensor sits at
    # (3, 0.6); one car is placed 20 m along the boresight (azimuth 0), one 10 m along a line 25 deg
    # right of the ego's heading (45 deg right of the boresight), then the scene is turned by the
    # ego's heading: ranges 20 and 10 m, azimuths 0 and -45 deg whatever the heading.
    sx, sy = 3.0, 0.6
    local = [(0.0, 0.0), (sx + 20 * math.cos(math.radians(20)), sy + 20 * math.sin(math.radians(20))),
             (sx + 10 * math.cos(math.radians(-25)), sy + 10 * math.sin(math.radians(-25)))]
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    x = [[c * u - s * v for u, v in local]]
    y = [[s * u + c * v for u, v in local]]
    tracks = Tracks.of(make_scene(x, y, heading_rad=heading_rad))
    range_m, azimuth_rad = polar(tracks, Mount(x_m=sx, y_m=sy, yaw_rad=math.radians(20)))
    np.testing.assert_allclose(np.asarray(range_m)[1:, 0], [20.0, 10.0], rtol=1e-12)
    np.testing.assert_allclose(np.degrees(np.asarray(azimuth_rad)[1:, 0]), [0.0, -45.0], atol=1e-6)


def test_the_fov_gate_is_centred_on_the_yaw():
    # A car 30 m from the radar's mount point, 40 deg left of the ego's heading; HFOV 30 deg sees
    # +-15 deg about the boresight: yaw 0 misses it, 26 deg sees it (40 - 26 = 14), 24 misses it (16).
    radar = Radar.from_toml()
    az = math.radians(40.0)
    scene = make_scene([[0.0, radar.mount_x_m + 30 * math.cos(az)]], [[0.0, 30 * math.sin(az)]])
    seen = [float(radar.detect(scene, {"hfov_deg": 30.0, "yaw_deg": yaw}, KEY, mode="hard").p_detect[0, 1])
            for yaw in (0.0, 26.0, 24.0, 40.0, 54.0, 56.0)]
    assert seen == [0.0, 1.0, 0.0, 1.0, 1.0, 0.0]


def test_occlusion_is_seen_from_the_mount_point():
    # Camera 2.5 m ahead of the ego's centre; an occluder (4.5 x 1.8 m) at (12, 1.6) and the target
    # at (40, 3.0). Angular intervals, half-width atan((L |sin| + W |cos|) / 2 / range) about each
    # line of sight, by hand:
    #   from (2.5, 0):    occluder 9.560 +- 7.458 deg = [2.102, 17.018], target 4.574 +- 1.639 =
    #                     [2.935, 6.213]: covered whole (fraction 1), not detected;
    #   from (2.5, -0.9): occluder 14.744 +- 8.356 = [6.387, 23.100], target 5.937 +- 1.714 =
    #                     [4.224, 7.651]: covered 1.264 of 3.427 deg = 0.36879, detected (>= 0.6 visible).
    camera = Camera.from_toml()
    scene = make_scene([[0.0, 40.0, 12.0]], [[0.0, 3.0, 1.6]])
    tracks = Tracks.of(scene)
    for y_m, hidden, seen in [(0.0, 1.0, 0.0), (-0.9, 0.36879, 1.0)]:
        mount = Mount(x_m=2.5, y_m=y_m)
        range_m, azimuth_rad = polar(tracks, mount)
        _, fraction = vehicle_occlusion(tracks, range_m, azimuth_rad, mount, "hard", 1.0, 0.2)
        assert float(fraction[1, 0]) == pytest.approx(hidden, abs=2e-5)
        det = camera.detect(scene, {"hfov_deg": 90.0, "mount_y_m": y_m}, KEY, mode="hard")
        assert float(det.p_detect[0, 1]) == seen


@pytest.mark.parametrize("params, match", [
    ({"yaw_deg": (-190.0, 0.0)}, r"outside the domain of yaw_deg: \[-180, 180\] deg"),
    ({"mount_x_m": (0.0, 4.5)}, r"outside the domain of mount_x_m: \[-2.3, 4.2\] m"),
    ({"mount_x_m": (-2.4, 0.0)}, "outside the domain of mount_x_m"),
    ({"mount_y_m": (-1.0, 0.0)}, r"outside the domain of mount_y_m: \[-0.9, 0.9\] m"),
    ({"mount_y": (0.5, 0.1)}, "lo < hi"),
])
def test_a_mounting_bound_outside_its_envelope_is_refused(params, match):
    with pytest.raises(ds.InputError, match=match):
        ds.Problem(sensor="camera", params=params)


def test_the_envelope_edges_are_accepted_and_short_names_resolve():
    p = ds.Problem(sensor=["radar", "camera"], params={"radar.yaw": (-180, 180), "camera.mount_x": (-2.3, 4.2),
                                                        "camera.mount_y": (-0.9, 0.9)})
    assert set(p.params) == {"radar.yaw_deg", "camera.mount_x_m", "camera.mount_y_m"}


@pytest.mark.parametrize("text, match", [
    ("mount_y_m = 1.5\n", r"camera mount_y_m = 1.5 is outside its envelope \[-0.9, 0.9\] m"),
    ("yaw_deg = 200.0\n", "camera yaw_deg = 200.0 is outside its envelope"),
    ("[params]\nyaw_deg = 10.0\n", "yaw_deg is a top-level key of the sensor config"),
])
def test_a_sensor_config_mounted_outside_its_envelope_is_refused(tmp_path, text, match):
    path = tmp_path / "camera.toml"
    path.write_text(text)
    with pytest.raises(ds.InputError, match=match):
        Camera.from_toml(path)


def test_a_sensor_config_on_its_envelopes_edges_is_accepted(tmp_path):
    for x, y, yaw in ((-2.3, -0.9, -180.0), (4.2, 0.9, 180.0)):
        path = tmp_path / "camera.toml"
        path.write_text(f"mount_x_m = {x}\nmount_y_m = {y}\nyaw_deg = {yaw}\n")
        config = Camera.from_toml(path).config
        assert (config.mount_x_m, config.mount_y_m, config.yaw_deg) == (x, y, yaw)


def test_the_mounting_of_parameters_in_radians_and_the_configs_where_they_leave_it():
    config = load_config("radar")  # mounted 4.2 m ahead on the centre line, facing forward
    assert mount_of(config.params, config) == Mount(x_m=4.2, y_m=0.0, yaw_rad=0.0)
    turned = mount_of(make_params(config, yaw_deg=1, mount_x_m=-1.5, mount_y_m=0.4), config)
    assert turned.yaw_rad == pytest.approx(math.pi / 180.0, rel=1e-15)  # 1 deg, an int too
    assert (turned.x_m, turned.y_m) == (-1.5, 0.4)
    # A static zero yaw stays the Python number 0.0, which the geometry skips.
    assert type(mount_of(make_params(config, yaw_deg=0), config).yaw_rad) is float


def test_a_mounting_outside_its_envelope_on_the_cli_is_one_line_exit_2_nothing_written(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "diffsense.optimise", "--sensor", "radar,camera",
                           "--param", "radar.mount_y_m=-1.2:0.5", "--out", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "outside the domain of radar.mount_y_m" in lines[0], proc.stderr
    assert not out.exists()


def test_a_free_mount_x_widens_the_scenes_relevance_reach_to_its_front_bound():
    from diffsense.metrics._build import relevance_reach
    from diffsense.predictors import InputSpec
    from diffsense.sensors._mount import relevance_stand_ins

    camera = Camera.from_toml()  # mounted 2.5 m ahead
    spec = InputSpec(history_points=16, future_points=25, rate_hz=5.0, grid_cells=13, grid_lanes=3, grid_cell_m=4.572)
    stand_ins = relevance_stand_ins({"camera.hfov_deg": (30.0, 90.0), "camera.mount_x_m": (1.0, 3.7)})
    assert [s.mount_x_m for s in stand_ins] == [3.7]
    assert relevance_reach(spec, [camera])["sensor_reach_m"] == 2.5
    assert relevance_reach(spec, [camera, *stand_ins])["sensor_reach_m"] == 3.7
    assert relevance_stand_ins({"mount_x_m": (-1.0, 1.0)})[0].mount_x_m == 1.0  # a lone sensor's name
    # The parameter's own name is the part after the last dot, however many prefixes it has.
    nested = relevance_stand_ins({"a.b.mount_x_m": (0.0, 2.0), "a.mount_x_m.x": (0.0, 3.0)})
    assert [s.mount_x_m for s in nested] == [2.0]
