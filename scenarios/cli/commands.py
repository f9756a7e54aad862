"""The ``grindtwin`` subcommands: run, replay, sweep, check, report, steady, calibrate, serve, plant-server.

Each command is a pair ``add_<name>_parser(subparsers)`` / ``cmd_<name>(args) -> int``, to be
registered in :mod:`scenarios.cli`. Every ``cmd_*`` returns its exit code itself: 0 success,
2 bad input (one clear message on stderr, no traceback), 1 a run that failed (with the
reason), so it behaves the same however it is called.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import re
import signal
import sys
import threading
from pathlib import Path

from scenarios.errors import RECEIVED_SIGNALS, Interrupted, RunError, SceneError


def _fail(kind: str, command: str, exc: BaseException) -> int:
    if kind == "input":
        sys.stderr.write(f"grindtwin: error: {exc}\n")
        return 2
    sys.stderr.write(f"grindtwin: {command} failed: {exc}\n")
    return 1


#: Packages whose exception families the commands map to exit codes: (module, input error, any error).
ERROR_FAMILIES = (("twin.errors", "TwinInputError", "TwinError"), ("mpc.errors", "MpcInputError", "MpcError"),
                  ("dem.errors", "DemInputError", "DemError"))


def _families() -> tuple[tuple, tuple]:
    """(bad-input classes, failed-run classes) of the packages loaded so far: a package that was
    never imported raised nothing (so the CLI imports none of them for this)."""
    bad, failed = [SceneError], [RunError, OSError]
    for module, input_name, base_name in ERROR_FAMILIES:
        mod = sys.modules.get(module)
        if mod is not None:
            bad.append(getattr(mod, input_name))
            failed.append(getattr(mod, base_name))
    return tuple(bad), tuple(failed)


@contextlib.contextmanager
def _signals_unwind(received: list):
    """SIGINT raises KeyboardInterrupt and SIGTERM :class:`Interrupted`, so that a run unwinds
    and removes its partial output; each signal is also appended to ``received``, because a
    signal that lands inside a CasADi call comes out of it as some other exception. The previous
    handlers are restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        received.append(signum)
        raise KeyboardInterrupt if signum == signal.SIGINT else Interrupted(signum)

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def _interrupted(command: str, signum: int, kept: str | None = None) -> int:
    """The exit message of a signal; ``kept``: what was written nonetheless (an interrupted sweep's cases)."""
    written = kept or "no results were written (a partial folder, if any, was removed)"
    sys.stderr.write(f"grindtwin: {command} interrupted by {signal.Signals(signum).name}; {written}\n")
    return 128 + signum  # the shell's convention: 130 for SIGINT, 143 for SIGTERM


