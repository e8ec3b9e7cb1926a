"""The relaxed-reference estimator: E_ref's own detection draws, each relaxed, so the smooth
objective tends to the reference itself as its temperature falls (`diffsense.metrics._estimators`)."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import config as cfg
from diffsense import sensors as sensor
from diffsense.metrics._estimators import relaxed_draw
from diffsense.sensors._laws import CameraDetection, RadarDetection
from tests.test_reference import H, e2, radar_objective, reference, value_and_grad

@pytest.fixture(scope="module")
def relaxed():
    return radar_objective(kind="relaxed-reference", draws=4)


def test_relaxed_draw_against_the_odds_ratio():
    # sigmoid(logit p - logit u) = p (1 - u) / (p (1 - u) + u (1 - p)): an independent form.
    for p, u in [(0.9, 0.1), (0.3, 0.6), (0.7, 0.7), (0.02, 0.5)]:
        odds = p * (1 - u) / (p * (1 - u) + u * (1 - p))
        assert float(relaxed_draw(jnp.asarray(p), jnp.asarray(u), 1.0)) == pytest.approx(odds, rel=1e-12)
    # temperature t: the same form with the odds ratio raised to 1/t
    ratio = (0.6 / 0.4) / (0.5 / 0.5)
    assert float(relaxed_draw(jnp.asarray(0.6), jnp.asarray(0.5), 0.25)) == pytest.approx(ratio**4 / (1 + ratio**4), rel=1e-12)
    # the hard draw 1[u < p] in the limit, and finite values and gradients at 0 and 1
    assert float(relaxed_draw(jnp.asarray(0.51), jnp.asarray(0.5), 1e-6)) == 1.0
    assert float(relaxed_draw(jnp.asarray(0.49), jnp.asarray(0.5), 1e-6)) == 0.0
    for p, u in [(0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0)]:
        g = jax.grad(lambda q: relaxed_draw(q, jnp.asarray(u), 0.01))(jnp.asarray(p))
        assert np.isfinite(float(g))


def test_tends_to_the_reference_as_the_temperature_falls(relaxed):
    assert np.ptp(np.asarray(reference(relaxed, 8.0).draws)) > 0  # a beam this narrow: random draws
    for r in (8.0, 12.0):
        ref = reference(relaxed, r)
        cold = float(e2(relaxed, r, 1e-7))  # temperature 1e-9 in logit units
        np.testing.assert_allclose(cold, float(ref.e2), rtol=1e-9)
    # warm, the relaxation shows: the gap closes as the temperature falls
    ref = float(reference(relaxed, 8.0).e2)
    gaps = [abs(float(e2(relaxed, 8.0, tau)) - ref) for tau in (50.0, 5.0, 1e-3)]
    assert gaps[0] > gaps[1] > gaps[2] and gaps[0] > 1e-3 * ref


def test_gradient_matches_float64_central_differences(relaxed):
    for r in (9.0, 12.0):
        value, grad = value_and_grad(relaxed, jnp.asarray(r), 1.0)
        assert abs(float(grad)) > 1e-6
        h = 1e-5  # the relaxed draws bend within 0.01 logit units: a small step
        fd = (float(e2(relaxed, r + h, 1.0)) - float(e2(relaxed, r - h, 1.0))) / (2 * h)
        np.testing.assert_allclose(float(grad), fd, rtol=1e-5)
        np.testing.assert_allclose(float(value), float(e2(relaxed, r, 1.0)), rtol=1e-12)


def test_auto_under_a_random_law_and_mean_field_otherwise(relaxed):
    # one free parameter: straight-through (E_ref's value); several: relaxed-reference
    auto = radar_objective(kind="auto", draws=4)
    assert auto.estimator_kind == "straight-through"
    assert float(e2(auto, 10.0, 1.0)) == pytest.approx(float(reference(auto, 10.0).e2), rel=1e-12)
    assert float(e2(auto, 10.0, 1.0)) != float(e2(relaxed, 10.0, 1.0))
    two = dataclasses.replace(auto, names=(H, "range_m"))
    assert two.estimator_kind == "relaxed-reference"
    assert float(e2(two, 10.0, 1.0)) == float(e2(relaxed, 10.0, 1.0))
    threshold = sensor.Radar.from_toml()
    a = radar_objective(threshold, kind="auto", draws=4)
    m = radar_objective(threshold, kind="mean-field", draws=4)
    assert float(e2(a, 10.0, 1.0)) == float(e2(m, 10.0, 1.0))
    # under the threshold law explicit relaxed-reference has nothing to draw: mean-field too
    rr = radar_objective(threshold, kind="relaxed-reference", draws=4)
    assert float(e2(rr, 10.0, 1.0)) == float(e2(m, 10.0, 1.0))


def test_same_seed_same_value_bit_for_bit(relaxed):
    again = radar_objective(kind="relaxed-reference", draws=4)
    assert float(e2(again, 11.0, 1.0)) == float(e2(relaxed, 11.0, 1.0))
    other = radar_objective(kind="relaxed-reference", draws=8, key=jax.random.PRNGKey(3))
    assert float(e2(other, 8.0, 1.0)) != float(e2(relaxed, 8.0, 1.0))


@pytest.mark.parametrize("pfa", [1e-12, 0.1])
def test_no_nan_or_inf_at_the_extremes(pfa):
    config = cfg.replace(sensor.load_config("radar"), detection=RadarDetection(law="swerling1", pfa=pfa))
    obj = radar_objective(sensor.Radar(config), kind="relaxed-reference", draws=2)
    vg = eqx.filter_jit(lambda o, x: jax.value_and_grad(lambda v: o.e2({H: v[0], "range_m": v[1]}))(x))
    for hfov_deg in (0.01, 360.0):
        for range_m in (0.1, 1000.0):
            v, g = vg(obj, jnp.asarray([hfov_deg, range_m]))
            assert np.isfinite(float(v)) and np.all(np.isfinite(np.asarray(g))), (pfa, hfov_deg, range_m)


CAMERA_LAW = sensor.Camera(cfg.replace(sensor.load_config("camera"), detection=CameraDetection(law="confidence")))


def test_camera_gradients_and_extremes():
    # The confidence camera through the whole objective with relaxed-reference (the default for
    # several parameters): against float64 central differences at 20 deg (draws on the image's
    # edge) and 40 deg, and finite at HFOV 0.01/360 deg x range 0.1/1000 m. One compiled
    # program (HFOV and range) serves both checks.
    camera = radar_objective(CAMERA_LAW, kind="relaxed-reference", draws=4)
    assert np.ptp(np.asarray(reference(camera, 20.0).draws)) > 0
    vg = eqx.filter_jit(lambda o, x: jax.value_and_grad(lambda v: o.e2({H: v[0], "range_m": v[1]}))(x))
    for r in (20.0, 40.0):
        h = 1e-5
        up, down = (float(vg(camera, jnp.asarray([r + s, 100.0]))[0]) for s in (h, -h))
        grad = float(vg(camera, jnp.asarray([r, 100.0]))[1][0])
        assert abs(grad) > 1e-3
        np.testing.assert_allclose(grad, (up - down) / (2 * h), rtol=1e-5)
    for hfov_deg in (0.01, 360.0):
        for range_m in (0.1, 1000.0):
            v, g = vg(camera, jnp.asarray([hfov_deg, range_m]))
            assert np.isfinite(float(v)) and np.all(np.isfinite(np.asarray(g))), (hfov_deg, range_m)


def test_the_solver_notes_name_the_answer_objective_it_is_given():
    # A bowl whose answer objective is good only in a dip at the 90-deg step (the soft optimum
    # is overruled), and one 0.05 m better only just beside the soft optimum (the polish moves
    # the answer): each note names the objective the solver was given.
    from diffsense.solve import solve
    from tests._analytic_objectives import HI, LO, dip_at

    for name, other in (("E_ref", "E_hard"), ("E_hard", "E_ref")):
        kw = {} if name == "E_hard" else {"answer_name": name}  # E_hard is the default
        overruled = solve(*dip_at(float(np.deg2rad(90.0)), center=1.3), (LO, HI), **kw).notes
        polished = solve(*dip_at(1.33, center=1.3, penalty=0.05), (LO, HI), **kw).notes
        assert [n for n in overruled if "worse than the best step" in n] == [next(iter(overruled))]
        assert f"has {name}=" in overruled[0] and overruled[0].endswith(f"candidates on {name}")
        assert [n for n in polished if n.startswith("hard polish")] == [polished[-1]]
        assert f"lowered {name} from" in polished[-1]
        assert not any(other in n for n in overruled + polished)


def test_optimise_judges_the_answer_on_the_reference_and_reports_it(monkeypatch):
    import diffsense as ds
    from diffsense.study import _optimise
    from diffsense.metrics import EstimatorConfig
    from diffsense.report import summary_table
    from diffsense.solve import Evaluator, SolveConfig

    names = []  # the answer objective's name optimise gives the solver
    real_solve = _optimise.solve
    monkeypatch.setattr(_optimise, "solve", lambda *a, **kw: names.append(kw.get("answer_name")) or real_solve(*a, **kw))

    E = radar_objective(kind="auto", draws=4)
    problem = ds.Problem(sensor_config="configs/sensors/laws/radar_swerling1.toml", params={H: (5.0, 20.0)},
                         steps=(5.0, 10.0, 15.0, 20.0), estimator=EstimatorConfig(reference_draws=4),
                         solve=SolveConfig(max_evaluations=10))
    result = ds.optimise(problem, E=E, figures=False)
    out = result.to_json()
    ev = Evaluator(E)
    r_star = out["r_star"][H]
    ref = out["reference"]
    assert ref["answer_on"] == "E_ref" and ref["estimator"] == "auto" and ref["draws"] == 4
    assert ref["estimator_used"] == "straight-through"
    assert ref["E_ref_star"] == ev.e_reference(r_star) and ref["E_ref_star_se"] == float(ev.reference(r_star).e_se)
    # the sweep and the answer are judged on E_ref, the answer no worse than any step
    for step in out["sweep"]:
        assert step["E_hard"] == ev.e_reference(step["r"])
    assert ref["E_ref_star"] <= min(s["E_hard"] for s in out["sweep"])
    assert out["E_hard_star"] == ev.e_hard(r_star)  # the median-threshold E, reported beside it
    assert names == ["E_ref"] and not any("E_hard" in n for n in out["notes"])
    assert "E_ref(r*) = " in summary_table(out)


def test_draw_margins_say_when_the_relaxation_is_exact(relaxed):
    # The relaxed draw sigmoid(m / lambda) is within sigmoid(-m_min / lambda) of its hard value, so
    # at a temperature far below the smallest margin the estimate is E_ref; at one far above it,
    # the nearest draw is blurred and the estimate moves.
    from diffsense.metrics import reference_draw_margins

    m = np.asarray(eqx.filter_jit(reference_draw_margins)(relaxed, jnp.asarray(8.0), 4))
    assert m.shape[0] == 4 and m.ndim == 4 and np.all(np.isfinite(m)) and np.all(m >= 0)
    ref = float(reference(relaxed, 8.0).e2)
    lam = relaxed.estimator.reference_temperature
    m_min = float(m.min())
    assert m_min > 0
    assert float(e2(relaxed, 8.0, 1e-3 * m_min / lam)) == pytest.approx(ref, rel=1e-9)
    assert abs(float(e2(relaxed, 8.0, 1e3 * m_min / lam)) - ref) > 1e-6 * ref
