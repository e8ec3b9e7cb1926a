"""Boundaries of the cost model's input checks and the lone sensor's breakdown labels, each pinned
by hand (these are the surviving mutants of the partial mutation run of diffsense/metrics/_cost.py,
docs/mutation.md)."""

from __future__ import annotations

import pytest

from diffsense.errors import InputError
from diffsense.metrics._cost import CostTerm, SensorCost, cost_breakdown, load_costs
from diffsense.sensors import Radar


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
