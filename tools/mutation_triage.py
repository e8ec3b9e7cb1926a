"""A fast first pass over the mutants a `tools/mutation.py` run left unchecked (docs/mutation.md).

    python tools/mutation_triage.py /tmp/mut/X tests/test_sensor_geometry.py tests/test_mounting.py
    python tools/mutation_triage.py /tmp/mut/X tests/test_detection_laws.py --module _laws.py

mutmut runs, for each mutant, every selected test that reaches the mutated function. For the
small helpers every model calls (a safe norm, an angle wrap) that is the whole subset, in an order
that puts the tests written for the helper late: even a mutant that fails its helper's own test
takes minutes. This pass runs each unchecked mutant of the workdir (status "not checked") against
a short list of focused tests instead, two at a time, stopping at the first failure, through
mutmut's own switch (`MUTANT_UNDER_TEST` in the workdir's `mutants/` tree, the trampolines mutmut
generated). It writes `<workdir>/triage.md`: the mutants the focused tests kill, and the ones they
do not — those still need `tools/mutation.py ... --mutants NAME` (the whole subset) or a review.
With `--module`, only that file's mutants are triaged (into `triage-<module>.md`), so one
statistics pass over many files serves a triage per file, each with its own focused tests.

With `--reach SECONDS` (and no focused tests), each mutant instead runs the tests that the run's
statistics pass saw reach its function, fastest first, until their recorded durations would pass
SECONDS: mutmut runs the same tests in no particular order. A mutant whose reaching tests all fit
in the budget and pass has survived mutmut's own check; one cut short says so ("not killed
within budget") and needs the rest of its tests or a review.

With `--compile-cache DIR`, every pytest run reads and writes JAX's persistent compilation cache
in DIR. The cache is keyed by the compiled program itself, so a mutant that changes a program
compiles its own, and the programs it leaves alone (scenes, the predictor, other stages) load
instead of compiling: most of a mutant's time otherwise. The check that the tests pass
unmutated then runs every test the mutants will run, filling the cache; a test the warm cache
broke would fail there, not pass as a kill. (The tests that count compilations set a cache
folder of their own.)

With `--sample N` (and `--seed S`, default 0), a uniform random sample of N of the unchecked
mutants is triaged instead of all of them: its score estimates the file's (docs/mutation.md,
"Package-wide estimates"), and its survivors are the ones to review.

A triage prints each mutant's status as it finishes ("12/427 name: killed"); `--resume LOG`
reads those lines from an interrupted run's stderr and triages only the mutants it had not
finished (the report covers all of them; its minutes are the resumed run's).
"""

from __future__ import annotations

import argparse
import collections
import concurrent.futures
import json
import os
import random
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mutation import _diff, _results  # noqa: E402


_CACHE_ENV: dict[str, str] = {}  # set once by --compile-cache, before any run
_STATUSES = ("killed", "survived", "not killed within budget", "timeout", "no tests", "error")


