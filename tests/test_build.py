"""Building E(r) (`diffsense.metrics.make_objective`) and the scene batches behind it
(`simulate_scenes`, `speed_shifted_scenes`, `recorded_scenes`, `with_scenes`, `pad_vehicles`):
refusals, defaults, the truth rebuilt from other scenes, padding, and dtypes.

The toy scenes drive straight along x at constant speed (tests/_synthetic.py), so the target's
true future along s is its speed times the time ahead: at the predictor's j-th point,
(j + 1) * frames_per_point * 0.1 s.
"""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense import config as cfg
from diffsense import metrics, scene
from diffsense.metrics import EstimatorConfig
from diffsense.predictors import CSLSTM_SPEC
from diffsense.runtime import InputError
from diffsense.sensors import Camera, Radar, Suite, Weather
from diffsense.tracks import prediction_frames
from tests import _toy_pipeline as toy
from tests._recorded_files import write_highd
from tests._synthetic import straight_scene
from tests._toy_pipeline import ToySensor, float32, toy_scenes

SC01 = Path(__file__).resolve().parents[1] / "configs" / "scenarios" / "sc01.toml"
REACH = dict(spec=CSLSTM_SPEC, sensors=(ToySensor(),))


def _make(n: int = 2, scenes=None, sensor=None, predictor=None, instants=2, **kwargs):
    if scenes is None:
        scenes, scenario = toy_scenes(n)
    else:
        scenario = np.arange(scenes.x_m.shape[0]) % 2
    kwargs.setdefault("names", ("range_m",))
    predictor = toy.ToyPredictor(jnp.asarray(toy.TOY_GAIN, scenes.x_m.dtype)) if predictor is None else predictor
    return metrics.make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:instants],
                          ToySensor() if sensor is None else sensor, predictor, **kwargs)


def test_refusals_name_the_culprit():
    with pytest.raises(InputError, match="'eq13'"):
        _make(question="eq13")
    for penalty in (-1.0, -1e-12, float("nan"), float("inf")):
        with pytest.raises(InputError, match="miss_penalty_m2"):
            _make(question="tracked", miss_penalty_m2=penalty)
    with pytest.raises(InputError, match="hfov_deg"):
        _make(names=("range_m", "hfov_deg"))


def test_defaults_and_what_is_kept():
    E = _make(n=3)  # toy scenarios 0, 1, 0
    assert E.scenario_names == ("scenario0", "scenario1")
    assert E.names == ("range_m",) and E.fill == "hold" and E.question == "eq12"
    assert E.miss_penalty_m2 == 100.0  # a 10 m RMS error
    assert E.frames == tuple(int(f) for f in prediction_frames(101)[:2]) and all(type(f) is int for f in E.frames)
    np.testing.assert_array_equal(np.asarray(E.data.weight), [1.0, 1.0, 1.0])
    np.testing.assert_array_equal(np.asarray(E.data.scenario), [0, 1, 0])
    keys = lambda o: np.asarray(jax.random.key_data(o.data.noise_key))
    np.testing.assert_array_equal(keys(E), keys(_make(n=3, key=jax.random.PRNGKey(0))))  # key 0 by default
    assert not np.array_equal(keys(E), keys(_make(n=3, key=jax.random.PRNGKey(1))))
    assert len({tuple(k) for k in keys(E)}) == 3  # one key per variant
    zero = _make(question="tracked", miss_penalty_m2=0)  # no price for a miss is allowed
    assert zero.question == "tracked" and zero.miss_penalty_m2 == 0.0 and isinstance(zero.miss_penalty_m2, float)
    # Monte-Carlo uniforms only for the Monte-Carlo estimator, one set per variant, inside (0, 1)
    u = np.asarray(_make(n=3, estimator=EstimatorConfig(kind="mc", samples=3)).data.mc_uniform)
    assert u.shape == (3, 3, 101, 4) and u.dtype == np.float64
    assert 0.0 < u.min() and u.max() < 1.0 and not np.array_equal(u[0], u[1])
    assert np.asarray(E.data.mc_uniform).shape == (3, 0, 101, 4)
    # scalar weather is every variant's, in the scenes' dtype
    wet = _make(n=3, weather=Weather(rain_mm_h=4.0, fog_visibility_m=300.0))
    np.testing.assert_array_equal(np.asarray(wet.weather.rain_mm_h), [4.0, 4.0, 4.0])
    np.testing.assert_array_equal(np.asarray(wet.weather.fog_visibility_m), [300.0] * 3)
    assert wet.weather.rain_mm_h.dtype == jnp.float64


