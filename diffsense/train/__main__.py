"""`python -m diffsense.train`: the same as `diffsense train` (the command line is diffsense.cli.train's)."""

from diffsense.cli import run
from diffsense.cli.train import main

run(main, end_process=True)
