"""Pooling scenarios of different vehicle counts: E^2 of the pooled, padded batch against a
recomputation of each scenario on its own, unpadded.

Scenario A has two variants of five vehicles, scenario B one variant of three, padded to five
with the slots `simulate_scenes` adds. Eq. 12 pools every prediction instant, so the pooled E^2
is the instant-weighted mean of the scenarios' own: (2 E_A^2 + 1 E_B^2) / 3, not their plain
mean. The measurement-noise draws are passed as arrays (not keys) so that each real vehicle
gets the same draws whether or not its scene is padded.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.metrics import make_objective, pad_vehicles
from diffsense.tracks import prediction_frames
from tests._synthetic import straight_scene
from tests._toy_pipeline import THRESHOLD_RADAR, ToyPredictor

R = "hfov_deg"
FRAMES = prediction_frames(101, stride_frames=8)  # 3 instants per variant


def _variant(shift_m: float, wide: bool):
    """Ego, a target ahead changing lane, and (if wide) a car on each side, one of them beside
    the ego where a narrow radar cannot see it."""
    s0 = [0.0, 28.0 + shift_m, 12.0, 45.0 - shift_m, 6.0]
    lane, speed = [1, 1, 2, 0, 2], [25.0, 23.0, 26.0, 24.0, 25.5]
    keep = 5 if wide else 3
    return straight_scene(s0[:keep], lane[:keep], speed[:keep], num_frames=101,
                          lane_change=(1, 2.0 + shift_m / 10, 4.0, 2))


def _stack(scenes):
    return jax.tree.map(lambda *a: jnp.stack(a), *scenes)


def _objective(scenes, scenario, draws, names):
    obj = make_objective(scenes, np.asarray(scenario), FRAMES, THRESHOLD_RADAR,
                         ToyPredictor(jnp.asarray(0.05)), names=(R,), shard=False, scenario_names=names)
    return eqx.tree_at(lambda o: o.data.noise_key, obj, draws)


@pytest.fixture(scope="module")
def objectives():
    a = _stack([_variant(0.0, True), _variant(6.0, True)])
    b = _stack([_variant(3.0, False)])
    assert (a.num_vehicles, b.num_vehicles) == (5, 3)
    draws = jax.random.normal(jax.random.PRNGKey(3), (3, 2, 101, 5), jnp.float64)
    pooled = jax.tree.map(lambda x, y: jnp.concatenate([x, y]), a, pad_vehicles(b, 5))
    return (_objective(pooled, [0, 0, 1], draws, ("A", "B")),
            _objective(a, [0, 0], draws[:2], ("A",)),
            _objective(b, [0], draws[2:, :, :, :3], ("B",)))


@eqx.filter_jit
def _evaluate(obj, r):
    """Soft E^2 and the hard evaluation at each r [m^2]."""
    return jax.vmap(lambda x: (obj.e2({R: x}), obj.hard({R: x})))(r)


R_DEG = jnp.asarray([24.0, 70.0])


@pytest.fixture(scope="module")
def evaluations(objectives):
    return [_evaluate(o, R_DEG) for o in objectives]


def test_pooled_e2_is_the_instant_weighted_mean_of_the_scenarios(evaluations):
    (soft, hard), (soft_a, hard_a), (soft_b, hard_b) = evaluations
    for value, e2_a, e2_b in ((soft, soft_a, soft_b), (hard.e2, hard_a.e2, hard_b.e2)):
        np.testing.assert_allclose(value, (2 * e2_a + e2_b) / 3, rtol=1e-12)
        # The scenarios differ enough that a plain mean over scenarios would be caught.
        assert np.all(np.abs((e2_a + e2_b) / 2 - value) > 1e-3 * value)
    # The field of view changes what the radar sees in A (else r would not be tested at all).
    assert hard_a.e2[0] != hard_a.e2[1]


def test_per_scenario_curves_follow_the_scenario_index(evaluations):
    (_, hard), (_, hard_a), (_, hard_b) = evaluations
    assert hard.rmse_sensor.shape == (2, 2, 25)
    for row, alone in ((0, hard_a), (1, hard_b)):
        np.testing.assert_allclose(hard.rmse_sensor[:, row], alone.rmse_sensor[:, 0], rtol=1e-12)
        np.testing.assert_allclose(hard.rmse_gt[:, row], alone.rmse_gt[:, 0], rtol=1e-12)
    np.testing.assert_allclose(hard.sq_instant, np.concatenate([hard_a.sq_instant, hard_b.sq_instant], axis=1),
                               rtol=1e-12)
    assert not np.allclose(hard_a.rmse_sensor[:, 0], hard_b.rmse_sensor[:, 0])