def _future_s(E, speeds_mps):
    """The target's true future along s [n, F] for scenes whose target drives at `speeds_mps`."""
    step_s = E.spec.frames_per_point(0.1) * 0.1
    return np.asarray(speeds_mps)[:, None] * step_s * np.arange(1, E.data.true_fut.shape[2] + 1)[None, :]


@pytest.fixture(scope="module")
def objective():
    return toy.toy_objective(n=3, instants=2)


def test_true_future_is_the_targets_speed_times_the_time_ahead(objective):
    fut = np.asarray(objective.data.true_fut)  # [n, I, F, 2]
    for i in range(fut.shape[1]):
        np.testing.assert_allclose(fut[:, i, :, 0], _future_s(objective, [24.0, 25.0, 26.0]), atol=1e-9)


def test_with_scenes_rebuilds_the_truth_from_the_new_scenes(objective):
    # the same cars, every one 3 m/s faster: the target's future along s grows by 3 m/s
    faster = [straight_scene(s0_m=[0.0, 25.0 + 5 * k, 45.0 + 7 * k, 80.0 - 3 * k], lane=[1, 2, 2, 1],
                             speed_mps=[28.0, 27.0 + k, 27.5, 28.5], lane_change=(1, 3.0 + k, 4.0, 1))
              for k in range(3)]
    moved = metrics.with_scenes(objective, jax.tree.map(lambda *a: jnp.stack(a), *faster))
    fut = np.asarray(moved.data.true_fut)
    np.testing.assert_allclose(fut[:, 0, :, 0], _future_s(objective, [27.0, 28.0, 29.0]), atol=1e-9)
    np.testing.assert_allclose(fut[..., 1], np.asarray(objective.data.true_fut)[..., 1], atol=1e-9)
    assert moved.data.gt_pred.shape == objective.data.gt_pred.shape
    assert not np.allclose(np.asarray(moved.data.gt_pred), np.asarray(objective.data.gt_pred))
    np.testing.assert_array_equal(np.asarray(moved.data.scenes.speed_mps[:, 0, scene.TARGET_INDEX]), [27, 28, 29])
    # fewer scenes than rows (padding, as sharding adds): the last one repeated
    for first in (2, 1):
        fewer = metrics.with_scenes(objective, jax.tree.map(lambda a: a[:first], objective.data.scenes))
        s, fut = np.asarray(fewer.data.scenes.s_m), np.asarray(fewer.data.true_fut)
        assert s.shape[0] == 3
        for row in range(first, 3):
            np.testing.assert_array_equal(s[row], np.asarray(objective.data.scenes.s_m)[first - 1])
            np.testing.assert_array_equal(fut[row], np.asarray(objective.data.true_fut)[first - 1])


