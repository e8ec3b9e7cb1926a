"""`diffsense/metrics/_build.py` pinned by hand: `make_objective`'s refusals and defaults, the
settings the scene builders forward, padding, and dtypes (each test written for surviving
mutants of its mutation run, docs/mutation.md)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.metrics import EstimatorConfig, make_objective
from diffsense.sensors import Weather
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, ToySensor, toy_scenes


def _make(n: int = 2, **kwargs):
    jax.config.update("jax_enable_x64", True)
    scenes, scenario = toy_scenes(n)
    frames = prediction_frames(scenes.num_frames)[:2]
    kwargs.setdefault("names", ("range_m",))
    return make_objective(scenes, scenario, frames, ToySensor(), ToyPredictor(jnp.asarray(TOY_GAIN)), **kwargs)


def test_unknown_question_is_refused_by_name():
    with pytest.raises(InputError, match=r"^unknown objective 'eq13' \(known: eq12, tracked\)$"):
        _make(question="eq13")


@pytest.mark.parametrize("penalty", [-1.0, -1e-12, float("nan"), float("inf")])
def test_miss_penalty_must_be_finite_and_not_negative(penalty):
    with pytest.raises(InputError, match=r"^miss_penalty_m2 must be a finite number >= 0, got "):
        _make(question="tracked", miss_penalty_m2=penalty)


def test_a_zero_miss_penalty_is_allowed_and_kept_as_a_float():
    assert _make(question="tracked").miss_penalty_m2 == 100.0  # the default: a 10 m RMS error
    E = _make(question="tracked", miss_penalty_m2=0)
    assert E.question == "tracked" and E.miss_penalty_m2 == 0.0 and isinstance(E.miss_penalty_m2, float)


def test_an_unknown_free_parameter_is_refused():
    with pytest.raises(InputError):
        _make(names=("range_m", "hfov_deg"))


def test_defaults_name_the_scenarios_by_index_and_fix_key_zero():
    E = _make(n=3)  # toy scenarios 0, 1, 0
    assert E.scenario_names == ("scenario0", "scenario1")
    assert E.names == ("range_m",) and E.fill == "hold" and E.question == "eq12"
    assert E.frames == tuple(int(f) for f in prediction_frames(101)[:2])
    assert all(type(f) is int for f in E.frames)
    same = _make(n=3, key=jax.random.PRNGKey(0))
    other = _make(n=3, key=jax.random.PRNGKey(1))
    keys = lambda o: np.asarray(jax.random.key_data(o.data.noise_key))  # noqa: E731
    np.testing.assert_array_equal(keys(E), keys(same))
    assert not np.array_equal(keys(E), keys(other))
    assert len({tuple(k) for k in keys(E)}) == 3  # one key per variant


def test_monte_carlo_uniforms_only_for_the_monte_carlo_estimator():
    mc = _make(n=3, estimator=EstimatorConfig(kind="mc", samples=3))
    u = np.asarray(mc.data.mc_uniform)
    assert u.shape == (3, 3, 101, 4) and u.dtype == np.float64
    assert 0.0 < u.min() and u.max() < 1.0 and not np.array_equal(u[0], u[1])  # per variant
    assert np.asarray(_make().data.mc_uniform).shape == (2, 0, 101, 4)


def test_scalar_weather_is_every_variants_in_the_scenes_dtype():
    E = _make(n=3, weather=Weather(rain_mm_h=4.0, fog_visibility_m=300.0))
    np.testing.assert_array_equal(np.asarray(E.weather.rain_mm_h), [4.0, 4.0, 4.0])
    np.testing.assert_array_equal(np.asarray(E.weather.fog_visibility_m), [300.0] * 3)
    assert E.weather.rain_mm_h.dtype == jnp.float64
    np.testing.assert_array_equal(np.asarray(E.data.weight), [1.0, 1.0, 1.0])
    np.testing.assert_array_equal(np.asarray(E.data.scenario), [0, 1, 0])


def test_padding_by_one_slot_adds_a_background_car_and_keeps_the_frame_period():
    """Pooling pads with the scene package's absent vehicles: present False, a car in the
    background role, the ego's size, 1 km behind the ego; the scene's frame period is kept
    (0.04 s here, not the 0.1 s default)."""
    import dataclasses

    from diffsense.metrics._build import _pad_vehicles
    from diffsense.scene import BACKGROUND, CAR
    from tests._synthetic import straight_scene

    jax.config.update("jax_enable_x64", True)
    scene = straight_scene(s0_m=[0.0, 20.0, 40.0], lane=[1, 1, 2], speed_mps=[25.0, 24.0, 26.0], num_frames=5,
                           dt_s=0.04)
    scene = dataclasses.replace(scene, length_m=jnp.asarray([5.0, 4.5, 4.0]), kind=jnp.asarray([2, 0, 1]),
                                role=jnp.asarray([0, 1, 2]))
    padded = _pad_vehicles(scene, 4)
    assert padded.num_vehicles == 4 and padded.dt_s == 0.04
    assert np.asarray(padded.present).tolist() == [True, True, True, False]
    assert int(padded.role[3]) == BACKGROUND and int(padded.kind[3]) == CAR
    assert float(padded.length_m[3]) == 5.0  # the ego's
    np.testing.assert_allclose(np.asarray(padded.s_m[:, 3]), 25.0 * 0.04 * np.arange(5) - 1000.0, atol=1e-9)
    np.testing.assert_array_equal(np.asarray(padded.kind[:3]), [2, 0, 1])
    assert _pad_vehicles(scene, 3) is scene


SHARDED = """
import json, jax
jax.config.update("jax_enable_x64", True)
from tests._toy_pipeline import toy_objective
E = toy_objective(n=3, instants=2)
print(json.dumps({"weight": E.data.weight.tolist(), "rain": E.weather.rain_mm_h.shape[0],
                  "devices": len(E.data.weight.sharding.device_set),
                  "E": float(E({"range_m": 30.0}, mode="hard"))}))
