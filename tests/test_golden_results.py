"""The main job's answers do not move when the code is reorganised: two small problems' result.json,
stored by the command line before the package was restructured (tests/golden/), must come back
equal, every number of it (r*, E_hard, E_soft, every sweep step, the breakdown, the evaluation
counts, the problem's config), bit for bit.

Same config and seed, same result: a difference here is a change of behaviour, never noise. A change
that is meant to move the numbers (new physics, a new default) re-stores the files and says so. Both
problems name the threshold detection law they were stored under (the physical profile's default
law is now the probabilistic one): choosing it by a sensor config gives the same numbers bit for bit.
"judged" (the answer judged on a fresh seed) was added to the files after they were stored, from the
first run that reported it. The box answer was re-stored when the box solve began to check its
descents' iterates on the hard objective every few steps (`BoxConfig.check_every`): its J fell
from 1.1452 to 1.1443. "breakdown_of" and "E_pooled" (what the breakdown is of, and its pooled
value) were added when the breakdown became that of the value the answer is chosen on, and the box
result's "tracked", null until then, was filled; every other number stayed as stored. The config's
"window_s" and "crossing_at_s" (the windows cut from recorded scenes) were added with the defaults
when recorded windows came to fit the data. The intervals from the scene sample ("ci_level",
"ci_method", "E_ci", "comparisons", each sweep entry's "E_ci" and near_optimal's
"indistinguishable") were added from the first run that reported them; every number stored
before stayed as it was (the box answer, of one variant per scenario, has none: null, [] and a
note). The config's "target_ci" (the decision's interval to reach by adding variants) was added
with its default, null; the comparisons' "ci_unpaired" were re-stored when the intervals became
the expanded percentile ones (the paired ones, at 2 variants the resamples' extremes, stayed).
"r_star_ci" (how far r* would move with other traffic: null for the box answer), ci_method's
"r_star", "r_star_points" and "r_star_resolution", and each comparison's "of" ("sweep") were added
from the first run that reported them; every other number stayed as stored. So were the
breakdown parts' "E_ci" (each scenario, coverage part and horizon step), the judged value's
"E_ci", and the box answer's interval keys (its comparison with the default suite; one variant:
no interval).
r*'s interval and ci_method's "r_star", "r_star_points" and "r_star_resolution" were re-stored
when the interval came to add points where the resamples' picks fall (the line answer's went from
[40.73, 60] over 9 points to [36.67, 70] over 17), and programs_run gained "intervals" (those
points' programs); every other number stayed as stored. ci_method's "r_star_caveat" (r*'s interval
is a lower bound where r* is chosen on E_hard) was added from the first run that reported it.
When a many-parameter answer's r* came to have an interval along each parameter's axis, the box
file's programs_run gained "intervals" (zero: one variant per scenario gives no interval) and its
ci_method's "r_star" came to read "not estimated" (later with how to ask for it); the config's
box gained "r_star_axes" with its default, false; every other number stayed as stored.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

GOLDEN = Path(__file__).parent / "golden"
ROOT = Path(__file__).resolve().parents[1]

# The keys that describe the run rather than its answer: timings and the installed versions.
NOT_ANSWERS = ("wall_s", "versions")

CASES = {
    "line": ["--param", "hfov", "--interval", "30", "180", "--scenarios", "sc01,sc04", "--variants", "2",
             "--sensor-config", "configs/sensors/laws/radar_threshold.toml"],
    "box": ["--suite", "tests/golden/radar_camera_d4_threshold.toml", "--scenarios", "sc01", "--variants", "1"],
}


def _differences(got, want, path="") -> list[str]:
    """Every place where `got` differs from `want` (a float must be the same float)."""
    if isinstance(want, dict):
        if not isinstance(got, dict) or set(got) != set(want):
            return [f"{path}: keys {sorted(got) if isinstance(got, dict) else got!r} != {sorted(want)}"]
        return [d for k in want for d in _differences(got[k], want[k], f"{path}.{k}")]
    if isinstance(want, list):
        if not isinstance(got, list) or len(got) != len(want):
            return [f"{path}: {got!r} != {want!r}"]
        return [d for i, (g, w) in enumerate(zip(got, want)) for d in _differences(g, w, f"{path}[{i}]")]
    return [] if got == want and type(got) is type(want) else [f"{path}: {got!r} != {want!r}"]


# The box case compiles a suite's programs at XLA's full optimisation (a minute on two cores):
# slow; the line case keeps the fast suite's guard.
@pytest.mark.parametrize("case", [pytest.param("box", marks=pytest.mark.slow), "line"])
def test_result_json_is_the_stored_one(case, tmp_path):
    # The answer a user gets: XLA's full optimisation (the suite compiles at level 0, whose
    # float32 arithmetic rounds differently), and no persistent cache the suite did not make.
    env = dict(os.environ, JAX_DISABLE_MOST_OPTIMIZATIONS="0", DIFFSENSE_NO_CACHE="1")
    done = subprocess.run([sys.executable, "-m", "diffsense.optimise", *CASES[case], "--out", str(tmp_path), "--quiet"],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    got = json.loads((tmp_path / "result.json").read_text())
    want = json.loads((GOLDEN / f"{case}_result.json").read_text())
    for key in NOT_ANSWERS:
        got.pop(key, None)
    differences = _differences(got, want)
    assert not differences, f"{len(differences)} differences, the first: " + "; ".join(differences[:5])
