"""Weather physics: ITU-R P.838-3 rain attenuation at 77 GHz, Koschmieder contrast, rain for the
camera, and the weather reaching the sensors' detections.

References are independent of the code under test: the ITU-R validation examples for P.838-3,
a numpy evaluation of the recommendation's regressions written as array sums, and hand
calculations of Koschmieder's law.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _laws import threshold_config
from _sensor_scenes import ahead

from diffsense import sensors

# ITU-R Study Group 3 validation examples for P.838-3 (slant paths; as distributed with the
# open-source ITU-Rpy package's tests): elevation [deg], f [GHz], R [mm/h], tilt [deg], k, alpha,
# gamma [dB/km].
ITU_VALIDATION = [
    (31.07699124, 14.25, 26.48052, 0.0, 0.03975488, 1.12418043, 1.58130839),
    (40.232036, 29.0, 33.936232, 0.0, 0.22031404, 0.9504446, 6.27846024),
    (48.24117054, 14.25, 63.62668149, 90.0, 0.04226474, 1.07871664, 3.72901264),
    (85.80459566, 29.0, 99.13558978, 90.0, 0.21737148, 0.93950825, 16.3183686),
]

# P.838-3 Tables 1-4 as the recommendation prints them: columns a_j, b_j, c_j; then m, c.
TABLES = {
    "kH": (np.array([[-5.33980, -0.35351, -0.23789, -0.94158],
                     [-0.10008, 1.26970, 0.86036, 0.64552],
                     [1.13098, 0.45400, 0.15354, 0.16817]]), -0.18961, 0.71147),
    "kV": (np.array([[-3.80595, -3.44965, -0.39902, 0.50167],
                     [0.56934, -0.22911, 0.73042, 1.07319],
                     [0.81061, 0.51059, 0.11899, 0.27195]]), -0.16398, 0.63297),
    "aH": (np.array([[-0.14318, 0.29591, 0.32177, -5.37610, 16.1721],
                     [1.82442, 0.77564, 0.63773, -0.96230, -3.29980],
                     [-0.55187, 0.19822, 0.13164, 1.47828, 3.43990]]), 0.67849, -1.95537),
    "aV": (np.array([[-0.07771, 0.56727, -0.20238, -48.2991, 48.5833],
                     [2.33840, 0.95545, 1.14520, 0.791669, 0.791459],
                     [-0.76284, 0.54039, 0.26809, 0.116226, 0.116479]]), -0.053739, 0.83433),
}


def numpy_coefficient(name: str, f_ghz: float) -> float:
    (a, b, c), m, const = TABLES[name]
    x = np.log10(f_ghz)
    value = np.sum(a * np.exp(-np.square((x - b) / c))) + m * x + const
    return 10.0**value if name.startswith("k") else value


@pytest.mark.parametrize("row", ITU_VALIDATION)
def test_rain_matches_the_itu_validation_examples(row):
    el, f, rate, tilt, k_ref, alpha_ref, gamma_ref = row
    k, alpha = sensors.rain_coefficients(f, math.radians(tilt), math.radians(el))
    gamma = sensors.rain_specific_attenuation_db_per_km(rate, f, math.radians(tilt), math.radians(el))
    np.testing.assert_allclose([k, alpha, gamma], [k_ref, alpha_ref, gamma_ref], rtol=1e-6)


def test_rain_at_77_ghz_matches_a_numpy_evaluation_of_the_regressions():
    for tilt, (k_name, a_name) in ((0.0, ("kH", "aH")), (math.pi / 2, ("kV", "aV"))):
        k, alpha = sensors.rain_coefficients(77.0, tilt)
        np.testing.assert_allclose(k, numpy_coefficient(k_name, 77.0), rtol=1e-12)
        np.testing.assert_allclose(alpha, numpy_coefficient(a_name, 77.0), rtol=1e-12)
    # The values quoted in the module docstring.
    np.testing.assert_allclose(sensors.rain_coefficients(77.0), (1.1320, 0.7177), atol=5e-5)
    np.testing.assert_allclose(sensors.rain_coefficients(77.0, math.pi / 2), (1.1276, 0.7073), atol=5e-5)
    rates = np.array([10.0, 25.0, 50.0, 100.0])
    kh, ah = numpy_coefficient("kH", 77.0), numpy_coefficient("aH", 77.0)
    gamma_h = sensors.rain_specific_attenuation_db_per_km(rates)
    np.testing.assert_allclose(gamma_h, kh * rates**ah, rtol=1e-12)
    np.testing.assert_allclose(gamma_h, [5.91, 11.41, 18.76, 30.85], atol=5e-3)
    gamma_v = sensors.rain_specific_attenuation_db_per_km(rates, tilt_rad=math.pi / 2)
    np.testing.assert_allclose(gamma_v, [5.75, 10.99, 17.94, 29.29], atol=5e-3)


def test_rain_at_any_polarisation_tilt_and_elevation_mixes_h_and_v_as_p838_says():
    # P.838-3 eqs. (4), (5) with tau = 30 deg, theta = 20 deg: c = cos^2(theta) cos(2 tau)
    c = math.cos(math.radians(20.0)) ** 2 * 0.5
    kh, kv = numpy_coefficient("kH", 77.0), numpy_coefficient("kV", 77.0)
    ah, av = numpy_coefficient("aH", 77.0), numpy_coefficient("aV", 77.0)
    k_ref = (kh + kv + (kh - kv) * c) / 2
    alpha_ref = (kh * ah + kv * av + (kh * ah - kv * av) * c) / (2 * k_ref)
    got = sensors.rain_coefficients(77.0, math.radians(30.0), math.radians(20.0))
    np.testing.assert_allclose(got, (k_ref, alpha_ref), rtol=1e-12)
    # 250 m out and back through 50 mm/h on that path: 2 x 0.25 km x k R^alpha
    loss = sensors.rain_two_way_loss_db(250.0, 50.0, 77.0, math.radians(30.0), math.radians(20.0))
    np.testing.assert_allclose(loss, 0.5 * k_ref * 50.0**alpha_ref, rtol=1e-12)


def test_rain_attenuation_takes_the_precision_of_all_its_inputs():
    rate = np.float32(10.0)
    assert sensors.rain_specific_attenuation_db_per_km(rate).dtype == np.float32  # Python defaults
    assert sensors.rain_specific_attenuation_db_per_km(rate, np.float64(77.0)).dtype == np.float64
    assert sensors.rain_specific_attenuation_db_per_km(rate, 77.0, np.float64(0.3)).dtype == np.float64
    assert sensors.rain_specific_attenuation_db_per_km(rate, 77.0, 0.0, np.float64(0.1)).dtype == np.float64
    # integers come in at the default float (float64 under the suite's x64), not float32
    k, alpha = sensors.rain_coefficients(np.int32(77))
    assert k.dtype == alpha.dtype == jnp.float64 and (float(k), float(alpha)) == tuple(map(float, sensors.rain_coefficients(77.0)))
    assert sensors.rain_two_way_loss_db(np.array([100], np.int64), np.float32(5.0)).dtype == jnp.float64
    # the sensors' weather takes the scene's float type: weather values arrive as E's (float64)
    rain = sensors.Weather(rain_mm_h=jnp.asarray(25.0, jnp.float64))
    loss = rain.radar_loss_db(jnp.asarray([50.0, 150.0], jnp.float32))
    assert loss.dtype == jnp.float32 and np.all(np.asarray(loss) > 0)
    # 1827.06 m for 25 mm/h of rain; with 300 m of fog 1 / (1/300 + 1/1827.06) m (extinctions add)
    fog = jnp.asarray(300.0, jnp.float64)
    rain_range = rain.camera_range_m(jnp.float32)
    both = sensors.Weather(rain_mm_h=rain.rain_mm_h, fog_visibility_m=fog).camera_range_m(jnp.float32)
    assert rain_range.dtype == both.dtype == jnp.float32
    assert float(rain_range) == pytest.approx(1827.06, abs=0.05)
    assert float(both) == pytest.approx(1.0 / (1.0 / 300.0 + 1.0 / float(rain_range)), rel=1e-5)


def test_two_way_loss_crosses_the_rain_twice():
    gamma = numpy_coefficient("kH", 77.0) * 100.0 ** numpy_coefficient("aH", 77.0)
    # 100 m out and back through 100 mm/h: 2 x 0.1 km x gamma.
    np.testing.assert_allclose(sensors.rain_two_way_loss_db(100.0, 100.0), 0.2 * gamma, rtol=1e-12)
    np.testing.assert_allclose(sensors.rain_two_way_loss_db(100.0, 100.0), 6.169, atol=1e-3)


def test_koschmieder_by_hand():
    assert sensors.KOSCHMIEDER_CONSTANT == pytest.approx(3.912, abs=5e-4)
    beta = sensors.fog_extinction_1pm(200.0)
    np.testing.assert_allclose(sensors.apparent_contrast(200.0, beta), 0.02, rtol=1e-12)  # at r = V
    np.testing.assert_allclose(sensors.apparent_contrast(100.0, beta), math.sqrt(0.02), rtol=1e-12)
    np.testing.assert_allclose(sensors.apparent_contrast(100.0, beta, 0.5), 0.5 * math.sqrt(0.02), rtol=1e-12)
    np.testing.assert_allclose(sensors.contrast_range_m(beta), 200.0, rtol=1e-12)
    # C0 = 0.5 reaches 2 % where exp(-beta r) = 0.04: r = V ln 25 / ln 50.
    np.testing.assert_allclose(sensors.contrast_range_m(beta, 0.5), 200.0 * math.log(25) / math.log(50), rtol=1e-12)
    np.testing.assert_allclose(sensors.visibility_m(beta), 200.0, rtol=1e-12)
    # integer inputs are numbers, not integer arrays: beta = 2 /m, C0 = 0.5 reaches 2 % at
    # ln(0.5 / 0.02) / 2 m (an integer beta must not round C0 down to 0)
    np.testing.assert_allclose(sensors.contrast_range_m(2, 0.5), math.log(25) / 2, rtol=1e-12)
    np.testing.assert_allclose(sensors.visibility_m(jnp.asarray(2)), sensors.KOSCHMIEDER_CONSTANT / 2, rtol=1e-12)
    # the camera's extinction is dry unless a rain rate is given; the range keeps beta's precision
    np.testing.assert_allclose(sensors.camera_extinction_1pm(200.0), sensors.KOSCHMIEDER_CONSTANT / 200.0, rtol=1e-12)
    assert sensors.contrast_range_m(np.float32(0.02), np.float64(0.5)).dtype == np.float32


def test_rain_lowers_the_camera_visibility():
    # 1.076 * 25^0.67 dB/km -> nepers/km -> visibility 3.912 / beta.
    db_per_km = 1.076 * math.exp(0.67 * math.log(25.0))
    beta_per_km = db_per_km * math.log(10.0) / 10.0
    expected_m = 1000.0 * -math.log(0.02) / beta_per_km
    np.testing.assert_allclose(sensors.visibility_m(sensors.rain_extinction_1pm(25.0)), expected_m, rtol=1e-12)
    np.testing.assert_allclose(expected_m, 1827.0, atol=0.5)
    both = sensors.camera_extinction_1pm(500.0, 25.0)
    np.testing.assert_allclose(both, 3.912023005428146 / 500.0 + beta_per_km / 1000.0, rtol=1e-12)


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_clear_weather_changes_nothing_bit_for_bit(dtype):
    r = jnp.asarray([0.0, 1.0, 37.3, 150.0], dtype)
    snr = jnp.asarray([3.0, -7.25, 12.5, 0.1], dtype)
    loss = sensors.rain_two_way_loss_db(r, jnp.zeros((), dtype))
    assert loss.dtype == dtype and np.all(np.asarray(loss) == 0.0)
    assert np.array_equal(np.asarray(snr - loss), np.asarray(snr))
    beta = sensors.camera_extinction_1pm(jnp.asarray(jnp.inf, dtype), jnp.zeros((), dtype))
    assert beta.dtype == dtype and float(beta) == 0.0
    assert np.all(np.asarray(sensors.contrast_transmission(r, beta)) == 1.0)
    limit = jnp.asarray(100.0, dtype)
    assert np.asarray(jnp.minimum(limit, sensors.contrast_range_m(beta))).tobytes() == np.asarray(limit).tobytes()
    grad = jax.grad(lambda v: jnp.minimum(limit, sensors.contrast_range_m(sensors.camera_extinction_1pm(v))))
    assert float(grad(jnp.asarray(jnp.inf, dtype))) == 0.0


RAINS = [0.0, 1e-9, 0.1, 1.0, 10.0, 50.0, 100.0, 200.0]
VISIBILITIES = [10.0, 50.0, 300.0, 1000.0, 10000.0]


def _finite_value_and_grads(fn, *args):
    value = fn(*args)
    grads = jax.grad(fn, argnums=tuple(range(len(args))))(*args)
    return np.isfinite(float(value)) and all(np.isfinite(float(g)) for g in grads)


def test_no_nan_or_inf_in_values_or_gradients():
    radar = lambda rain, r: sensors.rain_two_way_loss_db(r, rain)  # noqa: E731
    camera = lambda vis, rain, r: sensors.contrast_transmission(r, sensors.camera_extinction_1pm(vis, rain))  # noqa: E731
    limit = lambda vis, rain: jnp.minimum(120.0, sensors.contrast_range_m(sensors.camera_extinction_1pm(vis, rain)))  # noqa: E731
    for rain in RAINS:
        assert _finite_value_and_grads(radar, jnp.float64(rain), jnp.float64(80.0))
        for vis in VISIBILITIES:
            args = (jnp.float64(vis), jnp.float64(rain))
            assert _finite_value_and_grads(camera, *args, jnp.float64(80.0))
            assert _finite_value_and_grads(limit, *args)
            assert _finite_value_and_grads(sensors.contrast_range_m, sensors.camera_extinction_1pm(*args))


def _central_difference(fn, x, h):
    return (fn(x + h) - fn(x - h)) / (2.0 * h)


@pytest.mark.parametrize("rain", [0.1, 1.0, 10.0, 50.0, 200.0])
def test_radar_gradient_matches_finite_differences(rain):
    fn = lambda x: sensors.rain_two_way_loss_db(75.0, x)  # noqa: E731
    x = jnp.float64(rain)
    np.testing.assert_allclose(jax.grad(fn)(x), _central_difference(fn, x, 1e-5 * rain), rtol=1e-6)


@pytest.mark.parametrize("vis", [10.0, 300.0, 10000.0])
@pytest.mark.parametrize("rain", [0.0, 5.0, 200.0])
def test_camera_gradients_match_finite_differences(vis, rain):
    for fn, x, h in (
        (lambda v: sensors.contrast_transmission(60.0, sensors.camera_extinction_1pm(v, rain)), vis, 1e-5 * vis),
        (lambda v: sensors.contrast_range_m(sensors.camera_extinction_1pm(v, rain)), vis, 1e-5 * vis),
        (lambda r: sensors.contrast_range_m(sensors.camera_extinction_1pm(vis, r)), rain, 1e-5 * rain),
    ):
        if h == 0.0:
            continue  # rain = 0: the one-sided derivative is infinite; the code reports 0
        x = jnp.float64(x)
        np.testing.assert_allclose(jax.grad(fn)(x), _central_difference(fn, x, h), rtol=1e-6)


@pytest.mark.parametrize("name", ["radar", "camera"])
def test_every_sensor_function_passes_the_weather_on(name):
    # Radar at 60 deg: a car at 87 m sits on the SNR edge (p ~ 1/2); 25 mm/h of rain takes ~2 dB off it.
    # Camera: a car at 60 m is seen in clear weather and lost in 50 m fog (hard).
    config = threshold_config(name)
    params = sensors.make_params(config, hfov_deg=60.0)
    scene = ahead(config, [87.0 if name == "radar" else 60.0])
    weather = sensors.Weather(rain_mm_h=25.0) if name == "radar" else sensors.Weather(fog_visibility_m=50.0)
    mode = "soft" if name == "radar" else "hard"
    p_fn = sensors.radar_p_detect if name == "radar" else sensors.camera_p_detect
    det_fn = sensors.radar_detect if name == "radar" else sensors.camera_detect
    device = (sensors.Radar if name == "radar" else sensors.Camera)(config)
    key = jax.random.key(5, impl="rbg")
    clear = float(p_fn(scene, params, config, mode=mode)[0, 1])
    for p in (p_fn(scene, params, config, mode=mode, weather=weather),
              det_fn(scene, params, config, key, mode=mode, weather=weather).p_detect,
              device.detect(scene, {"hfov_deg": 60.0}, key, mode=mode, weather=weather).p_detect):
        assert float(p[0, 1]) < clear - 0.3, (clear, float(p[0, 1]))
