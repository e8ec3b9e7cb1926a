"""A fast first pass over the mutants a `tools/mutation.py` run left unchecked (docs/mutation.md).

    python tools/mutation_triage.py /tmp/mut/X tests/test_sensor_numerics.py tests/test_mounting.py
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
"""

from __future__ import annotations

import argparse
import concurrent.futures
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mutation import _diff, _results  # noqa: E402


def _run_one(mutants: Path, name: str | None, tests: list[str], timeout_s: float) -> str:
    """'killed', 'survived', 'timeout' or 'error' of one mutant (None: none) against the tests.

    Only failing tests (pytest exit 1) or a failed collection (2) count as a kill: a usage error
    or no test collected (4, 5) is an 'error', so a mistyped test path cannot pass as a kill.
    """
    env = {k: v for k, v in os.environ.items() if k != "MUTANT_UNDER_TEST"}
    if name is not None:
        env["MUTANT_UNDER_TEST"] = name
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-m", "not slow",
           *tests]
    try:
        done = subprocess.run(cmd, cwd=mutants, env=env, capture_output=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return "timeout"
    return {0: "survived", 1: "killed", 2: "killed"}.get(done.returncode, "error")


def _unchecked(results: dict[str, str], module: str | None) -> list[str]:
    """The sorted names of the run's unchecked mutants, of one module when `module` is given
    (a file name such as `_laws.py` or `_laws`: mutmut names a mutant `package.module.x_function
    __mutmut_N`, so the module is everything before the last dot)."""
    todo = [n for n, s in results.items() if s == "not checked"]
    if module is not None:
        stem = module.removesuffix(".py")
        todo = [n for n in todo if n.rsplit(".", 1)[0].rsplit(".", 1)[-1] == stem]
    return sorted(todo)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("workdir", type=Path, help="the --workdir of a tools/mutation.py run")
    parser.add_argument("tests", nargs="+", help="focused test files (paths in the repository)")
    parser.add_argument("--jobs", type=int, default=2, help="mutants at a time (default 2)")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per mutant")
    parser.add_argument("--module", help="triage only this file's mutants (e.g. _laws.py)")
    args = parser.parse_args(argv)
    if not (args.workdir / "mutants").is_dir():
        print(f"error: {args.workdir} holds no mutmut run (no mutants/ folder)", file=sys.stderr)
        return 2
    if _run_one(args.workdir / "mutants", None, args.tests, args.timeout) != "survived":
        print(f"error: the focused tests do not pass on the unmutated tree of {args.workdir}",
              file=sys.stderr)
        return 2
    todo = _unchecked(_results(args.workdir), args.module)
    if not todo:
        print(f"error: {args.workdir} has no unchecked mutants"
              + (f" of {args.module}" if args.module else ""), file=sys.stderr)
        return 2
    start = time.monotonic()
    status = {}
    with concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
        futures = {pool.submit(_run_one, args.workdir / "mutants", n, args.tests, args.timeout): n
                   for n in todo}
        for done in concurrent.futures.as_completed(futures):
            status[futures[done]] = done.result()
            print(f"{len(status)}/{len(todo)} {futures[done]}: {status[futures[done]]}",
                  file=sys.stderr, flush=True)
    minutes = (time.monotonic() - start) / 60
    counts = {s: sum(v == s for v in status.values()) for s in ("killed", "survived", "timeout", "error")}
    of = f" of {args.module}" if args.module else ""
    lines = [f"# Triage of {len(todo)} unchecked mutants{of} ({minutes:.1f} min)", "",
             "Focused tests: " + " ".join(args.tests), "",
             ", ".join(f"{k}: {v}" for k, v in counts.items()), "", "## Not killed", ""]
    for name in (n for n in todo if status[n] != "killed"):
        lines += [f"### {name} ({status[name]})", "", "```diff", _diff(args.workdir, name), "```", ""]
    out = "triage.md" if args.module is None else f"triage-{args.module.removesuffix('.py')}.md"
    (args.workdir / out).write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
