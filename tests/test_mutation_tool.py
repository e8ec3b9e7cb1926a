"""tools/mutation.py's pure parts: the sample's draw and the Wilson interval of its score."""

import importlib.util
import json
import math
import random
import subprocess
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location(
    "mutation_tool", Path(__file__).resolve().parents[1] / "tools" / "mutation.py")
mutation = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(mutation)

NAMES = [f"diffsense.solve._box.x_f__mutmut_{i}" for i in range(1, 301)]


def test_sample_is_n_distinct_names_of_the_population():
    drawn = mutation.draw_sample(NAMES, 70, seed=0)
    assert len(drawn) == 70 == len(set(drawn))
    assert set(drawn) <= set(NAMES)
    assert drawn == sorted(drawn)


def test_same_seed_same_sample_whatever_the_order_of_the_names():
    shuffled = NAMES[::-1][150:] + NAMES[::-1][:150]
    assert mutation.draw_sample(NAMES, 70, seed=3) == mutation.draw_sample(shuffled, 70, seed=3)
    assert mutation.draw_sample(NAMES, 70, seed=3) != mutation.draw_sample(NAMES, 70, seed=4)


def test_sample_of_all_is_all_and_too_many_is_refused():
    assert mutation.draw_sample(NAMES, len(NAMES)) == sorted(NAMES)
    with pytest.raises(ValueError):
        mutation.draw_sample(NAMES, len(NAMES) + 1)


def test_sample_is_uniform():
    # each of 10 names drawn 3 at a time over 2000 seeds: expected 600 draws each, binomial
    # sd sqrt(2000 * 0.3 * 0.7) = 20.5; 5 sd either side
    counts = {name: 0 for name in NAMES[:10]}
    for seed in range(2000):
        for name in mutation.draw_sample(NAMES[:10], 3, seed):
            counts[name] += 1
    assert all(abs(c - 600) < 103 for c in counts.values()), counts


def test_wilson_interval_textbook_values():
    # Newcombe (1998), Stat. Med. 17:857, table I: 81/263 -> 0.2553 to 0.3662 (method 3)
    low, high = mutation.wilson_interval(81, 263)
    assert (round(low, 4), round(high, 4)) == (0.2553, 0.3662)
    # 15/148 -> 0.0624 to 0.1605 and 0/20 -> 0 to 0.1611 from the same table
    assert tuple(round(v, 4) for v in mutation.wilson_interval(15, 148)) == (0.0624, 0.1605)
    low, high = mutation.wilson_interval(0, 20)
    assert low == 0.0 and round(high, 4) == 0.1611


def test_wilson_interval_solves_the_score_equation():
    # the bounds are the two p with (k/n - p)^2 = z^2 p (1 - p) / n
    k, n, z = 63, 70, 1.959963984540054
    for p in mutation.wilson_interval(k, n):
        assert math.isclose((k / n - p) ** 2, z * z * p * (1 - p) / n, rel_tol=1e-9)


def _triage_module():
    spec = importlib.util.spec_from_file_location(
        "mutation_triage", Path(__file__).resolve().parents[1] / "tools" / "mutation_triage.py")
    triage = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(triage)
    return triage


