"""Mutation testing of one package with mutmut, by hand (too slow for CI): docs/mutation.md.

    python tools/mutation.py sensors                  # every file of diffsense/sensors/
    python tools/mutation.py sensors --files _camera.py _radar.py
    python tools/mutation.py solve --rev HEAD~1 --max-children 2
    python tools/mutation.py metrics --sample 70 --seed 0   # a uniform sample of the mutants

The commit `--rev` (default HEAD: commit first) is exported with `git archive` into a scratch
directory, so edits in the working tree during the run change nothing. There the `[mutmut]`
section of setup.cfg is completed from the package's `[mutmut:PACKAGE]` section (the files to
mutate and a fast, relevant test subset) and `mutmut run` mutates the package, running for each
mutant only the selected tests that reach the mutated function. The summary (counts per file and
every surviving mutant's diff) is printed and written to `<workdir>/report.md`; review each
survivor there: kill it with a test or list it in docs/mutation.md as equivalent, with why.

`--sample N` estimates a package's score without running every mutant: a first `mutmut run`
generates all mutants and records the tests' statistics but runs no mutant (it is given a name
that matches none), then N names are drawn uniformly without replacement (from the sorted names,
seeded by `--seed`, so the draw is the same on every machine) and only they are run. The report
gives the sample's killed / survived / other and killed / N with a 95 % Wilson interval.

mutmut's fork server imports only third-party packages (tools/mutation_preload.txt) before it
forks a process per mutant, which imports diffsense and the tests afresh: a process that had
already run the tests would carry jax's compiled functions, traced without the mutation, into
every mutant.
"""

from __future__ import annotations

import argparse
import collections
import configparser
import fnmatch
import json
import math
import random
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# Every package of diffsense/ (docs/architecture.md); each has a [mutmut:PACKAGE] section in setup.cfg.
PACKAGES = ("runtime", "config", "scene", "sensors", "tracks", "predictors", "metrics", "train", "solve", "study",
            "report", "cli")


# A mutant name pattern that matches no mutant: `mutmut run` with it generates the mutants and
# collects the test statistics, then stops before running any mutant.
_NO_MUTANT = "no-mutant-has-this-name"
_Z95 = 1.959963984540054  # the standard normal's 97.5 % quantile


def draw_sample(names: list[str], n: int, seed: int = 0) -> list[str]:
    """`n` of `names` drawn uniformly without replacement, the same for the same names and seed
    (whatever their order); returned sorted."""
    pool = sorted(set(names))
    if not 0 <= n <= len(pool):
        raise ValueError(f"cannot draw {n} of {len(pool)} mutants")
    return sorted(random.Random(seed).sample(pool, n))


def wilson_interval(successes: int, trials: int, z: float = _Z95) -> tuple[float, float]:
    """The Wilson score interval of a binomial proportion (95 % for the default z)."""
    if trials <= 0 or not 0 <= successes <= trials:
        raise ValueError(f"{successes} successes of {trials} trials")
    p = successes / trials
    z2n = z * z / trials
    centre = (p + z2n / 2) / (1 + z2n)
    half = z / (1 + z2n) * math.sqrt(p * (1 - p) / trials + z2n / (4 * trials))
    return max(0.0, centre - half), min(1.0, centre + half)


def _export(rev: str, workdir: Path) -> str:
    """Unpack commit `rev` of the repository into `workdir`; returns its full hash."""
    commit = subprocess.run(["git", "rev-parse", rev], cwd=ROOT, check=True, capture_output=True,
                            text=True).stdout.strip()
    workdir.mkdir(parents=True)
    archive = subprocess.run(["git", "archive", commit], cwd=ROOT, check=True, capture_output=True)
    subprocess.run(["tar", "-x", "-C", str(workdir)], input=archive.stdout, check=True)
    # The editable install maps the package diffsense._configs to the working tree's configs/:
    # a real package of that name inside the copy shadows it, so the commit's configs are read.
    shutil.copytree(workdir / "configs", workdir / "diffsense" / "_configs")
    (workdir / "diffsense" / "_configs" / "__init__.py").touch()
    return commit


def _folder(package: str) -> str:
    """The package's folder."""
    return f"diffsense/{package}"


