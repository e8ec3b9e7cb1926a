"""`target_ci` (`ds.Problem(target_ci=M)`, `--target-ci M`): the one-parameter job doubles the
variants until the decision's interval (second-best step against the best, paired) has a
half-width under M or excludes 0, up to a cap, and says in result.json's "target_ci" how many it
used. A small radar problem (sc01 + sc03, threshold law, two close steps): a loose target is met
at the first count, a tight one doubles."""

from __future__ import annotations

import pytest

import diffsense as ds
from diffsense.cli.optimise import _parser, problems
from tests._laws import THRESHOLD


def _problem(target: float) -> ds.Problem:
    return ds.Problem(params={"hfov_deg": (30.0, 150.0)}, scenarios=["sc01", "sc03"], variants=2,
                      steps=(121.0, 124.0), sensor_config=THRESHOLD["radar"], target_ci=target)


def _record(target: float, lines: list[str]) -> dict:
    result = ds.optimise(_problem(target), figures=False, judge=False, max_variants=4, progress=lines.append)
    out = result.to_json()
    assert out["config"]["target_ci"] == target and out["config"]["variants"] == out["target_ci"]["variants_used"]
    return out["target_ci"]


def test_a_loose_target_is_met_at_the_first_count():
    lines = []
    got = _record(1000.0, lines)
    assert got["met"] and got["variants_used"] == 2 and [t["variants"] for t in got["tried"]] == [2]
    assert got["half_width_m"] < 1000.0
    assert sum(line.startswith("target CI") for line in lines) == 1


def test_a_tight_target_doubles_the_variants_up_to_the_cap():
    lines = []
    got = _record(1e-9, lines)
    assert [t["variants"] for t in got["tried"]] == [2, 4] and got["variants_used"] == 4 and got["cap"] == 4
    first = got["tried"][0]
    assert not first["clear"] and first["half_width_m"] > 1e-9  # not met at 2: it doubled
    assert got["met"] == got["tried"][-1]["clear"]  # 4 is the cap: met only by a clear decision
    assert "doubling to 4" in "\n".join(lines)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_a_target_must_be_a_positive_finite_half_width(bad):
    with pytest.raises(ds.InputError, match="target_ci"):
        _problem(bad)


def test_the_flag_sets_the_field():
    problem, = problems(_parser().parse_args(["--target-ci", "0.25", "--scenarios", "sc01"]))
    assert problem.traffic.target_ci == 0.25
