"""`diffsense case-study`: the case study's tables and the paper's statements from results files.

    diffsense case-study benchmarks/results/case_study_shipped.json \
        benchmarks/results/case_study_ngsim.json --figure-dir docs/img
"""

from __future__ import annotations

import argparse

from diffsense.cli import Parser

PROG = "diffsense case-study"


def _parser(prog: str) -> argparse.ArgumentParser:
    p = Parser(prog=prog, description="Print the case study's tables (markdown) and the paper's three statements "
                                      "from the JSON files benchmarks/case_study.py writes.")
    p.add_argument("results", nargs="+", help="results files of benchmarks/case_study.py")
    p.add_argument("--figure-dir", action="append", default=[], metavar="DIR",
                   help="also write the paper's Figs. 6 and 7 (PNG) into DIR (repeatable)")
    return p


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    args = _parser(prog).parse_args(argv)
    from diffsense import report  # start-up: matplotlib's figures, only once the flags are good

    return report.print_case_study(args.results, args.figure_dir)