def test_triage_refuses_a_workdir_without_a_run(tmp_path, capsys):
    triage = _triage_module()
    assert triage.main([str(tmp_path), "tests/test_sensor_numerics.py"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "no mutants/ folder" in err and err.count("\n") == 1


def test_triage_refuses_focused_tests_that_do_not_pass_unmutated(tmp_path, capsys):
    # a mistyped test path collects nothing (pytest exit 4): refused, not counted as kills
    triage = _triage_module()
    (tmp_path / "mutants").mkdir()
    assert triage.main([str(tmp_path), "tests/no_such_test_file.py"]) == 2
    assert "do not pass on the unmutated tree" in capsys.readouterr().err


def test_triage_selects_one_modules_unchecked_mutants():
    triage = _triage_module()
    results = {"diffsense.sensors._laws.x_swerling__mutmut_2": "not checked",
               "diffsense.sensors._laws.x_swerling__mutmut_1": "not checked",
               "diffsense.sensors._laws.x_pfa__mutmut_1": "killed",
               "diffsense.sensors._lawsx.x_f__mutmut_1": "not checked",
               "diffsense.sensors._params.xǁRadarParamsǁcheck__mutmut_1": "not checked"}
    assert triage._unchecked(results, "_laws.py") == [
        "diffsense.sensors._laws.x_swerling__mutmut_1", "diffsense.sensors._laws.x_swerling__mutmut_2"]
    assert triage._unchecked(results, "_params") == [
        "diffsense.sensors._params.xǁRadarParamsǁcheck__mutmut_1"]
    assert len(triage._unchecked(results, None)) == 4


def test_triage_reach_runs_a_functions_tests_fastest_first_within_the_budget(tmp_path):
    triage = _triage_module()
    (tmp_path / "mutants").mkdir()
    stats = {"duration_by_test": {"a": 5.0, "b": 1.0, "c": 30.0, "d": 2.0},
             "tests_by_mangled_function_name": {"m.x_f": ["a", "b", "c"], "m.x_g": ["d"]}}
    (tmp_path / "mutants" / "mutmut-stats.json").write_text(json.dumps(stats))
    reaching = triage._reaching(tmp_path, 10.0)
    assert reaching["m.x_f"] == (["b", "a"], False)  # c would pass the 10 s budget
    assert reaching["m.x_g"] == (["d"], True)
    assert triage._reaching(tmp_path, 0.5)["m.x_f"] == (["b"], False)  # at least one test
    assert triage._run_planned(tmp_path, "m.x_h__mutmut_1", ([], True), 1.0) == "no tests"
    assert triage._fastest(tmp_path, 2) == ["b", "d"]  # the unmutated check of --reach


def test_triage_with_a_compile_cache_first_runs_every_planned_test_unmutated_with_it(tmp_path, monkeypatch):
    triage = _triage_module()
    (tmp_path / "mutants").mkdir()
    stats = {"duration_by_test": {"a": 5.0, "b": 1.0, "c": 30.0, "d": 2.0},
             "tests_by_mangled_function_name": {"m.x_f": ["a", "b", "c"], "m.x_g": ["d"]}}
    (tmp_path / "mutants" / "mutmut-stats.json").write_text(json.dumps(stats))
    monkeypatch.setattr(triage, "_results", lambda w: {"m.x_f__mutmut_1": "not checked",
                                                       "m.x_g__mutmut_1": "not checked"})
    monkeypatch.setattr(triage, "_diff", lambda w, n: "")
    runs = []

    def fake_run(cmd, cwd, env, capture_output, timeout):
        runs.append((cmd[cmd.index("not slow") + 1:], env.get("MUTANT_UNDER_TEST"),
                     env.get("JAX_COMPILATION_CACHE_DIR"), env.get("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS")))
        return subprocess.CompletedProcess(cmd, 1 if "MUTANT_UNDER_TEST" in env else 0, b"", b"")

    monkeypatch.setattr(triage.subprocess, "run", fake_run)
    cache = str((tmp_path / "cache").resolve())
    assert triage.main([str(tmp_path), "--reach", "10", "--jobs", "1", "--compile-cache", cache]) == 0
    # the three fastest without the cache, then every planned test (c is past the budget) with it
    assert runs[:2] == [(["b", "d", "a"], None, None, None), (["a", "b", "d"], None, cache, "0")]
    assert sorted(runs[2:]) == [(["b", "a"], "m.x_f__mutmut_1", cache, "0"), (["d"], "m.x_g__mutmut_1", cache, "0")]
    assert "(a shared compilation cache)" in (tmp_path / "triage.md").read_text()


def test_triage_resumes_from_an_interrupted_runs_log(tmp_path, monkeypatch):
    triage = _triage_module()
    (tmp_path / "mutants").mkdir()
    names = ["m.x_f__mutmut_1", "m.x_f__mutmut_2", "m.x_f__mutmut_3"]
    monkeypatch.setattr(triage, "_results", lambda w: {n: "not checked" for n in names})
    monkeypatch.setattr(triage, "_diff", lambda w, n: "")
    log = tmp_path / "old.err"
    log.write_text("1/3 m.x_f__mutmut_2: killed\n2/3 m.x_f__mutmut_3: not killed within budget\n"
                   "2/3 m.x_g__mutmut_9: killed\nTraceback (most recent call last):\n")
    runs = []

    def fake_run(cmd, cwd, env, capture_output, timeout):
        runs.append(env.get("MUTANT_UNDER_TEST"))
        return subprocess.CompletedProcess(cmd, 1 if "MUTANT_UNDER_TEST" in env else 0, b"", b"")

    monkeypatch.setattr(triage.subprocess, "run", fake_run)
    assert triage.main([str(tmp_path), "tests/test_x.py", "--resume", str(log)]) == 0
    assert runs == [None, "m.x_f__mutmut_1"]  # the unmutated check, then only the unfinished one
    report = (tmp_path / "triage.md").read_text()
    assert "killed: 2, survived: 0, not killed within budget: 1" in report
    assert "m.x_f__mutmut_3 (not killed within budget)" in report


def test_triage_wants_focused_tests_or_reach_but_not_both(tmp_path, capsys):
    triage = _triage_module()
    assert triage.main([str(tmp_path)]) == 2
    assert triage.main([str(tmp_path), "tests/test_x.py", "--reach", "60"]) == 2
    assert capsys.readouterr().err.count("error: give focused tests or --reach") == 2


def test_triage_counts_a_broken_conftest_or_test_module_as_a_kill_and_a_missing_path_as_an_error():
    triage = _triage_module()
    assert triage._status(4, b"ImportError while loading conftest '/x/tests/conftest.py'.") == "killed"
    assert triage._status(4, b"ERROR tests/test_fusion.py - TypeError\nERROR: found no collectors for "
                                b"tests/test_fusion.py::test_fuse_by_hand") == "killed"
    assert triage._status(4, b"ERROR: file or directory not found: tests/nope.py") == "error"
    assert triage._status(4, b"ERROR: not found: tests/test_fusion.py::test_nope\n"
                             b"(no match in any of [<Module test_fusion.py>])") == "error"
    assert [triage._status(rc, b"") for rc in (0, 1, 2, 5)] == ["survived", "killed", "killed", "error"]


def test_triage_sample_runs_a_seeded_uniform_subset_and_says_so(tmp_path, monkeypatch, capsys):
    triage = _triage_module()
    (tmp_path / "mutants").mkdir()
    names = [f"m.x_f__mutmut_{i}" for i in range(1, 41)]
    monkeypatch.setattr(triage, "_results", lambda w: {n: "not checked" for n in names} | {"m.x_g__mutmut_1": "killed"})
    monkeypatch.setattr(triage, "_diff", lambda w, n: "")
    ran = []

    def fake_run(cmd, cwd, env, capture_output, timeout):
        if "MUTANT_UNDER_TEST" in env:
            ran.append(env["MUTANT_UNDER_TEST"])
        return subprocess.CompletedProcess(cmd, 1 if "MUTANT_UNDER_TEST" in env else 0, b"", b"")

    monkeypatch.setattr(triage.subprocess, "run", fake_run)
    assert triage.main([str(tmp_path), "t.py", "--jobs", "1", "--sample", "7", "--seed", "3"]) == 0
    assert sorted(ran) == sorted(random.Random(3).sample(sorted(names), 7))
    assert "Triage of 7 unchecked mutants (a uniform sample of 40, seed 3)" in (tmp_path / "triage.md").read_text()
    first = list(ran)
    ran.clear()
    assert triage.main([str(tmp_path), "t.py", "--jobs", "1", "--sample", "7", "--seed", "4"]) == 0
    assert sorted(ran) != sorted(first)  # another seed, another draw
    ran.clear()
    assert triage.main([str(tmp_path), "t.py", "--jobs", "1", "--sample", "40"]) == 0
    assert len(ran) == 40 and "uniform sample" not in (tmp_path / "triage.md").read_text()
    capsys.readouterr()
    assert triage.main([str(tmp_path), "t.py", "--sample", "0"]) == 2
    assert capsys.readouterr().err.startswith("error: --sample must be a positive")
