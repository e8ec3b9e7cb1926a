"""`python -m diffsense.optimise`: the main job's command line, in diffsense.cli.optimise.

Only `python -m` runs this file; the library's entry point is the function `diffsense.optimise`.
"""

if __name__ == "__main__":
    from diffsense.cli import run
    from diffsense.cli.optimise import main

    run(main, end_process=True)
