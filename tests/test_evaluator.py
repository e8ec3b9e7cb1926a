"""`Evaluator`, the solver's face of a pure objective, on a bowl worked by hand: its values and
gradients, its reference, its detections, its precision, the progress it reports, each point
evaluated once; the breakdown of the toy objective against numpy; and the forms the solvers take
(`solver_fns`, `host_value_and_grad`, `BoxFunctions.from_evaluator`).

The bowl: E_soft^2(x, tau) = (x - 3)^2 + tau / 4 [m^2], E_hard^2(x) = (x - 3)^2 + 1/4, so
E_hard(3) = 0.5 m, E_soft^2(4, 1) = 1.25 with gradient 2, E_soft^2(4, 2) = 1.5,
E_soft^2(3.5, 1) = 0.5 (E_soft = sqrt(0.5) m, below 1 m); its reference is E_hard plus 1 m.
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
from diffsense.solve import BoxFunctions, Evaluator
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import (
    THRESHOLD_RADAR,
    TOY_GAIN,
    ToyPredictor,
    toy_objective,
    toy_scenes,
)


class _Hard(NamedTuple):
    e2: jax.Array
    objective: jax.Array


class Bowl(eqx.Module):
    """An objective's interface with the bowl's numbers."""

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


def _swerling_radar():
    radar = load_config("radar")
    return Radar(cfg.replace(radar, detection=cfg.replace(radar.detection, law="swerling1")))


class DeterministicBowl(Bowl):
    """The bowl with a threshold-law sensor: its reference is its hard evaluation."""

    sensor: Radar = eqx.field(static=True, default_factory=lambda: THRESHOLD_RADAR)


class RandomLawBowl(Bowl):
    """The bowl with a Swerling I radar: its reference is drawn (here: E_hard plus 1 m)."""

    sensor: Radar = eqx.field(static=True, default_factory=_swerling_radar)


class Bowl32(Bowl):
    """The bowl in float32, whose soft E^2 gains 100 m^2 if tau does not arrive in float32."""

    @property
    def dtype(self):
        return jnp.float32

    def e2(self, x, tau):
        return (x - 3.0) ** 2 + tau / 4.0 + (0.0 if tau.dtype == jnp.float32 else 100.0)

    def detections(self, x, mode, tau):
        return x * tau  # the temperature, as given


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def test_soft_values_and_gradients_at_tau_one_by_default_each_point_run_once():
    ev = Evaluator(Bowl())
    v, g = ev.value_and_grad(4.0)
    assert (v, g.tolist()) == (1.25, [2.0])
    assert ev.e2_soft(4.0) == 1.25 and ev.e2_soft(4.0, 2.0) == 1.5
    assert ev.counts == {"soft": 2, "hard": 0}  # (4, 1) asked three times, (4, 2) once
    ev.hard(3.0), ev.hard(3.0), ev.e_hard(4.0), ev.e_hard(3.0)
    assert ev.counts == {"soft": 2, "hard": 2} and ev.hard_points() == [(3.0,), (4.0,)]


def test_progress_reports_e_in_metres_with_the_temperature_once_per_point():
    seen = []
    ev = Evaluator(Bowl(), progress=lambda kind, value, tau: seen.append((kind, value, tau)))
    ev.value_and_grad(3.5, 1.0)
    ev.value_and_grad(3.5, 1.0)
    ev.e_hard(3.0)
    ev.e_reference(3.0)  # E_ref(3) = sqrt(0 + 1/4) + 1 = 1.5 m
    assert seen == [("soft", pytest.approx(np.sqrt(0.5), abs=1e-15), 1.0), ("hard", 0.5, 0.0),
                    ("reference", pytest.approx(1.5, abs=1e-12), 0.0)]


def test_a_random_law_draws_its_reference_once_per_point():
    for objective in (Bowl(), RandomLawBowl()):
        ev = Evaluator(objective)
        ev.reference(3.0), ev.reference(4.0)
        assert ev.e_reference(3.0) == pytest.approx(1.5, abs=1e-12)
        assert ev.reference_count == 2 and ev.counts["hard"] == 0
        assert ev.reference_points() == [(3.0,), (4.0,)] and ev.hard_points() == []


def test_a_deterministic_reference_is_the_hard_evaluation():
    ev = Evaluator(DeterministicBowl())
    ref = ev.reference(5.0)  # (5 - 3)^2 + 1/4 = 4.25: E_ref = sqrt(4.25), from the hard pass
    assert float(ref.e2) == 4.25 and float(ref.e) == pytest.approx(np.sqrt(4.25), abs=1e-12)
    assert ev.reference_count == 0 and ev.counts["hard"] == 1
    low = Evaluator(DeterministicBowl()).reference(3.0)  # E_hard^2(3) = 0.25: E_ref = 0.5 m
    assert float(low.e) == 0.5 and np.asarray(low.draws).tolist() == [0.25]  # the one draw
    for se in (low.e2_se, low.e_se):
        assert se.dtype == np.float64 and se.shape == np.shape(low.e2) and float(se) == 0.0


def test_a_swerling_radars_hard_detections_ignore_the_temperature():
    """Each hard detection is the median of its random event (0 or 1); soft ones are not."""
    scenes, scenario = toy_scenes(1)
    E = make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:2], _swerling_radar(),
                       ToyPredictor(jnp.asarray(TOY_GAIN)), names=("hfov_deg",), shard=False)
    ev = Evaluator(E)
    p = np.asarray(ev.detections(60.0).p_detect)
    assert np.array_equal(p, np.asarray(ev.detections(60.0, "hard").p_detect)) and set(np.unique(p)) <= {0.0, 1.0}
    assert not np.array_equal(p, np.asarray(ev.detections(60.0, "soft").p_detect))
    assert np.array_equal(p, np.asarray(ev.detections(60.0, "hard", 2.0).p_detect))


def test_a_float32_objective_runs_in_float32_and_hands_back_float64_gradients():
    ev = Evaluator(Bowl32())
    assert ev.value_and_grad(4.0, 1.0)[0] == 1.25  # tau arrived in float32
    hard = ev.hard(4.1)
    assert hard.e2.dtype == np.float32
    assert float(hard.e2) == float(np.float32(np.float32(4.1) - np.float32(3.0)) ** 2 + np.float32(0.25))
    v, g = ev.value_and_grad(4.1, 1.0)
    assert g.dtype == np.float64 and float(np.float32(v)) == v  # E^2 computed in float32
    assert v == pytest.approx(1.1**2 + 0.25, rel=1e-6) and v != 1.1**2 + 0.25
    assert np.asarray(ev.reference(4.1).e).dtype == np.float32
    assert ev.detections(4.1, "soft", np.float64(0.5)).dtype == jnp.float32
    assert float(ev.detections(4.0, "soft", 0.5)) == 2.0  # x * tau: the temperature passed


def test_the_breakdown_by_scenario_against_numpy():
    E = toy_objective(n=2, instants=2)  # variant 0 is scenario0, variant 1 scenario1
    ev = Evaluator(E)
    out = ev.breakdown(42.0, of_reference=False)  # of E_hard (the toy sensor declares no law)
    sq = np.asarray(ev.hard(42.0).sq_instant, np.float64)  # [N, I]
    for k, name in enumerate(("scenario0", "scenario1")):
        assert out["by_scenario"][name]["E_hard"] == pytest.approx(np.sqrt(sq[k].mean()), rel=1e-9)
    assert out["E_hard"] == pytest.approx(np.sqrt(sq.mean()), rel=1e-9)
    assert out["tracked"]["miss_penalty_m2"] == float(E.miss_penalty_m2)  # result.json's key


def test_the_one_parameter_solvers_forms():
    ev = Evaluator(Bowl())
    v, g = ev.host_value_and_grad(4.0, 2.0)
    assert (v, g) == (1.5, 2.0) and type(v) is float and type(g) is float  # (4 - 3)^2 + 2/4, 2 (4 - 3)
    e2_soft, e_hard = ev.solver_fns()  # e_hard: E, not E^2
    v, g = jax.jit(jax.value_and_grad(e2_soft))(4.0, 2.0)  # through a callback, compiled
    assert (float(v), float(g)) == (1.5, 2.0) and e_hard(3.0) == 0.5
    e2_soft, _ = ev.solver_fns(jnp.float32)
    value, slope = jax.jvp(lambda x: e2_soft(x, jnp.float32(1.0)), (jnp.float32(4.0),), (jnp.float32(1.0),))
    assert value.dtype == slope.dtype == jnp.float32 and (float(value), float(slope)) == (1.25, 2.0)


def test_box_functions_from_an_evaluator_with_and_without_a_cost():
    fns = BoxFunctions.from_evaluator(Evaluator(Bowl()))
    v, g = fns.e2_soft([4.0], 1.0)
    assert v == 1.25 and g.tolist() == [2.0]
    assert fns.j_hard([3.0], 5.0) == (0.5, 0.5, 0.0)  # no cost model: J = E_hard
    fns = BoxFunctions.from_evaluator(Evaluator(Bowl()), cost=lambda r: 2.0 * r["range_m"] + 1.0)
    c, gc = fns.cost(np.array([4.0]))
    assert c == 9.0 and gc.tolist() == [2.0]
    assert fns.j_hard(np.array([3.0]), 0.5) == (0.5 + 0.5 * 7.0, 0.5, 7.0)
