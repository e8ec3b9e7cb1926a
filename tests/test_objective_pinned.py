"""The objective's questions and its hard evaluation, pinned to hand-made predictions and
numpy recomputations written loop by loop (surviving mutants of the mutation run of
diffsense/metrics/_objective.py and one of _build.py, docs/mutation.md).

Two toy variants of four instants each; a prediction offset from the ground-truth-input
prediction by a hand-chosen distance on the first five of its 25 horizon steps, so each
instant's squared error (the mean over horizon steps of the squared distance) is that distance
squared over 5.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.metrics import EstimatorConfig
from tests._toy_pipeline import toy_objective

# The offset [m] of instant i of variant n (x for variant 0, y for variant 1, so a mix-up of the
# coordinate axis shows); squared and over 5: sq[n, i].
OFFSET_M = np.array([[1.0, 2.0, 3.0, 4.0], [5.0, 0.0, 0.0, 0.0]])
SQ = OFFSET_M**2 / 5.0  # [[0.2, 0.8, 1.8, 3.2], [5, 0, 0, 0]]
TRACKED = np.array([[1.0, 0.5, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0]])
PENALTY_M2 = 50.0


def _objective(question: str, weight=(1.0, 1.0)):
    jax.config.update("jax_enable_x64", True)
    E = toy_objective(n=2, instants=4, question=question, miss_penalty_m2=PENALTY_M2)
    return eqx.tree_at(lambda o: o.data.weight, E, jnp.asarray(weight, E.dtype))


def _offset_prediction(E) -> jax.Array:
    gt = np.asarray(E.data.gt_pred)  # [N, I, F, 2]
    assert gt.shape == (2, 4, 25, 2)
    pred = gt.copy()
    for n in range(2):
        for i in range(4):
            pred[n, i, :5, n] += OFFSET_M[n, i]
    return jnp.asarray(pred)


@pytest.mark.parametrize("weight, expected", [
    ((1.0, 1.0), (0.2 + 0.8 + 1.8 + 3.2 + 5.0) / 8),  # every instant counts once: 1.375 m^2
    ((1.0, 0.0), (0.2 + 0.8 + 1.8 + 3.2) / 4),  # variant 1 is padding: 1.5 m^2
])
def test_eq12_is_the_weighted_mean_over_instants_of_the_squared_error(weight, expected):
    E = _objective("eq12", weight)
    value = E._question(_offset_prediction(E), jnp.asarray(TRACKED))
    assert float(value) == pytest.approx(expected, rel=1e-12)
    # The tracked probabilities play no part in Eq. 12.
    assert float(E._question(_offset_prediction(E), jnp.zeros((2, 4)))) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("weight, expected", [
    # seen = 1 + 0.5 + 0.5 = 2 of 8: (1 x 0.2 + 0.5 x 0.8 + 0.5 x 5) / (1 + 2) + 50 x (1 - 2/8)
    ((1.0, 1.0), 3.1 / 3.0 + 37.5),
    # variant 1 is padding: seen 1.5 of 4: (0.2 + 0.4) / 2.5 + 50 x (1 - 1.5/4)
    ((1.0, 0.0), 0.6 / 2.5 + 31.25),
])
def test_tracked_is_the_seen_instants_error_plus_the_price_of_the_missed(weight, expected):
    E = _objective("tracked", weight)
    value = E._question(_offset_prediction(E), jnp.asarray(TRACKED))
    assert float(value) == pytest.approx(expected, rel=1e-12)


def test_tracked_with_every_instant_seen_costs_no_penalty():
    E = _objective("tracked")
    value = E._question(_offset_prediction(E), jnp.ones((2, 4)))
    assert float(value) == pytest.approx(SQ.sum() / 9.0, rel=1e-12)  # 8 instants + 1 pseudo-instant


@pytest.mark.parametrize("weight", [(1.0, 1.0), (1.0, 0.0)])
def test_hard_evaluation_against_a_loop_by_loop_recomputation(weight):
    """Every field of `hard` that reports an error, from the objective's own data with numpy;
    with variant 1 as padding (weight 0), E^2 is variant 0's alone."""
    E = _objective("eq12", weight)
    h = jax.tree.map(np.asarray, E.hard({"range_m": 30.0}))
    det = E.detections({"range_m": 30.0}, "hard")
    pred = np.asarray(E._predict(det))
    gt, fut = np.asarray(E.data.gt_pred), np.asarray(E.data.true_fut)
    n_var, n_inst, n_step = gt.shape[:3]
    sq_instant = np.zeros((n_var, n_inst))
    sq_true_gt = np.zeros((n_var, n_inst, n_step))
    sq_true_sensor = np.zeros((n_var, n_inst, n_step))
    for n in range(n_var):
        for i in range(n_inst):
            for k in range(n_step):
                dx, dy = pred[n, i, k] - gt[n, i, k]
                sq_instant[n, i] += (dx * dx + dy * dy) / n_step
                sq_true_gt[n, i, k] = ((gt[n, i, k] - fut[n, i, k]) ** 2).sum()
                sq_true_sensor[n, i, k] = ((pred[n, i, k] - fut[n, i, k]) ** 2).sum()
    assert sq_instant.max() > 0.0  # the sensor at 30 m misses something
    np.testing.assert_allclose(h.sq_instant, sq_instant, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(h.sq_true_gt, sq_true_gt, rtol=1e-12)
    np.testing.assert_allclose(h.sq_true_sensor, sq_true_sensor, rtol=1e-12)
    e2 = sq_instant.mean() if weight[1] else sq_instant[0].mean()
    assert abs(sq_instant[0].mean() - sq_instant.mean()) > 1e-3 * e2  # the weights matter
    np.testing.assert_allclose(h.e2, e2, rtol=1e-10)
    np.testing.assert_allclose(h.objective, e2, rtol=1e-10)
    # sq_error [N, F]: the mean over instants, step by step
    per_step = ((pred - gt) ** 2).sum(axis=-1).mean(axis=1)
    np.testing.assert_allclose(h.sq_error, per_step, rtol=1e-10, atol=1e-12)
    assert float(E({"range_m": 30.0}, mode="hard")) == pytest.approx(np.sqrt(e2), rel=1e-10)
    # RMSE against the true future per scenario (toy variants: scenarios 0 and 1), over its
    # real variants only: a scenario whose one variant is padding reports 0, not NaN.
    assert list(np.asarray(E.data.scenario)) == [0, 1]
    for sq_true, rmse in ((sq_true_gt, h.rmse_gt), (sq_true_sensor, h.rmse_sensor)):
        np.testing.assert_allclose(rmse[0], np.sqrt(sq_true[0].mean(axis=0)), rtol=1e-12)
        np.testing.assert_allclose(rmse[1], np.sqrt(sq_true[1].mean(axis=0)) * weight[1], rtol=1e-12)


def test_point_names_the_values_in_order():
    E = _objective("eq12")
    assert E.names == ("range_m",)
    assert {k: float(v) for k, v in E.point(42.0).items()} == {"range_m": 42.0}
    assert {k: float(v) for k, v in E.point(jnp.array([7.0])).items()} == {"range_m": 7.0}


def test_e_at_a_temperature_is_the_root_of_e2_at_it():
    E = _objective("eq12")
    r = {"range_m": 30.0}
    cold, warm = float(E(r, tau=0.5)), float(E(r))
    assert cold == pytest.approx(float(E.e2(r, 0.5)) ** 0.5, rel=1e-12)
    assert warm == pytest.approx(float(E.e2(r, 1.0)) ** 0.5, rel=1e-12)
    assert abs(cold - warm) > 1e-6 * warm  # the temperature matters at the range's edge


def test_predictions_use_the_predictors_own_input_spec():
    """A predictor whose social grid is 3 cells long (not the CS-LSTM's 13) sees fewer
    neighbours: the objective's predictions are the predictor's on inputs built to its spec."""
    import dataclasses

    from diffsense.metrics import make_objective
    from diffsense.predictors import CSLSTM_SPEC
    from diffsense.tracks import build_inputs, flatten_instants, ground_truth_detections, prediction_frames
    from tests._toy_pipeline import ToyPredictor, ToySensor, toy_scenes

    jax.config.update("jax_enable_x64", True)
    spec = dataclasses.replace(CSLSTM_SPEC, grid_cells=3)
    predictor = ToyPredictor(jnp.asarray(0.5), spec=spec)
    scenes, scenario = toy_scenes(2)
    frames = prediction_frames(scenes.num_frames)[:4]
    E = make_objective(scenes, scenario, frames, ToySensor(), predictor, names=("range_m",))
    det = E.detections({"range_m": 1000.0}, "hard")

    def by_hand(s, truth=False):
        def one(n):
            scene = jax.tree.map(lambda a: a[n], scenes)
            seen = ground_truth_detections(scene) if truth else jax.tree.map(lambda a: a[n], det)
            return build_inputs(scene, seen, jnp.asarray(frames), "hold", s)

        return np.stack([np.asarray(predictor(flatten_instants(jax.tree.map(lambda a: a[None], one(n)))))
                         for n in range(2)])

    np.testing.assert_allclose(np.asarray(E._predict(det)), by_hand(spec), rtol=1e-12)
    assert not np.allclose(by_hand(spec), by_hand(CSLSTM_SPEC))  # the grid's length matters
    # the ground-truth-input predictions, made once when E is built, to the same spec
    np.testing.assert_allclose(np.asarray(E.data.gt_pred), by_hand(spec, truth=True), rtol=1e-12)
    assert not np.allclose(by_hand(spec, truth=True), by_hand(CSLSTM_SPEC, truth=True))


def test_sensor_detections_are_the_sensors_own_in_the_mode_and_weather_asked():
    """Each variant's detections are `sensor.detect` of its scene with its noise key, in the
    mode asked (the toy's hard mode gives 0/1, its soft mode a logistic) and in the variant's
    weather (a radar in 50 mm/h of rain loses its far echoes)."""
    from diffsense.metrics import make_objective
    from diffsense.sensors import Radar, Weather
    from diffsense.tracks import prediction_frames
    from tests._toy_pipeline import ToyPredictor, toy_scenes

    E = _objective("eq12")
    r = {"range_m": 30.0}
    for mode in ("hard", "soft"):
        p = np.asarray(E._sensor_detections(r, mode, 1.0).p_detect)
        for n in range(2):
            scene = jax.tree.map(lambda a: a[n], E.data.scenes)
            alone = E.sensor.detect(scene, r, E.data.noise_key[n], mode=mode)
            np.testing.assert_array_equal(p[n], np.asarray(alone.p_detect))
        assert np.all((p == 0.0) | (p == 1.0)) == (mode == "hard")

    scenes, scenario = toy_scenes(2)
    rain = Weather(rain_mm_h=50.0, fog_visibility_m=np.inf)
    wet = make_objective(scenes, scenario, prediction_frames(101)[:2], Radar.from_toml(),
                         ToyPredictor(jnp.asarray(0.01)), names=("range_m",), weather=rain)
    radar_r = {"range_m": 60.0}
    p = np.asarray(wet._sensor_detections(radar_r, "soft", 1.0).p_detect)
    for n in range(2):
        scene = jax.tree.map(lambda a: a[n], scenes)
        in_rain = wet.sensor.detect(scene, radar_r, wet.data.noise_key[n], weather=rain)
        clear = wet.sensor.detect(scene, radar_r, wet.data.noise_key[n])
        np.testing.assert_allclose(p[n], np.asarray(in_rain.p_detect), rtol=1e-12, atol=1e-300)
        assert np.max(np.abs(np.asarray(clear.p_detect) - p[n])) > 1e-3


@pytest.mark.parametrize("kind", ["relaxed-reference", "straight-through"])
def test_sq_error_of_the_drawn_estimators_is_split_by_variant_and_step(kind):
    """Under a random detection law the drawn estimators average each draw's [N, F] split over
    the draws (axis 0), keeping the split: its weighted mean is E^2, and it still grows with the
    horizon step and differs between the variants."""
    from tests.test_reference import radar_objective

    E = radar_objective(n=2, kind=kind, draws=3)
    assert E.estimator_kind == kind
    r = {"hfov_deg": 20.0}
    sq = np.asarray(eqx.filter_jit(lambda o: o.sq_error(r))(E))
    assert sq.shape == (2, 25)
    assert float(np.mean(sq)) == pytest.approx(float(eqx.filter_jit(lambda o: o.e2(r))(E)), rel=1e-10)
    assert np.all(sq[:, -1] > sq[:, 0]) and abs(sq[0, -1] - sq[1, -1]) > 1e-6 * sq[0, -1]


def test_detections_default_to_hard_and_the_target_window_spans_the_history():
    """`detections(r)` is the hard view; the target's window at an instant is its detections
    over the predictor's 3-s history: 16 points, 2 frames apart at 10 Hz, so the 31 frames up
    to and including the instant's."""
    from diffsense.scene import TARGET_INDEX

    E = _objective("eq12")
    r = {"range_m": 30.0}
    det = E.detections(r)
    np.testing.assert_array_equal(np.asarray(det.p_detect), np.asarray(E.detections(r, "hard").p_detect))
    p = np.asarray(E.detections(r, "soft").p_detect)  # distinct values frame by frame
    window = np.asarray(E._target_window(E.detections(r, "soft")))
    assert window.shape == (2, 4, 31)
    for n in range(2):
        for i, f in enumerate(E.frames):
            np.testing.assert_array_equal(window[n, i], p[n, f - 30: f + 1, TARGET_INDEX])


def test_hard_tracked_objective_counts_an_instant_seen_once_in_its_window():
    """The hard "tracked" J at r: an instant is tracked if its target was detected at least
    once in the history window (not only if detected throughout), recomputed from the hard
    evaluation's own detections and per-instant errors."""
    from diffsense.scene import TARGET_INDEX

    E = _objective("tracked")
    for range_m in (26.0, 30.0, 34.0):  # somewhere the target is seen only part of a window
        h = jax.tree.map(np.asarray, E.hard({"range_m": range_m}))
        seen_once = np.zeros((2, 4))
        seen_throughout = np.zeros((2, 4))
        for n in range(2):
            for i, f in enumerate(E.frames):
                window = h.p_detect[n, f - 30: f + 1, TARGET_INDEX]
                seen_once[n, i], seen_throughout[n, i] = window.max(), window.min()
        if np.array_equal(seen_once, seen_throughout):
            continue
        q = seen_once
        expected = (q * h.sq_instant).sum() / (1.0 + q.sum()) + PENALTY_M2 * (1.0 - q.mean())
        assert float(h.objective) == pytest.approx(expected, rel=1e-12)
        return
    pytest.fail("no range tried sees the target only part of a window")


def test_hard_detection_at_an_even_chance_is_a_detection():
    """The hard view decides each detection by its probability's median, p >= 1/2: a plug-in
    sensor that detects every car with probability exactly 1/2 detects them all."""
    from diffsense.sensors._datatypes import Detections
    from tests._toy_pipeline import ToySensor

    class CoinSensor(ToySensor):
        def _detect(self, scene, r, noise, mode, temperature, weather):
            det = super()._detect(scene, r, noise, mode, temperature, weather)
            p = jnp.full_like(det.p_detect, 0.5).at[..., 0].set(1.0)
            return Detections(p_detect=p, x_m=det.x_m, y_m=det.y_m)

    E = _objective("eq12")
    coin = eqx.tree_at(lambda o: o.sensor, E, CoinSensor())
    assert np.all(np.asarray(coin.detections({"range_m": 30.0}, "hard").p_detect) == 1.0)


def _float32(scenes):
    return jax.tree.map(lambda a: a.astype(jnp.float32) if jnp.issubdtype(a.dtype, jnp.floating) else a, scenes)


def test_float32_objective_stays_float32_in_hard_mode_and_under_float64_weather():
    """With x64 on, a float32 objective's hard detections and hard E stay float32, and so does
    its value when its weather is moved by a float64 amount (as the ODD sensitivity moves it):
    the sensor sees the weather in the objective's dtype."""
    from diffsense import config as cfg
    from diffsense import sensors as sensor
    from diffsense.metrics import make_objective
    from diffsense.sensors._laws import RadarDetection
    from diffsense.tracks import prediction_frames
    from tests._toy_pipeline import TOY_GAIN, ToyPredictor, ToySensor, toy_scenes

    jax.config.update("jax_enable_x64", True)
    scenes, scenario = toy_scenes(1)
    scenes = _float32(scenes)
    predictor = ToyPredictor(jnp.asarray(TOY_GAIN, jnp.float32))
    frames = prediction_frames(scenes.num_frames)[:1]
    toy = make_objective(scenes, scenario, frames, ToySensor(), predictor, names=("range_m",))
    # compiled once each (op by op, these ran as some hundreds of small programs)
    assert eqx.filter_jit(lambda o: o.detections({"range_m": 30.0}).p_detect)(toy).dtype == jnp.float32
    assert eqx.filter_jit(lambda o: o({"range_m": 30.0}, mode="hard"))(toy).dtype == jnp.float32

    radar = sensor.Radar(cfg.replace(sensor.load_config("radar"), detection=RadarDetection(law="swerling1")))
    E = make_objective(scenes, scenario, frames, radar, predictor, names=("hfov_deg",),
                       estimator=EstimatorConfig(kind="mean-field"), shard=False)

    def wetter(shift_mm_h):
        moved = eqx.tree_at(lambda o: o.weather.rain_mm_h, E, E.weather.rain_mm_h + shift_mm_h)
        return moved.e2({"hfov_deg": 20.0})

    value, grad = jax.jit(jax.value_and_grad(wetter))(jnp.float64(5.0))
    assert value.dtype == jnp.float32
    assert np.isfinite(float(grad)) and float(grad) != 0.0  # the rain reaches the radar

    # A plug-in sensor that reads the rain rate as it is (the shipped ones cast it themselves)
    # is handed it in the objective's dtype.
    seen = []

    class RainyToy(ToySensor):
        def _detect(self, scene, r, noise, mode, temperature, weather):
            seen.append(jnp.asarray(weather.rain_mm_h).dtype)
            return super()._detect(scene, r, noise, mode, temperature, weather)

    rainy = eqx.tree_at(lambda o: (o.sensor, o.weather.rain_mm_h), toy,
                        (RainyToy(), jnp.asarray(toy.weather.rain_mm_h, jnp.float64) + 1.0))
    rainy.e2({"range_m": 30.0})
    assert seen == [jnp.dtype(jnp.float32)]
