"""The sensor cost model (`diffsense.metrics._cost`, `configs/costs.toml`): values by hand,
gradients against central differences, and refusals."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.metrics._cost import cost_breakdown, load_costs, make_cost
from diffsense.sensors import Camera, Radar
from diffsense.sensors._fusion import Suite
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


def test_refusals(tmp_path):
    with pytest.raises(InputError, match="no cost for sensor 'toy'"):
        make_cost(MODEL, ToySensor())
    with pytest.raises(InputError, match="unknown suite parameter 'hfov_deg'"):
        make_cost(MODEL, SUITE)({"hfov_deg": 30.0})
    bad = tmp_path / "costs.toml"
    bad.write_text('currency = "EUR"\n[sensors.radar]\nbase = 1.0\n[[sensors.radar.terms]]\n'
                   'param = "beam_deg"\nform = "power"\ncoefficient = 1.0\nreference = 1.0\nexponent = 1.0\n')
    with pytest.raises(InputError, match="unknown radar parameter 'beam_deg'"):
        make_cost(load_costs(bad), Radar.from_toml())
    bad.write_text('currency = "EUR"\n[sensors.radar]\nbase = -1.0\n')
    with pytest.raises(InputError, match="base cost must be >= 0"):
        load_costs(bad)
    bad.write_text('currency = "EUR"\n[sensors.radar]\nbase = 1.0\n[[sensors.radar.terms]]\n'
                   'param = "range_m"\nform = "cubic"\ncoefficient = 1.0\nreference = 1.0\nexponent = 1.0\n')
    with pytest.raises(InputError, match="form"):
        load_costs(bad)
