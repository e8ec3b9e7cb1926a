"""`python -m diffsense.train`: the command line in diffsense.cli.train."""

from diffsense.cli import run
from diffsense.cli.train import main

run(main, end_process=True)
