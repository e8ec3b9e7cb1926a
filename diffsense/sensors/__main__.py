"""`python -m diffsense.sensors`: the same as `diffsense sensors` (the command line is diffsense.cli.sensors's)."""

from diffsense.cli import run
from diffsense.cli.sensors import main

run(main, end_process=True)
