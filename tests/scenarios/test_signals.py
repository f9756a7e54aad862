"""Real signals in the middle of a run (a subprocess of the grindtwin command): one line, the
exit code of the signal, no traceback, and nothing left that looks like a result."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tests.scenarios.test_runner import short_pyrite_scene

ROOT = Path(__file__).resolve().parents[2]
COMMAND = [sys.executable, "-c", "import sys; from scenarios.cli import main; sys.exit(main())"]
#: Long enough (an open loop of 200 h at one-minute samples) that the signal lands mid-sweep.
LONG_H = 200.0
#: A single run 10x longer: 200 h ran in about a second on a quiet machine, and the run ended
#: before the signal.
RUN_LONG_H = 2000.0


class Running:
    """The command in a subprocess, its stderr collected as it comes (the progress bar)."""

    def __init__(self, args):
        self.proc = subprocess.Popen([*COMMAND, *map(str, args)], cwd=ROOT, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self.err = ""
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in iter(lambda: self.proc.stderr.read(64), ""):
            self.err += line

    def wait_for_progress(self, timeout_s: float = 120.0):
        """Until the progress bar has moved (the run is integrating), then a moment more."""
        deadline = time.monotonic() + timeout_s
        while "sample/s" not in self.err and "case/s" not in self.err and "it/s" not in self.err:
            assert self.proc.poll() is None, self.err
            assert time.monotonic() < deadline, "no progress: " + self.err
            time.sleep(0.05)
        time.sleep(0.5)
        assert self.proc.poll() is None, "the run ended before the signal: make it longer"

    def finish(self, sig) -> tuple[int, str]:
        self.proc.send_signal(sig)
        self.proc.wait(timeout=120)
        self._reader.join(timeout=10)
        self.proc.stdout.close()
        self.proc.stderr.close()
        return self.proc.returncode, self.err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_mid_run_leaves_nothing_that_looks_complete(tmp_path, sig):
    scene = short_pyrite_scene(tmp_path, duration_h=RUN_LONG_H)
    out = tmp_path / "out"
    run = Running(["run", scene, "--out", out])
    run.wait_for_progress()
    code, err = run.finish(sig)
    assert code == 128 + sig, err
    assert "Traceback" not in err
    assert f"interrupted by {sig.name}" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["short.toml"]  # no out, .partial or .lock


def test_ctrl_c_in_a_sweep_stops_its_workers_without_tracebacks(tmp_path):
    scene = short_pyrite_scene(tmp_path, duration_h=LONG_H)
    out = tmp_path / "sweep"
    run = Running(["sweep", scene, "--vary", "feed.feed_tph=24,30,36", "--workers", "2", "--out", out])
    run.wait_for_progress()  # the sweep's bar shows "0/3 [00:00<?, ?case/s]" when the cases start
    t0 = time.monotonic()
    code, err = run.finish(signal.SIGINT)
    assert code == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert time.monotonic() - t0 < 60  # the workers were stopped, not waited for
    assert sorted(p.name for p in tmp_path.iterdir()) == ["short.toml"]


def test_an_interrupted_sweep_keeps_the_cases_that_finished(tmp_path):
    """A sweep stopped after its short case finished, its long ones running: the finished case was lost with
    the rest (hours of cases, for a Ctrl-C); now the folder is written whole with it, the others' error says
    they did not run, and the exit code and message are the signal's."""
    import pandas as pd

    from scenarios.run.sweep import NOT_RUN

    scene = short_pyrite_scene(tmp_path, duration_h=RUN_LONG_H)
    out = tmp_path / "sweep"
    minute = 1 / 60  # the scene's sample period; the first case samples every 20 h, 100 samples in all
    run = Running(["sweep", scene, "--vary", f"scene.sample_period_h=20,{minute!r},{minute!r}", "--workers", 2,
                   "--out", out])
    deadline = time.monotonic() + 180
    while not re.search(r"sweep:[^\r\n]*1/3", run.err):  # the short case has finished
        assert run.proc.poll() is None and time.monotonic() < deadline, run.err
        time.sleep(0.05)
    code, err = run.finish(signal.SIGINT)
    assert code == 130, err
    assert "Traceback" not in err, err
    done = re.search(r"the (\d) of 3 cases that finished were written", err)
    assert done, err
    table = pd.read_csv(out / "sweep.csv")
    ran = table["error"].isna()
    assert ran[0] and ran.sum() == int(done.group(1)) < 3, err  # the short case, and any long one that finished
    assert (table["error"][~ran] == NOT_RUN).all()
    assert table["duration_h"][ran].eq(RUN_LONG_H).all() and table["duration_h"][~ran].isna().all()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["short.toml", "sweep"]  # no .partial or .lock


