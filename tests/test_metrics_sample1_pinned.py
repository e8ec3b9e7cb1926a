"""The survivors of the metrics package's second mutation sample (seed 1, docs/mutation.md), each
pinned to a value worked by hand.

- Padding a batch's vehicle axis adds absent cars: present False, 1 km behind the ego at every
  frame, and the ego's size (here 4.5 m x 1.8 m, not 0 x 0, so no geometric test divides by a
  zero size); the real vehicles are unchanged.
- Simulated scenes: the weather of each variant is its scenario TOML's (a copy of sc01 with
  2 mm/h of rain and 300 m of fog, beside sc01 itself: clear, rain 0 and visibility infinite),
  and `background_vehicles` sets every scenario's background count (sc01 ships 0).
- Recorded scenes are reduced at the instants the default problem predicts at: by default the
  vehicles kept are those relevant at every 4th frame, `Problem`'s `prediction_stride_frames`
  (the simulated scenes' default stride too).
- A Monte-Carlo estimator of one sample is allowed; none is not.
"""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path

import jax
import numpy as np
import pytest

from diffsense.study._problem import Problem
from diffsense.runtime._errors import InputError
from diffsense.metrics import EstimatorConfig, recorded_scenes, simulate_scenes, speed_shifted_scenes
from diffsense.metrics import _build
from diffsense.metrics._build import _pad_vehicles
from diffsense.predictors import CSLSTM_SPEC
from diffsense.scene import relevant_vehicles
from tests._recorded_files import write_highd
from tests._synthetic import straight_scene
from tests._toy_pipeline import ToySensor


def test_padding_adds_absent_cars_far_behind_the_ego():
    jax.config.update("jax_enable_x64", True)
    scene = straight_scene(s0_m=[0.0, 20.0, 40.0], lane=[1, 1, 2], speed_mps=[25.0, 24.0, 26.0], num_frames=5)
    padded = _pad_vehicles(scene, 5)
    present, s, x = (np.asarray(a) for a in (padded.present, padded.s_m, padded.x_m))
    assert s.shape == (5, 5) and list(present) == [True, True, True, False, False]
    ego_s = 25.0 * 0.1 * np.arange(5)  # the ego drives at 25 m/s from s = 0
    for v in (3, 4):
        np.testing.assert_allclose(s[:, v], ego_s - 1000.0, atol=1e-9)
        np.testing.assert_allclose(x[:, v], ego_s - 1000.0, atol=1e-9)  # the road runs along +x from 0
    np.testing.assert_array_equal(np.asarray(padded.length_m)[3:], 4.5)  # the ego's size
    np.testing.assert_array_equal(np.asarray(padded.width_m)[3:], 1.8)
    np.testing.assert_array_equal(s[:, :3], np.asarray(scene.s_m))
    np.testing.assert_array_equal(np.asarray(padded.speed_mps)[:, :3], np.asarray(scene.speed_mps))


@pytest.fixture(scope="module")
def foggy_and_clear(tmp_path_factory):
    jax.config.update("jax_enable_x64", True)
    shipped = Path(__file__).resolve().parents[1] / "configs" / "scenarios" / "sc01.toml"
    text = shipped.read_text().replace('name = "sc01"', 'name = "sc01_fog"')
    text += "\n[weather]\nrain_mm_h = 2.0\nfog_visibility_m = 300.0\n"
    path = tmp_path_factory.mktemp("scenario") / "sc01_fog.toml"
    path.write_text(text)
    return speed_shifted_scenes((str(path), "sc01"), 2, jax.random.key(0), spec=CSLSTM_SPEC,
                                sensors=(ToySensor(),), stride_frames=10, background_vehicles=3)


def test_simulated_variants_carry_their_scenarios_weather_and_background(foggy_and_clear):
    # One test for both: mutmut runs a mutant's tests only where its statistics saw the function
    # called, and the module's fixture calls it once, in the first test that asks for it.
    shifted, index, names, weather = foggy_and_clear
    assert names == ("sc01_fog", "sc01") and list(index) == [0, 0, 1, 1]
    np.testing.assert_array_equal(np.asarray(weather.rain_mm_h), [2.0, 2.0, 0.0, 0.0])
    np.testing.assert_array_equal(np.asarray(weather.fog_visibility_m), [300.0, 300.0, np.inf, np.inf])
    assert [c.background.count for c in shifted.configs] == [3, 3]


def test_scenes_default_to_the_problems_prediction_stride():
    stride = {f.name: f.default for f in dataclasses.fields(Problem)}["prediction_stride_frames"]
    assert stride == 4
    for fn in (recorded_scenes, simulate_scenes, speed_shifted_scenes):
        assert inspect.signature(fn).parameters["stride_frames"].default == stride


def test_recorded_scenes_keep_the_vehicles_relevant_at_every_fourth_frame(tmp_path, monkeypatch):
    asked = []

    def spy(scene, frames, **reach):
        asked.append(np.asarray(frames))
        return relevant_vehicles(scene, frames, **reach)

    monkeypatch.setattr(_build, "relevant_vehicles", spy)
    recorded_scenes(f"highd:{write_highd(tmp_path)}", spec=CSLSTM_SPEC, sensors=(ToySensor(),))
    assert asked and all(len(frames) >= 2 and set(np.diff(frames)) == {4} for frames in asked)


def test_one_monte_carlo_sample_is_allowed_none_is_not():
    assert EstimatorConfig(kind="mc", samples=1).samples == 1
    with pytest.raises(InputError, match="samples must be >= 1"):
        EstimatorConfig(kind="mc", samples=0)
