"""`Result`: what `diffsense.optimise` found, and the result.json it writes.

result.json schema (every key always present; non-finite numbers are written as null):

    "sensor"        string   the sensor's kind ("radar", "camera", ...)
    "params"        {name: [lo, hi]}     the free parameters and their bounds (their own units)
    "units"         {name: string}       unit of each parameter
    "param"         string   the parameter of a one-parameter problem (null otherwise)
    "interval"      [lo, hi] its bounds (null otherwise)
    "r_star"        {name: number}       the answer
    "E_soft_star"   number   E at r* with the estimator at the final temperature [m]
    "E_hard_star"   number   E at r* with hard detections [m] (each detection its probability's
                             median); under the threshold law <= every sweep step's E_hard
    "reference"     {"answer_on": "E_hard" | "E_ref", "estimator", "E_ref_star": m, "E_ref_star_se": m,
                             "draws": K}  E_ref at r* (the hard objective's expectation over K
                             detection draws) and its standard error. Under a probabilistic
                             detection law the sweep, the answer and the polish are judged on E_ref
                             (answer_on "E_ref", and the sweep's "E_hard" entries hold E_ref);
                             under the threshold law E_ref = E_hard (one draw, SE 0); null for
                             many-parameter problems
    "judged"        {"E_ref": m, "E_ref_se": m, "E_ci": [lo, hi] | null, "seed": s, "variants": n}
                             the answer judged on data it was not chosen on: E_ref at r* over the
                             scene variants, noise and detection draws of the seed s
                             (`diffsense.study._judge`), with its interval from that seed's scene
                             sample (null as "E_ci" is); null when the run was asked not to judge
    "ci_level"      number   the level of every interval below (0.9)
    "ci_method"     {"method", "resamples": B, "strata": "scenario" | "none", "seed", "note": string | null,
                             "r_star", "r_star_points", "r_star_resolution", "r_star_caveat"
                             (with intervals; the caveat a string where r* is chosen on E_hard,
                             whose interval covers less than its level, else null)}
                             how the intervals are made (`diffsense.metrics.bootstrap_ci`: a
                             stratified expanded percentile bootstrap over scene variants, reweighting
                             per-variant sums the run computed; detection draws' error included
                             under a probabilistic law); "note" says why there is none
    "E_ci"          [lo, hi] | null   interval [m] on the answer's E at r* (E_ref_star under a
                             probabilistic law, E_hard_star under the threshold law); null where
                             it cannot be estimated (one variant per scenario)
    "r_star_ci"     {name: [lo, hi]} | null   how far r* would move with other traffic: the
                             percentile interval of r* re-picked on each resample as the point of
                             least E among the points the run evaluated E at (`diffsense.metrics.
                             argmin_ci`), with points added where the picks fall until they lie
                             1 % of the interval (or a quarter of r*'s interval) apart there
                             (two rounds of eight points at most), so
                             resolved to them: "ci_method" holds "r_star_points" (how many) and
                             "r_star_resolution" (the widest gap between neighbouring points from
                             the one below the interval to the one above it, parameter units);
                             null as "E_ci" is. A many-parameter answer's (null unless asked
                             for: `BoxConfig.r_star_axes`, --r-star-axes): per parameter, the
                             same along its axis through r* with the others held at r* (9 points
                             across its bounds to begin with; the pick is J's, E + lambda x cost),
                             "r_star_points" and "r_star_resolution" then {name: value}, and
                             "r_star_caveat" says the interval is conditional on the others
    "comparisons"   [{"a", "b", "diff_m", "ci", "ci_unpaired", "paired", "of", "verdict"}, ...]
                             each sweep step (and r*, where it is no step) against the best step
                             ("of": "sweep"), then, with `--sensor both`, the first sensor's
                             answer against the other's, each at its r* ("of": "sensors"):
                             diff_m = E(a) - E(b) [m], "ci" its paired interval (the same scenes
                             resampled for both), "ci_unpaired" the interval had they seen
                             independent scenes, "verdict" in plain words. A many-parameter
                             answer has one: r* against the default suite (the sensors' defaults
                             clipped to the box, "of": "default")
    "sweep"         [{"r": number, "E_hard": m, "E_soft": m, "E_ci": [lo, hi] | null}, ...]
                             the stepped sweep, each step's E with its interval
    "evaluations"   {"objective": int, "gradient": int}  of the continuous solve (sweep excluded)
    "programs_run"  {"solve": {"soft": int, "hard": int}, "figures": {...},
                     "intervals": {"hard": int, "reference": int}}  compiled-program
                             runs (memoised points are not run again): the solve's, those
                             after it for the figures and the report (a many-parameter answer's
                             default-suite comparison), and the points evaluated for r*'s
                             interval (made dense where the picks fall; a many-parameter
                             answer's along each parameter's axis)
    "wall_s"        {"compile": s, "run": s, "programs_compiled": n, "programs_lowered": m}
                             (n: programs XLA compiled rather than loaded from the persistent
                             compilation cache; m: programs JAX traced and lowered, compiled or
                             found in that cache, rather than loaded whole from executables/)
    "on_bound"      bool     r* is an end of the interval (then dr*/dtheta = 0)
    "bracket"       [lo, hi] where the continuous solve searched
    "tau_schedule"  [number, ...]  temperature multipliers of the continuation, largest first
    "notes"         [string, ...]  why the answer is what it is, when that needs saying
    "objective"     string   the question E answers: "eq12" (every instant) or "tracked"
    "breakdown_of"  "E_ref" | "E_hard"   what "by_scenario", "by_horizon" and "coverage" break
                             down: the value the answer is chosen on (E_ref over its detection
                             draws under a probabilistic law, E_hard otherwise); their parts'
                             values are keyed by it ("E_hard" below reads "E_ref" then)
    "E_pooled"      m        the breakdown's pooled E (Eq. 12 over every instant, of every draw)
    "by_scenario"   {scenario: {"E_hard": m, "E_ci": [lo, hi] | null, "coverage": {...}}}   at r*
                             (Eq. 12), each with its interval from the scenario's own variants
    "by_horizon"    {"t_s": [...], "E_hard": [...], "E_ci": [[lo, hi] | null, ...], "rmse_true_gt": [...],
                             "rmse_true_sensor": [...]}   at r*, per horizon step: Eq. 12 with its
                             interval, and both predictions against the true future
                             (ground-truth input, sensor input) [m]
    "coverage"      {"at_instant": f, "in_window": f, "throughout": f, "parts": {"throughout" |
                             "partly" | "never": {"share": f, "E_hard": m, "E_ci": [lo, hi] | null}}}
                             pooled, at r*: shares of instants whose target is detected at the
                             instant, at least once in the history window, throughout it; E on
                             each part with its interval (`diffsense.metrics.part_cis`)
    "tracked"       {"E_tracked": m, "missed_share": f, "J_m2": m^2, "miss_penalty_m2": m^2}
                             at r*: the "tracked" question's pieces (whichever was optimised)
    "sweep" entries also hold "by_scenario" and "coverage" at their step.
    "near_optimal"  {"tolerance_m": m, "intervals": [[lo, hi], ...], "indistinguishable": [r, ...] | null}
                             "intervals": every evaluated r whose E_hard is within the tolerance
                             of the best (`diffsense.solve._answer`; the "flat" flag reads it);
                             "indistinguishable": the sweep steps the scene sample cannot tell
                             from the best step (their paired difference's interval holds 0), the
                             best included; null without intervals
    "flags"         [string, ...]  "pressing_on_bound", "flat" (`diffsense.solve._answer`)
    "domain"        {"factor", "validation_rmse_m": [m at 1..5 s], "scenarios": {name: {"rmse_gt_m":
                             [...], "inside": bool}}, "outside": [names]}  the predictor's domain
                             check (`diffsense.study._domain`); a scenario outside it also gets a note
    "box"           only for many parameters (or a cost): {"J_star", "cost", "cost_weight",
                             "gradient" (dJ/dr per parameter at r*: what still matters),
                             "gradient_E", "on_bound" (per parameter), "source", "counts",
                             "cost_by_member" ({member: cost} at r*, a lone sensor under its kind)}
    "sensitivity"   {theta: {param: dr*/dtheta}} or null: how r* moves with each ODD parameter asked
                             for (`diffsense.sensitivity`; 0 on a bound)
    "scenarios"     [string, ...]
    "config"        object   the problem as plain JSON
    "versions"      {"python", "jax", ..., "diffsense": string}
    "dense_check"   object   only with Problem.dense_check (see `diffsense.optimise`)
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import platform
from typing import Any

import numpy as np

from diffsense.metrics import LEVEL
from diffsense.runtime import __version__, json_ready
from diffsense.solve import SolveResult

_PACKAGES = ("jax", "jaxlib", "flax", "optax", "optimistix", "numpy")
RESULT_KEYS = ("sensor", "params", "units", "param", "interval", "r_star", "E_soft_star", "E_hard_star", "reference", "judged", "ci_level",
               "ci_method", "E_ci", "r_star_ci", "comparisons", "sweep",
               "evaluations", "programs_run", "wall_s", "on_bound", "bracket", "tau_schedule", "notes",
               "objective", "breakdown_of", "E_pooled", "by_scenario", "by_horizon", "coverage", "tracked", "near_optimal", "flags", "domain", "sensitivity", "scenarios",
               "config", "versions")


def versions() -> dict[str, str]:
    """Versions of Python, the numerical packages and diffsense."""
    out = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    out["diffsense"] = __version__
    return out


@dataclasses.dataclass(frozen=True)
class Curves:
    """What the figures draw, from evaluations the run made (nothing interpolated).

    Attributes:
        r: [n] parameter values evaluated, ascending.
        E_soft, E_hard, dE_dr: [n] E [m] (soft at the final temperature; for the hard estimator
            E_soft repeats E_hard) and dE/dr [m per unit] at each r.
        horizon_gt: {scenario: [F]} RMSE of the ground-truth-input prediction against the true
            future, per horizon step [m].
        horizon_sensor: {scenario: {r: [F]}} the same for the sensor-input prediction, per step.
        horizon_s: [F] time of each horizon step [s].
        timeline: {r: [T, K]} hard detections of the nominal variant of the first scenario.
        timeline_roles: [K] the role of each column of the timeline.
        dt_s: frame period of the timeline [s].
    """

    r: tuple[float, ...]
    E_soft: tuple[float, ...]
    E_hard: tuple[float, ...]
    dE_dr: tuple[float, ...]
    horizon_gt: dict[str, np.ndarray]
    horizon_sensor: dict[str, dict[float, np.ndarray]]
    horizon_s: tuple[float, ...]
    timeline: dict[float, np.ndarray]
    timeline_roles: tuple[str, ...]
    dt_s: float


@dataclasses.dataclass(frozen=True)
class Result:
    """The answer of `diffsense.optimise`, with everything that explains it.

    `r_star` is a dict like r (`{"hfov_deg": 30.2}`); `solve` is the one-parameter solver's
    full record (sweep, levels, bracket); `to_json()` is the result.json content. `intervals`
    holds result.json's interval keys and, beyond them, the answer's per-variant sums
    ("answer_sums", "strata") that `diffsense.study.modality_comparisons` pairs across sensors.
    """

    sensor: str
    params: dict[str, tuple[float, float]]
    units: dict[str, str]
    r_star: dict[str, float]
    E_hard_star: float
    E_soft_star: float
    solve: SolveResult | None
    programs_run: dict[str, dict[str, int]]
    wall_s: dict[str, float]
    scenarios: tuple[str, ...]
    config: dict[str, Any]
    curves: Curves | None = None
    dense_check: dict[str, Any] | None = None
    breakdown: dict[str, Any] | None = None
    sweep_breakdown: tuple[dict[str, Any], ...] = ()
    tracked: dict[str, Any] | None = None
    near_optimal: dict[str, Any] | None = None
    flags: tuple[str, ...] = ()
    domain: dict[str, Any] | None = None
    sensitivity: dict[str, dict[str, Any]] | None = None
    box: Any = None
    reference: dict[str, Any] | None = None
    box_notes: tuple[str, ...] = ()
    judged: dict[str, Any] | None = None
    member_costs: dict[str, float] | None = None
    intervals: dict[str, Any] | None = None

    @property
    def sweep(self):
        return self.solve.sweep if self.solve is not None else ()

    @property
    def evaluations(self) -> dict[str, int]:
        if self.solve is None:
            screened = {"screened": self.box.counts["screen"]} if "screen" in self.box.counts else {}
            return {"objective": self.box.counts["hard"], "gradient": self.box.counts["soft"]} | screened
        return dict(self.solve.evaluations)

    @property
    def notes(self) -> tuple[str, ...]:
        return self.solve.notes if self.solve is not None else self.box_notes

    @property
    def on_bound(self) -> bool:
        """r* is on a bound (one-parameter problems), or any parameter is (many parameters)."""
        if self.solve is None:
            return any(self.box.on_bound.values())
        return self.solve.on_bound

    @property
    def param(self) -> str | None:
        """The parameter of a one-parameter problem."""
        return next(iter(self.params)) if len(self.params) == 1 else None

    def to_json(self) -> dict[str, Any]:
        """The result.json content (module docstring), JSON-ready."""
        if self.solve is None:
            return self._box_json()
        name = self.param
        s = self.solve
        out = {
            "sensor": self.sensor,
            "params": {k: list(v) for k, v in self.params.items()},
            "units": dict(self.units),
            "param": name,
            "interval": list(self.params[name]) if name else None,
            "r_star": dict(self.r_star),
            "E_soft_star": self.E_soft_star,
            "E_hard_star": self.E_hard_star,
            "reference": self.reference,
            "judged": self.judged,
            **self._intervals_json(),
            "sweep": [{"r": p.r, "E_hard": p.E_hard, "E_soft": p.E_soft, "E_ci": ci}
                      | ({k: b[k] for k in ("by_scenario", "coverage")} if b else {})
                      for p, b, ci in zip(s.sweep, self.sweep_breakdown or [None] * len(s.sweep),
                                          (self.intervals or {}).get("sweep_E_ci") or [None] * len(s.sweep))],
            "evaluations": {k: s.evaluations[k] for k in ("objective", "gradient")},
            "programs_run": self.programs_run,
            "wall_s": dict(self.wall_s),
            "on_bound": s.on_bound,
            "bracket": list(s.bracket),
            "tau_schedule": list(s.tau_schedule),
            "notes": list(s.notes),
            "objective": self.config.get("objective", "eq12"), **self._breakdown_of(),
            "by_scenario": (self.breakdown or {}).get("by_scenario"),
            "by_horizon": (self.breakdown or {}).get("by_horizon"),
            "coverage": (self.breakdown or {}).get("coverage"),
            "tracked": self.tracked,
            "near_optimal": self.near_optimal,
            "flags": list(self.flags),
            "domain": self.domain,
            "sensitivity": self.sensitivity,
            "scenarios": list(self.scenarios),
            "config": self.config,
            "versions": versions(),
        }
        if self.dense_check is not None:
            out["dense_check"] = self.dense_check
        return json_ready(out)

    def _intervals_json(self) -> dict[str, Any]:
        """result.json's "ci_level", "ci_method", "E_ci", "r_star_ci" and "comparisons" (module docstring)."""
        ci = self.intervals or {"ci_level": LEVEL, "ci_method": {
            "method": None, "resamples": 0, "strata": None, "seed": None,
            "note": "no interval: not computed for a many-parameter solve"}, "E_ci": None, "comparisons": []}
        r_ci = ci.get("r_star_ci")
        return {k: ci[k] for k in ("ci_level", "ci_method", "E_ci")} | {
            "r_star_ci": None if r_ci is None else (r_ci if isinstance(r_ci, dict) else {self.param: list(r_ci)}),
            "comparisons": ci["comparisons"]} | (
            {"target_ci": ci["target_ci"]} if "target_ci" in ci else {})

    def _breakdown_of(self) -> dict[str, Any]:
        """result.json's "breakdown_of" and "E_pooled": which value the breakdown is of."""
        of = "E_ref" if self.breakdown and "E_ref" in self.breakdown else "E_hard"
        return {"breakdown_of": of, "E_pooled": (self.breakdown or {}).get(of)}

    def _box_json(self) -> dict[str, Any]:
        """result.json of a many-parameter (box) solve: the same keys where they apply; "sweep",
        "bracket" and the one-parameter keys are empty or null, and "box" holds the solve."""
        b = self.box
        out = {
            "sensor": self.sensor, "params": {k: list(v) for k, v in self.params.items()}, "units": dict(self.units),
            "param": None, "interval": None, "r_star": dict(self.r_star), "E_soft_star": self.E_soft_star,
            "E_hard_star": self.E_hard_star, "reference": self.reference, "judged": self.judged, **self._intervals_json(), "sweep": [], "evaluations": self.evaluations,
            "programs_run": self.programs_run, "wall_s": dict(self.wall_s), "on_bound": self.on_bound,
            "bracket": None, "tau_schedule": list(b.tau_schedule), "notes": list(self.box_notes),
            "objective": self.config.get("objective", "eq12"), **self._breakdown_of(),
            "by_scenario": (self.breakdown or {}).get("by_scenario"),
            "by_horizon": (self.breakdown or {}).get("by_horizon"),
            "coverage": (self.breakdown or {}).get("coverage"), "tracked": self.tracked,
            "near_optimal": None, "flags": [f"{n}:on_{side}_bound" for n, side in b.on_bound.items() if side],
            "domain": self.domain, "sensitivity": self.sensitivity, "scenarios": list(self.scenarios),
            "config": self.config, "versions": versions(),
            "box": {"J_star": b.J_star, "cost": b.cost, "cost_weight": b.cost_weight, "gradient": b.gradient,
                    "gradient_E": b.gradient_E, "on_bound": b.on_bound, "source": b.source,
                    "counts": b.counts},
        }
        if self.member_costs is not None:  # the cost per member [currency]
            out["box"]["cost_by_member"] = dict(self.member_costs)
        return json_ready(out)
