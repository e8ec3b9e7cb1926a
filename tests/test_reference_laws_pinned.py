"""Which sensors the reference objective draws (`is_deterministic`, `declares_random_law` of
`diffsense/metrics/_reference.py`): the shipped radar and camera use the "threshold" law
(configs/sensors/*.toml); a custom sensor has no config and is taken as probabilistic, declaring
no law of its own."""

from __future__ import annotations

from pathlib import Path

from diffsense.metrics import is_deterministic
from diffsense.metrics._reference import declares_random_law
from diffsense.sensors import Camera, Radar
from diffsense.sensors._fusion import Suite
from tests._toy_pipeline import ToySensor

LAWS = Path(__file__).resolve().parents[1] / "configs" / "sensors" / "laws"


def test_threshold_sensors_are_deterministic_and_declare_no_random_law():
    radar, camera = Radar.from_toml(), Camera.from_toml()
    for sensor in (radar, camera, Suite((radar, camera))):
        assert is_deterministic(sensor) and not declares_random_law(sensor)


def test_a_custom_sensor_is_drawn_but_declares_no_law():
    toy = ToySensor()
    assert is_deterministic(toy) is False and declares_random_law(toy) is False


def test_a_swerling_radar_makes_its_suite_random():
    swerling = Radar.from_toml(LAWS / "radar_swerling1.toml")
    suite = Suite((swerling, Camera.from_toml()))
    assert not is_deterministic(swerling) and declares_random_law(swerling)
    assert not is_deterministic(suite) and declares_random_law(suite)
