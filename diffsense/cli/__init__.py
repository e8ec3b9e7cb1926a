"""Every command-line face of diffsense: the only code that knows argv.

One console command, `diffsense COMMAND ...` (`diffsense/cli/_main.py`, also `python -m
diffsense.cli COMMAND ...`); each command's module holds its argparse front-end (built on the one
`Parser`) and a `main(argv, prog) -> int`; the work is the library's. The `python -m` forms run
the same mains:

    diffsense optimise      python -m diffsense.optimise      diffsense.cli.optimise  (also `diffsense-optimise`)
    diffsense inspect       python -m diffsense.sensors inspect   diffsense.cli.sensors
    diffsense scene         python -m diffsense.scene         diffsense.cli.scene
    diffsense generate      python -m diffsense.scene generate    diffsense.cli.generate
    diffsense train         python -m diffsense.train         diffsense.cli.train
    diffsense predict       python -m diffsense.predictors    diffsense.cli.predict
    diffsense case-study                                      diffsense.cli.case_study

Every face runs its main under `run(main)`, the one error contract: bad input (an `InputError`,
a bad flag, an `OSError`) is one `error:` line and exit 2, never a traceback; SIGINT exits 130,
SIGTERM 143.
"""

from diffsense.cli._parser import Parser
from diffsense.cli._progress import Progress
from diffsense.cli._run import run, setup_jax

__all__ = ["Parser", "Progress", "run", "setup_jax"]