def _configure(workdir: Path, package: str, files: list[str]) -> list[str]:
    """Write the scratch setup.cfg's [mutmut] section for `package`; returns the test files."""
    parser = configparser.ConfigParser()
    parser.read(workdir / "setup.cfg")
    section = parser[f"mutmut:{package}"]
    folder = _folder(package)
    patterns = [f"{folder}/{f}" for f in files] if files else [f"{folder}/*"]
    tests = section["tests"].split()
    parser["mutmut"]["only_mutate"] = "\n" + "\n".join(patterns)
    parser["mutmut"]["pytest_add_cli_args_test_selection"] = "\n" + "\n".join(tests)
    for name in list(parser.sections()):
        if name.startswith("mutmut:"):
            parser.remove_section(name)
    with open(workdir / "setup.cfg", "w") as f:
        parser.write(f)
    return tests


def _results(workdir: Path) -> dict[str, str]:
    """mutant name -> status (killed, survived, no tests, timeout, ...) of the last run."""
    out = subprocess.run(["mutmut", "results", "--all", "true"], cwd=workdir, check=True,
                         capture_output=True, text=True).stdout
    pairs = (line.strip().rsplit(": ", 1) for line in out.splitlines() if ": " in line)
    return {name: status for name, status in pairs}


def _diff(workdir: Path, name: str) -> str:
    out = subprocess.run(["mutmut", "show", name], cwd=workdir, capture_output=True, text=True).stdout
    lines = [ln for ln in out.splitlines() if ln[:1] in "+-" and ln[:3] not in ("+++", "---")]
    return "\n".join(lines)


def _sample_lines(results: dict[str, str], population: int, seed: int) -> list[str]:
    """The report's paragraph on a sampled run: its counts and killed / sampled with its
    interval (equivalent mutants are not known yet: the docs correct the score for them)."""
    counts = collections.Counter(results.values())
    n, killed = len(results), counts["killed"]
    low, high = wilson_interval(killed, n)
    return [f"Sample: {n} of {population} mutants, seed {seed}: {killed} killed, "
            f"{counts['survived']} survived, {n - killed - counts['survived']} other "
            f"({', '.join(f'{c} {s}' for s, c in sorted(counts.items()))}).", "",
            f"Score of the sample: {killed} / {n} = {100 * killed / n:.1f} % "
            f"(95 % Wilson interval {100 * low:.1f} % to {100 * high:.1f} %), before "
            "equivalent mutants are taken out.", ""]


def _report(workdir: Path, package: str, commit: str, tests: list[str], command: str,
            wall_s: float, names: list[str] | None = None, sample: tuple[int, int] | None = None,
            ) -> str:
    """The report of the run: of the mutants in `names` if given (a sample or --mutants), with
    the sample's paragraph if `sample` = (all mutants, seed)."""
    results = _results(workdir)
    if names:
        wanted = set(names)
        results = {name: status for name, status in results.items()
                   if name in wanted or any(fnmatch.fnmatch(name, w) for w in wanted)}
    by_file: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for name, status in results.items():
        module = name.split(".x_")[0].split(".xǁ")[0]
        by_file[module][status] += 1
    total = collections.Counter(results.values())
    lines = [f"# Mutation run: {_folder(package)} at {commit[:12]}", "",
             f"Command: `{command}` ({wall_s / 60:.1f} min)", "",
             f"Tests: {' '.join(tests)}", ""]
    if sample is not None:
        lines += _sample_lines(results, *sample)
    lines += ["| module | mutants | killed | survived | other |", "|---|---|---|---|---|"]
    for module, counts in sorted(by_file.items()):
        other = sum(counts.values()) - counts["killed"] - counts["survived"]
        lines.append(f"| {module} | {sum(counts.values())} | {counts['killed']} | "
                     f"{counts['survived']} | {other} |")
    lines += ["", f"Total: {sum(total.values())} mutants, " +
              ", ".join(f"{n} {s}" for s, n in sorted(total.items())), "", "## Survivors", ""]
    for name, status in sorted(results.items()):
        if status == "survived":
            lines += [f"### {name}", "```diff", _diff(workdir, name), "```", ""]
    others = sorted(f"{name} ({status})" for name, status in results.items()
                    if status not in ("killed", "survived"))
    lines += ["## Neither killed nor survived", ""] + [f"- {name}" for name in others]
    return "\n".join(lines)


