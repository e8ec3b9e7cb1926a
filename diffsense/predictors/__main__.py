"""`python -m diffsense.predictors`: the same as `diffsense predict` (the command line is diffsense.cli.predict's)."""

from diffsense.cli import run
from diffsense.cli.predict import main

run(main, end_process=True)
