"""Boundaries of the cost model's input checks and the lone sensor's breakdown labels, coverage
parts, the target's window and the probability of a track, the objective's identity and sq_error's default temperature, each pinned by hand (these
are surviving mutants of the partial mutation run of diffsense/metrics, docs/mutation.md)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.metrics._cost import CostTerm, SensorCost, cost_breakdown, load_costs
from diffsense.metrics._coverage import COVERAGE_PARTS, coverage_classes, coverage_parts, p_tracked, target_window
from diffsense.scene import TARGET_INDEX
from diffsense.sensors import Radar
from tests._toy_pipeline import toy_objective


@pytest.mark.parametrize("coefficient", [0.0, 0.5])
def test_cost_term_accepts_a_coefficient_of_zero_or_below_one(coefficient):
    term = CostTerm(param="range_m", form="power", coefficient=coefficient, reference=100.0, exponent=1.0)
    assert float(term(100.0)) == pytest.approx(coefficient)  # a term costs its coefficient at its reference


def test_cost_term_rejects_a_negative_coefficient():
    with pytest.raises(InputError):
        CostTerm(param="range_m", form="power", coefficient=-1.0, reference=100.0, exponent=1.0)


def test_power_term_rejects_a_zero_reference_but_a_db_term_accepts_it():
    with pytest.raises(InputError):
        CostTerm(param="range_m", form="power", coefficient=1.0, reference=0.0, exponent=1.0)
    db = CostTerm(param="gain_db", form="db", coefficient=2.0, reference=0.0, exponent=1.0)
    assert float(db(10.0)) == pytest.approx(20.0)  # 2 * 10^(1 * (10 - 0) / 10)


@pytest.mark.parametrize("base", [0.0, 0.5])
def test_sensor_cost_accepts_a_base_of_zero_or_below_one(base):
    assert SensorCost(base=base, terms=()).base == base


def test_sensor_cost_rejects_a_negative_base():
    with pytest.raises(InputError):
        SensorCost(base=-1.0, terms=())


def test_lone_sensor_breakdown_labels_carry_its_kind():
    parts = cost_breakdown(load_costs(), Radar.from_toml(), {})
    # the shipped radar at its defaults: base 45, each term its coefficient (15 + 10 + 10 + 5)
    assert parts["radar.base"] == pytest.approx(45.0)
    assert all(k.startswith("radar.") for k in parts)
    assert sum(parts.values()) == pytest.approx(85.0)


def test_coverage_parts_of_hand_made_windows():
    # Windows of three frames: seen throughout, seen once (partly), never seen.
    windows = jnp.array([[1.0, 1.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    parts = coverage_parts(np.asarray(coverage_classes(windows)))
    assert tuple(parts) == COVERAGE_PARTS == ("throughout", "partly", "never")
    assert {k: v.tolist() for k, v in parts.items()} == {
        "throughout": [True, False, False], "partly": [False, True, False],
        "never": [False, False, True]}


def test_coverage_classes_of_hand_made_windows():
    # [at_instant, in_window, throughout]: seen only at the instant (the window's newest frame),
    # only before it, throughout.
    windows = jnp.array([[0.0, 0.0, 1.0], [1.0, 1.0, 0.0], [1.0, 1.0, 1.0]])
    np.testing.assert_array_equal(np.asarray(coverage_classes(windows)), [[1, 1, 0], [0, 1, 0], [1, 1, 1]])
    # The classes keep the window's dtype: a float32 run is not promoted to float64 (x64 is on).
    assert coverage_classes(windows.astype(jnp.float32)).dtype == jnp.float32


def test_target_window_is_the_targets_history_oldest_first():
    # p_detect[t, v] = 10 t + v: the windows of frames 3 and 5 over 2 frames of history.
    p_detect = 10.0 * jnp.arange(6.0)[:, None] + jnp.arange(3.0)[None, :]
    window = target_window(p_detect, jnp.array([3, 5]), 2)
    expected = 10.0 * np.array([[1.0, 2.0, 3.0], [3.0, 4.0, 5.0]]) + TARGET_INDEX
    np.testing.assert_array_equal(np.asarray(window), expected)


def test_p_tracked_of_hand_made_windows():
    # 1 - prod(1 - p) over each window: 1 - 0.5 * 0.5 * 1 and 1 - 0.9 * 0.8 * 0.7, per window.
    windows = jnp.array([[0.5, 0.5, 0.0], [0.1, 0.2, 0.3]])
    np.testing.assert_allclose(np.asarray(p_tracked(windows)), [0.75, 0.496], rtol=1e-12)
    # The objective hands it every variant's windows at once, [N, I, W]: the product runs over W.
    batched = jnp.stack([windows, windows[::-1]])
    np.testing.assert_allclose(np.asarray(p_tracked(batched)), [[0.75, 0.496], [0.496, 0.75]], rtol=1e-12)


def test_p_tracked_is_one_with_a_finite_gradient_when_a_detection_is_certain():
    # log1p(-1) is -inf: the clip below 1 keeps the gradient finite, as the docstring promises.
    windows = jnp.array([[1.0, 0.3, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(np.asarray(p_tracked(windows)), [1.0, 0.0], atol=1e-11)
    grad = jax.grad(lambda w: jnp.sum(p_tracked(w)))(windows)
    assert bool(jnp.all(jnp.isfinite(grad)))
    np.testing.assert_allclose(np.asarray(grad[1]), [1.0, 1.0, 1.0])  # d/dp_j of 1 - prod(1 - p) at p = 0


def test_objective_is_hashed_and_compared_by_identity():
    # Two objectives built alike are different keys (arrays are not hashable by value).
    a, b = toy_objective(n=1, instants=2), toy_objective(n=1, instants=2)
    assert a == a and a != b and hash(a) != hash(b) and len({a: 0, b: 1}) == 2


def test_sq_error_defaults_to_the_documented_temperature():
    # With no tau, E^2 split by variant and step averages to E^2 at tau = 1 (the sensors'
    # documented temperatures), as the objective's own default gives it.
    obj = toy_objective(n=1, instants=2)
    sq = eqx.filter_jit(lambda o: o.sq_error({"range_m": 40.0}))(obj)
    e2_tau1 = eqx.filter_jit(lambda o: o.e2({"range_m": 40.0}, 1.0))(obj)
    assert float(jnp.mean(sq)) == pytest.approx(float(e2_tau1), rel=1e-12)