def test_a_signal_inside_a_serial_cases_solver_is_not_that_cases_failure(tmp_path, monkeypatch, capsys):
    """One worker: the first case runs, a SIGINT lands inside the second's solver call (CasADi lets it out as
    another exception, recorded by the handler): the case was recorded as failed with that error and the sweep
    went on to the next; now it stops there, the first case written, the others not run."""
    import pandas as pd

    from scenarios.cli import commands, main
    from scenarios.errors import RECEIVED_SIGNALS
    from scenarios.run.sweep import NOT_RUN

    calls, real = [], commands.sweep_case

    def case(scene):
        calls.append(scene)
        if len(calls) == 2:
            RECEIVED_SIGNALS.append(signal.SIGINT)  # what the CLI's handler does before the solver's error
            raise RuntimeError("casadi: Error in Function::call for 'F' [IdasInterface]: interrupted")
        return real(scene)

    monkeypatch.setattr(commands, "sweep_case", case)
    scene = short_pyrite_scene(tmp_path, duration_h=0.5)
    out = tmp_path / "sweep"
    code = main(["sweep", str(scene), "--vary", "feed.feed_tph=24,30,36", "--workers", "1", "--out", str(out),
                 "--quiet"])
    assert code == 130 and len(calls) == 2
    assert "the 1 of 3 cases that finished were written" in capsys.readouterr().err
    table = pd.read_csv(out / "sweep.csv")
    assert table["error"].isna().tolist() == [True, False, False] and (table["error"][1:] == NOT_RUN).all()


def _quick_case(x):
    return {"x": x}


@pytest.mark.parametrize("on", ["process pool", "dask cluster"])
def test_a_pools_finished_but_uncollected_cases_are_kept_on_a_signal(monkeypatch, on):
    """With worker processes, a signal while the sweep collected one finished case labelled the others that had
    finished meanwhile, not yet collected, "not run" (their results lost): now every finished case is kept, on a
    Dask cluster too. The signal comes at the first collection, a second after it, when all four quick cases are
    done."""
    import distributed

    from scenarios.run import sweep

    class SignalAtFirstUpdate:
        def __init__(self, *args, **kwargs):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def update(self, n=1):
            time.sleep(1.0)  # the other workers' cases finish meanwhile
            raise KeyboardInterrupt

    monkeypatch.setattr(sweep, "tqdm", SignalAtFirstUpdate)
    outcomes = [(None, sweep.NOT_RUN)] * 4
    with pytest.raises(KeyboardInterrupt):
        if on == "process pool":
            sweep._run_local(_quick_case, [0, 1, 2, 3], 2, False, outcomes)
        else:
            with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                          dashboard_address=None) as cluster:
                sweep._run_dask(_quick_case, [0, 1, 2, 3], cluster, False, outcomes)
    assert sorted(o[0]["x"] for o in outcomes) == [0, 1, 2, 3] and all(o[1] is None for o in outcomes)


def _hold_the_progress_bars_lock(seconds: float) -> None:
    """A worker inside a progress bar's lock (a disabled bar takes it too) when it is stopped."""
    from tqdm.auto import tqdm

    with tqdm.get_lock():
        time.sleep(seconds)


def test_a_worker_stopped_inside_a_progress_bar_lock_leaves_the_parents_free():
    """A sweep stopped by Ctrl-C hung for good in its bar's close (seen once in a full test run: the parent's main
    thread and tqdm's monitor both waiting on tqdm's lock): the lock is a multiprocessing one that forked workers
    share, and the sweep terminates its workers, one of them inside it. Workers now lock their own."""
    from concurrent.futures import ProcessPoolExecutor

    from tqdm.auto import tqdm

    from scenarios.run.sweep import _stop_workers, _worker_ignores_signals

    with tqdm(total=1, disable=True):  # the parent's lock exists before the fork, as in a sweep
        pass
    shared = tqdm.get_lock().locks[0]  # tqdm's default: the multiprocessing lock first
    pool = ProcessPoolExecutor(max_workers=1, initializer=_worker_ignores_signals)
    pool.submit(_hold_the_progress_bars_lock, 60.0)
    time.sleep(3.0)  # the worker is inside the lock
    _stop_workers(pool)
    free = shared.acquire(timeout=5)
    if free:
        shared.release()
    assert free


def test_a_sweeps_workers_are_forked_with_the_signals_held(monkeypatch):
    """A Ctrl-C landing between a worker's fork and its initializer raised KeyboardInterrupt in the worker, whose
    traceback reached the terminal (seen in a fresh-clone CI: test_ctrl_c_in_a_sweep... found 'Exception ignored
    in ... logging ... _releaseLock' in stderr). The pool now forks its workers (at its first submit) with SIGINT
    and SIGTERM held, and each worker unholds them once it ignores them."""
    from concurrent.futures import ProcessPoolExecutor

    from scenarios.run import sweep

    held_at_submit = []
    submit = ProcessPoolExecutor.submit

    def recording(self, *args, **kwargs):
        held_at_submit.append(sweep.PARENT_SIGNALS <= signal.pthread_sigmask(signal.SIG_BLOCK, []))
        return submit(self, *args, **kwargs)

    monkeypatch.setattr(ProcessPoolExecutor, "submit", recording)
    outcomes = [(None, sweep.NOT_RUN)] * 2
    sweep._run_local(_quick_case, [0, 1], 2, False, outcomes)
    assert held_at_submit == [True, True] and not sweep.PARENT_SIGNALS & signal.pthread_sigmask(signal.SIG_BLOCK, [])
    assert sorted(o[0]["x"] for o in outcomes) == [0, 1]
