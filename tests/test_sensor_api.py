"""The public face of diffsense.sensors: every entry point agrees with the others under jit, the
defaults (soft, temperature 1), the ego and padding rules, the float type kept, the refusals of a
bad mode, temperature or shape, and the registry that builds sensors by name."""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sensor_scenes import ahead, jit_detect, jit_p_detect, make_scene, traffic_scene

from diffsense import config as cfg
from diffsense import sensors
from diffsense.runtime import InputError
from tests._laws import THRESHOLD, threshold_config
from tests._synthetic import straight_scene
from tests._toy_pipeline import ToySensor

KEY = jax.random.key(11, impl="rbg")  # threefry compiles ~3 s slower on CPU
RADAR = threshold_config("radar")  # the gates: soft between 0 and 1, hard 0/1
CAMERA = threshold_config("camera")
STATIC = ("config", "mode")


def _same(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-12, atol=1e-12)


def test_detect_dispatches_and_agrees_with_the_sensor_functions_under_jit():
    scene = traffic_scene(num_frames=4)
    for config, own_detect, own_p in ((RADAR, sensors.radar_detect, sensors.radar_p_detect),
                                      (CAMERA, sensors.camera_detect, sensors.camera_p_detect)):
        def all_four(s, p, t, config, own_detect=own_detect, own_p=own_p):
            return [(sensors.detect(s, p, config, KEY, mode=mode, temperature=t),
                     own_detect(s, p, config, KEY, mode=mode, temperature=t),
                     sensors.p_detect(s, p, config, mode=mode, temperature=t),
                     own_p(s, p, config, mode=mode, temperature=t)) for mode in sensors.MODES]
        results = jax.jit(all_four, static_argnames="config")(scene, config.params, 0.5, config=config)
        for det, own, p, p_own in results:
            _same(det, own)
            _same(det.p_detect, p)
            _same(p, p_own)
        soft, hard = (r[2] for r in results)
        assert set(np.unique(hard)) == {0.0, 1.0} and np.any((soft > 0) & (soft < 1))


@pytest.mark.parametrize("name", ["radar", "camera"])
def test_every_entry_point_defaults_to_soft_at_temperature_1(name):
    # A car at the camera's resolvability edge at 180 deg, the radar's 100 m range edge at 30 deg: p ~ 1/2.
    config = RADAR if name == "radar" else CAMERA
    params = sensors.make_params(config, hfov_deg=180.0 if name == "camera" else 30.0)
    scene = ahead(config, [73.335 if name == "camera" else 100.0])
    p_fn = sensors.camera_p_detect if name == "camera" else sensors.radar_p_detect
    det_fn = sensors.camera_detect if name == "camera" else sensors.radar_detect
    explicit = float(p_fn(scene, params, config, mode="soft", temperature=1.0)[0, 1])
    assert 0.2 < explicit < 0.8
    assert float(p_fn(scene, params, config)[0, 1]) == explicit
    assert float(det_fn(scene, params, config, KEY).p_detect[0, 1]) == explicit
    assert float(sensors.p_detect(scene, params, config)[0, 1]) == explicit
    assert float(sensors.detect(scene, params, config, KEY).p_detect[0, 1]) == explicit
    device = sensors.Radar(config) if name == "radar" else sensors.Camera(config)
    assert float(device.detect(scene, {"hfov_deg": float(params.hfov_deg)}, KEY).p_detect[0, 1]) == explicit
    # detect_batch hands mode and temperature on
    scenes = jax.tree.map(lambda a: jnp.stack([a, a]), scene)
    for mode, temperature in (("hard", 1.0), ("soft", 3.0)):
        batch = sensors.detect_batch(scenes, params, config, KEY, mode=mode, temperature=temperature)
        single = sensors.p_detect(scene, params, config, mode=mode, temperature=temperature)
        np.testing.assert_allclose(np.asarray(batch.p_detect[1]), np.asarray(single), rtol=1e-12)


