"""`python -m diffsense.sensors inspect ...`: the same as `diffsense inspect ...` (the command line is diffsense.cli.sensors's)."""

from diffsense.cli import run
from diffsense.cli.sensors import main

run(main, end_process=True)