def test_pad_vehicles_adds_absent_background_cars_far_behind_the_ego():
    """Padding adds the scene package's absent vehicles: present False, a car in the background
    role, the ego's size, 1 km behind the ego; the real vehicles and the frame period (0.04 s
    here, not the 0.1 s default) are kept."""
    cars = straight_scene(s0_m=[0.0, 20.0, 40.0], lane=[1, 1, 2], speed_mps=[25.0, 24.0, 26.0], num_frames=5,
                           dt_s=0.04)
    cars = dataclasses.replace(cars, length_m=jnp.asarray([5.0, 4.5, 4.0]), width_m=jnp.asarray([2.0, 1.8, 1.7]),
                                kind=jnp.asarray([2, 0, 1]), role=jnp.asarray([0, 1, 2]))
    padded = metrics.pad_vehicles(cars, 5)
    assert padded.num_vehicles == 5 and padded.dt_s == 0.04
    assert np.asarray(padded.present).tolist() == [True, True, True, False, False]
    ego_s = 25.0 * 0.04 * np.arange(5)
    for v in (3, 4):
        assert int(padded.role[v]) == scene.BACKGROUND and int(padded.kind[v]) == scene.CAR
        assert (float(padded.length_m[v]), float(padded.width_m[v])) == (5.0, 2.0)  # the ego's
        np.testing.assert_allclose(np.asarray(padded.s_m[:, v]), ego_s - 1000.0, atol=1e-9)
        np.testing.assert_allclose(np.asarray(padded.x_m[:, v]), ego_s - 1000.0, atol=1e-9)  # the road runs along +x
    for name in ("s_m", "x_m", "y_m", "speed_mps", "lane", "present", "length_m", "kind", "role"):
        np.testing.assert_array_equal(np.asarray(getattr(padded, name))[..., :3], np.asarray(getattr(cars, name)))
    assert metrics.pad_vehicles(cars, 3) is cars


