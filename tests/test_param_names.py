"""A problem's parameter names and bounds (`diffsense.sensors.resolve_name`, `resolve_params`): full,
short or qualified names resolved to the sensor's, foreign and unknown ones refused with the known
ones, bounds checked against each parameter's domain and kept as floats. No program is compiled."""

from __future__ import annotations

import math

import pytest

from diffsense.runtime import InputError, finite_number
from diffsense.sensors import Camera, Radar, Suite, resolve_name, resolve_params

RADAR, CAMERA = Radar.from_toml(), Camera.from_toml()
SUITE = Suite((RADAR, CAMERA))


@pytest.mark.parametrize("given, full", [("hfov_deg", "hfov_deg"), ("hfov", "hfov_deg"),
                                         ("radar.hfov_deg", "hfov_deg"), ("radar.range", "range_m"),
                                         ("tx_power", "tx_power_dbm"), ("noise_figure", "noise_figure_db")])
def test_a_radar_parameter_by_full_short_or_qualified_name(given, full):
    assert resolve_name(RADAR, given) == full


def test_suite_names_resolve_within_their_member():
    assert resolve_name(SUITE, "radar.hfov_deg") == "radar.hfov_deg"
    assert resolve_name(SUITE, "radar.hfov") == "radar.hfov_deg"
    assert resolve_name(SUITE, "camera.width") == "camera.width_px"
    # The first dot names the member, which resolves the rest: "radar.camera.hfov" asks the radar
    # for camera.hfov (refused below), "radar.radar.hfov" the radar for radar.hfov.
    assert resolve_name(SUITE, "radar.radar.hfov") == "radar.hfov_deg"


@pytest.mark.parametrize("sensor, name, message", [
    (RADAR, "fov", ("unknown radar parameter 'fov' (known: hfov (hfov_deg), vfov (vfov_deg), range (range_m), "
                    "tx_power (tx_power_dbm), noise_figure (noise_figure_db), yaw (yaw_deg), "
                    "mount_x (mount_x_m), mount_y (mount_y_m))")),
    (RADAR, "radar.hfov.deg", "unknown radar parameter 'hfov.deg' (known: "),
    (RADAR, "camera.hfov_deg", "parameter camera.hfov_deg names sensor 'camera', not in this problem (radar)"),
    (CAMERA, "camera.snr", "unknown camera parameter 'snr' (known: "),
    (SUITE, "hfov", "a suite's parameters are qualified by the sensor: give e.g. radar.hfov, camera.hfov"),
    (SUITE, "lidar.hfov", "parameter lidar.hfov names sensor 'lidar', not in the suite (radar, camera)"),
    (SUITE, "camera.snr", "unknown camera parameter 'snr' (known: "),
    (SUITE, "radar.camera.hfov", "parameter camera.hfov names sensor 'camera', not in this problem (radar)"),
])
def test_unknown_and_foreign_names_are_refused_with_the_known_ones(sensor, name, message):
    with pytest.raises(InputError) as info:
        resolve_name(sensor, name)
    assert str(info.value).startswith(message)


def test_bounds_are_resolved_checked_and_kept_as_floats():
    out = resolve_params(RADAR, {"hfov": (30, 180), "radar.range_m": ("40", 90.5)})
    assert out == {"hfov_deg": (30.0, 180.0), "range_m": (40.0, 90.5)}
    assert all(type(v) is float for bounds in out.values() for v in bounds)
    assert list(out) == ["hfov_deg", "range_m"]
    # The domain's own edges: HFOV (0, 360] deg takes 360 and refuses 0.
    assert resolve_params(RADAR, {"hfov": (359, 360)}) == {"hfov_deg": (359.0, 360.0)}


def test_finite_numbers_are_floats_and_the_rest_is_refused_by_name():
    for value, ok in ((3, 3.0), ("2.5", 2.5), (-0.0, 0.0), (1e308, 1e308)):
        assert finite_number(value, "x") == ok and type(finite_number(value, "x")) is float
    for value in (None, "x", math.nan, -math.inf):
        with pytest.raises(InputError, match="^cost_weight must be"):
            finite_number(value, "cost_weight")