def test_the_ego_is_known_and_padding_is_never_detected_nor_hides_anything():
    scene = traffic_scene(num_frames=5)
    for config in (RADAR, CAMERA):
        det = jit_detect(scene, config.params, config, KEY)
        np.testing.assert_array_equal(det.p_detect[:, 0], 1.0)
        np.testing.assert_array_equal(det.x_m[:, 0], scene.x_m[:, 0])
        np.testing.assert_array_equal(det.p_detect[:, -1], 0.0)
    # A padding slot parked 20 m ahead, in line with a car at 40 m; the output keeps float32.
    parked = make_scene([[0.0, 40.0, 20.0]], [[0.0, 0.0, 0.0]], present=[True, True, False], dtype=np.float32)
    for mode in sensors.MODES:
        p = jit_p_detect(parked, CAMERA.params, CAMERA, mode=mode)
        assert p.dtype == np.float32 and float(p[0, 1]) > 0.99 and float(p[0, 2]) == 0.0


@pytest.mark.parametrize("name", [
    pytest.param("radar", marks=pytest.mark.xfail(strict=True, reason=(
        "radar_gain_dbi is a strong float64 under x64 (jnp.log10 of a weak scalar is not weak), "
        "so the SNR, the radar's p and noise scales promote a float32 scene to float64"))),
    "camera", "camera hard", "camera paper hard", "camera confidence",
])
def test_float32_scenes_stay_float32(name):
    sensor_name, *rest = name.split()
    config = sensors.load_config(sensor_name, profile="paper" if "paper" in rest else "physical")
    if "confidence" in rest:
        config = cfg.replace(config, detection=sensors.CameraDetection(law="confidence"))
    scene = make_scene([[0.0, 40.0, 60.0]], [[0.0, 1.0, -3.0]], dtype=np.float32)
    det = jax.jit(sensors.detect, static_argnames=STATIC)(scene, config.params, config, jax.random.key(0, impl="rbg"),
                                                          mode="hard" if "hard" in rest else "soft")
    assert {det.p_detect.dtype, det.x_m.dtype, det.y_m.dtype} == {np.dtype(np.float32)}


def test_traced_parameters_are_left_unchecked():
    k = jax.jit(lambda w: sensors.camera_px_per_rad(sensors.check_params(
        sensors.with_param(CAMERA.params, "width_px", w))))(2560.0)
    assert float(k) == pytest.approx(2560.0 / math.radians(30.0))


def test_a_bad_mode_temperature_or_shape_is_refused():
    one = traffic_scene(num_frames=4)
    with pytest.raises(InputError, match="noise"):
        sensors.detect(one, RADAR.params, RADAR, jnp.zeros((2, 3, 8)))
    with pytest.raises(InputError, match="detect_batch"):
        sensors.p_detect(jax.tree.map(lambda a: jnp.stack([a, a]), one), RADAR.params, RADAR)
    with pytest.raises(InputError, match="'fuzzy'"):
        sensors.p_detect(one, RADAR.params, RADAR, mode="fuzzy")
    for bad in (0.0, -1.0, math.nan, math.inf):
        for call in (lambda t: sensors.p_detect(one, RADAR.params, RADAR, temperature=t),
                     lambda t: sensors.detect(one, CAMERA.params, CAMERA, KEY, temperature=t)):
            with pytest.raises(InputError, match="temperature"):
                call(bad)
    with pytest.raises(InputError, match="CameraConfig"):
        sensors.p_detect(one, RADAR.params, CAMERA)


