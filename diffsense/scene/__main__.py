"""`python -m diffsense.scene`: the command line in diffsense.cli.scene."""

from diffsense.cli import run
from diffsense.cli.scene import main

run(main, end_process=True)
