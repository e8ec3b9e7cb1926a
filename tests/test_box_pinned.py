"""The box solve's bookkeeping (`diffsense/solve/_box.py`) and the bracketed secant's default
first probe (`_bracketed.py`), by hand.

Box: E_soft^2(x, tau) = 1 + tau + (x - 8)^2 / 100 over [0, 20] with E_hard^2 = 1 + (x - 8)^2 / 100:
each start's J_soft is E_soft at the last temperature (tau 1) of its answer x, sqrt(2 + (x-8)^2/100).
Secant on g(y) = y - 6 over [0, 8] from 0.5, default probe a quarter bracket (2): g(0.5) = -5.5,
probe 2.5 (g -3.5, secant slope 1), overshoot 1.5 * 3.5 past it: 7.75 (g +1.75), then regula
falsi 2.5 + 3.5 * 5.25 / 5.25 = 6.0, an exact zero.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from diffsense.solve._box import BoxConfig, box_solve
from diffsense.solve._box_fns import BoxFunctions
from diffsense.solve._box_space import halton
from diffsense.solve._bracketed import BracketedSecant


def _fns():
    return BoxFunctions.from_jax(("range_m",), lambda x, tau: 1.0 + tau + (x[0] - 8.0) ** 2 / 100.0,
                                 lambda x: jnp.sqrt(1.0 + (x[0] - 8.0) ** 2 / 100.0))


def test_each_start_reports_j_soft_at_the_last_temperature():
    jax.config.update("jax_enable_x64", True)
    result = box_solve(_fns(), {"range_m": (0.0, 20.0)}, BoxConfig(tau_schedule=(4.0, 2.0, 1.0)))
    assert result.starts
    for start in result.starts:
        x = start.x["range_m"]
        assert start.J_soft == pytest.approx(np.sqrt(2.0 + (x - 8.0) ** 2 / 100.0), rel=1e-12)


def test_box_solve_turns_float64_on():
    jax.config.update("jax_enable_x64", False)
    try:
        result = box_solve(_fns(), {"range_m": (0.0, 20.0)})
        assert jax.config.jax_enable_x64
        assert result.x_star["range_m"] == pytest.approx(8.0, abs=1e-3)
    finally:
        jax.config.update("jax_enable_x64", True)


def _secant_points(shift=0.0, **options):
    """The points g(y) = y - 6 is asked at by the secant on [0, 8] from 0.5, and the answer; all
    of it moved by `shift`."""
    jax.config.update("jax_enable_x64", True)
    asked = []

    def g(y, args):
        jax.debug.callback(lambda v: asked.append(float(v)), y, ordered=True)
        return y - (6.0 + shift)

    sol = optx.root_find(g, BracketedSecant(rtol=0.0, atol=1e-6), jnp.asarray(0.5 + shift),
                         options=dict(lower=shift, upper=8.0 + shift, **options), max_steps=20, throw=False)
    jax.effects_barrier()
    return asked, float(sol.value)


def test_bracketed_secant_first_probe_is_a_quarter_of_the_bracket():
    assert _secant_points() == ([0.5, 2.5, 7.75, 6.0], 6.0)


def test_bracketed_secant_stops_after_max_evaluations():
    asked, _ = _secant_points(max_evaluations=2)
    assert asked == [0.5, 2.5]



def test_bracketed_secant_first_probe_is_a_quarter_of_the_bracket_width():
    # The case above moved by +2 (g = y - 8 on [2, 10] from 2.5): the same steps, moved.
    assert _secant_points(shift=2.0) == ([2.5, 4.5, 9.75, 8.0], 8.0)


def test_halton_is_the_radical_inverse_rotated_by_the_seeds_draw():
    # The first four radical inverses in bases 2 and 3, written out, then the Cranley-Patterson
    # shift drawn from seed 0 (the default) added modulo 1.
    radical = np.array([[1 / 2, 1 / 3], [1 / 4, 2 / 3], [3 / 4, 1 / 9], [1 / 8, 4 / 9]])
    shift = np.random.default_rng(0).uniform(size=2)
    np.testing.assert_allclose(halton(4, 2), (radical + shift) % 1.0, rtol=0, atol=1e-15)
