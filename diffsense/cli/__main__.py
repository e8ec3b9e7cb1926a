"""`python -m diffsense.cli COMMAND ...`: the `diffsense` console command without its script."""

from diffsense.cli import run
from diffsense.cli._main import main

run(lambda: main(prog="python -m diffsense.cli"), end_process=True)
