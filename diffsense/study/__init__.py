"""A user's problem and the jobs run on it: what is asked, and the answer with how sure it is.

    problem = Problem(sensor="radar", params={"hfov_deg": (30.0, 180.0)}, scenarios=["sc01"])
    problem.sensing.built, problem.traffic.variants   # its specs: one per stage (`TrafficSpec`, ...)
    E = objective(problem)                 # E(r) [m]: a pure equinox Module
    result = optimise(problem)             # the main job: a `Result`
    front = pareto(Problem.from_suite("configs/suites/radar_camera_d4.toml"))
    sensitivity(problem, result, ["rain_mm_h"])   # dr*/dtheta at the answer
    modality_comparisons({"radar": a, "camera": b})  # paired, over the scenes both saw
    box_r_star_interval(ev, x, bounds, strata)        # how far each of r*'s parameters would move
"""

from diffsense.study._box_job import DEFAULT_LAMBDAS, ParetoFront, check_lambdas, pareto
from diffsense.study._domain import domain_check, domain_note
from diffsense.study._intervals import (
    answer_ci,
    box_intervals,
    breakdown_intervals,
    modality_comparisons,
    paired_comparison,
    with_modality_comparisons,
)
from diffsense.study._judge import judge_seed, judging_objective
from diffsense.study._line_job import planned_evaluations
from diffsense.study._members import Member, named_members
from diffsense.study._objective import (
    memory_estimate_bytes,
    objective,
    recorded_cut,
    seed_keys,
    traffic_scenes,
)
from diffsense.study._optimise import optimise
from diffsense.study._problem import Problem, problem_config
from diffsense.study._r_star import box_r_star_interval, r_star_interval
from diffsense.study._result import Curves, Result
from diffsense.study._sensitivity import (
    ODD_PARAMETERS,
    WEATHER_PARAMETERS,
    check_theta,
    odd_shift,
    sensitivity,
)
from diffsense.study._settings import (
    Settings,
    load_settings,
    problem_fields,
    shared_fields,
)
from diffsense.study._specs import (
    WEATHER_DOMAINS,
    PredictionSpec,
    QuestionSpec,
    SensingSpec,
    SolverSpec,
    TrafficSpec,
)
from diffsense.study._suite_file import checked, load_suite

__all__ = [
    "DEFAULT_LAMBDAS", "ODD_PARAMETERS", "WEATHER_DOMAINS", "WEATHER_PARAMETERS", "Curves", "Member", "ParetoFront",
    "PredictionSpec", "Problem", "QuestionSpec", "Result", "SensingSpec", "Settings", "SolverSpec", "TrafficSpec",
    "answer_ci", "box_intervals", "box_r_star_interval", "breakdown_intervals", "check_lambdas", "check_theta", "checked", "domain_check", "domain_note", "judge_seed", "judging_objective",
    "load_settings", "load_suite",
    "memory_estimate_bytes", "modality_comparisons", "named_members", "paired_comparison", "objective", "odd_shift", "optimise", "pareto", "planned_evaluations",
    "problem_config", "problem_fields", "r_star_interval", "recorded_cut", "seed_keys", "sensitivity", "shared_fields", "traffic_scenes", "with_modality_comparisons",
]
