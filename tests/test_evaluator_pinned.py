"""The solver's wrapper of an objective (`diffsense/solve/_evaluator.py`) on a bowl worked by hand,
and its breakdown of the toy objective against a numpy recomputation.

The bowl: E_soft^2(x, tau) = (x - 3)^2 + tau / 4 [m^2], E_hard^2(x) = (x - 3)^2 + 1/4, so
E_hard(3) = 0.5 m, E_soft^2(4, 1) = 1.25 with gradient 2, E_soft^2(4, 2) = 1.5,
E_soft^2(3.5, 1) = 0.5 (E_soft = sqrt(0.5) m, below 1 m).
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import config as cfg
from diffsense.metrics import ReferenceEvaluation, make_objective
from diffsense.sensors import Radar, load_config
from diffsense.sensors._laws import RadarDetection
from diffsense.solve import Evaluator
from diffsense.solve._box_fns import BoxFunctions
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, toy_objective, toy_scenes


class _Hard(NamedTuple):
    e2: jax.Array
    objective: jax.Array


class Bowl(eqx.Module):
    """An objective's interface with the bowl's numbers; its reference is E_hard plus 1 m."""

    names: tuple[str, ...] = eqx.field(static=True, default=("range_m",))

    @property
    def dtype(self):
        return jnp.float64

    def point(self, v):
        return v[0]

    def e2(self, x, tau):
        return (x - 3.0) ** 2 + tau / 4.0

    def hard(self, x):
        e2 = (x - 3.0) ** 2 + 0.25
        return _Hard(e2=e2, objective=e2)

    def reference(self, x):
        e = jnp.sqrt((x - 3.0) ** 2 + 0.25) + 1.0
        zero = jnp.zeros_like(e)
        return ReferenceEvaluation(e2=e * e, e2_se=zero, e=e, e_se=zero, draws=(e * e)[None])


class DeterministicBowl(Bowl):
    """The bowl with a threshold-law sensor: its reference is its hard evaluation."""

    sensor: Radar = eqx.field(static=True, default_factory=Radar.from_toml)


class RandomLawBowl(Bowl):
    """The bowl with a Swerling I radar: its reference is drawn (here: E_hard plus 1 m)."""

    sensor: Radar = eqx.field(static=True, default_factory=lambda: Radar(
        cfg.replace(load_config("radar"), detection=RadarDetection(law="swerling1"))))


class Bowl32(Bowl):
    """The bowl run in float32, the precision the evaluator must hand it; detections x * tau."""

    @property
    def dtype(self):
        return jnp.float32

    def detections(self, x, mode, tau):
        return x * tau


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def test_soft_values_memoised_at_tau_one_by_default():
    ev = Evaluator(Bowl())
    v, g = ev.value_and_grad(4.0)
    assert (v, float(g[0])) == (1.25, 2.0)
    assert ev.e2_soft(4.0) == 1.25 and ev.e2_soft(4.0, 2.0) == 1.5
    assert ev.counts["soft"] == 2  # (4, 1) asked three times, (4, 2) once


def test_hard_value_and_progress_report_e_not_e_squared():
    seen = []
    ev = Evaluator(Bowl(), progress=lambda kind, value, tau: seen.append((kind, value, tau)))
    assert ev.e_hard(3.0) == 0.5
    assert seen == [("hard", 0.5, 0.0)]


def test_reference_of_a_random_and_of_a_deterministic_objective():
    assert Evaluator(Bowl()).e_reference(3.0) == pytest.approx(1.5, abs=1e-12)
    ev = Evaluator(DeterministicBowl())
    ref = ev.reference(5.0)  # (5 - 3)^2 + 1/4 = 4.25: E_ref = sqrt(4.25), from the hard pass
    assert float(ref.e2) == 4.25 and float(ref.e) == pytest.approx(np.sqrt(4.25), abs=1e-12)
    assert ev.e_reference(5.0) == pytest.approx(np.sqrt(4.25), abs=1e-12) and ev.reference_count == 0


def test_solver_fns_reach_the_compiled_program_through_a_callback():
    e2_soft, e_hard = Evaluator(Bowl()).solver_fns()
    v, g = jax.jit(jax.value_and_grad(e2_soft))(4.0, 2.0)
    assert (float(v), float(g)) == (1.5, 2.0)
    assert e_hard(3.0) == 0.5


def test_box_functions_from_an_evaluator_keep_the_cost():
    fns = BoxFunctions.from_evaluator(Evaluator(Bowl()), cost=lambda r: 2.0 * r["range_m"] + 1.0)
    c, gc = fns.cost(np.array([4.0]))
    assert c == 9.0 and gc.tolist() == [2.0]
    assert fns.j_hard(np.array([3.0]), 0.5) == (0.5 + 0.5 * 7.0, 0.5, 7.0)


def test_breakdown_by_scenario_against_numpy():
    E = toy_objective(n=2, instants=2)  # variant 0 is scenario0, variant 1 scenario1
    ev = Evaluator(E)
    out = ev.breakdown(42.0)
    sq = np.asarray(ev.hard(42.0).sq_instant, np.float64)  # [N, I]
    for k, name in enumerate(("scenario0", "scenario1")):
        assert out["by_scenario"][name]["E_hard"] == pytest.approx(np.sqrt(sq[k].mean()), rel=1e-9)
    assert out["E_hard"] == pytest.approx(np.sqrt(sq.mean()), rel=1e-9)
    assert out["tracked"]["miss_penalty_m2"] == float(E.miss_penalty_m2)  # result.json's key


def test_hard_programs_are_counted_once_per_point():
    ev = Evaluator(Bowl())
    ev.hard(3.0), ev.hard(3.0), ev.e_hard(4.0), ev.e_hard(3.0)
    assert ev.counts == {"soft": 0, "hard": 2}


def test_reference_programs_are_counted_once_per_point():
    ev = Evaluator(Bowl())
    ev.reference(3.0), ev.e_reference(3.0), ev.reference(4.0)
    assert ev.reference_count == 2 and ev.counts["hard"] == 0
    assert ev.reference_points() == [(3.0,), (4.0,)] and ev.hard_points() == []
    ev.e_hard(5.0)
    assert ev.hard_points() == [(5.0,)]


def test_deterministic_reference_below_one_metre_has_zero_standard_error():
    ref = Evaluator(DeterministicBowl()).reference(3.0)  # E_hard^2(3) = 0.25: E_ref = 0.5 m
    assert float(ref.e) == 0.5 and float(ref.e2) == 0.25
    for se in (ref.e2_se, ref.e_se):
        assert se.dtype == np.float64 and se.shape == np.shape(ref.e2) and float(se) == 0.0
    assert np.asarray(ref.draws).tolist() == [0.25]  # the one draw: the hard objective itself


def test_a_random_law_sensor_draws_its_reference():
    ev = Evaluator(RandomLawBowl())
    assert ev.e_reference(3.0) == pytest.approx(1.5, abs=1e-12)  # E_hard + 1: the drawn reference
    assert ev.reference_count == 1 and ev.counts["hard"] == 0


def test_soft_progress_reports_e_and_the_temperature():
    seen = []
    ev = Evaluator(Bowl(), progress=lambda kind, value, tau: seen.append((kind, value, tau)))
    ev.value_and_grad(3.5, 1.0)
    ev.value_and_grad(3.5, 1.0)  # memoised: no second report
    assert seen == [("soft", pytest.approx(np.sqrt(0.5), abs=1e-15), 1.0)]


def test_a_float32_objective_runs_in_float32_and_hands_back_float64_gradients():
    ev = Evaluator(Bowl32())
    hard = ev.hard(4.1)
    assert hard.e2.dtype == np.float32
    assert float(hard.e2) == float(np.float32(np.float32(4.1) - np.float32(3.0)) ** 2 + np.float32(0.25))
    v, g = ev.value_and_grad(4.1, 1.0)
    assert g.dtype == np.float64 and float(np.float32(v)) == v  # E^2 computed in float32
    assert v == pytest.approx(1.1**2 + 0.25, rel=1e-6) and v != 1.1**2 + 0.25
    assert np.asarray(ev.reference(4.1).e).dtype == np.float32
    assert ev.detections(4.1, "soft", np.float64(0.5)).dtype == jnp.float32


def test_detections_are_hard_by_default():
    """A Swerling I radar's hard detections: each the median of its random event (0 or 1)."""
    scenes, scenario = toy_scenes(1)
    E = make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:2], RandomLawBowl().sensor,
                       ToyPredictor(jnp.asarray(TOY_GAIN)), names=("hfov_deg",), shard=False)
    ev = Evaluator(E)
    default, hard, soft = ev.detections(60.0), ev.detections(60.0, "hard"), ev.detections(60.0, "soft")
    p = np.asarray(default.p_detect)
    assert np.array_equal(p, np.asarray(hard.p_detect)) and set(np.unique(p)) <= {0.0, 1.0}
    assert not np.array_equal(p, np.asarray(soft.p_detect))
    # Hard detections have no temperature: the default tau is not read in hard mode.
    assert np.array_equal(p, np.asarray(ev.detections(60.0, "hard", 2.0).p_detect))
