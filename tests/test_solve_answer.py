"""The answer is chosen on the hard objective: the soft optimum when it is at least as good as the
best step, else the best of the levels' answers and that step; then a compass search on E_hard
(the hard polish) that moves only on a strictly better probe; all within the evaluation budget,
whose count is the objectives' real calls. Under `soft_value_is_answer` every point a gradient
was asked at is a candidate too. Interval: HFOV 30..180 deg in radians, steps every 30 deg.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.solve import SolveConfig, solve
from tests._analytic_objectives import HI, LO, bowl, dip_at, ripple

BUDGET = SolveConfig().max_evaluations
XTOL = SolveConfig().xtol_rel * (HI - LO)


def _used(res):
    return res.evaluations["objective"] + res.evaluations["gradient"]


def _counting(e_hard, calls):
    return lambda r: calls.append(float(r)) or e_hard(r)


@pytest.mark.parametrize("center", [1.3, 4.0])
def test_the_evaluations_reported_are_the_objectives_real_calls(center):
    # A callback runs once per forward pass of the soft objective (inside the compiled root find
    # too); the sweep's own evaluations are not in `evaluations`.
    calls = {"soft": 0, "hard": 0}
    e2, eh = ripple(center)

    def bump(_):
        calls["soft"] += 1

    def e2_counted(r, tau):
        jax.debug.callback(bump, r)
        return e2(r, tau)

    def eh_counted(r):
        calls["hard"] += 1
        return eh(r)

    res = solve(e2_counted, eh_counted, (LO, HI))
    n = len(res.sweep)
    assert calls["hard"] - n + calls["soft"] - n == sum(res.evaluations.values()) <= BUDGET
    assert calls["soft"] - n >= res.evaluations["gradient"]


def test_the_hard_objective_overrules_a_worse_soft_optimum():
    # Soft minimum at 1.3, but the hard objective is 0.5 m better only within 0.01 of the 90-deg
    # step: the step wins, then the polish walks inside the dip towards the bowl's centre.
    r_dip = float(np.deg2rad(90.0))
    e2, eh = dip_at(r_dip, center=1.3)
    unpolished = solve(e2, eh, (LO, HI), config=SolveConfig(hard_polish=0))
    assert unpolished.r_star == pytest.approx(r_dip) and unpolished.notes
    res = solve(e2, eh, (LO, HI))
    assert abs(res.r_star - r_dip) <= 0.01 and res.r_star <= r_dip
    assert res.E_hard_star <= float(eh(r_dip)) <= min(p.E_hard for p in res.sweep)
    assert _used(res) <= BUDGET


def test_an_earlier_level_answer_wins_when_the_last_is_worse_than_the_best_step():
    # The rippled bowl's levels (tau 4, 2, 1) answer r0, r1, r2; E_hard is made 1 m worse within
    # 0.003 rad of r0 and r2 only (no sweep step is that close, so bracket and levels stay the
    # same): of r2, r0, r1 and the best step, r1 is best on E_hard.
    e2, e_hard = ripple(1.3)
    plain = solve(e2, e_hard, (LO, HI), config=SolveConfig(hard_polish=0))
    r0, r1, r2 = (level.r for level in plain.levels)

    def e_hard_penalised(r):
        r = jnp.asarray(r)
        return e_hard(r) + 1.0 * ((jnp.abs(r - r2) < 0.003) | (jnp.abs(r - r0) < 0.003))

    res = solve(e2, e_hard_penalised, (LO, HI), config=SolveConfig(hard_polish=0))
    assert [level.r for level in res.levels] == [r0, r1, r2]
    assert res.r_star == r1 and res.E_hard_star == pytest.approx(float(e_hard(r1)))


@pytest.mark.parametrize("budget, earlier", [(11, 0), (13, 1)])
def test_earlier_levels_are_candidates_only_within_the_budget(budget, earlier):
    # E_hard is good only within 0.01 rad of the 90-deg step. After the levels' gradients and
    # E_hard at the soft optimum, earlier levels are evaluated while more than one evaluation is
    # left (the last is kept for E_soft): none at 11 (9 + 1 spent), the first at 13 (10 + 1).
    r_step = float(np.deg2rad(90.0))
    e2, e_hard = dip_at(r_step, center=1.3)
    hard_calls = []
    res = solve(e2, _counting(e_hard, hard_calls), (LO, HI), config=SolveConfig(max_evaluations=budget, hard_polish=0))
    assert res.evaluations["gradient"] + 1 + earlier == budget - 1
    assert hard_calls[len(res.sweep):] == [lv.r for lv in res.levels[-1:] + res.levels[:earlier]]
    assert res.evaluations["objective"] == 1 + earlier and res.r_star == r_step


def test_an_earlier_level_tying_the_best_step_is_preferred():
    # E_hard is 2 m within 0.003 rad of the last level's answer (which holds the second level's
    # too), 1 m elsewhere: the first level's answer ties the best step (60 deg) and is preferred.
    e2, _ = bowl(1.3)
    plain = solve(e2, bowl(1.3)[1], (LO, HI), config=SolveConfig(hard_polish=0))
    r0, r1, r2 = (level.r for level in plain.levels)
    assert abs(r1 - r2) < 0.003 < abs(r0 - r2)
    res = solve(e2, lambda r: 1.0 + 1.0 * (jnp.abs(jnp.asarray(r) - r2) < 0.003), (LO, HI),
                config=SolveConfig(hard_polish=0))
    assert res.r_star == r0 and res.E_hard_star == 1.0


def test_a_soft_optimum_tying_the_best_step_is_kept_as_it_is():
    # E_hard is 1 m everywhere: the soft optimum ties the best step and is kept; no other
    # candidate is evaluated and nothing is noted.
    hard_calls = []
    res = solve(bowl(1.3)[0], _counting(lambda r: 1.0, hard_calls), (LO, HI), config=SolveConfig(hard_polish=0))
    assert res.r_star == res.levels[-1].r and res.E_hard_star == 1.0 and res.notes == ()
    assert hard_calls[len(res.sweep):] == [res.r_star]


# The polish's first step is a sixteenth of the bracket: +-60/16 deg = 0.0654 rad from the soft
# optimum 1.3 (1.3654, 1.2346), then +-30/16 deg = 0.0327 rad (1.333: inside a dip at 1.33).
@pytest.mark.parametrize("method, reserve", [("secant", False), ("bisection", True)])
def test_the_polish_lands_in_a_dip_narrower_than_the_soft_objective(method, reserve):
    # Soft bowl at 1.3; E_hard is 0.05 m lower only within 0.01 rad of 1.33. (Bisection's
    # continuation leaves two probes at the default budget: its run reserves the polish's.)
    e2, eh = dip_at(1.33, center=1.3, penalty=0.05)
    plain = solve(e2, eh, (LO, HI), config=SolveConfig(method=method, hard_polish=0))
    assert abs(plain.r_star - 1.3) <= XTOL and plain.E_hard_star == pytest.approx(1.05, abs=1e-6)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method, reserve_polish=reserve))
    assert abs(res.r_star - 1.33) <= 0.01 and _used(res) <= BUDGET
    assert res.E_hard_star == pytest.approx(np.sqrt(1.0 + (res.r_star - 1.3) ** 2))
    assert res.E_hard_star < plain.E_hard_star - 0.04
    # the third probe (+w/32) is the one taken; its next three do not improve
    assert res.r_star - res.levels[-1].r == pytest.approx((res.bracket[1] - res.bracket[0]) / 32, abs=1e-12)
    assert res.evaluations["objective"] == 1 + 6 + 1  # E_hard(r_soft), 6 probes, E_soft(r*)


@pytest.mark.parametrize("method", ["secant", "bisection"])
def test_the_polish_moves_only_on_a_strictly_better_probe(method):
    # E_hard is exactly 1 on a plateau |r - 1.3| < 0.2 and the bowl outside: every polish probe
    # around the soft optimum ties with it.
    e2, eh_bowl = bowl(1.3)

    def eh(r):
        return jnp.where(jnp.abs(jnp.asarray(r) - 1.3) < 0.2, 1.0, eh_bowl(r))

    calls = []
    res = solve(e2, _counting(eh, calls), (LO, HI), config=SolveConfig(method=method))
    probes = calls[6 + 1:]  # after the six sweep steps and E_hard at the soft optimum
    assert any(abs(p - 1.3) < 0.2 for p in probes)  # a tying probe was evaluated ...
    assert res.r_star == res.levels[-1].r  # ... and not taken


def test_a_polish_reserved_is_not_starved_by_a_hungry_continuation():
    # A rippled bowl whose E_hard is 0.05 m better only within 0.01 rad of 1.385, beside the soft
    # optimum (~1.37). A tight tolerance makes the continuation spend the budget.
    e2, eh_rippled = ripple(1.3)

    def eh(r):
        return eh_rippled(r) + 0.05 * (jnp.abs(jnp.asarray(r) - 1.385) > 0.01)

    hungry = solve(e2, eh, (LO, HI), config=SolveConfig(xtol_rel=1e-6))
    cfg = SolveConfig(xtol_rel=1e-6, reserve_polish=True)
    reserved = solve(e2, eh, (LO, HI), config=cfg)
    assert abs(hungry.r_star - 1.385) > 0.01 and abs(reserved.r_star - 1.385) <= 0.01
    assert reserved.E_hard_star < hungry.E_hard_star - 0.04
    assert sum(level.gradient_evaluations for level in reserved.levels) <= BUDGET - 2 - cfg.hard_polish
    assert _used(reserved) <= BUDGET


# The compass search probe by probe, on an interval (0, 1) whose steps leave one end unevaluated:
# the soft bowl's minimum 0.5 is worse on E_hard than the best step, so the polish starts there.
# Bracket (0, 1): first step 1/16; xtol_rel = 1/64 makes 1/64 the finest step it may take.
@pytest.mark.parametrize("steps, hard_center, polish, probes", [
    # from 0.0625: 0.125 (worse), 0.0 (better, the bound: moves); from 0: 0.0625 (worse), -0.0625
    # (outside: free); 1/32: 0.03125 (worse), 1/64: 0.015625 (worse); 1/128 is finer than 1/64.
    ([0.0625, 1.0], 0.0, 6, [0.125, 0.0, 0.0625, 0.03125, 0.015625]),
    # from 0.9375: 1.0 (better, the bound: moves); from 1: 1.0625 (outside: free, the other side
    # is still probed) 0.9375 (worse); 1/32: 0.96875 (worse); 1/64: 0.984375 (worse).
    ([0.0, 0.9375], 1.0, 6, [1.0, 0.9375, 0.96875, 0.984375]),
    ([0.0, 0.9375], 1.0, 1, [1.0]),  # a polish of one probe
])
def test_the_polish_probes_reach_an_unevaluated_bound(steps, hard_center, polish, probes):
    hard_calls = []

    def e_hard(r):
        hard_calls.append(float(r))
        return float(np.sqrt(1.0 + (float(r) - hard_center) ** 2))

    cfg = SolveConfig(tau_schedule=(1.0,), xtol_rel=1 / 64, hard_polish=polish)
    res = solve(bowl(0.5)[0], e_hard, (0.0, 1.0), steps=steps, config=cfg,
                value_and_grad=lambda r, tau: (tau + (r - 0.5) ** 2, 2.0 * (r - 0.5)))
    assert res.bracket == (0.0, 1.0)
    # after the sweep's two steps and E_hard at the soft optimum (~0.5, within tol):
    assert abs(hard_calls[2] - 0.5) <= 1 / 64 and hard_calls[3:] == probes
    assert res.r_star == hard_center and res.E_hard_star == 1.0 and res.on_bound
    assert res.E_soft_star == pytest.approx(np.sqrt(1.25), abs=1e-15)  # at the polished r*


# --- the soft value is the answer objective's own (straight-through under a probabilistic law) --
# On [0, 10] with steps 0, 6, 10 and no polish: the gradient is that of the bowl (r - 5)^2, so the
# levels' root is 5; the value is the answer objective E(r) = 1 + |r - 4.2|, lowest at 4.2, which
# the gradient never sees. The best step is 6 (E 2.8), the levels' answer 5 (E 1.8).
STEPS = (0.0, 6.0, 10.0)


def answer_E(r: float) -> float:
    return 1.0 + abs(r - 4.2)


def _run(value_is_answer: bool, e_hard=answer_E, budget=BUDGET, polish=0):
    asked, hard = [], []

    def value_and_grad(r, tau):
        asked.append((r, tau))
        return answer_E(r) ** 2, 2.0 * (r - 5.0)

    result = solve(lambda r, tau: r, lambda r: hard.append(float(r)) or e_hard(float(r)), (0.0, 10.0), steps=STEPS,
                   config=SolveConfig(hard_polish=polish, max_evaluations=budget), value_and_grad=value_and_grad,
                   answer_name="E_ref", soft_value_is_answer=value_is_answer)
    return result, asked, hard


def test_without_it_the_answer_is_the_levels_root():
    result, asked, _ = _run(False)
    assert result.r_star == pytest.approx(5.0, abs=1e-6) and result.E_hard_star == pytest.approx(1.8, abs=1e-6)
    assert min(answer_E(r) for r, _ in asked) < result.E_hard_star  # a better point was seen, and not taken
    assert asked[:3] == [(0.0, 1.0), (6.0, 1.0), (10.0, 1.0)]  # the sweep's soft values
    assert result.E_soft_star == pytest.approx(1.8) and result.evaluations["objective"] == 2  # E_soft at 5


def test_with_it_the_sweep_reads_e_soft_off_e_hard_and_asks_no_soft_value():
    result, asked, hard = _run(True)
    assert hard[:3] == list(STEPS) and not {(0.0, 1.0), (10.0, 1.0)} & set(asked)
    assert [(p.E_hard, p.E_soft) for p in result.sweep] == [(answer_E(r), answer_E(r)) for r in STEPS]


def test_with_it_the_best_point_the_gradient_saw_is_the_answer_once_confirmed():
    result, asked, hard = _run(True)
    best = min({r for r, _ in asked} - set(STEPS), key=answer_E)
    assert result.r_star == best and result.E_hard_star == answer_E(best) < 1.8
    assert hard[-1] == best  # confirmed by one more evaluation of the answer objective
    # E_ref at the levels' root, then at the point confirmed; E_soft at r* is E_hard_star
    assert result.evaluations["objective"] == 2 and result.E_soft_star == result.E_hard_star


@pytest.mark.parametrize("confirmed", [0.0, 0.1])
def test_a_point_seen_lower_is_taken_only_if_the_answer_objective_confirms_it_strictly(confirmed):
    # The answer objective, asked at the best point seen, answers no lower than the levels' 1.8 m.
    best = _run(True)[0].r_star
    result, _, hard = _run(True, e_hard=lambda r: 1.8 + confirmed if r == best else answer_E(r))
    assert hard[-1] == best and result.r_star == pytest.approx(5.0, abs=1e-6)
    assert result.E_hard_star == pytest.approx(1.8, abs=1e-6)


@pytest.mark.parametrize("budget", [9, 10, 12])
def test_the_confirmation_and_the_polish_stay_inside_the_budget(budget):
    # the polish spends what is left: no evaluation is kept back for E_soft at r*, which is E_hard_star
    result, _, _ = _run(True, budget=budget, polish=6)
    assert result.evaluations["objective"] + result.evaluations["gradient"] == budget


def test_an_answer_on_a_step_reports_the_sweeps_e_soft_there():
    # E_hard is lowest at the step 6; the soft root 5 is worse there on E_hard, so the answer is
    # the step, and E_soft at r* is the sweep's soft value at 6 (sqrt 3), not E_hard (1).
    result = solve(lambda r, tau: r, lambda r: 1.0 + abs(float(r) - 6.0), (0.0, 10.0), steps=STEPS,
                   config=SolveConfig(hard_polish=0),
                   value_and_grad=lambda r, tau: (2.0 + (r - 5.0) ** 2, 2.0 * (r - 5.0)))
    assert result.r_star == 6.0 and result.E_hard_star == 1.0
    assert result.E_soft_star == pytest.approx(3.0 ** 0.5, rel=1e-12)
