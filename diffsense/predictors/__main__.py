"""`python -m diffsense.predictors`: the command line in diffsense.cli.predict."""

from diffsense.cli import run
from diffsense.cli.predict import main

run(main, end_process=True)
