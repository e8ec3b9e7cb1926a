"""The console command and its faces: `diffsense --help` lists the commands; every command's
--help exits 0 under the name the user typed; an unknown command or a bad flag is one `error:`
line naming the command, exit 2; the `python -m` forms and the console scripts run the same
mains; importing `diffsense.optimise` leaves the function `ds.optimise` in place."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import diffsense as ds
from diffsense.cli import case_study, generate, optimise, predict, run, scene, sensors, train
from diffsense.cli._main import main

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ["optimise", "inspect", "scene", "generate", "train", "predict", "case-study"]


def _exit(argv, capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as e:
        run(lambda: main(argv))
    out, err = capsys.readouterr()
    return e.value.code, out, err


def test_help_and_version(capsys):
    code, out, _ = _exit(["--help"], capsys)
    assert code == 0 and [line.split()[0] for line in out.splitlines() if line.startswith("  ")] == COMMANDS
    assert _exit(["--version"], capsys)[:2] == (0, f"diffsense {ds.__version__}\n")


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_s_help_names_it_and_exits_0(command, capsys):
    code, out, err = _exit([command, "--help"], capsys)
    assert (code, err) == (0, "") and out.startswith(f"usage: diffsense {command} ")


@pytest.mark.parametrize("argv, culprit", [
    (["bogus"], "'bogus'"),
    ([], "a command is needed"),
    (["optimise", "--bogus"], "--bogus"),
    (["optimise", "--variants", "many"], "'many'"),
    (["inspect", "--sensor", "sonar"], "'sonar'"),
    (["scene", "draw"], "'draw'"),
    (["generate", "--samples", "5"], "--out"),
    (["train"], "--config"),
    (["predict", "frobnicate"], "'frobnicate'"),
    (["case-study"], "results"),
])
def test_an_unknown_command_or_a_bad_flag_is_one_error_line_exit_2(argv, culprit, capsys):
    code, out, err = _exit(argv, capsys)
    prog = f"diffsense {argv[0]}" if argv and argv[0] in COMMANDS else "diffsense"
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"error: {prog}: ") and culprit in err


@pytest.mark.parametrize("module, argv, prog", [
    (optimise, [], "python -m diffsense.optimise"), (sensors, ["inspect"], "python -m diffsense.sensors inspect"),
    (scene, [], "python -m diffsense.scene"), (scene, ["generate"], "python -m diffsense.scene generate"),
    (generate, [], "python -m diffsense.scene generate"), (train, [], "python -m diffsense.train"),
    (predict, [], "python -m diffsense.predictors"), (case_study, [], "diffsense case-study"),
])
def test_each_main_alone_is_named_as_its_python_m_form(module, argv, prog, capsys):
    with pytest.raises(SystemExit) as e:
        module.main([*argv, "--help"])
    assert e.value.code == 0 and capsys.readouterr().out.startswith(f"usage: {prog} ")


def test_the_faces_in_real_processes():
    """Each face in its own process (started together: each imports the package, seconds apart)."""
    script = Path(sys.executable).with_name("diffsense")
    if not script.is_file():
        pytest.skip("the console scripts are not installed (pip install -e .)")
    shadow = ("import types, diffsense as ds, diffsense.optimise, diffsense.study\n"
              "from diffsense import optimise\n"
              "print(type(ds.optimise).__name__, optimise is ds.optimise is diffsense.study.optimise,"
              " isinstance(ds.optimise, types.ModuleType))\n")
    runs = {
        "help": [str(script), "--help"],
        "unknown": [sys.executable, "-m", "diffsense.cli", "bogus"],
        "-m optimise": [sys.executable, "-m", "diffsense.optimise", "--bogus"],
        "diffsense-optimise": [str(script.with_name("diffsense-optimise")), "--bogus"],
        "-m train": [sys.executable, "-m", "diffsense.train", "--config", "/no/such.toml"],
        "shadow": [sys.executable, "-c", shadow],
    }
    procs = {k: subprocess.Popen(v, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for k, v in runs.items()}
    done = {k: (p.wait(timeout=300), *p.communicate()) for k, p in procs.items()}
    code, out, err = done["help"]
    assert code == 0 and err == ""
    assert [line.split()[0] for line in out.splitlines() if line.startswith("  ")] == COMMANDS
    for name, prog, culprit in [("unknown", "python -m diffsense.cli", "'bogus'"),
                                ("-m optimise", "python -m diffsense.optimise", "--bogus"),
                                ("diffsense-optimise", "diffsense-optimise", "--bogus"),
                                ("-m train", None, "/no/such.toml")]:
        code, out, err = done[name]
        assert code == 2 and out == "" and err.count("\n") == 1 and culprit in err, (name, err)
        assert err.startswith(f"error: {prog}: " if prog else "error: ") and "Traceback" not in err
    code, out, err = done["shadow"]
    assert code == 0, err
    assert out.split() == ["function", "True", "False"]  # importing the -m module shadows nothing
