"""Mounting as parameters: yaw_deg, mount_x_m and mount_y_m move the sensor on the ego, the FOV gate
turns with the yaw, the default mounting is the unmounted sensor bit for bit, a mounting outside
its envelope is refused in one line, and a free mounting widens the scenes' relevance reach.
(The geometry seen from the mount point: tests/test_sensor_geometry.py.)"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sensor_scenes import jit_p_detect, make_scene, traffic_scene

import diffsense as ds
from diffsense.metrics import relevance_reach
from diffsense.predictors import InputSpec
from diffsense.sensors import Camera, Radar, relevance_stand_ins

ROOT = Path(__file__).resolve().parents[1]
KEY = jax.random.key(5, impl="rbg")
LAWS = ROOT / "configs" / "sensors" / "laws"


def threshold(cls):
    """The sensor under the deterministic threshold law, whose hard detections are 0 or 1
    (whichever law the profile defaults to)."""
    return cls.from_toml(LAWS / f"{cls.kind}_threshold.toml")


@pytest.mark.parametrize("make", [Radar.from_toml, Camera.from_toml])
def test_the_default_mounting_given_as_arrays_is_the_unmounted_sensor_bit_for_bit(make):
    sensor = make()
    scene = traffic_scene()
    scene = make_scene(scene.x_m, scene.y_m, heading_rad=0.3, kind=scene.kind, present=scene.present)
    mount = {"yaw_deg": jnp.asarray(0.0), "mount_x_m": jnp.asarray(sensor.mount_x_m), "mount_y_m": jnp.asarray(0.0)}
    for mode in ("soft", "hard"):
        plain = jax.jit(lambda s, mode=mode: sensor.detect(s, {}, KEY, mode=mode))(scene)
        given = jax.jit(lambda s, m, mode=mode: sensor.detect(s, m, KEY, mode=mode))(scene, mount)
        for a, b in zip(jax.tree.leaves(plain), jax.tree.leaves(given), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_the_sensors_sit_ahead_of_the_egos_centre():
    # A small object 3.5 m ahead of the ego's centre is behind the radar (4.2 m), ahead of the camera (2.5 m).
    scene = make_scene([[0.0, 3.5]], [[0.0, 0.0]], length_m=[4.5, 0.4], width_m=[1.8, 0.4])
    for sensor, seen in ((threshold(Radar), 0.0), (threshold(Camera), 1.0)):
        assert float(jit_p_detect(scene, sensor.config.params, sensor.config, mode="hard")[0, 1]) == seen


def test_the_fov_gate_is_centred_on_the_yaw_in_degrees():
    # A car 30 m from the radar's mount point, 40 deg left of the ego's heading; HFOV 30 deg sees
    # +-15 deg about the boresight: yaw 0 misses it, 26 sees it (40 - 26 = 14), 24 misses it (16).
    radar = threshold(Radar)
    az = math.radians(40.0)
    scene = make_scene([[0.0, radar.mount_x_m + 30 * math.cos(az)]], [[0.0, 30 * math.sin(az)]])
    seen = [float(radar.detect(scene, {"hfov_deg": 30.0, "yaw_deg": yaw}, KEY, mode="hard").p_detect[0, 1])
            for yaw in (0.0, 26.0, 24.0, 40.0, 54.0, 56.0, 54)]
    assert seen == [0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0]  # an integer yaw is degrees too
    # Turned 90 deg left, a car 15 m to its left is straight ahead of it, one 15 m ahead 90 deg right.
    turned = {"hfov_deg": 10.0, "yaw_deg": 90.0}
    beside = make_scene([[0.0, 4.2, 19.2]], [[0.0, 15.0, 0.0]])
    assert radar.detect(beside, turned, KEY, mode="hard").p_detect[0].tolist() == [1.0, 1.0, 0.0]


@pytest.mark.parametrize("params, culprit", [
    ({"yaw_deg": (-190.0, 0.0)}, r"yaw_deg: \[-180, 180\] deg"),
    ({"mount_x_m": (0.0, 4.5)}, r"mount_x_m: \[-2.3, 4.2\] m"),
    ({"mount_x_m": (-2.4, 0.0)}, "mount_x_m"),
    ({"mount_y_m": (-1.0, 0.0)}, r"mount_y_m: \[-0.9, 0.9\] m"),
    ({"mount_y": (0.5, 0.1)}, "mount_y_m"),
])
def test_a_mounting_bound_outside_its_envelope_is_refused(params, culprit):
    with pytest.raises(ds.InputError, match=culprit):
        ds.Problem(sensor="camera", params=params)


def test_the_envelope_edges_are_accepted_and_short_names_resolve():
    p = ds.Problem(sensor=["radar", "camera"], params={"radar.yaw": (-180, 180), "camera.mount_x": (-2.3, 4.2),
                                                        "camera.mount_y": (-0.9, 0.9)})
    assert set(p.params) == {"radar.yaw_deg", "camera.mount_x_m", "camera.mount_y_m"}


def test_a_mounting_outside_its_envelope_on_the_cli_is_one_line_exit_2_nothing_written(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "diffsense.optimise", "--sensor", "radar,camera",
                           "--param", "radar.mount_y_m=-1.2:0.5", "--out", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "radar.mount_y_m" in lines[0], proc.stderr
    assert lines[0].startswith("error: ") and not out.exists()


def test_a_free_mount_x_widens_the_scenes_relevance_reach_to_its_front_bound():
    camera = Camera.from_toml()  # mounted 2.5 m ahead
    spec = InputSpec(history_points=16, future_points=25, rate_hz=5.0, grid_cells=13, grid_lanes=3, grid_cell_m=4.572)
    stand_ins = relevance_stand_ins({"camera.hfov_deg": (30.0, 90.0), "camera.mount_x_m": (1.0, 3.7)})
    assert [s.mount_x_m for s in stand_ins] == [3.7]
    assert relevance_reach(spec, [camera])["sensor_reach_m"] == 2.5
    assert relevance_reach(spec, [camera, *stand_ins])["sensor_reach_m"] == 3.7
    assert relevance_stand_ins({"mount_x_m": (-1.0, 1.0)})[0].mount_x_m == 1.0  # a lone sensor's name
    # The parameter's own name is the part after the last dot, however many prefixes it has.
    assert [s.mount_x_m for s in relevance_stand_ins({"a.b.mount_x_m": (0.0, 2.0), "a.mount_x_m.x": (0.0, 3.0)})] == [2.0]
