"""Execute the notebooks top to bottom, in place (the committed outputs) or in fast mode.

    python notebooks/execute.py                 # every notebook, full size, outputs written back
    python notebooks/execute.py 01 03           # the notebooks whose names start with 01, 03
    python notebooks/execute.py --fast          # small shapes (DIFFSENSE_NOTEBOOK_FAST=1), nothing written

Each notebook reads DIFFSENSE_NOTEBOOK_FAST in its parameters cell. A cell that raises stops the
run with the notebook's name and the error; written notebooks are replaced atomically. The
notebooks use only diffsense's public API; notebooks 02 and 03 run their benchmark
(benchmarks/bench_tradeoff.py, bench_baseline.py) as a command and read its --json output.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
FAST_ENV = "DIFFSENSE_NOTEBOOK_FAST"


def notebooks(prefixes: list[str]) -> list[Path]:
    found = sorted(HERE.glob("[0-9][0-9]_*.ipynb"))
    if prefixes:
        found = [p for p in found if any(p.name.startswith(x) for x in prefixes)]
    return found


def execute(path: Path, fast: bool, timeout_s: int = 3600, write: bool = True, extra_code: str = "") -> float:
    """Run one notebook in a fresh kernel with the notebooks folder as working directory;
    returns the wall time [s]. Raises nbclient's CellExecutionError on a failing cell.

    `extra_code` runs as one more cell after the notebook's own (a test reads the kernel's state
    with it); a notebook run with it is never written back.
    """
    import nbclient
    import nbformat

    nb = nbformat.read(path, as_version=4)
    if extra_code:
        if write:
            raise ValueError("a notebook executed with extra_code is not written back")
        nb.cells.append(nbformat.v4.new_code_cell(extra_code))
    old = os.environ.get(FAST_ENV)
    os.environ[FAST_ENV] = "1" if fast else "0"  # the kernel inherits this process's environment
    try:
        t0 = time.perf_counter()
        # A kernel on a loaded 2-core machine can take over nbclient's default 60 s to start.
        nbclient.NotebookClient(nb, timeout=timeout_s, startup_timeout=300, kernel_name="python3",
                                resources={"metadata": {"path": str(HERE)}}).execute()
        wall = time.perf_counter() - t0
    finally:
        if old is None:
            os.environ.pop(FAST_ENV, None)
        else:
            os.environ[FAST_ENV] = old
    if write:
        tmp = path.with_suffix(".ipynb.tmp")
        nbformat.write(nb, tmp)
        os.replace(tmp, path)
    return wall


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("prefixes", nargs="*", help="notebook name prefixes (default: all)")
    p.add_argument("--fast", action="store_true", help="small shapes; outputs not written back")
    p.add_argument("--cell-timeout", type=int, default=3600, metavar="S",
                   help="longest a single cell may run [s] (default 3600)")
    args = p.parse_args()
    paths = notebooks(args.prefixes)
    if not paths:
        print(f"error: no notebook matches {args.prefixes}", file=sys.stderr)
        return 2
    for path in paths:
        wall = execute(path, fast=args.fast, timeout_s=args.cell_timeout, write=not args.fast)
        print(f"{path.name}: executed in {wall:.1f} s" + (" (fast mode, not written)" if args.fast else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
