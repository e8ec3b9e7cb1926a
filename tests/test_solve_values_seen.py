"""The continuous solve when the soft objective's value is the answer objective's own
(straight-through under a probabilistic law: E_ref's value, a relaxed gradient).

The problem, on [0, 10] with steps 0, 6, 10 and no hard polish: the gradient is that of the bowl
(r - 5)^2, so the levels' root is 5; the value is the answer objective E(r) = 1 + |r - 4.2|,
lowest at 4.2, which the gradient never sees. The best step is 6 (E 2.8), the levels' answer
5 (E 1.8). Every point the gradient was asked at is an answer candidate only under
`soft_value_is_answer`: the answer is then the lowest of them, confirmed on the answer objective.
"""

from __future__ import annotations

import jax
import pytest

from diffsense.solve import SolveConfig, solve
from diffsense.solve._continuous import _best_seen
from diffsense.solve._levels import Counted

STEPS = (0.0, 6.0, 10.0)
CONFIG = SolveConfig(hard_polish=0)


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def answer_E(r: float) -> float:
    return 1.0 + abs(r - 4.2)


def _run(value_is_answer: bool):
    asked, hard = [], []

    def value_and_grad(r, tau):
        asked.append((r, tau))
        return answer_E(r) ** 2, 2.0 * (r - 5.0)

    def e_hard(r):
        hard.append(float(r))
        return answer_E(float(r))

    result = solve(lambda r, tau: r, e_hard, (0.0, 10.0), steps=STEPS, config=CONFIG,
                   value_and_grad=value_and_grad, answer_name="E_ref", soft_value_is_answer=value_is_answer)
    return result, asked, hard


def test_without_it_the_answer_is_the_levels_root():
    result, asked, _ = _run(False)
    assert result.r_star == pytest.approx(5.0, abs=1e-6) and result.E_hard_star == pytest.approx(1.8, abs=1e-6)
    assert min(answer_E(r) for r, _ in asked) < result.E_hard_star  # a better point was seen, and not taken
    assert asked[:3] == [(0.0, 1.0), (6.0, 1.0), (10.0, 1.0)]  # the sweep's soft values


def test_with_it_the_sweep_reads_e_soft_off_e_hard_and_asks_no_soft_value():
    result, asked, hard = _run(True)
    assert hard[:3] == list(STEPS) and not {(0.0, 1.0), (10.0, 1.0)} & set(asked)
    assert [(p.E_hard, p.E_soft) for p in result.sweep] == [(answer_E(r), answer_E(r)) for r in STEPS]


def test_with_it_the_answer_is_the_best_point_the_gradient_saw_confirmed_on_the_answer_objective():
    result, asked, hard = _run(True)
    best = min({r for r, _ in asked} - set(STEPS), key=answer_E)
    assert result.r_star == best and result.E_hard_star == answer_E(best) < 1.8
    assert hard[-1] == best  # confirmed by one more evaluation of the answer objective
    assert result.notes[-1] == (
        f"a gradient evaluation saw a lower E_ref than the levels' answer r={5.0:.6g} (1.8 m): "
        f"answer r={best:.6g} ({answer_E(best):.6g} m)")
    # E_ref at the levels' root, then at the point confirmed; E_soft at r* is E_hard_star, not evaluated
    assert result.evaluations["objective"] == 2 and result.E_soft_star == result.E_hard_star
    without = _run(False)[0]
    assert without.E_soft_star == pytest.approx(1.8) and without.evaluations["objective"] == 2  # E_soft at 5


def test_the_confirmation_and_the_polish_stay_inside_the_budget():
    for budget in (9, 10, 12):
        result = solve(lambda r, tau: r, lambda r: answer_E(float(r)), (0.0, 10.0), steps=STEPS,
                       config=SolveConfig(max_evaluations=budget), soft_value_is_answer=True,
                       value_and_grad=lambda r, tau: (answer_E(r) ** 2, 2.0 * (r - 5.0)))
        # the polish spends what is left: no evaluation is kept back for E_soft at r*, which is E_hard_star
        assert result.evaluations["objective"] + result.evaluations["gradient"] == budget
        assert not any("exceed the budget" in note for note in result.notes)


