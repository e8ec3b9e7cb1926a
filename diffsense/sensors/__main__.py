"""`python -m diffsense.sensors`: the command line in diffsense.cli.sensors."""

from diffsense.cli import run
from diffsense.cli.sensors import main

run(main, end_process=True)
