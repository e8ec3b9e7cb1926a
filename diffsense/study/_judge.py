"""An answer judged on data it was not chosen on: E_ref at r* over a fresh seed's scenes and draws.

A solve picks r* on its own sample: the problem's scene variants and, under a probabilistic
detection law, its K detection draws (common random numbers). The lowest value it finds is then
biased low, by how well r* fits that sample's noise (the winner's curse), and the more points a
method tries the larger the bias. The judged value removes it: the same problem with the seed
`judge_seed(seed)` draws other scene variants (the variant-0 nominal scene of each scenario is
the same), other measurement noise and other detection draws, and E_ref is evaluated there at
r* once. Recorded traffic keeps its scenes; its noise and draws are fresh.

Under the threshold law E_ref is E_hard (its standard error 0): the judged value is then E_hard
on the fresh variants.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from diffsense.metrics import Objective
from diffsense.solve import Evaluator
from diffsense.study._intervals import answer_ci
from diffsense.study._objective import objective
from diffsense.study._problem import Problem

# Added to the problem's seed to give the judging seed: far from the small seeds users and the
# benchmarks pass (0, 1, 2, ...), so that no solve of those is judged on another's own sample.
JUDGE_SEED_OFFSET = 1_000_003


def judge_seed(seed: int) -> int:
    """The seed an answer of a problem with `seed` is judged on (seeds are 32-bit: it wraps)."""
    return (int(seed) + JUDGE_SEED_OFFSET) % 2**32


def judging_objective(problem: Problem, E: Objective) -> Objective:
    """The objective of `problem` on its judging seed, with `E`'s predictor (loaded once) and its
    scenes padded to `E`'s vehicle count where they have fewer: absent vehicles change no number,
    and the judging evaluation then runs `E`'s compiled reference program instead of compiling
    its own."""
    vehicles = E.data.scenes.num_vehicles
    return objective(problem.replace(seed=judge_seed(problem.seed)), predictor=E.predictor, min_vehicles=vehicles)


def judged(problem: Problem, E: Objective, r_star: dict[str, float]) -> dict[str, Any]:
    """result.json's "judged": E_ref [m] at `r_star` on the judging seed with its Monte-Carlo
    standard error [m], its interval from the judging seed's scene sample ("E_ci", [lo, hi] [m]
    or null, as result.json's own "E_ci"), the seed and the variants per scenario."""
    judge = judging_objective(problem, E)
    # the evaluator's own programs: the ones the solve compiled for E's shapes
    ev, x = Evaluator(judge), np.asarray([r_star[n] for n in judge.names])
    ref = ev.reference(x)
    ci = answer_ci(ev, x, seed=judge_seed(problem.seed), recorded=problem.traffic.scenes is not None)
    return {"E_ref": float(ref.e), "E_ref_se": float(ref.e_se), "E_ci": ci, "seed": judge_seed(problem.seed),
            "variants": problem.traffic.variants}
