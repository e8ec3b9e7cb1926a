"""`python -m diffsense.cli COMMAND ...`: the `diffsense` console command without its script."""

from diffsense.cli._main import console

console()
