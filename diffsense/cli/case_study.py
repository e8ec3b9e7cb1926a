"""The case study's command line: its tables and the paper's statements from results files.

    diffsense case-study benchmarks/results/case_study_shipped.json \
        benchmarks/results/case_study_ngsim.json --figure-dir docs/img
"""

from __future__ import annotations

import argparse

from diffsense.runtime import InputError


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # argparse's usage dump + exit 2 -> our one line + exit 2
        raise InputError(message)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="diffsense case-study",
                description="Print the case study's tables (markdown) and the paper's three statements from the "
                            "JSON files benchmarks/case_study.py writes.")
    p.add_argument("results", nargs="+", help="results files of benchmarks/case_study.py")
    p.add_argument("--figure-dir", action="append", default=[], metavar="DIR",
                   help="also write the paper's Figs. 6 and 7 (PNG) into DIR (repeatable)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from diffsense.report.case_study import print_case_study  # matplotlib: only once the flags are good

    return print_case_study(args.results, args.figure_dir)


if __name__ == "__main__":
    from diffsense.cli import run

    run(main, end_process=True)