def test_a_plugged_in_sensor_is_never_handed_an_unknown_mode():
    # ToySensor reads any mode but "soft" as hard: the base class refuses the word first.
    scene = straight_scene(s0_m=[0.0, 30.0], lane=[1, 1], speed_mps=[25.0, 25.0], num_frames=3)
    for bad in ("SOFT", None, 1.0):
        with pytest.raises(InputError, match="mode"):
            ToySensor().detect(scene, noise=jax.random.PRNGKey(0), mode=bad)
    assert float(ToySensor().detect(scene, noise=jax.random.PRNGKey(0), mode="hard").p_detect[0, 1]) == 1.0
    with pytest.raises(InputError, match="noise"):
        ToySensor().detect(scene)
    # its soft gate is sigmoid((range_m - distance) / (2 T)): the car 30 m ahead with a 32 m range is
    # 1 / (1 + e^-1) at T = 1, the default
    p = float(ToySensor().detect(scene, {"range_m": 32.0}, jax.random.PRNGKey(0)).p_detect[0, 1])
    assert p == pytest.approx(1.0 / (1.0 + math.exp(-1.0)), rel=1e-6)


def test_the_registry_names_and_builds_sensors():
    before = sensors.sensor_names()  # radar and camera first (other tests may have added theirs)
    assert before[:2] == ("radar", "camera") and "toy_2" not in before
    sensors.register("toy_2", ToySensor)  # '_' and digits are allowed; ToySensor() takes no arguments
    assert sensors.sensor_names() == (*before, "toy_2") and isinstance(sensors.make_sensor("toy_2"), ToySensor)
    for bad in ("", "_", "a.b", "a-b", "a b"):  # "_" alone names nothing: no letter or digit
        with pytest.raises(InputError, match=repr(bad)):
            sensors.register(bad, ToySensor)
    assert sensors.sensor_names() == (*before, "toy_2")
    with pytest.raises(InputError, match="'lidar'"):
        sensors.make_sensor("lidar")


def test_make_sensor_builds_the_profile_asked_for_and_a_list_is_a_suite():
    camera = sensors.make_sensor(["camera"])  # one name: that sensor, not a suite
    assert isinstance(camera, sensors.Camera) and camera.config == sensors.load_config("camera")
    paper = sensors.make_sensor(("radar",), profile="paper")
    assert isinstance(paper, sensors.Radar) and paper.config == sensors.load_config("radar", profile="paper") != RADAR
    assert sensors.make_sensor("radar", THRESHOLD["radar"]).config == RADAR
    suite = sensors.make_sensor(["radar", "camera"], profile="paper")
    assert [m.config for m in suite.members] == [sensors.load_config(n, profile="paper") for n in ("radar", "camera")]
    radar = sensors.Radar.from_toml()
    assert sensors.make_sensor(radar) is radar
    for kwargs in ({"profile": "paper"}, {"config": "radar.toml"}):
        with pytest.raises(InputError, match="own constants"):
            sensors.make_sensor(radar, **kwargs)
    with pytest.raises(InputError, match="config"):
        sensors.make_sensor(["radar", "camera"], config="radar.toml")


def test_a_sensor_offers_its_parameters_with_their_defaults_domains_and_docs():
    for cls, config in ((sensors.Radar, RADAR), (sensors.Camera, CAMERA)):
        narrow = dataclasses.replace(config, params=dataclasses.replace(config.params, hfov_deg=45.0))
        assert cls(narrow).spec("hfov_deg").default == 45.0 != config.params.hfov_deg
        assert cls(narrow).defaults()["hfov_deg"] == 45.0
        assert all(isinstance(s.doc, str) and s.doc for s in cls(config).param_specs())
    radar = sensors.make_sensor("radar")
    assert radar.spec("hfov_deg").describe() == "(0, 360] deg"
    assert radar.spec("tx_power_dbm").describe() == "[-30, 40] dBm"
    with pytest.raises(InputError, match="'fov'") as caught:
        radar.spec("fov")
    known = "hfov_deg, vfov_deg, range_m, tx_power_dbm, noise_figure_db, yaw_deg, mount_x_m, mount_y_m"
    assert known in str(caught.value)
    with pytest.raises(InputError, match="'fov'"):
        radar.detect(traffic_scene(2), {"fov": 1.0}, KEY)
