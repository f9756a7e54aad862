"""The exported C controller as a user builds and calls it (gcc, make), against the Python
controller and estimator it was exported from: what it refuses (a preview that is not a blend, a
non-finite input to the estimate, NULL, a replay line of another length), what its statuses mean
in the header and the manifest, the Makefile (an edited header rebuilds, `make clean` leaves a
user's objects), and the out-dir rules (the current folder, an edited export, a user's folder of
a listed name, an unsupported solver refused before any work, no folder left by a failed export)."""

from __future__ import annotations

from pathlib import Path

import pytest

from scenarios.cli import main

REFERENCE = Path(__file__).parents[2] / "scenarios" / "reference_transition.toml"


@pytest.mark.parametrize("solver, qpsol, key", [("ipopt", None, "controller.solver = 'ipopt'"),
                                               ("rti", "hpipm", "controller.qpsol = 'hpipm'")])
def test_a_solver_it_does_not_export_is_refused_before_any_work(tmp_path, monkeypatch, capsys, solver, qpsol, key):
    """A scene with the default solver (IPOPT) built its models and its IPOPT controller (11 s)
    before the refusal, which named neither the key nor the file's setting. Now the scene's key
    and value are named and nothing is built."""
    import scenarios.run.models as models

    text = REFERENCE.read_text().replace('solver = "rti"', f'solver = "{solver}"', 1)
    text = text.replace('qpsol = "condensed"', f'qpsol = "{qpsol}"' if qpsol else "", 1)
    scene = tmp_path / "s.toml"
    scene.write_text(text)

    def no_build(*a, **k):
        raise AssertionError("the models were built before the refusal")

    monkeypatch.setattr(models, "build_models", no_build)
    assert main(["export-controller", str(scene), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert key in err and "controller.solver = 'rti' and controller.qpsol = 'condensed'" in err
    assert not (tmp_path / "x").exists()
