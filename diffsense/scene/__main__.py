"""`python -m diffsense.scene`: the same as `diffsense scene` (the command line is diffsense.cli.scene's)."""

from diffsense.cli import run
from diffsense.cli.scene import main

run(main, end_process=True)
