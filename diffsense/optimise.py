"""`python -m diffsense.optimise`: the same as `diffsense optimise` (the command line is diffsense.cli.optimise's).

Only `python -m` runs this file; the library's entry point is the function `diffsense.optimise`,
which importing this module leaves in place (`diffsense/__init__.py`).
"""

if __name__ == "__main__":  # importing the module (never needed) does not import the command line
    from diffsense.cli import run
    from diffsense.cli.optimise import main

    run(main, end_process=True)
