"""Every command-line front-end of diffsense: the only code that knows argv.

Each module holds one command's argparse front-end and a `main(argv) -> int`; the work is the
library's. `run(main)` is the shared contract: bad input is one `error:` line and exit 2, never
a traceback; Ctrl-C exits 130.

    python -m diffsense.optimise     diffsense.cli.optimise   (also the `diffsense-optimise` script)
    python -m diffsense.scene        diffsense.cli.scene
    python -m diffsense.sensors      diffsense.cli.sensors
    python -m diffsense.predictors   diffsense.cli.predict
    python -m diffsense.train        diffsense.cli.train
"""

from diffsense.cli._run import run, setup_jax

__all__ = ["run", "setup_jax"]
