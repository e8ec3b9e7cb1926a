"""The sensor cost model (`diffsense.metrics.make_cost`, `configs/costs.toml`): values by hand,
gradients against float64 central differences, the terms' bounds on their edges, and refusals."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from diffsense import metrics
from diffsense.metrics import cost_breakdown, load_costs, make_cost
from diffsense.runtime import InputError
from diffsense.sensors import Camera, Radar, Suite
from tests._toy_pipeline import ToySensor

MODEL = load_costs()
SUITE = Suite((Radar.from_toml(), Camera.from_toml()))


def test_shipped_costs_by_hand():
    radar, camera = make_cost(MODEL, Radar.from_toml()), make_cost(MODEL, Camera.from_toml())
    # At the defaults each term is its coefficient: 45 + 15 + 10 + 10 + 5 and 25 + 10 + 5 + 2 + 5.
    assert float(radar({})) == pytest.approx(85.0, abs=1e-12)
    assert float(camera({})) == pytest.approx(47.0, abs=1e-12)
    # Range doubled: 15 -> 30; HFOV 120 deg: 10 -> 40; 17 dBm is 10^0.3 = 1.9953 times the power:
    # 10 -> 19.953; noise figure 7.8 dB: 5 / 10^0.3 = 2.5059. vfov has no term.
    r = {"range_m": 200.0, "hfov_deg": 120.0, "tx_power_dbm": 17.0, "noise_figure_db": 7.8, "vfov_deg": 40.0}
    assert float(radar(r)) == pytest.approx(45.0 + 30.0 + 40.0 + 19.952623 + 2.505936, abs=1e-5)
    # 2560 px is twice the width, four times the pixels: 10 -> 40; baseline 0.3 m: 5 -> 12.5.
    c = {"width_px": 2560.0, "baseline_m": 0.3, "hfov_deg": 60.0, "range_m": 50.0}
    assert float(camera(c)) == pytest.approx(25.0 + 40.0 + 12.5 + 10.0 + 1.0, abs=1e-9)
    suite = make_cost(MODEL, SUITE)
    both = {"radar." + k: v for k, v in r.items()} | {"camera." + k: v for k, v in c.items()}
    assert float(suite(both)) == pytest.approx(float(radar(r)) + float(camera(c)), abs=1e-9)
    parts = cost_breakdown(MODEL, SUITE, both)
    assert parts["radar.base"] == 45.0 and parts["camera.width_px"] == pytest.approx(40.0)
    assert sum(parts.values()) == pytest.approx(float(suite(both)), abs=1e-9)
    # a lone sensor's parts are labelled with its kind
    alone = cost_breakdown(MODEL, Radar.from_toml(), {})
    assert alone["radar.base"] == pytest.approx(45.0) and all(k.startswith("radar.") for k in alone)
    assert sum(alone.values()) == pytest.approx(85.0)


def test_gradient_matches_central_differences_for_every_parameter():
    cost = make_cost(MODEL, SUITE)
    r0 = {s.name: s.default * 1.3 for s in SUITE.param_specs()}
    r0["radar.tx_power_dbm"] = 11.0
    grad = jax.grad(cost)(r0)
    f = jax.jit(cost)
    for name, value in r0.items():
        h = 1e-6 * max(abs(value), 1.0)
        up, down = dict(r0), dict(r0)
        up[name], down[name] = value + h, value - h
        fd = (float(f(up)) - float(f(down))) / (2 * h)
        np.testing.assert_allclose(float(grad[name]), fd, rtol=1e-7, atol=1e-10, err_msg=name)
    assert float(grad["radar.vfov_deg"]) == 0.0
    for name in ("radar.range_m", "radar.hfov_deg", "radar.tx_power_dbm", "camera.width_px", "camera.hfov_deg"):
        assert float(grad[name]) > 0.0, name  # rises with range, power, resolution, field of view
    assert float(grad["radar.noise_figure_db"]) < 0.0  # a quieter receiver costs more


@pytest.mark.parametrize("value", [0.0, 0.5])
def test_a_coefficient_or_base_of_zero_or_below_one_is_allowed(value):
    term = metrics.CostTerm(param="range_m", form="power", coefficient=value, reference=100.0, exponent=1.0)
    assert float(term(100.0)) == pytest.approx(value)  # a term costs its coefficient at its reference
    assert metrics.SensorCost(base=value, terms=()).base == value


def test_a_db_term_by_hand_and_its_reference_may_be_zero():
    db = metrics.CostTerm(param="gain_db", form="db", coefficient=2.0, reference=0.0, exponent=1.0)
    assert float(db(10.0)) == pytest.approx(20.0)  # 2 * 10^(1 * (10 - 0) / 10)


def test_refusals(tmp_path):
    with pytest.raises(InputError):
        metrics.CostTerm(param="range_m", form="power", coefficient=-1.0, reference=100.0, exponent=1.0)
    with pytest.raises(InputError):  # a power term's reference must be > 0
        metrics.CostTerm(param="range_m", form="power", coefficient=1.0, reference=0.0, exponent=1.0)
    with pytest.raises(InputError):
        metrics.SensorCost(base=-1.0, terms=())
    with pytest.raises(InputError, match="range_m"):
        term = metrics.CostTerm(param="range_m", form="power", coefficient=1.0, reference=1.0, exponent=1.0)
        metrics.SensorCost(base=1.0, terms=(term, term))
    with pytest.raises(InputError, match="'toy'"):
        make_cost(MODEL, ToySensor())
    with pytest.raises(InputError, match="'hfov_deg'"):
        make_cost(MODEL, SUITE)({"hfov_deg": 30.0})
    bad = tmp_path / "costs.toml"
    bad.write_text('currency = "EUR"\n[sensors.radar]\nbase = 1.0\n[[sensors.radar.terms]]\n'
                   'param = "beam_deg"\nform = "power"\ncoefficient = 1.0\nreference = 1.0\nexponent = 1.0\n')
    with pytest.raises(InputError, match="'beam_deg'"):
        make_cost(load_costs(bad), Radar.from_toml())
    bad.write_text('currency = "EUR"\n[sensors.radar]\nbase = -1.0\n')
    with pytest.raises(InputError):
        load_costs(bad)
    bad.write_text('currency = "EUR"\n[sensors.radar]\nbase = 1.0\n[[sensors.radar.terms]]\n'
                   'param = "range_m"\nform = "cubic"\ncoefficient = 1.0\nreference = 1.0\nexponent = 1.0\n')
    with pytest.raises(InputError, match="form"):
        load_costs(bad)