def _stdout_closed() -> bool:
    """True when stdout is a pipe its reader has closed (``grindtwin steady | head``): polling its
    write end reports an error (POLLERR; tested on Linux; where poll says nothing the broken pipe
    stays a failed run, as before). Then stdout is pointed at the null device, so that Python's
    own flush at exit does not report it again (the Python docs' note on SIGPIPE)."""
    import select

    try:
        fd = sys.stdout.fileno()
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        closed = any(events & select.POLLERR for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no real stdout (captured), or no poll here
        return False
    if closed:
        os.dup2(os.open(os.devnull, os.O_WRONLY), fd)
    return closed


def _exit_codes(command: str):
    """Map the exception families to exit codes: 2 bad input, 1 failed run, 128 + signal number
    when interrupted (SIGINT, SIGTERM); one line on stderr, no traceback. A reader that closed
    stdout early ends the command quietly with 141 (128 + SIGPIPE, what a shell shows for a
    program stopped that way); any other broken pipe (a socket) is a failed run."""

    def wrap(fn):
        @functools.wraps(fn)
        def inner(args) -> int:
            received = RECEIVED_SIGNALS  # shared with the output's commit, which then writes nothing
            received.clear()
            try:
                with _signals_unwind(received):
                    return fn(args)
            except BaseException as exc:  # noqa: BLE001 - sorted below, anything else re-raised
                kept = getattr(exc, "kept", None)
                if received or isinstance(exc, KeyboardInterrupt):
                    return _interrupted(command, received[0] if received else signal.SIGINT, kept)
                if isinstance(exc, Interrupted):
                    return _interrupted(command, exc.signum, kept)
                if isinstance(exc, BrokenPipeError) and _stdout_closed():
                    return 128 + signal.SIGPIPE
                bad, failed = _families()
                if isinstance(exc, bad):
                    return _fail("input", command, exc)
                if isinstance(exc, failed):
                    return _fail("run", command, exc)
                raise
            finally:  # a later command, or the Python API in the same process, starts without this one's signals
                received.clear()
        return inner
    return wrap


def _value_text(key: str, value) -> str:
    """A KPI on the terminal: n/a when undefined, a share as a percentage that never rounds to 0 or
    100 % (0.99996 printed as "1" said every sample was in the band), else 4 significant digits."""
    from scenarios.output.labels import is_percent, percent_text

    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return percent_text(float(value)) if is_percent(key) else f"{value:.4g}"


def _print_kpis(summary: dict, out=None) -> None:
    out = out or sys.stdout
    out.write(f"{summary['scene']} ({summary.get('mode')}, controller {summary.get('controller')})\n")
    width = max([26, *map(len, summary["kpis"])])
    for key, value in summary["kpis"].items():
        out.write(f"  {key:{width}s} {_value_text(key, value)}\n")
    for warning in summary.get("warnings") or []:
        sys.stderr.write(f"grindtwin: warning: {warning}\n")


def _add_calibration_option(p) -> None:
    p.add_argument("--calibration", metavar="NAME|PATH",
                   help="the calibration the twin runs: a shipped name (dem, the default; table) or a calibration file")


def _calibration_arg(value):
    """``--calibration``: a shipped name as given, a file as an absolute path (scenes resolve
    relative paths against their own folder)."""
    if value is None:
        return None
    return str(Path(value).resolve()) if Path(value).is_file() else value


def _calibrated_twin(blend, mill, calibration):
    """A command's twin: of the effects, size grid and mixers its calibration was fitted with (a file fitted
    with others ran with the defaults and a note, exit 0, where a scene of it is refused). A mill other than
    the calibration's keeps its mixers' shares its own (Calibration.mixers_mismatch)."""
    from twin import SizeGrid, Twin
    from twin.calibration import load_calibration

    cal = load_calibration(calibration)
    return Twin(blend, mill=mill, calibration=cal, effects=list(cal.effects), grid=SizeGrid(**cal.size_grid),
                n_mixers=cal.n_mixers)


def _with_calibration(scene, value):
    """The scene with ``--calibration`` (if given) in place of its own ``calibration``."""
    if value is not None:
        scene.calibration = _calibration_arg(value)
    return scene


def _where_results_went(result) -> None:
    """Say where the results are, or that nothing was written (no --out)."""
    if result.out_dir is not None:
        print(f"results in {result.out_dir}")
    else:
        sys.stderr.write("grindtwin: no --out DIR given: the time series, plots and summary were not written\n")


def _check_output_options(args) -> None:
    """--csv and --xlsx write into --out: refuse them without it, before any work."""
    asked = [f"--{name}" for name in ("csv", "xlsx") if getattr(args, name, False)]
    if asked and not args.out:
        raise SceneError(f"{' and '.join(asked)} write into the results folder: give --out DIR")


def _add_output_options(p) -> None:
    p.add_argument("--out", help="write the results into this folder (created; replaced when complete)")
    p.add_argument("--csv", action="store_true", help="also write timeseries.csv")
    p.add_argument("--xlsx", action="store_true", help="also write run.xlsx: KPIs, time series, every stream "
                   "size by size, the scene")
    p.add_argument("--no-plots", action="store_true", help="do not draw the PNG plots")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


# --------------------------------------------------------------------------- run
def add_run_parser(subparsers):
    p = subparsers.add_parser("run", help="run a scene (open or closed loop) and write its results",
                              description="Run SCENE.toml: the twin driven by the scene's feed "
                              "schedule, open loop or with its controller; KPIs on stdout.")
    p.add_argument("scene", help="scene file (TOML)")
    _add_calibration_option(p)
    _add_output_options(p)
    p.set_defaults(func=cmd_run)
    return p


@_exit_codes("run")
def cmd_run(args) -> int:
    from scenarios.scene import load_scene
    from scenarios.run import run_scene

    _check_output_options(args)
    scene = _with_calibration(load_scene(args.scene), args.calibration)
    result = run_scene(scene, out_dir=args.out, progress=not args.quiet, csv=args.csv,
                       plots=not args.no_plots, xlsx=args.xlsx)
    _print_kpis(result.summary)
    _where_results_went(result)
    return 0


# --------------------------------------------------------------------------- replay
def add_replay_parser(subparsers):
    p = subparsers.add_parser("replay", help="drive a scene with recorded plant data",
                              description="Replay a recorded history (CSV or Parquet: timestamp, "
                              "mineral wt% or ore fractions, optionally recorded feed_tph, "
                              "speed_frac_critical, p80_um) through SCENE.toml; the run's inputs and "
                              "P80 sit beside the recorded ones.")
    p.add_argument("scene", help="scene file (TOML)")
    p.add_argument("--history", required=True, help="recorded history, .csv or .parquet")
    p.add_argument("--duration-h", type=float, default=None,
                   help="replay this long [h] (default: the whole history)")
    _add_calibration_option(p)
    _add_output_options(p)
    p.set_defaults(func=cmd_replay)
    return p


@_exit_codes("replay")
def cmd_replay(args) -> int:
    from scenarios.run import replay_scene
    from scenarios.run.runner import replay_input_scene

    _check_output_options(args)
    if not Path(args.history).is_file():
        raise SceneError(f"{args.history}: history file not found")
    if args.duration_h is not None and not args.duration_h > 0:
        raise SceneError(f"--duration-h must be > 0 (got {args.duration_h:g})")
    scene = replay_input_scene(args.scene, args.history, args.duration_h)
    result = replay_scene(_with_calibration(scene, args.calibration), args.history, out_dir=args.out,
                          progress=not args.quiet, duration_h=args.duration_h, csv=args.csv,
                          plots=not args.no_plots, xlsx=args.xlsx)
    _print_kpis(result.summary)
    differences = result.summary.get("replay", {}).get("run_minus_recorded", {})
    width = max([26, *map(len, differences)])
    for key, value in differences.items():
        print(f"  {key:{width}s} {_value_text(key, value)}")
    _where_results_went(result)
    return 0


# --------------------------------------------------------------------------- sweep
#: Key of the sweep case's result that carries its time series (popped before the table is written).
TRACE_KEY = "trace"
#: Columns of a case kept for the sweep's comparison (plot and workbook).
TRACE_COLUMNS = ("time_h", "p80_um", "content_p80_um", "feed_tph", "speed_frac_critical")


def sweep_case(scene) -> dict:
    """The sweep's ``run_case``: run the scene quietly, return its KPIs, its warnings (joined by
    "; ", None without any) and, under :data:`TRACE_KEY`, its :data:`TRACE_COLUMNS` (picklable:
    module level)."""
    from scenarios.run import run_scene

    res = run_scene(scene, out_dir=None, progress=False)
    trace = {c: res.frame[c].to_numpy(float).tolist() for c in TRACE_COLUMNS if c in res.frame}
    return dict(res.kpis) | {"warnings": "; ".join(res.summary["warnings"]) or None, TRACE_KEY: trace}


def _pop_traces(table):
    """The cases' traces as one long table (``case`` + :data:`TRACE_COLUMNS`), removed from ``table``."""
    import pandas as pd

    if TRACE_KEY not in table:
        return None
    parts = [pd.DataFrame(tr).assign(case=case) for case, tr in zip(table["case"], table.pop(TRACE_KEY))
             if isinstance(tr, dict)]
    return pd.concat(parts, ignore_index=True) if parts else None


def add_sweep_parser(subparsers):
    p = subparsers.add_parser("sweep", help="what-if study: vary scene keys, one row per case",
                              description="Run SCENE.toml for every combination (cartesian) or "
                              "every i-th tuple (paired) of the varied keys; a local process pool "
                              "by default, a Dask cluster with --scheduler.")
    p.add_argument("scene", help="scene file (TOML)")
    p.add_argument("--vary", action="append", required=True, metavar="KEY=v1,v2,...",
                   help="a scene key path and its values (or start:stop:step); repeatable")
    p.add_argument("--mode", choices=["cartesian", "paired"], default="cartesian")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, default=None, help="local processes (default: all cores)")
    g.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://host:8786")
    p.add_argument("--out", help="write sweep.csv, sweep.parquet, sweep_traces.csv and sweep.png into this folder "
                   "(created; replaced when complete)")
    p.add_argument("--xlsx", action="store_true", help="also write sweep.xlsx (with --out)")
    p.add_argument("--max-cases", type=int, default=None, metavar="N",
                   help="allow up to N cases (default: scenarios.run.sweep.MAX_CASES, 1000)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_calibration_option(p)
    p.set_defaults(func=cmd_sweep)
    return p


@_exit_codes("sweep")
def cmd_sweep(args) -> int:
    import pandas as pd

    from scenarios.output import claim_output
    from scenarios.run import MAX_CASES, parse_vary, run_sweep

    if args.workers is not None and args.workers < 1:
        raise SceneError(f"--workers must be >= 1 (got {args.workers})")
    if args.max_cases is not None and args.max_cases < 1:
        raise SceneError(f"--max-cases must be >= 1 (got {args.max_cases})")
    if args.xlsx and not args.out:
        raise SceneError("--xlsx writes into the results folder: give --out DIR")
    vary = {}
    for text in args.vary:
        key, values = parse_vary(text)
        if key in vary:
            raise SceneError(f"--vary {key}: given twice")
        vary[key] = values
    if args.calibration is not None:  # as a varied key with one value (every case runs it)
        if "calibration" in vary:
            raise SceneError("--calibration and --vary calibration=...: give one")
        n = len(next(iter(vary.values()))) if args.mode == "paired" else 1
        vary["calibration"] = [_calibration_arg(args.calibration)] * n
    with claim_output(args.out, protect=(Path(args.scene),)) as claim:
        try:
            table = run_sweep(args.scene, vary, sweep_case, mode=args.mode, workers=args.workers,
                              scheduler=args.scheduler, progress=not args.quiet, max_cases=args.max_cases or MAX_CASES,
                              check=_sweep_workbook_fits if args.xlsx else None)
        except (KeyboardInterrupt, Interrupted) as exc:
            _keep_finished_cases(claim, exc, args)
            raise
        traces = _pop_traces(table)
        if claim is not None:
            claim.commit(lambda folder: _write_sweep(folder, table, traces, args.scene, args.xlsx), kind="sweep")
    if claim is None:
        sys.stderr.write("grindtwin: no --out DIR given: the sweep's table was not written\n")
    cols = ["case", *vary, "start_feed_tph", "start_p80_um", "p80_iae_um_h", "specific_energy_kwh_t",
            "throughput_tph", "error"]  # what each case started from, beside what it did
    with pd.option_context("display.width", 160, "display.max_columns", 20):
        print(table[[c for c in cols if c in table.columns]].to_string(index=False))
    warned = table[table["warnings"].notna()] if "warnings" in table else table.iloc[:0]
    for _, row in warned.head(SWEEP_FAILURES_SHOWN).iterrows():
        setting = ", ".join(f"{k}={row[k]!r}" for k in vary)
        sys.stderr.write(f"grindtwin: warning: case {row['case']} ({setting}): {row['warnings']}\n")
    if len(warned) > SWEEP_FAILURES_SHOWN:
        sys.stderr.write(f"grindtwin: warning: and {len(warned) - SWEEP_FAILURES_SHOWN} more cases warn (see the "
                         "warnings column)\n")
    failed = table[table["error"].notna()]
    if len(failed):
        sys.stderr.write(f"grindtwin: sweep: {len(failed)} of {len(table)} cases failed:\n")
        for _, row in failed.head(SWEEP_FAILURES_SHOWN).iterrows():
            setting = ", ".join(f"{k}={row[k]!r}" for k in vary)
            sys.stderr.write(f"  case {row['case']} ({setting}): {row['error']}\n")
        if len(failed) > SWEEP_FAILURES_SHOWN:
            sys.stderr.write(f"  and {len(failed) - SWEEP_FAILURES_SHOWN} more (see the error column)\n")
        return 1
    return 0


#: Failed cases listed on stderr by ``grindtwin sweep`` (the rest are in the table's error column).
SWEEP_FAILURES_SHOWN = 10


def _keep_finished_cases(claim, exc: BaseException, args) -> None:
    """An interrupted sweep's finished cases (``exc.partial_table``, :func:`scenarios.run.run_sweep`) written to
    --out as a whole sweep folder, the others' error "not run"; ``exc.kept`` then says so to the exit message.
    Nothing is written when no case finished or no --out was given."""
    from scenarios.run.sweep import NOT_RUN

    table = getattr(exc, "partial_table", None)
    if claim is None or table is None or not (table["error"] != NOT_RUN).any():
        return
    done = int((table["error"] != NOT_RUN).sum())
    if claim.final.exists():  # an earlier whole result there is not replaced by a part of this one
        exc.kept = (f"the {done} of {len(table)} cases that finished were not written: {claim.final} holds an earlier "
                    "result, kept (give a new --out to keep a sweep's finished cases)")
        return
    traces = _pop_traces(table)
    folder = claim.commit(lambda f: _write_sweep(f, table, traces, args.scene, args.xlsx), kind="sweep",
                          after_signal=True)
    exc.kept = (f"the {done} of {len(table)} cases that finished were written to {folder} (the others' error: "
                f"{NOT_RUN!r})")


def _sweep_workbook_fits(scenes) -> None:
    """--xlsx: refuse, before any case runs, a sweep whose P80 traces sheet (one row per sample time
    of any case) no Excel sheet holds; it failed only after every case had run."""
    import numpy as np

    from scenarios.output import workbook_problem

    from scenarios.output.workbook import TRACE_TIME_DECIMALS

    times = np.unique(np.round(np.concatenate([s.time_grid_h() for s in scenes]), TRACE_TIME_DECIMALS))
    problem = workbook_problem(len(times))
    if problem:
        raise SceneError(f"sweep {problem}")


def _write_sweep(folder: Path, table, traces, scene_path, xlsx: bool) -> None:
    """sweep.csv, sweep.parquet, sweep_traces.csv and sweep.png (P80 of every case, KPIs per
    case) into the claimed folder; sweep.xlsx on request."""
    from scenarios.output import write_sweep_plot, write_sweep_workbook
    from scenarios.output.workbook import tables_as_json, write_csv
    from scenarios.scene import validate_scene_dict

    if "warnings" in table:  # text, as "error": a failed case has none (NaN beside None made a column of numbers)
        table = table.astype({"warnings": object})
    flat = tables_as_json(table)  # a case's blend as JSON text: parquet wants plain columns
    write_csv(flat, folder / "sweep.csv", index=False)  # NaN written as such, as in a run folder; no text empty
    flat.to_parquet(folder / "sweep.parquet", index=False)
    # the base scene as the cases were made from it, as they are checked (not as written: its own controller
    # kind may read nothing of keys the cases read), not the file read again now: edited during the sweep, it
    # drew its new target beside the cases and was the workbook's scene; refused, it lost every case's result
    base = table.attrs.get("scene_table")
    scene = validate_scene_dict(base, scene_path)[0] if base is not None else None
    if traces is not None:
        write_csv(traces, folder / "sweep_traces.csv", index=False)
    varied = table.attrs.get("varied") or []  # a target the cases vary is no one line (it drew the base scene's)
    write_sweep_plot(table, traces, folder, None if "controller.target_p80_um" in varied or scene is None
                     else scene.controller.target_p80_um)
    if xlsx:
        write_sweep_workbook(table, traces, scene, folder / "sweep.xlsx")


# --------------------------------------------------------------------------- check
def add_check_parser(subparsers):
    p = subparsers.add_parser("check", help="validate scene files: everything run would refuse, "
                              "without running (exit 2 listing every problem)")
    p.add_argument("scenes", nargs="+", metavar="SCENE", help="scene file(s) (TOML)")
    p.set_defaults(func=cmd_check)
    return p


@_exit_codes("check")
def cmd_check(args) -> int:
    from scenarios.run import check_scene

    bad = 0
    for path in args.scenes:
        messages = check_scene(path)
        if messages:
            bad += 1
            for m in messages:
                sys.stderr.write(f"{m}\n")
        else:
            print(f"{path}: OK")
    return 2 if bad else 0


# --------------------------------------------------------------------------- report
def add_report_parser(subparsers):
    p = subparsers.add_parser("report", help="write RUN_DIR/report.html: KPI table and plots, self-contained")
    p.add_argument("run_dir", help="a folder written by grindtwin run --out")
    p.set_defaults(func=cmd_report)
    return p


@_exit_codes("report")
def cmd_report(args) -> int:
    from scenarios.output import write_report

    print(write_report(args.run_dir))
    return 0


# --------------------------------------------------------------------------- steady
def _float_in(name, lo, hi, lo_open=False, hi_open=False):
    """argparse type: a float in an interval, the message naming the option and the interval."""
    import argparse

    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number. Got {text!r}.") from None
        ok = (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
        if not ok:
            br = ("(" if lo_open else "[") + f"{lo:g}, {hi:g}" + (")" if hi_open else "]")
            raise argparse.ArgumentTypeError(f"{name} must be in {br}. Got {text}.")
        return v
    return parse


def _opcua_url(text):
    """argparse type of --opcua: opc.tcp://HOST[:PORT] (a bad one was taken: serve sat disconnected for ever,
    its reconnect task dead of asyncua's ValueError; plant-server failed with a traceback after its models)."""
    import argparse
    from urllib.parse import urlsplit

    parts = urlsplit(text)
    try:
        port = parts.port
    except ValueError:
        port = -1
    if parts.scheme != "opc.tcp" or not parts.hostname or port == -1 or port == 0:
        raise argparse.ArgumentTypeError(f"--opcua must be an endpoint URL opc.tcp://HOST[:PORT] with a port in "
                                         f"[1, 65535] (e.g. opc.tcp://127.0.0.1:4840). Got {text!r}.")
    return text


def _feed_tph(text):
    """argparse type of steady's --feed-tph: the rates a twin takes (twin.FEED_TPH_MAX), imported
    when parsed (`grindtwin --help` imports no numerics)."""
    from twin import FEED_TPH_MAX

    return _float_in("--feed-tph", 0, FEED_TPH_MAX, hi_open=True)(text)


#: What `steady` and `optimize` run without --ore, --blend or --mill.
DEFAULT_ORE, DEFAULT_MILL = "B", "lab"


#: --mill's help: what it takes.
MILL_HELP = "lab, industrial, or a preset file (.json) `size-mill --write-preset` wrote"


def _mill(text: str) -> str:
    """argparse type of --mill: a preset's name or a preset file `size-mill --write-preset` wrote (read here:
    a missing or foreign file is refused before any work)."""
    import argparse

    from twin import MILLS, TwinInputError, is_preset_file, read_preset

    if not (text in MILLS or is_preset_file(text)):
        raise argparse.ArgumentTypeError(f"must be {MILL_HELP}. Got {text!r}.")
    if is_preset_file(text):
        try:
            read_preset(text)
        except TwinInputError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def _add_ore_options(p) -> None:
    p.add_argument("--ore", default=None, help=f"reference type A-D or a TOML file with [mineralogy] and [texture] "
                   f"(default {DEFAULT_ORE})")
    p.add_argument("--blend", help="blend of ores, e.g. B=0.6,D=0.4 (instead of --ore)")


def _blend_of(args):
    """The blend --ore or --blend names; both given was --ore silently dropped."""
    from twin import Blend, TwinInputError, load_ore

    if args.blend and args.ore is not None:
        raise SceneError(f"--ore {args.ore} and --blend {args.blend}: give one (a blend names its ores)")
    if not args.blend:
        return Blend.single(load_ore(args.ore or DEFAULT_ORE))
    try:
        return Blend.parse(args.blend)
    except TwinInputError as exc:  # "Blend fractions must sum to 1": of which option?
        raise SceneError(f"--blend {args.blend}: {exc}") from None


def add_steady_parser(subparsers):
    s = subparsers.add_parser("steady", help="steady-state KPIs of the mill for an ore or a blend")
    _add_ore_options(s)
    g = s.add_mutually_exclusive_group()
    g.add_argument("--feed-tph", type=_feed_tph, help="fresh feed rate [t/h]")
    g.add_argument("--at-constant-load", action="store_true",
                   help="solve for the feed rate that holds the nominal hold-up")
    s.add_argument("--speed", type=_float_in("--speed", 0, 1, True, True), default=None,
                   help="mill speed as a fraction of critical (0.70, not 70)")
    s.add_argument("--mill", default=None, type=_mill, help=f"{MILL_HELP} (default {DEFAULT_MILL})")
    s.add_argument("--json", action="store_true", help="print the KPIs as JSON (unit-suffixed keys)")
    s.add_argument("--surrogate", action="store_true",
                   help="answer from the PLS surrogate (lab mill; refuses inputs outside its training domain)")
    _add_calibration_option(s)
    s.add_argument("--uncertainty", nargs="?", type=int, const=0, default=None, metavar="N",
                   help="also print 90 %% intervals of P80, specific energy and throughput over the calibration's "
                   "bootstrap replicates of the DEM's particle scatter (N replicates, at least 20: one beyond each "
                   "end of the interval; default all)")
    s.add_argument("--scene", help="a scene file: its plant twin at the scene's initial feed and speed "
                   "(--feed-tph and --speed override them; --ore, --blend and --mill do not apply)")
    s.add_argument("--allow-overflow", action="store_true",
                   help="print a steady state that holds more ore than the mill filled to its shell (the model's "
                   "extrapolation, with a note) instead of refusing it")
    s.set_defaults(func=cmd_steady)
    return s


STEADY_KEYS = ("source", "feed_tph", "speed_frac_critical", "p80_um", "specific_energy_kwh_t", "power_kw",
               "throughput_tph", "holdup_t", "load_frac", "load_status")


def undefined_to_none(kpis: dict, unc: dict | None = None, noted: list[str] = ()) -> list[str]:
    """A steady state's undefined numbers set to None in place (printed "undefined", JSON null),
    with a note for each not already named in ``noted`` (the steady state's own notes): the
    specific energy at zero feed (the model's division floor gives ~1e7 kWh/t) and any value that
    is not finite (P80 without a product); the same in the uncertainty intervals ``unc``. Returns
    the notes."""
    notes = []
    named = set(re.findall(r"\w+", " ".join(noted)))  # the names the notes hold, as words
    if kpis.get("feed_tph") == 0 and "specific_energy_kwh_t" in kpis:
        kpis["specific_energy_kwh_t"] = None
        notes += [] if "specific_energy_kwh_t" in named else ["specific_energy_kwh_t is undefined at zero feed"]
        if unc and "specific_energy_kwh_t" in unc["intervals"]:
            unc["intervals"]["specific_energy_kwh_t"] = None
    if kpis.get("holdup_t") == 0 and "content_p80_um" in kpis:  # an empty mill has no content
        kpis["content_p80_um"] = None
        notes += [] if "content_p80_um" in named else ["content_p80_um is undefined in an empty mill"]
    for key, val in kpis.items():
        if isinstance(val, float) and not math.isfinite(val):
            kpis[key] = None
            notes += [] if key in named else [f"{key} is undefined at this state (not a finite number)"]
    for key, iv in (unc["intervals"] if unc else {}).items():
        if iv is not None and not all(math.isfinite(v) for v in iv):
            unc["intervals"][key] = None
    return notes


def refuse_overflow(twin, ss, allow: bool, what: str, blend=None) -> None:
    """Refuse (bad input, exit 2) a steady state ``ss`` of ``twin`` that holds more ore than the
    mill filled to its shell (:meth:`twin.Mill.max_holdup_t`): no mill runs there, and its numbers
    are the model's extrapolation, not a prediction. The error names the feed rate that fills the
    mill to its shell at this speed (solved at that load). ``allow`` (``--allow-overflow``) keeps
    the answer, with the steady state's own note (:mod:`twin.validity`)."""
    from twin import shell_capacity_t

    out = ss.summary()
    capacity_t = float(shell_capacity_t(twin.spec, out["holdup_t"], out.get("load_frac")))  # at the content's density
    if allow or not out["holdup_t"] > capacity_t:
        return
    speed = out["speed_frac_critical"]
    shell_load = twin.mill.max_holdup_t(twin.spec.solids_density_t_m3) / twin.spec.holdup_nominal_t  # by volume
    try:
        full = twin.steady_at_constant_load(speed, blend, load_frac=shell_load)
        allowed = f"feeds up to {full.summary()['feed_tph']:.4g} t/h (which fill it to its shell at this speed)"
    except Exception as exc:  # noqa: BLE001 - the limit is advice; the refusal stands without it
        allowed = f"a lower feed (the feed that fills it to its shell was not found: {exc})"
    from twin import nominal_pressure_note

    cyclones = nominal_pressure_note(twin.model)
    raise SceneError(f"{what} {out['feed_tph']:g} t/h: at {speed:.3g} of critical speed the mill's steady state "
                     f"would hold {out['holdup_t']:.4g} t of ore, more than it holds filled to its shell "
                     f"({capacity_t:.4g} t); it would overflow and these numbers would extrapolate the model "
                     f"beyond the mill. Allowed: {allowed}; --allow-overflow prints the extrapolation anyway."
                     + (f" {cyclones}" if cyclones else ""))


def _steady_or_refuse(solve, what: str, feed_tph: float):
    """``solve()``'s steady state; a feed at which the mill overloads (no steady state, the mill
    filled past its shell) is bad input (exit 2, as an overflowing steady state is), not a failure."""
    from twin import OverloadError

    try:
        return solve()
    except OverloadError as exc:
        raise SceneError(f"{what} {feed_tph:g} t/h: {exc}") from None


def refuse_slow_speed(twin, speed, what: str) -> None:
    """Refuse (bad input, exit 2) a speed at or below twin.SPEED_FACTOR_ZERO_FRAC_CRITICAL for a
    twin whose breakage follows the speed (its ``speed`` effect), naming the option, before
    anything is solved (the twin refuses it too, naming its own parameter)."""
    from twin import SPEED_FACTOR_ZERO_FRAC_CRITICAL as slowest

    if speed is None or "speed" not in twin.model.effect_names or speed > slowest:
        return
    raise SceneError(f"{what} {speed:g}: at or below {slowest:g} of critical speed the twin's "
                     "breakage rates are zero or negative (Austin et al. 1984, eq. 8.4, its speed effect), so it has "
                     f"no steady state there; allowed: a speed in ({slowest:g}, 1) of critical.")


def refuse_few_replicates(n: int, calibration, level: float) -> None:
    """Refuse (bad input, exit 2) ``--uncertainty N`` with 0 < N < twin.calibration.min_replicates,
    or a calibration that keeps fewer converged replicates than that, before anything is solved."""
    from twin.calibration import min_replicates

    need = min_replicates(level)
    reps = (calibration.record.get("bootstrap") or {}).get("replicates", [])
    kept = sum(bool(r.get("success", True)) for r in reps)
    why = (f"a {level:.0%} interval needs at least {need} bootstrap replicates (it leaves {(1 - level) / 2:.0%} of "
           f"them beyond each end: one on each side takes 2 / (1 - {level:g}) = {need}; fewer give the spread of a "
           "few draws, not the interval)")
    if kept < need:
        if calibration.breakage_map != "dem":  # --map mineralogy refuses --replicates: the advice could not be taken
            how = ("the mineralogy map has no bootstrap (its numbers are fitted to the table alone, no DEM scatter "
                   "to carry); use a DEM calibration (the default 'dem') for intervals")
        else:
            how = (f"make a calibration with more (grindtwin calibrate --replicates N, N >= {need}) and give it with "
                   "--calibration")
        raise SceneError(f"--uncertainty{f' {n}' if n else ''}: calibration {calibration.label()} keeps {kept} "
                         f"converged bootstrap replicate{'s' * (kept != 1)}; {why}. {how[0].upper() + how[1:]}.")
    if 0 < n < need:
        raise SceneError(f"--uncertainty {n}: {why}; give --uncertainty {need} or more, or 0 for all {kept}.")


def _steady_scene(args) -> int:
    """`grindtwin steady --scene FILE`: the scene's plant twin at its initial operating point."""
    from scenarios.run.models import build_models
    from scenarios.scene import load_scene
    from twin import circuit_cyclone, json_text, plitt_factors, plitt_factors_text

    given = [name for name, v in (("--surrogate", args.surrogate), ("--at-constant-load", args.at_constant_load),
                                  ("--blend", args.blend), ("--ore", args.ore), ("--mill", args.mill),
                                  ("--uncertainty", args.uncertainty)) if v is not None and v is not False]
    # (not `v not in (None, False)`: a bare --uncertainty is 0, equal to False, and was ignored without a word)
    if given:  # --ore and --mill were ignored without a word
        raise SceneError(f"--scene runs the scene's own twin (its ores and mill): {', '.join(given)} "
                         "do not apply.")
    scene = _with_calibration(load_scene(args.scene), args.calibration)
    models = build_models(scene)
    feed = args.feed_tph if args.feed_tph is not None else scene.feed.feed_tph
    if feed is None:
        raise SceneError(f"{args.scene}: a batch scene (no feed.feed_tph) has no steady state.")
    speed = args.speed if args.speed is not None else scene.feed.speed_frac_critical
    blend = [scene.feed.blend.get(n, 0.0) for n in models.components] if scene.feed.blend else None
    refuse_slow_speed(models.plant, speed, "--speed" if args.speed is not None else
                      f"{args.scene}: feed.speed_frac_critical")
    what = "--feed-tph" if args.feed_tph is not None else f"{args.scene}: feed.feed_tph"
    ss = _steady_or_refuse(lambda: models.plant.steady(feed_tph=feed, speed_frac_critical=speed, blend=blend),
                           what, feed)
    refuse_overflow(models.plant, ss, args.allow_overflow, what, blend)
    kpis = {"scene": scene.scene.name, **ss.summary()}
    notes = undefined_to_none(kpis, noted=ss.notes) + ss.notes + _scene_steady_notes(scene, models, args)
    cyclone = circuit_cyclone(models.plant.spec)  # its Plitt factors: a survey's are computed, not typed
    factors = {} if cyclone is None else plitt_factors(cyclone)
    if args.json:
        print(json_text(kpis | ({"cyclone_plitt_factors": factors} if factors else {}) | {"notes": notes}, indent=2))
        return 0
    print(f"Scene {scene.scene.name} ({args.scene}), steady state")
    for key, val in kpis.items():
        text = "undefined" if val is None else f"{val:.4g}" if isinstance(val, float) else val
        print(f"  {key:28s} {text}")
    if factors:
        print(f"  {'cyclone_plitt_factors':28s} {plitt_factors_text(factors)}")
    for note in notes:
        print(f"  note: {note}")
    return 0


def _scene_steady_notes(scene, models, args) -> list[str]:
    """What `steady --scene` answers for that a user could read otherwise: a scene whose runs start at
    the target's steady state, and a speed the breakage rates do not follow (no `speed` effect)."""
    notes = []
    if scene.feed.start == "target" and args.feed_tph is None:
        notes.append(f"at feed.feed_tph = {scene.feed.feed_tph:g} t/h; the scene's runs start at the steady state "
                     f"holding controller.target_p80_um (feed.start = \"target\"): grindtwin optimize finds its feed")
    if "speed" not in models.plant.model.effect_names:
        notes.append("the plant has no `speed` effect: its breakage rates are those of the nominal speed, and a "
                     "speed moves only the power and the kWh/t")
    from scenarios.run.models import survey_load_note

    return notes + [n for n in (survey_load_note(scene, models.plant.spec.feed_nominal_tph),) if n]


@_exit_codes("steady")
def cmd_steady(args) -> int:
    from twin import json_text
    from twin.calibration import load_calibration  # light: the surrogate needs neither CasADi nor scikit-learn

    if args.scene:
        return _steady_scene(args)
    args.mill = args.mill or DEFAULT_MILL
    blend = _blend_of(args)
    calibration = load_calibration(_calibration_arg(args.calibration))
    if args.uncertainty is not None and (args.surrogate or args.uncertainty < 0):
        raise SceneError("--uncertainty N needs N >= 0 (0: all replicates) and the twin, not --surrogate.")
    if args.uncertainty is not None:
        from twin.calibration import INTERVAL_LEVEL

        refuse_few_replicates(args.uncertainty, calibration, INTERVAL_LEVEL)
    if args.surrogate:
        from twin.surrogate import shipped_compiled, surrogate_steady

        if args.at_constant_load:
            raise SceneError("--surrogate answers at a given feed rate; it cannot be combined with --at-constant-load.")
        surrogate = shipped_compiled()
        trained = surrogate.metadata.get("mill", "lab")
        if args.mill != trained:  # surrogate_steady's own error named its parameter, not --mill
            raise SceneError(f"--mill {args.mill}: the surrogate was trained on the {trained!r} mill only; "
                             f"drop --surrogate for the twin of the {args.mill!r} mill.")
        kpis = surrogate_steady(blend, args.feed_tph, args.speed, mill=args.mill, surrogate=surrogate,
                                calibration=calibration)
        kpis = {k: v for k, v in kpis.items() if k in STEADY_KEYS or k == "source"}
    else:
        twin = _calibrated_twin(blend, args.mill, calibration)
        refuse_slow_speed(twin, args.speed, "--speed")
        what = "--feed-tph" if args.feed_tph is not None else "the mill's nominal feed (no --feed-tph given)"
        if args.at_constant_load:
            ss = twin.steady_at_constant_load(speed_frac_critical=args.speed)
        else:
            ss = _steady_or_refuse(lambda: twin.steady(feed_tph=args.feed_tph, speed_frac_critical=args.speed),
                                   what, args.feed_tph if args.feed_tph is not None else twin.mill.feed_nominal_tph)
        refuse_overflow(twin, ss, args.allow_overflow, what)
        ores = ss.ore_summary()  # each ore's P80, beside the blend's
        kpis = {k: v for k, v in ss.summary().items() if k in STEADY_KEYS or k in ores} | {"source": "twin"}
    unc = None
    if args.uncertainty is not None:
        from twin.calibration import min_replicates, steady_intervals

        unc = steady_intervals(blend, calibration, args.mill, args.feed_tph, args.speed,
                               at_load=args.at_constant_load, n=args.uncertainty or None)
    notes = undefined_to_none(kpis, unc, noted=[] if args.surrogate else ss.notes)
    if unc:  # B's measured 12.8 kWh/t lay outside its interval [13.10, 13.12]
        notes.append(f"the {unc['level']:.0%} intervals carry the DEM particles' scatter only, not the table's "
                     "measurement error, the loosely held fitted numbers or the model's form: no prediction "
                     "interval (a left-out ore is predicted within 3-7 %: benchmarks/results/twin_loo.md)")
    if unc and unc["n"] < min_replicates(unc["level"]):  # steady states that failed left too few
        notes.append(f"the {unc['level']:.0%} intervals are undefined: the steady state solved for {unc['n']} "
                     f"replicates, fewer than the {min_replicates(unc['level'])} an interval needs")
        unc["intervals"] = {key: None for key in unc["intervals"]}
    if args.surrogate:  # no hold-up or clay of its own: what its speed says, and the map's blind spot
        from twin import centrifuging_note

        notes += [n for n in [centrifuging_note(kpis.get("speed_frac_critical") or 0.0)] if n]
        notes += calibration.fit_notes() + calibration.ore_notes(blend.ores)
        if len(blend.ores) > 1:  # its P80 for A=B=C=D=0.25 was coarser than every pure ore's
            notes.append("the surrogate answers a blend as one ore of the blend's mean mineralogy and texture; the "
                         "twin (without --surrogate) grinds each ore as its own component")
    else:
        notes += ss.notes  # a twin's steady state carries its notes (texture, a sized circuit not run)
    if args.json:
        mineralogy = {o.name: {"wt_pct": o.wt_pct, **o.summary()} for o in blend.ores}
        print(json_text({"mill": args.mill, "blend": dict(zip(blend.names, blend.fractions)),
                         "calibration": calibration.identity(), **kpis, "mineralogy": mineralogy,
                         "notes": notes, **({"uncertainty": unc} if unc else {})}, indent=2))
        return 0
    print(f"Mill {args.mill}, blend " + ", ".join(f"{n} {f:.0%}" for n, f in zip(blend.names, blend.fractions))
          + f"; calibration {calibration.label()}")
    for key, val in kpis.items():
        text = "undefined" if val is None else f"{val:.4g}" if isinstance(val, float) else val
        print(f"  {key:24s} {text}")
    for note in notes:
        print(f"  note: {note}")
    if unc:
        _print_intervals(unc, at_load=args.at_constant_load)
    for ore in blend.ores:
        wt = ", ".join(f"{m} {w:.1f}" for m, w in sorted(ore.wt_pct.items(), key=lambda kv: -kv[1]))
        print(f"  ore {ore.name}: H_min {ore.hardness_index_gpa:.2f} GPa, textural index "
              f"{ore.textural_index:.2f}; wt%: {wt}")
    return 0


def _print_intervals(unc: dict, at_load: bool) -> None:
    left = ([f"{unc['failed']} failed steady states"] if unc["failed"] else []) + (
        [f"{unc['unconverged']} replicate{'s' * (unc['unconverged'] != 1)} whose table step did not converge"] if unc.get("unconverged") else [])
    print(f"  {unc['level']:.0%} intervals over {unc['n']} bootstrap replicates of the DEM's particle scatter"
          + (f" ({' and '.join(left)} left out)" if left else "") + ": the replicates' median [interval]")
    for key, iv in unc["intervals"].items():
        if iv is None:
            print(f"    {key:22s} undefined")
            continue
        lo, mid, hi = iv
        note = "" if at_load or key != "throughput_tph" else "  (the given feed rate)"
        print(f"    {key:22s} {mid:.4g}  [{lo:.4g}, {hi:.4g}]{note}")


# --------------------------------------------------------------------------- optimize
def add_optimize_parser(subparsers):
    o = subparsers.add_parser("optimize", help="feed rate and speed that hold a target P80 at least energy",
                              description="Steady set points for an ore or blend that hold the target P80 with "
                              "the load in its stable band; a table of alternatives (feed only, speed only, both "
                              "for least energy, both for most throughput).")
    _add_ore_options(o)
    o.add_argument("--target-p80-um", required=True, type=_float_in("--target-p80-um", 1.0, 1e4))
    o.add_argument("--mill", default=DEFAULT_MILL, type=_mill, help=f"{MILL_HELP} (default {DEFAULT_MILL})")
    o.add_argument("--mode", default="both", choices=["both", "feed", "speed"], help="which answer to pick")
    o.add_argument("--objective", default=None, choices=["min_energy", "max_throughput"],
                   help="with --mode both (default min_energy): one input alone has one answer")
    o.add_argument("--json", action="store_true", help="print the answer and the table as JSON")
    _add_calibration_option(o)
    o.set_defaults(func=cmd_optimize)
    return o


@_exit_codes("optimize")
def cmd_optimize(args) -> int:
    from mpc import MpcInputError, default_feed_bounds, optimal_setpoints
    from twin import json_text

    if args.objective is not None and args.mode != "both":
        raise SceneError(f"--objective {args.objective}: with --mode {args.mode} one input holds the target and "
                         "there is one answer; --objective chooses among --mode both's")
    blend = _blend_of(args)
    twin = _calibrated_twin(blend, args.mill, _calibration_arg(args.calibration))
    try:
        sp = optimal_setpoints(twin, list(blend.fractions), args.target_p80_um, mode=args.mode,
                               objective=args.objective or "min_energy", feed_bounds_tph=default_feed_bounds(twin))
    except MpcInputError as exc:
        raise SceneError(str(exc)) from None
    table = sp.table
    notes = list(twin.notes)
    if sp.feasible:  # the answer's own steady state, for what the models do not describe there
        notes = twin.steady(feed_tph=sp.feed_tph, speed_frac_critical=sp.speed_frac_critical,
                            blend=list(blend.fractions)).notes
    if args.json:
        # the table's records through json_text too: pandas' to_json wrote an infinity as null (undefined)
        print(json_text({"feasible": sp.feasible, "message": sp.message, "active": sp.active, "mode": sp.mode,
                         "objective": sp.objective if args.mode == "both" else None, "feed_tph": sp.feed_tph,
                         "speed_frac_critical": sp.speed_frac_critical, "p80_um": sp.p80_um,
                         "specific_energy_kwh_t": sp.specific_energy_kwh_t, "load_frac": sp.load_frac,
                         "power_kw": sp.power_kw, "table": table.to_dict(orient="records"), "notes": notes},
                        indent=2))
    else:
        print(f"Target P80 {args.target_p80_um:g} um, mill {args.mill}, blend "
              + ", ".join(f"{n} {f:.0%}" for n, f in zip(blend.names, blend.fractions)))
        print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
        print(("answer: " if sp.feasible else "no feasible answer: ") + sp.message)
        for note in notes:
            print(f"note: {note}")
    return 0 if sp.feasible else 1


# --------------------------------------------------------------------------- size-mill
def add_size_mill_parser(subparsers):
    z = subparsers.add_parser("size-mill", help="size a ball mill in closed circuit for an ore, feed and target P80",
                              description="The mill diameter (length 1.5 diameters, 35 % balls) and hydrocyclone "
                              "cluster (count, diameter, sump dilution) at which the twin's steady overflow P80 meets "
                              "the target with a circulating load of 2.5 and the cyclones at their design pressure, "
                              "rates scaled from the laboratory calibration by Austin's rules (twin.sizing, "
                              "twin.scaleup).")
    z.add_argument("--ore", default="B", help="reference type A-D or a TOML file with [mineralogy] and [texture]")
    z.add_argument("--feed-tph", required=True, type=_size_mill_input("feed_tph"))
    z.add_argument("--target-p80-um", required=True, type=_size_mill_input("target_p80_um"))
    z.add_argument("--speed", type=_size_mill_input("speed_frac_critical"), default=0.70,
                   help="mill speed as a fraction of critical (0.70, not 70)")
    z.add_argument("--cyclone-pressure-kpa", type=_size_mill_input("cyclone_pressure_kpa"), default=None,
                   help="the cyclones' design feed pressure [kPa] (default twin.sizing.DESIGN_CYCLONE_PRESSURE_KPA, "
                   "53: the Moly-Cop BallSim base case's cluster)")
    z.add_argument("--circuit", choices=["direct", "reverse"], default="direct",
                   help="fresh feed to the mill (direct, default) or to the cyclones' sump (reverse: the ball "
                   "mill of most SAG-ball circuits)")
    z.add_argument("--cyclone", metavar="FILE",
                   help="a TOML file of one cyclone table, as a scene's effect_options.classification.cyclone "
                   "(geometry and Plitt factors, or a 'survey'): the cyclones are of its shape and model; the "
                   "sizing chooses their count, diameter and dilution (default: twin.Hydrocyclone's shape, "
                   "Plitt's equations uncalibrated)")
    z.add_argument("--write-preset", metavar="PATH",
                   help="also write the answer as a preset file here (a new file or a preset grindtwin wrote; "
                   "the shipped `industrial` preset is twin/data/industrial_mill.json, written only when named); "
                   "`steady` and `optimize` run it as --mill PATH, a scene as [mill] preset = \"PATH\" (with its "
                   "cyclones when classification.kind = \"hydrocyclone\" gives no cyclone table)")
    z.add_argument("--json", action="store_true", help="print the answer as JSON")
    z.set_defaults(func=cmd_size_mill)
    return z


def _size_mill_input(name):
    """argparse type: a number size_mill takes as ``name`` (twin.sizing.check_size_mill_input: its
    ranges and message, so the parser and the sizing refuse the same values alike)."""
    import argparse

    def parse(text):
        from twin import TwinInputError, check_size_mill_input

        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number. Got {text!r}.") from None
        try:
            return check_size_mill_input(name, value)
        except TwinInputError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    return parse


@_exit_codes("size-mill")
def cmd_size_mill(args) -> int:
    import shlex

    from twin import (Hydrocyclone, check_preset_path, json_text, load_design_cyclone, load_ore, plitt_factors,
                      plitt_factors_text, size_mill, write_preset)

    if args.write_preset is not None:  # an empty path was no preset, silently
        check_preset_path(args.write_preset)  # before the sizing's minutes of work
        replaces = os.path.exists(args.write_preset)  # a preset grindtwin wrote (check_preset_path): said so
    pressure = {} if args.cyclone_pressure_kpa is None else {"cyclone_pressure_kpa": args.cyclone_pressure_kpa}
    cyclone = {} if args.cyclone is None else {"cyclone": load_design_cyclone(args.cyclone)}
    circuit = {} if args.circuit == "direct" else {"circuit": args.circuit}
    sized = size_mill(load_ore(args.ore), args.feed_tph, args.target_p80_um, args.speed, **cyclone, **pressure,
                      **circuit)

    def num(v):  # the record's command sizes this design again: 6 digits of %g rounded 31.1234567 t/h
        return f"{v:g}" if float(f"{v:g}") == v else repr(v)

    command = (f"grindtwin size-mill --ore {shlex.quote(args.ore)} --feed-tph {num(args.feed_tph)} --target-p80-um "
               f"{num(args.target_p80_um)} --speed {num(args.speed)}"
               + "".join(f" --cyclone-pressure-kpa {num(v)}" for v in pressure.values())
               + ("" if args.cyclone is None else f" --cyclone {shlex.quote(args.cyclone)}")
               + "".join(f" --circuit {v}" for v in circuit.values()))
    record = sized.record(command)
    if args.write_preset is not None:
        path = write_preset(sized, f"{command} --write-preset {shlex.quote(args.write_preset)}", args.write_preset)
        print(f"wrote {path}" + (" (replacing the preset it held)" if replaces else ""),
              file=sys.stderr if args.json else sys.stdout)  # --json: stdout is the JSON alone
    if args.json:
        print(json_text(record | {"notes": sized.notes}, indent=2))
        return 0
    m, z, c = sized.mill, record["sizing"], sized.cyclone
    print(f"Mill for ore {args.ore} at {args.feed_tph:g} t/h, P80 {args.target_p80_um:g} um, {args.speed:.2f} of critical:")
    print(f"  diameter_m                {m.diameter_m:.3f}\n  length_m                  {m.length_m:.3f}\n"
          f"  ball_filling_frac         {m.ball_filling_frac:.2f}\n  ball_size_mm              {m.ball_size_mm:g}\n"
          f"  power_model               {m.power_model}\n  hydrocyclones             {c['count']} x "
          f"{c['diameter_cm']:.3g} cm (inlet {c['inlet_cm']:.3g}, vortex finder {c['vortex_finder_cm']:.3g}, apex "
          f"{c['apex_cm']:.3g} cm), fed at {c['feed_solids_vol_pct']:.3g} % solids by volume")
    factors = plitt_factors_text(plitt_factors(Hydrocyclone(**c)), calibrated_only=True)
    if factors:
        print(f"  Plitt factors             {factors}")
    for key in ("p80_um", "circulating_load_frac", "power_kw", "specific_energy_kwh_t", "load_frac", "load_status",
                *sized.circuit):
        print(f"  {key:25s} {z[key]:.4g}" if isinstance(z[key], float) else f"  {key:25s} {z[key]}")
    for note in sized.notes:
        print(f"  note: {note}")
    return 0


# --------------------------------------------------------------------------- calibrate
def add_calibrate_parser(subparsers):
    import argparse

    # the options live with the calibration (twin.calibration.calibrate, `grindtwin calibrate --help`);
    # they are passed through untouched (no option prefix of our own), so building this parser imports nothing
    c = subparsers.add_parser("calibrate", help="make a calibration file (the DEM chain by default)", add_help=False,
                              prefix_chars="+", description="Make a calibration: see `grindtwin calibrate --help`.")
    c.add_argument("options", nargs=argparse.REMAINDER, help="the options of twin.calibration's command")
    c.set_defaults(func=cmd_calibrate)
    return c


def cmd_calibrate(args) -> int:
    from twin.calibration import main

    return main(args.options)


# --------------------------------------------------------------------------- bench
#: What each layer's accuracy costs in time (the resolution knobs of README's headline tables): the scripts
#: ``grindtwin bench LAYER`` runs. The other benchmarks compare with peers (Yade, LAMMPS, do-mpc: installed
#: beside, never dependencies), take arguments (an A/B against a revision) or study one question; each runs by
#: its name, ``grindtwin bench NAME [ARGS]``. (Every script with a __main__ block was run, and a layer stopped
#: at the first that needed arguments or a peer.)
BENCH_LAYERS = {
    "dem": ("dem_accuracy", "dem_time_step", "dem_drum_accuracy"),
    "twin": ("twin_accuracy", "twin_grid", "twin_surrogate"),
    "mpc": ("mpc_nmpc_horizon", "mpc_linear_horizon"),
}


def add_bench_parser(subparsers):
    b = subparsers.add_parser("bench", help="accuracy-against-time benchmarks (run from a checkout)",
                              description="From the repository checkout in the current directory: LAYER runs that "
                              "layer's accuracy-against-time benchmarks (all layers without one); NAME runs "
                              "benchmarks/NAME.py with the ARGS after --. Each writes its table to benchmarks/results/.")
    b.add_argument("target", nargs="?", metavar="LAYER|NAME",
                   help=f"a layer ({', '.join(BENCH_LAYERS)}; default: all) or one benchmark's name (dem_ab, ...)")
    b.add_argument("script_args", nargs="*", metavar="ARGS",
                   help="arguments of the benchmark NAME, after -- (grindtwin bench dem_ab -- --base HEAD~1)")
    b.add_argument("--list", action="store_true", help="list the scripts only")
    b.set_defaults(func=cmd_bench)
    return b


@_exit_codes("bench")
def cmd_bench(args) -> int:
    import subprocess

    from twin import is_grindtwin_checkout

    root = Path("benchmarks")
    if not (root.is_dir() and is_grindtwin_checkout(Path.cwd())):
        # another project's benchmarks/ would have its scripts run, and results written into it
        raise SceneError("grindtwin bench runs from a checkout of the grindtwin repository (its pyproject.toml "
                         f"names the project grindtwin, beside benchmarks/): {Path.cwd()} is not one.")
    known = sorted(p.stem for p in root.glob("*.py") if '__name__ == "__main__"' in p.read_text(encoding="utf-8"))
    if args.target is None or args.target in BENCH_LAYERS:
        if args.script_args:
            raise SceneError(f"bench {args.target or ''}: ARGS are for one benchmark by name, not a layer "
                             f"(got {' '.join(args.script_args)})")
        names = [n for layer in ([args.target] if args.target else BENCH_LAYERS) for n in BENCH_LAYERS[layer]]
        if args.list and args.target is None:  # the layers' scripts, then every other one (it listed 8 only)
            layered = set(names)
            print("\n".join([str(root / f"{n}.py") for n in names] + ["by name (grindtwin bench NAME -- ARGS):"]
                            + [f"  {root / f'{n}.py'}" for n in known if n not in layered]))
            return 0
    else:
        if args.target not in known:
            from scenarios.scene.keypaths import did_you_mean

            raise SceneError(f"bench {args.target}: not a layer ({', '.join(BENCH_LAYERS)}) or a benchmark of "
                             f"{root}/{did_you_mean(args.target, [*BENCH_LAYERS, *known])}")
        names = [args.target]
    for script in (root / f"{n}.py" for n in names):
        print(script)
        if not args.list and subprocess.call([sys.executable, str(script), *args.script_args]) != 0:
            raise RunError(f"benchmark {script} failed")
    return 0


# --------------------------------------------------------------------------- export-controller
def add_export_controller_parser(subparsers):
    p = subparsers.add_parser("export-controller", help="the scene's NMPC and EKF as C source with a small API",
                              description="Write SCENE.toml's controller (EKF step and real-time iteration "
                              "on the condensed QP) as C source with a C API (gt_controller.h), a Makefile "
                              "and a replay harness into DIR. DIR must be new, empty or a previous export. "
                              "--check DIR writes nothing: it says whether the export in DIR is what SCENE "
                              "exports now (exit 0), or prints each difference (exit 1).")
    p.add_argument("scene", help="scene file (TOML) with controller.kind = 'nmpc'")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", help="folder for the C source (created)")
    where.add_argument("--check", metavar="DIR", help="compare the export in DIR (its grindtwin_export.json's "
                       "built_from, its files) with what SCENE, its calibration and preset and this grindtwin "
                       "export now; writes nothing; exit 0 current, 1 stale (each difference printed)")
    p.set_defaults(func=cmd_export_controller)
    return p


@_exit_codes("export-controller")
def cmd_export_controller(args) -> int:
    from mpc import export_lock
    from scenarios.scene import load_scene
    from scenarios.run import export_scene_controller

    scene = load_scene(args.scene)
    if args.check is not None:
        return _check_export(scene, args)
    # the folder locked before the models are built: a second export to it is refused at once
    with export_lock(args.out):
        files = export_scene_controller(scene, args.out, source=str(args.scene))
    print(f"{len(files)} files in {args.out}: build with `make -C {args.out}`; API in gt_controller.h")
    return 0


def _check_export(scene, args) -> int:
    """``export-controller SCENE --check DIR``: 0 when the export in DIR is what SCENE exports now, else 1
    with each difference (item, recorded, now) on stdout; notes (where the files were, versions) either way."""
    from scenarios.run import check_scene_export

    found = check_scene_export(scene, args.check, source=str(args.scene))
    stale = [d for d in found if d.stale]

    def shown(value) -> str:
        text = value if isinstance(value, str) else json.dumps(value)
        return text if len(text) <= 200 else text[:200] + "..."

    if stale:
        print(f"{args.check}: stale: {len(stale)} item{'s' if len(stale) > 1 else ''} differ from what "
              f"{args.scene} exports now:")
    else:
        print(f"{args.check}: current: what {args.scene} exports now")
    for d in stale + [d for d in found if not d.stale]:
        print(f"  {'' if d.stale else 'note: '}{d.item}: recorded {shown(d.recorded)}, now {shown(d.current)}")
    if stale:
        print(f"export again: grindtwin export-controller {args.scene} --out {args.check}")
    return 1 if stale else 0


# --------------------------------------------------------------------------- serve, plant-server (OPC UA)
def _online():
    """``scenarios.online`` (the ``online`` extra), or a RunError saying how to install it."""
    try:
        import scenarios.online as online
    except ModuleNotFoundError as exc:
        if exc.name != "asyncua":
            raise
        raise RunError("the OPC UA commands need the 'online' extra: pip install 'grindtwin[online]'") from None
    return online


def _add_online_options(p) -> None:
    p.add_argument("scene", help="scene file (TOML)")
    p.add_argument("--opcua", required=True, metavar="URL", type=_opcua_url,
                   help="endpoint, e.g. opc.tcp://127.0.0.1:4840")
    p.add_argument("--speedup", type=_float_in("--speedup", 0, 1e6, lo_open=True), default=1.0,
                   help="plant hours pass this many times faster than real time (a virtual plant; default 1)")
    p.add_argument("--duration-h", type=_float_in("--duration-h", 0, 1e6, lo_open=True), default=None,
                   help="stop after this many plant hours (serve: of its own running; plant-server: of the scene's "
                   "time from 0, after any --hold-h; default: run until SIGTERM)")
    p.add_argument("--insecure", action="store_true", help="no security and anonymous users (commissioning only)")
    p.add_argument("--cert", help="this application's certificate (PEM)")
    p.add_argument("--key", help="its private key (PEM)")
    p.add_argument("--quiet", action="store_true", help="log warnings and errors only")


def _seed(text: str) -> int:
    """argparse type of ``--seed``: an integer >= 0 (numpy's seeds)."""
    import argparse

    if not text.isdigit():
        raise argparse.ArgumentTypeError(f"--seed must be an integer >= 0. Got {text!r}.")
    return int(text)


def _online_scene(args, tags_path):
    """``(scenarios.online, scene, tag map)`` of an OPC UA command, logging set up; the scene and
    the tag map are checked before anything connects."""
    from scenarios.scene import load_scene

    online = _online()
    _online_logging(args)
    scene = load_scene(args.scene)
    return online, scene, online.load_tags(tags_path, scene)


def _online_logging(args) -> None:
    import logging

    logging.basicConfig(level=logging.WARNING if args.quiet else logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    logging.getLogger("asyncua").setLevel(logging.ERROR)
    # its session's publish loop logs a traceback when the server goes; the service logs the loss
    logging.getLogger("asyncua.client.ua_session").setLevel(logging.CRITICAL)
    # its trust store logs a traceback with each refused client certificate (the plant server's log
    # filled with them): its message, which names the certificate, is kept
    logging.getLogger("asyncuagds.validate").addFilter(_without_traceback)


def _without_traceback(record) -> bool:
    """A logging filter: the record's message without its traceback."""
    record.exc_info, record.exc_text = None, None
    return True


def add_serve_parser(subparsers):
    p = subparsers.add_parser("serve", help="run the scene's estimator and NMPC against a plant over OPC UA",
                              description="Every sample period read the plant's measurements from the nodes of "
                              "TAGS.toml, estimate, solve and write the feed and speed setpoints; an audit row per "
                              "cycle (Parquet). SIGTERM leaves the setpoints at their last written values and "
                              "exits 0 after the stop.")
    _add_online_options(p)
    p.add_argument("--tags", required=True, help="tag map (TOML): which node holds what")
    p.add_argument("--audit", default="grindtwin-audit", help="folder of the audit log (default grindtwin-audit)")
    p.add_argument("--warmup-h", type=_float_in("--warmup-h", 0, 1e3), default=None,
                   help="estimate this long before moving anything (default 2 h)")
    p.add_argument("--server-cert", help="the plant server's certificate (PEM): only that server is accepted")
    p.add_argument("--user", help="OPC UA user name (password from $GRINDTWIN_OPCUA_PASSWORD or --password-file)")
    p.add_argument("--password-file", help="a file whose first line is the password")
    p.set_defaults(func=cmd_serve)
    return p


@_exit_codes("serve")
def cmd_serve(args) -> int:
    import asyncio

    online, scene, tags = _online_scene(args, args.tags)
    security = online.ClientSecurity(args.insecure, args.cert and Path(args.cert), args.key and Path(args.key),
                                     args.server_cert and Path(args.server_cert), args.user,
                                     online.read_password(args.password_file and Path(args.password_file))
                                     if args.user else None)
    security.check()
    online.check_audit_dir(Path(args.audit))  # before the models are built: a user's folder is refused at once,
    # and made at the first audit write: a start that fails leaves none behind
    settings = online.ServeSettings(args.opcua, security, Path(args.audit), speedup=args.speedup,
                                    warmup_h=args.warmup_h, duration_h=args.duration_h)
    parts = online.build_parts(scene, soft_sensor=tags.soft_sensor is not None,
                               surrogate=tags.soft_sensor is not None and tags.soft_sensor.surrogate_p80_um is not None)
    asyncio.run(online.Service(parts, tags, settings).run())
    return 0  # also after SIGTERM / SIGINT: a clean stop of a service, as systemd expects (README, Online)


def add_plant_server_parser(subparsers):
    p = subparsers.add_parser("plant-server", help="the scene's twin as a virtual plant behind an OPC UA server",
                              description="Serve the scene's plant twin (analyser noise, dead time and sampling; "
                              "belt analyser; watchdog; analyser faults) on the nodes of a tag map, in real time or "
                              "sped up, for commissioning grindtwin serve and operator training.")
    _add_online_options(p)
    p.add_argument("--tags", default=None, help="tag map (default: the virtual plant's, for ores B and D)")
    p.add_argument("--hold-h", type=_float_in("--hold-h", 0, 1e3), default=0.0,
                   help="run this long at the initial blend before the scene's time 0")
    p.add_argument("--record", help="write the plant's true trajectory here (plant.parquet, plant-kpis.json)")
    p.add_argument("--watchdog-h", type=_float_in("--watchdog-h", 0, 1e3, lo_open=True), default=None,
                   help="shed the service after this long without its heartbeat (default 3 samples)")
    p.add_argument("--mode", default=None, help="initial operator mode (default: the tag map's auto value)")
    p.add_argument("--paused", action="store_true", help="start frozen; Simulation.Run = true starts the plant")
    p.add_argument("--seed", type=_seed, default=None, help="the analysers' noise seed (default: the scene's)")
    p.add_argument("--trust", help="folder of the client certificates accepted")
    p.add_argument("--users", help="users file (TOML, scrypt hashes)")
    p.set_defaults(func=cmd_plant_server)
    return p


@_exit_codes("plant-server")
def cmd_plant_server(args) -> int:
    import asyncio

    online, scene, tags = _online_scene(args, args.tags or _online().VIRTUAL_PLANT_TAGS)
    security = online.ServerSecurity(args.insecure, *(a and Path(a) for a in (args.cert, args.key, args.trust,
                                                                              args.users)))
    security.check()
    mode = args.mode
    if mode is not None and isinstance(tags.mode.auto_value, int):
        if not mode.lstrip("-").isdigit():
            raise SceneError(f"--mode must be an integer for this tag map's mode node (got {mode!r})")
        mode = int(mode)
    settings = online.PlantServerSettings(args.opcua, security, speedup=args.speedup, hold_h=args.hold_h,
                                          duration_h=args.duration_h, record_dir=args.record and Path(args.record),
                                          watchdog_h=args.watchdog_h, initial_mode=mode, paused=args.paused,
                                          seed=args.seed)
    asyncio.run(online.PlantServer(scene, tags, settings).run())
    return 0  # also after SIGTERM / SIGINT: a clean stop of a service, as systemd expects (README, Online)


#: name -> (add_parser, cmd) for registration in scenarios.cli.
COMMANDS = {
    "steady": (add_steady_parser, cmd_steady),
    "optimize": (add_optimize_parser, cmd_optimize),
    "calibrate": (add_calibrate_parser, cmd_calibrate),
    "size-mill": (add_size_mill_parser, cmd_size_mill),
    "bench": (add_bench_parser, cmd_bench),
    "run": (add_run_parser, cmd_run),
    "replay": (add_replay_parser, cmd_replay),
    "sweep": (add_sweep_parser, cmd_sweep),
    "check": (add_check_parser, cmd_check),
    "report": (add_report_parser, cmd_report),
    "export-controller": (add_export_controller_parser, cmd_export_controller),
    "serve": (add_serve_parser, cmd_serve),
    "plant-server": (add_plant_server_parser, cmd_plant_server),
}