def _same_scenes(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_simulated_scenes_are_the_vehicles_relevant_at_every_stride_frames(tmp_path):
    """`metrics.simulate_scenes` is `metrics.speed_shifted_scenes(...).base`: each scenario simulated with every
    setting asked (each away from its default here) and reduced to the vehicles relevant at its
    prediction instants, every `stride_frames`; the re-simulation adds its offset to the base's."""
    near = tmp_path / "sc01_near.toml"  # the background 10 m behind the ego, where it is kept
    near.write_text(SC01.read_text().replace('name = "sc01"', 'name = "sc01_near"').replace("gap_m = 150.0", "gap_m = 10.0"))
    key = jax.random.key(3)
    asked = dict(stride_frames=400, background_vehicles=6, dtype=jnp.float32, speed_offset_kmh=6.0)
    scenes, index, names, weather = metrics.simulate_scenes((str(near),), 1, key, **REACH, **asked)
    shifted, index2, names2, weather2 = metrics.speed_shifted_scenes((str(near),), 1, key, **REACH, **asked)
    config = scene.load_scenario(str(near))
    config = cfg.replace(config, background=cfg.replace(config.background, count=6))
    sim = scene.simulate_scenario(config, 1, jax.random.fold_in(key, 0), dtype=jnp.float32, speed_offset_kmh=6.0)
    at = {stride: prediction_frames(sim.num_frames, stride, CSLSTM_SPEC, sim.dt_s) for stride in (4, 400)}
    reach = metrics.relevance_reach(**REACH)
    kept = {s: scene.select_vehicles(sim, *scene.relevant_selection(sim, f, **reach)) for s, f in at.items()}
    assert kept[4].num_vehicles != kept[400].num_vehicles  # one instant (stride 400) keeps fewer cars
    _same_scenes(scenes, kept[400])
    _same_scenes(scenes, shifted.base)
    _same_scenes(shifted(0.0), shifted.base)  # re-simulated in the dtype asked
    slower, _, _, _ = metrics.simulate_scenes((str(near),), 1, key, **REACH, **dict(asked, speed_offset_kmh=4.0))
    _same_scenes(shifted(-2.0), slower)
    assert names == names2 == ("sc01_near",) and list(index) == list(index2) == [0]
    _same_scenes(weather, weather2)
    # the defaults: stride 4 (a Problem's), the scenario's own background (none), float64, no offset
    default, _, _, _ = metrics.simulate_scenes((str(near),), 1, key, **REACH)
    explicit, _, _, _ = metrics.speed_shifted_scenes((str(near),), 1, key, **REACH, stride_frames=4, background_vehicles=0,
                                             dtype=jnp.float64, speed_offset_kmh=0.0)
    _same_scenes(default, explicit.base)
    assert default.s_m.dtype == jnp.float64 and default.num_vehicles == 5
    own, _, _, _ = metrics.speed_shifted_scenes((str(near),), 1, key, **REACH)
    assert own.base_offset_kmh == 0.0 and own.dtype == jnp.float64 and own.configs == explicit.configs
    _same_scenes(own.base, explicit.base)
    stride = inspect.signature(ds.Problem).parameters["prediction_stride_frames"].default
    assert stride == 4 and all(inspect.signature(fn).parameters["stride_frames"].default == stride
                               for fn in (metrics.recorded_scenes, metrics.simulate_scenes, metrics.speed_shifted_scenes))


def test_simulated_scenarios_are_pooled_scenario_major_with_their_weather_and_background(tmp_path):
    """Variants of each scenario in turn (variant 0 the scenario as written, whatever the key),
    each with its scenario TOML's weather (a copy of sc01 in 2 mm/h of rain and 300 m of fog,
    beside sc01: clear), and the background count asked (sc01 ships none)."""
    fog = tmp_path / "sc01_fog.toml"
    fog.write_text(SC01.read_text().replace('name = "sc01"', 'name = "sc01_fog"')
                   + "\n[weather]\nrain_mm_h = 2.0\nfog_visibility_m = 300.0\n")
    shifted, index, names, weather = metrics.speed_shifted_scenes((str(fog), "sc01"), 2, jax.random.key(0), **REACH,
                                                          stride_frames=10, background_vehicles=3)
    assert names == ("sc01_fog", "sc01") and list(index) == [0, 0, 1, 1]
    np.testing.assert_array_equal(np.asarray(weather.rain_mm_h), [2.0, 2.0, 0.0, 0.0])
    np.testing.assert_array_equal(np.asarray(weather.fog_visibility_m), [300.0, 300.0, np.inf, np.inf])
    assert [c.background.count for c in shifted.configs] == [3, 3]
    reach = dict(spec=CSLSTM_SPEC, sensors=[Radar.from_toml()], stride_frames=20)
    scenes, index, names, weather = metrics.simulate_scenes(["sc01", "sc02"], 2, jax.random.PRNGKey(0), **reach)
    assert index.tolist() == [0, 0, 1, 1] and names == ("sc01", "sc02") and np.shape(weather.rain_mm_h) == (4,)
    alone, _, _, _ = metrics.simulate_scenes(["sc02"], 2, jax.random.PRNGKey(5), **reach)
    np.testing.assert_allclose(scenes.x_m[2, :, : alone.num_vehicles], alone.x_m[0])
    assert not np.allclose(scenes.x_m[0, :, :2], scenes.x_m[2, :, :2])


def test_recorded_scenes_are_each_cut_reduced_at_every_stride_frames(tmp_path):
    """One clear scenario of one variant per cut, named after the whole file name (a colon in it
    too), each cut reduced to the vehicles relevant at its instants every `stride_frames`, in
    the dtype it was cut in."""
    path = write_highd(tmp_path, stem="a:01")
    source = f"highd:{path}"
    for stride, dtype in ((4, jnp.float64), (40, jnp.float32)):
        cut = scene.cut_recorded(source, window_s=20.0, dtype=dtype)
        scenes, index, names, weather = metrics.recorded_scenes(cut, **REACH, stride_frames=stride)
        assert scenes.s_m.dtype == dtype
        reach = metrics.relevance_reach(**REACH)
        cuts = [scene.relevant_vehicles(c, prediction_frames(c.num_frames, stride, CSLSTM_SPEC, c.dt_s), **reach)
                for c in scene.load_recorded(source, window_s=20.0, dtype=dtype)]
        width = max(c.num_vehicles for c in cuts)
        _same_scenes(scenes, jax.tree.map(lambda *a: jnp.stack(a), *[metrics.pad_vehicles(c, width) for c in cuts]))
        n = len(cuts)
        assert list(index) == list(range(n)) and names == tuple(f"{path.name}#{i}" for i in range(n))
        np.testing.assert_array_equal(weather.rain_mm_h, np.zeros(n))
        np.testing.assert_array_equal(weather.fog_visibility_m, np.full(n, np.inf))
        assert np.asarray(scenes.present)[:, :2].all()  # the ego and the target of every cut


def test_float32_scenes_make_a_float32_objective():
    """With x64 on, float32 scenes keep every float of the objective in float32 (the weights, the
    true future, the Monte-Carlo uniforms, the weather, r and E, hard detections and the coverage)
    and the scenario ids int32; the truth rebuilt from other scenes too."""
    scenes = float32(toy_scenes(2)[0])
    E = _make(scenes=scenes, estimator=EstimatorConfig(kind="mc", samples=2), instants=1)
    assert E.data.scenario.dtype == jnp.int32
    for name in ("weight", "true_fut", "mc_uniform", "gt_pred"):
        assert getattr(E.data, name).dtype == jnp.float32, name
    assert {leaf.dtype for leaf in jax.tree.leaves(E.weather)} == {jnp.dtype(jnp.float32)}
    assert E({"range_m": 40.0}).dtype == jnp.float32  # r given as Python floats
    assert eqx.filter_jit(lambda o: o.detections({"range_m": 30.0}).p_detect)(E).dtype == jnp.float32
    hard = eqx.filter_jit(lambda o: o.hard({"range_m": 30.0}))(E)
    assert hard.objective.dtype == hard.coverage.dtype == jnp.float32
    moved = metrics.with_scenes(E, scenes)
    assert moved.data.gt_pred.dtype == moved.data.true_fut.dtype == jnp.float32
    np.testing.assert_array_equal(np.asarray(moved.data.true_fut), np.asarray(E.data.true_fut))
    # a plug-in sensor that reads the rain rate as it is (the shipped ones cast it) is handed it in
    # the objective's dtype, even when the weather is moved by a float64 amount
    seen = []

    class RainyToy(ToySensor):
        def _detect(self, scene, r, noise, mode, temperature, weather):
            seen.append(jnp.asarray(weather.rain_mm_h).dtype)
            return super()._detect(scene, r, noise, mode, temperature, weather)

    rainy = eqx.tree_at(lambda o: (o.sensor, o.weather.rain_mm_h), E,
                        (RainyToy(), jnp.asarray(E.weather.rain_mm_h, jnp.float64) + 1.0))
    rainy.e2({"range_m": 30.0})
    assert seen and set(seen) == {jnp.dtype(jnp.float32)}


@pytest.mark.parametrize("kind, sensor", [("relaxed-reference", toy.SWERLING), ("straight-through", toy.SWERLING),
                                          ("mean-field", toy.SWERLING), ("mc", Suite((toy.SWERLING, Camera.from_toml())))])
def test_float32_objective_stays_float32_under_a_random_law(kind, sensor):
    """The estimators under a random detection law keep float32 too: a float64 temperature (a
    solver's schedule under x64), the relaxation, the hard draws and a suite's Monte-Carlo draws
    are taken in the objective's dtype; the weather moved by a float64 amount reaches the radar."""
    name = "hfov_deg" if kind != "mc" else "radar.hfov_deg"
    E = _make(scenes=float32(toy_scenes(1)[0]), sensor=sensor, names=(name,), instants=1, shard=False,
              estimator=EstimatorConfig(kind=kind, reference_draws=2, samples=2))

    def e2(h, shift_mm_h):
        moved = eqx.tree_at(lambda o: o.weather.rain_mm_h, E, E.weather.rain_mm_h + shift_mm_h)
        return moved.e2({name: h}, jnp.float64(1.0))

    value, grad = jax.jit(jax.value_and_grad(e2, argnums=(0, 1)))(jnp.float32(20.0), jnp.float64(5.0))
    assert value.dtype == grad[0].dtype == jnp.float32
    if kind == "mean-field":
        assert np.isfinite(float(grad[1])) and float(grad[1]) != 0.0  # the rain reaches the radar