def _counted(values_at: dict[float, float], hard_at: dict[float, float]):
    counted = Counted(lambda r, tau: r, lambda r: hard_at[float(r)], jax.numpy.float64,
                      value_and_grad=lambda r, tau: (values_at[r] ** 2, 0.0), keep_values=True)
    for r in values_at:
        counted.grad(r, 1.0)
    return counted


def test_the_values_seen_are_kept_as_r_and_e_in_the_order_asked():
    counted = _counted({3.0: 2.0, 1.0: 0.5, 2.0: 1.5}, {})
    assert counted.values_seen == [(3.0, 2.0), (1.0, 0.5), (2.0, 1.5)] and counted.gradient == 3
    assert counted.objective == 0  # the value comes with the gradient: no evaluation counted
    assert Counted(lambda r, tau: r, None, jax.numpy.float64,
                   value_and_grad=lambda r, tau: (1.0, 0.0)).keep_values is False


def test_a_point_is_taken_only_when_the_answer_objective_confirms_it_strictly_lower():
    notes = []
    # the best seen (r=1, 0.5) is confirmed at 0.9 < 1.0: taken, at its confirmed value
    assert _best_seen(_counted({1.0: 0.5, 2.0: 0.7}, {1.0: 0.9}), 4.0, 1.0, "E", notes, 3) == (1.0, 0.9)
    assert notes == ["a gradient evaluation saw a lower E than the levels' answer r=4 (1 m): answer r=1 (0.9 m)"]
    # confirmed no lower (equal, or higher): the answer stays, no note
    assert _best_seen(_counted({1.0: 0.5}, {1.0: 1.0}), 4.0, 1.0, "E", notes, 2) == (4.0, 1.0)
    assert _best_seen(_counted({1.0: 0.5}, {1.0: 1.2}), 4.0, 1.0, "E", notes, 2) == (4.0, 1.0) and len(notes) == 1
    # no evaluation left in the budget (one gradient spent of one): no confirmation, the answer stays
    counted = _counted({1.0: 0.5}, {1.0: 0.1})
    assert _best_seen(counted, 4.0, 1.0, "E", notes, 1) == (4.0, 1.0) and counted.objective == 0
    # nothing seen below the answer, or only the answer itself: no evaluation spent
    counted = _counted({1.0: 1.0, 4.0: 0.2}, {})
    assert _best_seen(counted, 4.0, 1.0, "E", notes, 9) == (4.0, 1.0) and counted.objective == 0


def test_without_a_host_objective_the_value_is_the_soft_objectives_own_and_uncounted():
    counted = Counted(lambda r, tau: tau * r**2, None, jax.numpy.float64, keep_values=True)
    assert counted.grad(3.0, 4.0) == 24.0
    assert counted.values_seen == [(3.0, 6.0)] and (counted.gradient, counted.objective) == (1, 0)


def test_an_answer_on_a_step_reports_the_sweeps_e_soft_there():
    # E_hard is lowest at the step 6; the soft objective's root 5 is worse there on E_hard, so the
    # answer is the step, and E_soft at r* is the sweep's soft value at 6 (sqrt 3), not E_hard (1)
    result = solve(lambda r, tau: r, lambda r: 1.0 + abs(float(r) - 6.0), (0.0, 10.0), steps=STEPS,
                   config=CONFIG, value_and_grad=lambda r, tau: (2.0 + (r - 5.0) ** 2, 2.0 * (r - 5.0)))
    assert result.r_star == 6.0 and result.E_hard_star == 1.0
    assert result.E_soft_star == pytest.approx(3.0 ** 0.5, rel=1e-12)