"""


def test_variants_are_sharded_by_default_over_four_devices():
    """On 4 simulated CPU devices `make_objective` shards by default: 3 variants padded to 4 at
    weight 0, the weather too, and the hard E the same as on one device."""
    one = _make(n=3)  # also here, so the mutation run sees this test reach make_objective
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-c", SHARDED], cwd=root, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["weight"] == [1.0, 1.0, 1.0, 0.0] and out["rain"] == 4 and out["devices"] == 4
    assert out["E"] == pytest.approx(float(one({"range_m": 30.0}, mode="hard")), rel=1e-12)


def test_recorded_scenes_come_in_the_dtype_asked(tmp_path):
    from diffsense.metrics import recorded_scenes
    from diffsense.predictors import CSLSTM_SPEC
    from tests._recorded_files import write_highd

    jax.config.update("jax_enable_x64", True)
    scenes, index, names, _ = recorded_scenes(f"highd:{write_highd(tmp_path)}", spec=CSLSTM_SPEC,
                                              sensors=(ToySensor(),), dtype=jnp.float32)
    assert scenes.x_m.dtype == jnp.float32 and scenes.s_m.dtype == jnp.float32
    assert scenes.x_m.shape[0] == len(names) == len(index)


def _same_scenes(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_simulate_scenes_forwards_every_setting_and_shares_the_defaults(tmp_path, monkeypatch):
    """`simulate_scenes` is `speed_shifted_scenes(...).base`: every setting forwarded (each away
    from its default here), and both default to stride 4, the scenario's own background, float64
    and no speed offset. The background is moved to 10 m behind the ego, where it is kept."""
    from diffsense.metrics import _build, simulate_scenes, speed_shifted_scenes
    from diffsense.predictors import CSLSTM_SPEC

    jax.config.update("jax_enable_x64", True)
    shipped = Path(__file__).resolve().parents[1] / "configs" / "scenarios" / "sc01.toml"
    near = tmp_path / "sc01_near.toml"
    near.write_text(shipped.read_text().replace('name = "sc01"', 'name = "sc01_near"')
                    .replace("gap_m = 150.0", "gap_m = 10.0"))
    strides, select = [], _build.relevant_selection

    def spy(scene, frames, **reach):
        strides.append(set(np.diff(np.asarray(frames)).tolist()))
        return select(scene, frames, **reach)

    monkeypatch.setattr(_build, "relevant_selection", spy)
    reach = dict(spec=CSLSTM_SPEC, sensors=(ToySensor(),))
    key = jax.random.key(3)
    asked = dict(stride_frames=40, background_vehicles=6, dtype=jnp.float32, speed_offset_kmh=6.0)
    scenes, index, names, weather = simulate_scenes((str(near),), 1, key, **reach, **asked)
    shifted, index2, names2, weather2 = speed_shifted_scenes((str(near),), 1, key, **reach, **asked)
    _same_scenes(scenes, shifted.base)
    _same_scenes(shifted(0.0), shifted.base)  # re-simulated in the dtype asked
    slower, _, _, _ = simulate_scenes((str(near),), 1, key, **reach, **dict(asked, speed_offset_kmh=4.0))
    _same_scenes(shifted(-2.0), slower)  # offsets add to the base's 6 km/h
    assert strides == [{40}] * 3
    assert scenes.s_m.dtype == jnp.float32 and scenes.num_vehicles == 8  # 3 of the 6 background cars kept
    assert names == names2 == ("sc01_near",) and list(index) == list(index2) == [0]
    _same_scenes(weather, weather2)
    # the speed offset is in the scenes: the ego drives 6 km/h faster than at no offset
    plain, _, _, _ = simulate_scenes((str(near),), 1, key, **reach, stride_frames=40, background_vehicles=6,
                                     dtype=jnp.float32)
    np.testing.assert_allclose(np.asarray(scenes.speed_mps)[0, 0, 0] - np.asarray(plain.speed_mps)[0, 0, 0],
                               6.0 / 3.6, rtol=1e-5)

    strides.clear()
    default, _, _, _ = simulate_scenes((str(near),), 1, key, **reach)
    explicit, _, _, _ = speed_shifted_scenes((str(near),), 1, key, **reach, stride_frames=4,
                                             background_vehicles=0, dtype=jnp.float64, speed_offset_kmh=0.0)
    _same_scenes(default, explicit.base)
    assert default.s_m.dtype == jnp.float64 and default.num_vehicles == 5  # the scenario's own background: none
    own, _, _, _ = speed_shifted_scenes((str(near),), 1, key, **reach)
    assert strides == [{4}, {4}, {4}]
    assert own.base_offset_kmh == 0.0 and own.dtype == jnp.float64 and own.configs == explicit.configs
    _same_scenes(own.base, explicit.base)


def test_recorded_scenes_are_named_after_the_whole_file_name(tmp_path):
    """The recording's file name is kept whole, a colon in it too, and each cut's weather is
    clear with one value per cut."""
    from diffsense.metrics import recorded_scenes
    from diffsense.predictors import CSLSTM_SPEC
    from tests._recorded_files import write_highd

    jax.config.update("jax_enable_x64", True)
    path = write_highd(tmp_path, stem="a:01")
    scenes, _, names, weather = recorded_scenes(f"highd:{path}", spec=CSLSTM_SPEC, sensors=(ToySensor(),))
    n = scenes.x_m.shape[0]
    assert names[0] == f"{path.name}#0" and path.name.startswith("a:01")
    assert np.shape(weather.rain_mm_h) == np.shape(weather.fog_visibility_m) == (n,)


def test_with_scenes_pads_one_scene_by_repeating_it_and_keeps_a_float32_objective():
    """One new scene for an objective of three rows (two of them padding, as sharding adds)
    fills all three; a float32 objective's ground truth stays float32 with x64 on."""
    from diffsense.metrics import with_scenes

    jax.config.update("jax_enable_x64", True)
    E = _make(n=3)
    one = jax.tree.map(lambda a: a[1:2], E.data.scenes)
    moved = with_scenes(E, one)
    s = np.asarray(moved.data.scenes.s_m)
    assert s.shape[0] == 3
    for row in range(3):
        np.testing.assert_array_equal(s[row], np.asarray(one.s_m)[0])
        np.testing.assert_array_equal(np.asarray(moved.data.true_fut)[row], np.asarray(E.data.true_fut)[1])

    scenes, scenario = toy_scenes(2)
    scenes = jax.tree.map(lambda a: a.astype(jnp.float32) if jnp.issubdtype(a.dtype, jnp.floating) else a, scenes)
    E32 = make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:1], ToySensor(),
                         ToyPredictor(jnp.asarray(TOY_GAIN)), names=("range_m",))
    moved32 = with_scenes(E32, scenes)
    assert moved32.data.gt_pred.dtype == moved32.data.true_fut.dtype == jnp.float32
    np.testing.assert_array_equal(np.asarray(moved32.data.true_fut), np.asarray(E32.data.true_fut))
