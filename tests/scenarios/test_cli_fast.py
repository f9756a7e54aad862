"""The first answers start fast: ``grindtwin --help`` imports neither numpy nor any floor below
the CLI, ``grindtwin steady --surrogate`` answers in plain Python, without numpy, CasADi, SciPy,
pandas, scikit-learn or numba (the wall times are measured in benchmarks/cli_startup.py)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

HEAVY = ("casadi", "scipy", "pandas", "sklearn", "numba", "matplotlib", "pydantic")


def imported_after(argv: list[str]) -> tuple[dict, str]:
    """Top-level modules imported by the grindtwin command ``argv`` in a fresh process, and its stdout."""
    code = ("import json, sys\nfrom scenarios.cli import main\n"
            "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            "sys.stderr.write(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))")
    res = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=120)
    return set(json.loads(res.stderr.strip().splitlines()[-1])), res.stdout


def test_help_imports_no_numerics():
    mods, out = imported_after(["--help"])
    assert "steady" in out and "optimize" in out
    assert not mods & {"numpy", "twin", "mpc", *HEAVY}


@pytest.mark.parametrize("argv", [["steady", "--surrogate", "--ore", "B", "--feed-tph", "0.031", "--speed", "0.70"],
                                  ["steady", "--surrogate", "--blend", "B=0.6,D=0.4", "--json"]])
def test_surrogate_answer_needs_no_numerics(argv):
    mods, out = imported_after(argv)
    assert "surrogate" in out and "p80_um" in out
    assert not mods & {"numpy", *HEAVY}, mods & {"numpy", *HEAVY}


def test_the_twin_answer_does_import_casadi():  # the check above can fail
    mods, out = imported_after(["steady", "--ore", "B", "--feed-tph", "0.031", "--speed", "0.70"])
    assert "casadi" in mods and "p80_um" in out


def test_checking_a_scene_needs_no_python_control():
    """python-control (which loads matplotlib and scipy.signal, over a second) is imported by the
    linear tools that use it, not by every command that reads a scene."""
    mods, out = imported_after(["check", str(Path(__file__).parents[2] / "scenarios" / "reference_transition.toml")])
    assert "mpc" in mods and "ok" in out.lower(), out  # the scene was read and checked
    assert "control" not in mods and "matplotlib" not in mods, mods & {"control", "matplotlib"}


def test_version_is_the_installed_distributions_and_imports_no_numerics():
    from importlib.metadata import version

    mods, out = imported_after(["--version"])
    assert out.startswith(f"grindtwin {version('grindtwin')} (Python ")
    assert not mods & {"numpy", "twin", "mpc", *HEAVY}


def test_a_reader_that_closes_stdout_early_ends_the_command_quietly():
    """``grindtwin steady ... | head -1``: the reader gone before the answer is written ends the
    command with 141 (128 + SIGPIPE) and nothing on stderr, not a 'failed' run."""
    code = "import sys\nfrom scenarios.cli import main\nsys.exit(main(sys.argv[1:]))"
    argv = ["steady", "--surrogate", "--ore", "B", "--feed-tph", "0.031", "--speed", "0.70"]
    with subprocess.Popen([sys.executable, "-c", code, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE) as proc:
        proc.stdout.close()  # before the interpreter has even started: the answer finds no reader
        assert proc.wait(timeout=120) == 141
        assert proc.stderr.read() == b""