def _parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("package", choices=PACKAGES)
    parser.add_argument("--files", nargs="*", default=[], help="file names inside the package")
    parser.add_argument("--rev", default="HEAD", help="commit to test (default HEAD)")
    parser.add_argument("--workdir", type=Path, help="scratch directory (default: a new temp dir)")
    parser.add_argument("--max-children", type=int, default=1, help="parallel mutants (default 1)")
    parser.add_argument("--mutants", nargs="*", default=[],
                        help="run only these mutants (names from an earlier report; the names "
                             "hold while the package's source is unchanged), e.g. to re-check "
                             "survivors after adding tests")
    parser.add_argument("--sample", type=int, metavar="N",
                        help="run only N mutants drawn uniformly from all of them (an estimate)")
    parser.add_argument("--seed", type=int, default=0, help="seed of --sample's draw (default 0)")
    parser.add_argument("--report-only", action="store_true",
                        help="only (re)write the report of the finished run in --workdir")
    args = parser.parse_args(argv)
    if args.report_only and args.workdir is None:
        parser.error("--report-only needs the --workdir of the run")
    if args.sample is not None and (args.mutants or args.sample < 1):
        parser.error("--sample takes N >= 1, and no --mutants")
    return args


def _draw(workdir: Path, args: argparse.Namespace) -> tuple[list[str], int]:
    """Generate every mutant and the test statistics without running a mutant, then draw the
    sample; returns its names and the number of mutants."""
    subprocess.run(["mutmut", "run", "--max-children", str(args.max_children), _NO_MUTANT],
                   cwd=workdir)  # fails on purpose once the statistics are saved: no name matches
    names = list(_results(workdir))
    names = draw_sample(names, min(args.sample, len(names)), args.seed)
    population = len(_results(workdir))
    (workdir / "sample.json").write_text(json.dumps(
        {"population": population, "seed": args.seed, "names": names}, indent=1))
    return names, population


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    if shutil.which("mutmut") is None:
        print("error: mutmut is not installed (pip install -e '.[mutation]')", file=sys.stderr)
        return 2
    command = "python tools/mutation.py " + " ".join(argv if argv is not None else sys.argv[1:])
    if args.report_only:
        tests = configparser.ConfigParser()
        tests.read(args.workdir / "setup.cfg")
        drawn = args.workdir / "sample.json"
        drawn = json.loads(drawn.read_text()) if drawn.exists() else None
        report = _report(args.workdir, args.package, "(as run)",
                         tests["mutmut"]["pytest_add_cli_args_test_selection"].split(), command, 0.0,
                         drawn["names"] if drawn else args.mutants,
                         (drawn["population"], drawn["seed"]) if drawn else None)
        (args.workdir / "report.md").write_text(report)
        print(report)
        return 0
    workdir = args.workdir or Path(tempfile.mkdtemp(prefix=f"mutation-{args.package}-")) / "tree"
    commit = _export(args.rev, workdir)
    tests = _configure(workdir, args.package, args.files)
    print(f"mutating {_folder(args.package)} of {commit[:12]} in {workdir}", flush=True)
    start = time.perf_counter()
    names, sample = list(args.mutants), None
    if args.sample is not None:
        names, population = _draw(workdir, args)
        sample = (population, args.seed)
        print(f"sample: {len(names)} of {population} mutants (seed {args.seed})", flush=True)
    run = subprocess.run(["mutmut", "run", "--max-children", str(args.max_children), *names],
                         cwd=workdir)
    wall_s = time.perf_counter() - start
    if not (workdir / "mutants" / "mutmut-stats.json").exists():
        print(f"error: mutmut collected no test statistics (exit {run.returncode}): run the "
              f"package's tests in {workdir} to see why", file=sys.stderr)
        return 1
    report = _report(workdir, args.package, commit, tests, command, wall_s, names, sample)
    (workdir / "report.md").write_text(report)
    print(report)
    print(json.dumps({"report": str(workdir / "report.md"), "mutmut_exit": run.returncode}))
    return run.returncode


if __name__ == "__main__":
    sys.exit(main())
