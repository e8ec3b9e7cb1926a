"""The inspection helpers behind `python -m diffsense.sensors inspect` (`_inspect.py`): the probe
scene and the coverage field, against hand values.

The shipped radar: HFOV 30 deg and range 100 m, mounted 4.2 m ahead of the ego's centre.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from diffsense.scene import CAR, EGO, TARGET, TRUCK
from diffsense.sensors._inspect import coverage_field, probe_scene
from diffsense.sensors._config import load_config


def test_probe_scene_is_the_ego_at_the_origin_and_one_probe_per_point():
    scene = probe_scene(jnp.asarray([10.0, 20.0, 30.0]), jnp.asarray([1.0, -2.0, 0.0]), kind=TRUCK,
                        length_m=12.0, width_m=2.5)
    np.testing.assert_array_equal(np.asarray(scene.x_m), [[0, 10], [0, 20], [0, 30]])
    np.testing.assert_array_equal(np.asarray(scene.y_m), [[0, 1], [0, -2], [0, 0]])
    np.testing.assert_array_equal(np.asarray(scene.role), [EGO, TARGET])
    np.testing.assert_array_equal(np.asarray(scene.kind), [CAR, TRUCK])
    np.testing.assert_array_equal(np.asarray(scene.length_m), [4.5, 12.0])
    np.testing.assert_array_equal(np.asarray(scene.width_m), [1.8, 2.5])


def test_radar_coverage_field_by_hand():
    config = load_config("radar")
    x = np.array([20.0, 60.0, 150.0])
    y = np.array([0.0, 40.0])
    field = coverage_field(config.params, config, x, y, mode="hard")
    # row y = 0: 15.8 and 55.8 m straight ahead are seen, 145.8 m is past the 100 m range;
    # row y = 40: 68 and 36 deg off the axis, outside the +-15 deg field of view
    np.testing.assert_array_equal(field, [[1.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