def _run_one(mutants: Path, name: str | None, tests: list[str], timeout_s: float) -> str:
    """'killed', 'survived', 'timeout' or 'error' of one mutant (None: none) against the tests.

    Only failing tests (pytest exit 1), a failed collection (2) or a conftest or test module the
    mutant breaks count as a kill: another usage error or no test collected (4, 5) is an 'error', so a
    mistyped test path cannot pass as a kill.
    """
    env = {k: v for k, v in os.environ.items() if k != "MUTANT_UNDER_TEST"} | _CACHE_ENV
    if name is not None:
        env["MUTANT_UNDER_TEST"] = name
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-m", "not slow",
           *tests]
    try:
        done = subprocess.run(cmd, cwd=mutants, env=env, capture_output=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return "timeout"
    return _status(done.returncode, done.stdout + done.stderr)


def _status(returncode: int, output: bytes) -> str:
    """pytest's exit -> status. A conftest or a test module that cannot be imported (exit 4 when
    tests are named by node id) is a kill too: the tree's tests pass unmutated (the statistics
    pass ran them all; the first check here reruns some), so the mutant broke what they load."""
    broken = (b"ImportError while loading conftest", b"found no collectors for")
    if returncode == 4 and any(b in output for b in broken):
        return "killed"
    return {0: "survived", 1: "killed", 2: "killed"}.get(returncode, "error")


def _stats(workdir: Path) -> dict:
    return json.loads((workdir / "mutants" / "mutmut-stats.json").read_text())


def _fastest(workdir: Path, n: int) -> list[str]:
    """The statistics pass's n fastest tests."""
    duration = _stats(workdir)["duration_by_test"]
    return sorted(duration, key=lambda t: (duration[t], t))[:n]


def _reaching(workdir: Path, budget_s: float) -> dict[str, tuple[list[str], bool]]:
    """mutmut's function name -> (its reaching tests, fastest first, within `budget_s` of
    recorded duration; whether that is all of them), from the run's statistics pass."""
    stats = _stats(workdir)
    duration = stats["duration_by_test"]
    out = {}
    for function, tests in stats["tests_by_mangled_function_name"].items():
        ordered = sorted(tests, key=lambda t: (duration.get(t, 0.0), t))
        chosen, total = [], 0.0
        for test in ordered:
            if chosen and total + duration.get(test, 0.0) > budget_s:
                break
            chosen.append(test)
            total += duration.get(test, 0.0)
        out[function] = (chosen, len(chosen) == len(ordered))
    return out


def _unchecked(results: dict[str, str], module: str | None) -> list[str]:
    """The sorted names of the run's unchecked mutants, of one module when `module` is given
    (a file name such as `_laws.py` or `_laws`: mutmut names a mutant `package.module.x_function
    __mutmut_N`, so the module is everything before the last dot)."""
    todo = [n for n, s in results.items() if s == "not checked"]
    if module is not None:
        stem = module.removesuffix(".py")
        todo = [n for n in todo if n.rsplit(".", 1)[0].rsplit(".", 1)[-1] == stem]
    return sorted(todo)


def _plans(args, todo: list[str]) -> dict[str, tuple[list[str], bool]]:
    """Each mutant's tests and whether they are all the tests that reach it."""
    if args.reach is None:
        return {n: (args.tests, True) for n in todo}  # "survived": the focused tests pass
    reaching = _reaching(args.workdir, args.reach)
    return {n: reaching.get(n.partition("__mutmut_")[0], ([], True)) for n in todo}


def _run_planned(mutants: Path, name: str, plan: tuple[list[str], bool], timeout_s: float) -> str:
    tests, complete = plan
    if not tests:
        return "no tests"
    status = _run_one(mutants, name, tests, timeout_s)
    return "not killed within budget" if status == "survived" and not complete else status


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("workdir", type=Path, help="the --workdir of a tools/mutation.py run")
    parser.add_argument("tests", nargs="*", help="focused test files (paths in the repository)")
    parser.add_argument("--jobs", type=int, default=2, help="mutants at a time (default 2)")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per mutant")
    parser.add_argument("--module", help="triage only this file's mutants (e.g. _laws.py)")
    parser.add_argument("--reach", type=float, metavar="SECONDS",
                        help="instead of focused tests: each mutant's reaching tests, fastest first")
    parser.add_argument("--compile-cache", type=Path, metavar="DIR",
                        help="share JAX's persistent compilation cache in DIR across the runs")
    parser.add_argument("--resume", type=Path, metavar="LOG",
                        help="take the statuses an interrupted triage printed (its stderr) as done")
    parser.add_argument("--sample", type=int, metavar="N", help="triage N mutants drawn at random")
    parser.add_argument("--seed", type=int, default=0, help="seed of --sample's draw (default 0)")
    args = parser.parse_args(argv)
    _CACHE_ENV.clear()
    if args.sample is not None and args.sample < 1:
        print(f"error: --sample must be a positive number of mutants, got {args.sample}", file=sys.stderr)
        return 2
    if (args.reach is None) == (not args.tests):
        print("error: give focused tests or --reach SECONDS (one of the two)", file=sys.stderr)
        return 2
    if not (args.workdir / "mutants").is_dir():
        print(f"error: {args.workdir} holds no mutmut run (no mutants/ folder)", file=sys.stderr)
        return 2
    # A broken tree would pass as every mutant killed: its tests must pass unmutated first
    # (with --reach, the statistics pass's three fastest tests).
    check = args.tests if args.reach is None else _fastest(args.workdir, 3)
    if not _passes_unmutated(args, check):
        return 2
    todo = _unchecked(_results(args.workdir), args.module)
    if not todo:
        print(f"error: {args.workdir} has no unchecked mutants"
              + (f" of {args.module}" if args.module else ""), file=sys.stderr)
        return 2
    unchecked = len(todo)
    if args.sample is not None and args.sample < unchecked:
        todo = sorted(random.Random(args.seed).sample(todo, args.sample))
    plans = _plans(args, todo)
    if args.compile_cache is not None:
        _CACHE_ENV.update(JAX_COMPILATION_CACHE_DIR=str(args.compile_cache.resolve()),
                          JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0",
                          JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES="0")
        # Every planned test, unmutated, with the cache: fills it, and shows it breaks none.
        if not _passes_unmutated(args, sorted({t for tests, _ in plans.values() for t in tests})):
            return 2
    start = time.monotonic()
    status = _resumed(args.resume, todo) if args.resume is not None else {}
    with concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
        futures = {pool.submit(_run_planned, args.workdir / "mutants", n, plans[n], args.timeout): n
                   for n in todo if n not in status}
        for done in concurrent.futures.as_completed(futures):
            status[futures[done]] = done.result()
            print(f"{len(status)}/{len(todo)} {futures[done]}: {status[futures[done]]}",
                  file=sys.stderr, flush=True)
    _write_report(args, todo, status, (time.monotonic() - start) / 60, unchecked)
    return 0


def _resumed(log: Path, todo: list[str]) -> dict[str, str]:
    """The statuses of `todo`'s mutants that an interrupted triage printed ("i/n name: status")."""
    done = {}
    for line in log.read_text().splitlines():
        name, sep, status = line.partition(" ")[2].partition(": ")
        if sep and name in todo and status in _STATUSES:
            done[name] = status
    return done


def _passes_unmutated(args, tests: list[str]) -> bool:
    if _run_one(args.workdir / "mutants", None, tests, args.timeout * 4) == "survived":
        return True
    print(f"error: the tests do not pass on the unmutated tree of {args.workdir}", file=sys.stderr)
    return False


def _write_report(args, todo: list[str], status: dict[str, str], minutes: float, unchecked: int) -> None:
    counts = collections.Counter(status.values())
    of = f" of {args.module}" if args.module else ""
    tests = (f"each mutant's reaching tests, fastest first, within {args.reach:g} s"
             if args.reach is not None else " ".join(args.tests))
    if args.compile_cache is not None:
        tests += " (a shared compilation cache)"
    sample = (f" (a uniform sample of {unchecked}, seed {args.seed})" if len(todo) < unchecked else "")
    lines = [f"# Triage of {len(todo)} unchecked mutants{of}{sample} ({minutes:.1f} min)", "",
             "Tests: " + tests, "",
             ", ".join(f"{k}: {counts[k]}" for k in _STATUSES),
             "", "## Not killed", ""]
    for name in (n for n in todo if status[n] != "killed"):
        lines += [f"### {name} ({status[name]})", "", "```diff", _diff(args.workdir, name), "```", ""]
    out = "triage.md" if args.module is None else f"triage-{args.module.removesuffix('.py')}.md"
    (args.workdir / out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
