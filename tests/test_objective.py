"""`Objective`'s public contract on the toy sensor and predictor: E(r) in its three modes, its
gradient against float64 central differences, jit and vmap of the module, its detections, its
split by variant and step, and what it refuses."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import tracks
from diffsense.metrics import EstimatorConfig, make_objective
from diffsense.predictors import CSLSTM_SPEC
from diffsense.runtime import InputError
from diffsense.sensors import Detections, Radar, Weather
from tests import _toy_pipeline as toy
from tests._toy_pipeline import ToyPredictor, ToySensor, toy_objective, toy_scenes

R = "range_m"


@pytest.fixture(scope="module")
def objective():
    return toy_objective(fill="hold")


# r and tau go in as arrays: `eqx.filter_jit` bakes a Python float into the program.
_e2 = eqx.filter_jit(lambda o, r, t: o.e2({R: r}, t))
_hard = eqx.filter_jit(lambda o, r: o({R: r}, mode="hard"))
_hard_evaluation = eqx.filter_jit(lambda o, r: o.hard({R: r}))
_value_and_grad = eqx.filter_jit(lambda o, r: jax.value_and_grad(lambda x: o.e2({R: x}))(r))


def e2(obj, r, tau=1.0):
    return float(_e2(obj, jnp.asarray(r), jnp.asarray(tau)))


def hard(obj, r):
    return float(_hard(obj, jnp.asarray(r)))


def test_blind_sensor_is_penalised(objective):
    blind, seeing = hard(objective, 0.5), hard(objective, 150.0)
    assert np.isfinite(blind) and blind > seeing > 0.0


def test_gradient_matches_float64_central_differences(objective):
    for r in (30.0, 55.0):
        value, grad = _value_and_grad(objective, jnp.asarray(r))
        h = 1e-4
        fd = (e2(objective, r + h) - e2(objective, r - h)) / (2 * h)
        np.testing.assert_allclose(float(grad), fd, rtol=1e-5, atol=1e-9)
        np.testing.assert_allclose(float(value), e2(objective, r), rtol=1e-12)


def test_e_is_the_root_of_e2_at_its_temperature_with_a_gradient_like_r(objective):
    value, grad = eqx.filter_jit(lambda o, r: jax.value_and_grad(o)(r))(objective, {R: 40.0})
    assert set(grad) == {R}
    np.testing.assert_allclose(float(value) ** 2, e2(objective, 40.0), rtol=1e-12)
    g_e2 = eqx.filter_jit(lambda o, x: jax.grad(lambda x: o.e2({R: x}))(x))(objective, 40.0)
    np.testing.assert_allclose(float(grad[R]), float(g_e2) / (2 * float(value)), rtol=1e-12)
    cold = float(eqx.filter_jit(lambda o: o({R: 30.0}, tau=0.5))(objective))
    assert cold == pytest.approx(e2(objective, 30.0, 0.5) ** 0.5, rel=1e-12)
    assert abs(cold - e2(objective, 30.0) ** 0.5) > 1e-6 * cold  # the temperature matters at the edge


def test_jit_and_vmap_of_the_module(objective):
    r = jnp.array([20.0, 40.0, 80.0])
    batch = jax.jit(jax.vmap(objective))({R: r})
    each = [float(jax.jit(objective)({R: x})) for x in r]
    np.testing.assert_allclose(np.asarray(batch), each, rtol=1e-12)
    np.testing.assert_allclose(float(objective({R: 40.0})), each[1], rtol=1e-12)  # op by op
    by_mode = jax.jit(objective, static_argnames="mode")({R: 40.0}, mode="hard")
    np.testing.assert_allclose(float(by_mode), hard(objective, 40.0), rtol=1e-12)


def test_refusals_name_the_culprit(objective):
    with pytest.raises(InputError, match="hfov_deg"):
        objective({"hfov_deg": 3.0})
    with pytest.raises(ValueError, match="median"):
        objective({R: 3.0}, mode="median")


def test_soft_tends_to_hard_as_temperature_shrinks(objective):
    hard_e2 = hard(objective, 47.3) ** 2
    gaps = [abs(e2(objective, 47.3, tau) - hard_e2) for tau in (1.0, 0.1, 1e-3)]
    assert gaps[-1] < 1e-6 * max(hard_e2, 1.0) and gaps[-1] <= gaps[0]


def test_same_key_same_objective(objective):
    assert e2(toy_objective(fill="hold"), 40.0) == e2(objective, 40.0)
    assert e2(toy_objective(fill="hold", key=jax.random.PRNGKey(7)), 40.0) != e2(objective, 40.0)


def test_objective_is_hashed_and_compared_by_identity():
    a, b = toy_objective(n=1, instants=2), toy_objective(n=1, instants=2)
    assert a == a and a != b and hash(a) != hash(b) and len({a: 0, b: 1}) == 2


def test_point_names_the_values_in_order(objective):
    assert objective.names == (R,)
    assert {k: float(v) for k, v in objective.point(42.0).items()} == {R: 42.0}
    assert {k: float(v) for k, v in objective.point(jnp.array([7.0])).items()} == {R: 7.0}


def test_detections_are_the_sensors_own_in_the_mode_temperature_and_weather_asked():
    """Each variant's detections are `sensor.detect` of its scene with its noise key: "hard" by
    default (the toy's 0/1), "soft" at temperature multiplier 1 unless told, in the variant's
    weather (a radar in 50 mm/h of rain loses its far echoes)."""
    E = toy_objective(n=2, instants=4)
    r = {R: 30.0}
    np.testing.assert_array_equal(np.asarray(E.detections(r).p_detect), np.asarray(E.detections(r, "hard").p_detect))
    for mode in ("hard", "soft"):
        p = np.asarray(E.detections(r, mode).p_detect)
        for n in range(2):
            scene = jax.tree.map(lambda a: a[n], E.data.scenes)
            alone = E.sensor.detect(scene, r, E.data.noise_key[n], mode=mode)
            np.testing.assert_array_equal(p[n], np.asarray(alone.p_detect))
        assert np.all((p == 0.0) | (p == 1.0)) == (mode == "hard")
    soft = np.asarray(E.detections(r, "soft").p_detect)
    np.testing.assert_array_equal(soft, np.asarray(E.detections(r, "soft", 1.0).p_detect))
    edge = (soft > 0.01) & (soft < 0.99)  # a car on the range gate's soft edge
    assert edge.any() and not np.allclose(soft[edge], np.asarray(E.detections(r, "soft", 2.0).p_detect)[edge])

    scenes, scenario = toy_scenes(2)
    rain = Weather(rain_mm_h=50.0, fog_visibility_m=np.inf)
    wet = make_objective(scenes, scenario, tracks.prediction_frames(101)[:2], Radar.from_toml(),
                         ToyPredictor(jnp.asarray(0.01)), names=(R,), weather=rain)
    radar_r = {R: 60.0}
    p = np.asarray(wet.detections(radar_r, "soft").p_detect)
    for n in range(2):
        scene = jax.tree.map(lambda a: a[n], scenes)
        in_rain = wet.sensor.detect(scene, radar_r, wet.data.noise_key[n], weather=rain)
        clear = wet.sensor.detect(scene, radar_r, wet.data.noise_key[n])
        np.testing.assert_allclose(p[n], np.asarray(in_rain.p_detect), rtol=1e-12, atol=1e-300)
        assert np.max(np.abs(np.asarray(clear.p_detect) - p[n])) > 1e-3


def test_hard_detection_at_an_even_chance_is_a_detection():
    """The hard view decides each detection by its probability's median, p >= 1/2: a plug-in
    sensor that detects every car with probability exactly 1/2 detects them all."""

    class CoinSensor(ToySensor):
        def _detect(self, scene, r, noise, mode, temperature, weather):
            det = super()._detect(scene, r, noise, mode, temperature, weather)
            return Detections(p_detect=jnp.full_like(det.p_detect, 0.5), x_m=det.x_m, y_m=det.y_m)

    coin = eqx.tree_at(lambda o: o.sensor, toy_objective(n=1, instants=2), CoinSensor())
    assert np.all(np.asarray(coin.detections({R: 30.0}, "hard").p_detect) == 1.0)


def test_hard_evaluation_carries_its_detections_and_grows_with_the_horizon(objective):
    near, far = _hard_evaluation(objective, jnp.asarray(20.0)), _hard_evaluation(objective, jnp.asarray(150.0))
    det = eqx.filter_jit(lambda o: o.detections({R: 20.0}, "hard").p_detect)(objective)
    np.testing.assert_array_equal(np.asarray(near.p_detect), np.asarray(det))
    assert set(np.unique(np.asarray(near.p_detect))) <= {0.0, 1.0}
    assert float(np.sum(far.p_detect)) > float(np.sum(near.p_detect))
    assert near.rmse_gt.shape == near.rmse_sensor.shape == (2, 25)
    assert np.all(np.isfinite(near.rmse_gt)) and near.rmse_sensor[:, -1].mean() > near.rmse_sensor[:, 0].mean()


def test_predictions_use_the_predictors_own_input_spec():
    """A predictor whose social grid is 3 cells long (not the CS-LSTM's 13) sees fewer
    neighbours: the ground-truth-input and the sensor-input ones the hard evaluation
    scores, are the predictor's on inputs built to its spec."""
    spec = dataclasses.replace(CSLSTM_SPEC, grid_cells=3)
    predictor = ToyPredictor(jnp.asarray(0.5), spec=spec)
    scenes, scenario = toy_scenes(2)
    frames = tracks.prediction_frames(scenes.num_frames)[:4]
    E = make_objective(scenes, scenario, frames, ToySensor(), predictor, names=(R,))
    det = E.detections({R: 1000.0}, "hard")

    def by_hand(s, truth=False):
        def one(n):
            scene = jax.tree.map(lambda a: a[n], scenes)
            seen = tracks.ground_truth_detections(scene) if truth else jax.tree.map(lambda a: a[n], det)
            return tracks.build_inputs(scene, seen, jnp.asarray(frames), "hold", s)

        return np.stack([np.asarray(predictor(tracks.flatten_instants(jax.tree.map(lambda a: a[None], one(n)))))
                         for n in range(2)])

    sq_true = np.sum((by_hand(spec) - np.asarray(E.data.true_fut)) ** 2, axis=-1)
    np.testing.assert_allclose(np.asarray(E.hard({R: 1000.0}).sq_true_sensor), sq_true, rtol=1e-12)
    assert not np.allclose(by_hand(spec), by_hand(CSLSTM_SPEC))  # the grid's length matters
    np.testing.assert_allclose(np.asarray(E.data.gt_pred), by_hand(spec, truth=True), rtol=1e-12)
    assert not np.allclose(by_hand(spec, truth=True), by_hand(CSLSTM_SPEC, truth=True))


def test_monte_carlo_estimator_is_deterministic_and_differentiable():
    mc = toy_objective(n=2, instants=4, fill="interp", key=jax.random.PRNGKey(1),
                       estimator=EstimatorConfig(kind="mc", samples=3, relax_temperature=0.3))
    v1, g1 = _value_and_grad(mc, jnp.asarray(40.0))
    v2, g2 = eqx.filter_jit(jax.value_and_grad(lambda r, m: m.e2({R: r})))(40.0, mc)
    assert (float(v1), float(g1)) == (float(v2), float(g2))
    h = 1e-4
    np.testing.assert_allclose(float(g1), (e2(mc, 40.0 + h) - e2(mc, 40.0 - h)) / (2 * h), rtol=1e-5, atol=1e-9)


def test_monte_carlo_memory_does_not_grow_with_samples():
    # Each sample is rematerialised in the backward pass: without it the compiled value-and-gradient
    # keeps every sample's activations (here 10x the K = 2 scratch memory at K = 32).
    scratch = {}
    for k in (2, 32):
        mc = toy_objective(n=2, instants=4, fill="interp",
                           estimator=EstimatorConfig(kind="mc", samples=k, relax_temperature=0.3))
        compiled = jax.jit(jax.value_and_grad(lambda r, m: m.e2({R: r}))).lower(40.0, mc).compile()
        scratch[k] = compiled.memory_analysis().temp_size_in_bytes
    assert scratch[32] < 2 * scratch[2], scratch


@pytest.mark.parametrize("kind", ["mean-field", "mc"])
def test_sq_error_by_variant_and_step_adds_up_to_the_objective(kind):
    obj = toy_objective(n=2, instants=4, fill="interp",
                        estimator=EstimatorConfig(kind=kind, samples=3, relax_temperature=0.3))
    r, tau = 40.0, 1.0
    sq = eqx.filter_jit(lambda o: o.sq_error({R: r}, tau))(obj)
    assert sq.shape == (2, 25) and np.all(np.isfinite(sq)) and np.all(sq >= 0.0)
    # with no tau, the documented temperatures (multiplier 1)
    np.testing.assert_array_equal(np.asarray(eqx.filter_jit(lambda o: o.sq_error({R: r}))(obj)), np.asarray(sq))

    def weighted(r_, w, o):
        return jnp.sum(w * o.sq_error({R: r_}, tau)) / (jnp.sum(o.data.weight) * 25)

    w = jnp.broadcast_to(obj.data.weight[:, None], sq.shape)
    value, grad = _value_and_grad(obj, jnp.asarray(r))
    np.testing.assert_allclose(float(eqx.filter_jit(weighted)(r, w, obj)), float(value), rtol=1e-12)
    # d/dw of dE^2/dr: each (variant, step)'s share of the gradient; the shares add up to it.
    shares = eqx.filter_jit(jax.grad(jax.grad(weighted, argnums=0), argnums=1))(r, w, obj)
    np.testing.assert_allclose(float(jnp.sum(shares * w)), float(grad), rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("kind", ["relaxed-reference", "straight-through"])
def test_sq_error_of_the_drawn_estimators_is_split_by_variant_and_step(kind):
    """Under a random detection law the drawn estimators average each draw's [N, F] split over
    the draws, keeping the split: its mean is E^2, it grows with the horizon step and differs
    between the variants."""
    E = toy.radar_objective(n=2, kind=kind, draws=3)
    assert E.estimator_kind == kind
    r = {"hfov_deg": 20.0}
    sq = np.asarray(eqx.filter_jit(lambda o: o.sq_error(r))(E))
    assert sq.shape == (2, 25)
    assert float(np.mean(sq)) == pytest.approx(float(eqx.filter_jit(lambda o: o.e2(r))(E)), rel=1e-10)
    assert np.all(sq[:, -1] > sq[:, 0]) and abs(sq[0, -1] - sq[1, -1]) > 1e-6 * sq[0, -1]

