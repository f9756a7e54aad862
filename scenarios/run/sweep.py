"""What-if sweeps: vary scene keys, run every case, one table of results.

``vary`` maps a key path (``"feed.feed_tph"``, ``"controller.weights.p80"``,
``"feed.schedule[0].blend"``) to a list of values. ``cartesian`` runs every combination,
``paired`` runs the i-th value of every key together (lists of equal length). Every path is
checked against the scene schema (below ``effect_options``, against the effects' declared
options) and every case is checked as ``grindtwin check`` checks a scene (its models built, its start found)
before any case runs. A case that fails while running is reported in the ``error`` column; the other
cases are kept. A sweep stopped by a signal (Ctrl-C, SIGTERM) re-raises it with the table of the cases
that finished as the exception's ``partial_table`` (the others' ``error``: :data:`NOT_RUN`).

Cases run in a local process pool (``workers``; 1 runs in this process) or, when
``scheduler`` is given (an address such as ``"tcp://host:8786"``, a ``distributed.Client``
or a cluster object such as ``LocalCluster``), on a Dask distributed cluster; that needs the
optional extra ``grindtwin[distributed]``.
"""

from __future__ import annotations

import copy
import itertools
import math
import pickle
import re
import signal
import threading
import tomllib
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path
from typing import Any, Callable, Literal

import numpy as np
import pandas as pd
from tqdm import auto as tqdm_auto
from tqdm.auto import tqdm
from tqdm.std import tqdm as std_tqdm

from scenarios.errors import Interrupted, RunError, SceneError, raise_if_interrupted
from scenarios.scene.keypaths import did_you_mean, format_path, parse_path, type_at
from scenarios.run.preflight import run_problems
from scenarios.scene.loader import read_toml, validate_scene_dict
from scenarios.scene.schema import Scene

RunCase = Callable[[Scene], dict]
#: What a case's run would refuse, as messages (none: it may run).
Preflight = Callable[[Scene], list]

#: A sweep of more cases than this is refused unless ``max_cases`` (``--max-cases``) allows it:
#: each case is a whole run (seconds to minutes), so a typo such as ``1:1000:0.001`` would
#: otherwise start days of work.
MAX_CASES = 1000
#: Most values one ``start:stop:step`` range may give (above any useful ``max_cases``).
MAX_RANGE_VALUES = 1_000_000
#: The ``error`` of a case a signal stopped the sweep before (or while) it ran.
NOT_RUN = "not run: the sweep was interrupted"


@dataclass
class Case:
    """One case of a sweep: its number, the values set (key path -> value), the raw scene table."""

    index: int
    values: dict[str, Any]
    data: dict[str, Any]


def parse_vary(text: str) -> tuple[str, list]:
    """``"KEY=v1,v2,..."`` or ``"KEY=start:stop:step"`` (stop included) -> ``(KEY, values)``.

    Values are read as TOML (``30``, ``0.7``, ``"nmpc"``, ``{ B = 0.6, D = 0.4 }``); a bare
    word is a string.
    """
    if "=" not in text:
        raise SceneError(f"--vary {text!r}: expected KEY=v1,v2,... or KEY=start:stop:step")
    key, spec = (s.strip() for s in text.split("=", 1))
    parts = spec.split(":")
    if len(parts) == 3 and "{" not in spec and '"' not in spec:
        try:
            start, stop, step = (float(p) for p in parts)
        except ValueError:
            raise SceneError(f"--vary {text!r}: start:stop:step must be numbers") from None
        if not all(math.isfinite(v) for v in (start, stop, step)):
            raise SceneError(f"--vary {text!r}: start:stop:step must be finite numbers")
        if step <= 0 or stop < start:
            raise SceneError(f"--vary {text!r}: need step > 0 and stop >= start")
        n = int(np.floor((stop - start) / step + 1e-9)) + 1
        if n > MAX_RANGE_VALUES:
            raise SceneError(f"--vary {text!r}: {n} values; a range gives at most {MAX_RANGE_VALUES}")
        values = [start + i * step for i in range(n)]
        if all(float(p).is_integer() for p in parts):
            values = [int(round(v)) for v in values]
        return key, values
    try:
        values = tomllib.loads(f"v = [{spec}]")["v"]
    except tomllib.TOMLDecodeError:
        values = []
        for item in (s.strip() for s in spec.split(",")):
            try:
                values.append(tomllib.loads(f"v = {item}")["v"])
            except tomllib.TOMLDecodeError:
                values.append(item)
    bad = [v for v in values if isinstance(v, float) and not math.isfinite(v)]
    if bad:
        raise SceneError(f"--vary {text!r}: values must be finite numbers (got {bad[0]})")
    return key, values


def case_count(vary: dict[str, list], mode: str = "cartesian") -> int:
    """How many cases ``vary`` makes (paired: the common length)."""
    lengths = [len(v) for v in vary.values()]
    return (max(lengths) if mode == "paired" else math.prod(lengths)) if lengths else 0


#: controller keys an open-loop run reads: its kind; the target, which the KPIs measure against and a
#: ``feed.start = "target"`` starts at; the load band of the KPI ``load_outside_band_frac``
OPEN_LOOP_CONTROLLER_KEYS = (("kind",), ("target_p80_um",), ("load_band_frac",))
#: sensor keys only a controller reads (an open-loop run's analyser trace has the P80's noise and lags)
OPEN_LOOP_IDLE = (("sensors", "power_noise_kw"), ("sensors", "load_noise_frac"))


def _refuse_options_no_case_reads(scene_dict: dict[str, Any], vary: dict[str, list], paths: dict, kind) -> None:
    """SceneError for a varied ``effect_options.EFFECT...`` of an effect only the controller's model has
    (``[plant]`` lists its own effects without it) in a sweep no case of which runs the NMPC: every case
    ran the same plant, rows labelled with values nothing read (an analyser dead time of the model, varied
    over open and PI loops)."""
    plant_effects = (scene_dict.get("plant") or {}).get("effects")
    kinds = set(vary.get("controller.kind", [kind]))
    if plant_effects is None or "nmpc" in kinds:
        return
    idle = [k for k, loc in paths.items() if loc[0] == "effect_options" and len(loc) > 1
            and loc[1] not in plant_effects]
    if idle:
        raise SceneError(f"sweep: {', '.join(idle)}: options of an effect only the controller's model has ([plant] "
                         f"effects {list(plant_effects)}), and no case runs the NMPC (controller.kind "
                         f"{sorted(kinds)}), so these keys change nothing; vary them in [plant.effect_options] with "
                         "the effect in [plant] effects, or vary controller.kind to 'nmpc' too")


def expand_cases(scene_dict: dict[str, Any], vary: dict[str, list],
                 mode: Literal["cartesian", "paired"] = "cartesian", max_cases: int = MAX_CASES) -> list[Case]:
    """The sweep's cases: a deep copy of ``scene_dict`` per case with the varied keys set;
    SceneError above ``max_cases`` cases (counted before anything is copied)."""
    if mode not in ("cartesian", "paired"):
        raise SceneError(f"sweep mode: must be 'cartesian' or 'paired' (got {mode!r})")
    if not vary:
        raise SceneError("sweep: nothing to vary; give at least one KEY and its values")
    paths = {key: _checked_path(scene_dict, key) for key in vary}
    for key, loc in paths.items():  # a table set after its own key overwrote it: rows labelled with values not run
        inner = [k for k, other in paths.items() if k != key and other[:len(loc)] == loc]
        if inner:
            raise SceneError(f"sweep: {inner[0]} lies inside {key}, which is varied too: each case would run one of "
                             "them and be labelled with both; vary the table or its keys, not both")
    idle = [k for k, loc in paths.items() if loc in OPEN_LOOP_IDLE or (loc[0] == "controller" and loc[1:2] not in
                                                                        OPEN_LOOP_CONTROLLER_KEYS)]
    kind = (scene_dict.get("controller") or {}).get("kind", "none")
    if idle and kind == "none" and "controller.kind" not in vary:  # every case the same, said nowhere
        raise SceneError(f"sweep: {', '.join(idle)}: the scene has no controller (controller.kind = 'none'), so "
                         "these keys change nothing; vary controller.kind too, or set it in the scene (an open-loop "
                         "run reads controller.target_p80_um and controller.load_band_frac)")
    _refuse_options_no_case_reads(scene_dict, vary, paths, kind)
    lists = {key: list(values) for key, values in vary.items()}
    for key, values in lists.items():
        if not values:
            raise SceneError(f"sweep: {key}: no values given")
    if mode == "paired":
        lengths = {key: len(v) for key, v in lists.items()}
        if len(set(lengths.values())) > 1:
            raise SceneError(f"sweep: paired mode needs lists of equal length (got {lengths})")
    n = case_count(lists, mode)
    if n > max_cases:
        raise SceneError(f"sweep: {n:,} cases, more than the limit of {max_cases:,}; vary fewer "
                         f"values, or raise the limit with --max-cases {n} (max_cases={n})")
    if mode == "paired":
        combos = list(zip(*lists.values()))
    else:
        combos = list(itertools.product(*lists.values()))
    cases = []
    for i, combo in enumerate(combos):
        data = copy.deepcopy(scene_dict)
        values = dict(zip(lists, combo))
        for key, value in values.items():
            _set(data, paths[key], copy.deepcopy(value))
        cases.append(Case(i, values, data))
    return cases


def validate_cases(cases: list[Case], source_path: str | Path | None, problems: Preflight | None = None,
                   progress: bool = False) -> list[Scene]:
    """Every case as a validated Scene; SceneError naming each invalid case and its problems (a
    problem every case has, the base scene's, is named once). ``problems(scene)``, when given, lists
    what else a case's run would refuse (``scenarios.run.preflight.run_problems`` builds the models
    and finds the start: about a second a case, so ``progress`` shows a bar)."""
    scenes, per_case = [], []
    for case in tqdm(cases, desc="check", unit="case", disable=not progress or problems is None):
        scene, errors = validate_scene_dict(case.data, source_path)
        if scene is not None and problems is not None:
            errors = problems(scene)
        per_case.append((case, [str(e) for e in errors]))
        scenes.append(scene)
    shared = [e for e in per_case[0][1] if all(e in errors for _, errors in per_case)] if len(per_case) > 1 else []
    problems = [f"every case: {e}" for e in shared]
    for case, errors in per_case:
        setting = ", ".join(f"{k}={v!r}" for k, v in case.values.items())
        problems += [f"case {case.index} ({setting}): {e}" for e in errors if e not in shared]
    if problems:
        raise SceneError(f"sweep of {source_path}: {len(problems)} problem{'s' * (len(problems) != 1)}\n  "
                         + "\n  ".join(problems))
    return scenes


def run_sweep(scene_path: str | Path, vary: dict[str, list], run_case: RunCase, *,
              mode: Literal["cartesian", "paired"] = "cartesian", workers: int | None = None,
              scheduler: Any = None, progress: bool = True, max_cases: int = MAX_CASES,
              check: Callable[[list[Scene]], None] | None = None,
              problems: Preflight | None = run_problems) -> pd.DataFrame:
    """Run ``run_case(scene) -> dict of KPIs`` for every case; one row per case.

    Columns: ``case``, the varied key paths, the KPIs (union over cases), ``error`` (``None``
    for a case that ran). ``run_case`` must be picklable (a module-level function). Before any
    case runs: every case is checked by ``problems`` (default: what a run of it would refuse,
    :func:`scenarios.run.preflight.run_problems`; None for a ``run_case`` that does not run the
    scene), the scheduler address is checked and the cluster reached, and ``check`` is called
    (given the validated scenes of the cases; it raises to refuse them).
    """
    scene_dict = read_toml(scene_path)  # read once: the table records what its cases were made from
    cases = expand_cases(scene_dict, vary, mode, max_cases)
    if isinstance(scheduler, str):
        check_scheduler_address(scheduler)
    scenes = validate_cases(cases, scene_path, problems, progress)
    if check is not None:
        check(scenes)
    outcomes: list = [(None, NOT_RUN)] * len(scenes)  # filled in as cases finish
    try:
        if scheduler is not None:
            _run_dask(run_case, scenes, scheduler, progress, outcomes)
        else:
            _run_local(run_case, scenes, workers, progress, outcomes)
    except (KeyboardInterrupt, Interrupted) as exc:  # the finished cases go with the signal, not lost
        exc.partial_table = _table(cases, outcomes, scene_path, mode, vary, scene_dict)
        raise
    return _table(cases, outcomes, scene_path, mode, vary, scene_dict)


def _table(cases: list[Case], outcomes: list, scene_path, mode: str, vary: dict, scene_dict: dict) -> pd.DataFrame:
    """One row per case; ``attrs``: the scene file, the mode, the varied keys and ``scene_table``, the file's table
    as the cases were made from it (what a sweep's outputs describe the base scene by: the file read again at the
    end was the one edited meanwhile)."""
    rows = [{"case": case.index, **case.values, **(kpis or {}), "error": error}
            for case, (kpis, error) in zip(cases, outcomes)]
    table = pd.DataFrame(rows)
    table.attrs.update(scene=str(scene_path), mode=mode, varied=list(vary), scene_table=scene_dict)
    return table


def run_one(run_case: RunCase, scene: Scene) -> tuple[dict | None, str | None]:
    """``(kpis, None)`` or ``(None, "ErrorType: message")``: a failing case never raises."""
    try:
        kpis = run_case(scene)
    except Exception as exc:  # noqa: BLE001 - the case's failure is the result
        return None, f"{type(exc).__name__}: {exc}"
    if not isinstance(kpis, dict):
        return None, f"TypeError: run_case returned {type(kpis).__name__}, expected a dict of KPIs"
    return kpis, None


def _run_local(run_case: RunCase, scenes: list[Scene], workers: int | None, progress: bool,
               outcomes: list) -> None:
    from dem import available_cores

    workers = min(workers or available_cores(), len(scenes))
    if workers > 1:
        _check_picklable(run_case)
    bar = tqdm(total=len(scenes), desc="sweep", unit="case", disable=not progress)
    with bar:
        if workers <= 1:
            for i, scene in enumerate(scenes):
                outcome = run_one(run_case, scene)
                raise_if_interrupted()  # a signal inside a solver call came out as the case's error
                outcomes[i] = outcome
                bar.update()
            return
        pool = ProcessPoolExecutor(max_workers=workers, initializer=_worker_ignores_signals)
        futures: dict = {}
        try:
            with _signals_held():  # the pool forks its workers at the first submit
                futures = {pool.submit(run_one, run_case, s): i for i, s in enumerate(scenes)}
            for fut in as_completed(futures):
                outcomes[futures[fut]] = _outcome(fut)
                bar.update()
        except BaseException:  # Ctrl-C, SIGTERM: stop the workers now, not after their cases
            _keep_finished(futures.items(), outcomes)
            _stop_workers(pool)
            raise
        pool.shutdown()


def _keep_finished(futures, outcomes: list) -> None:
    """On a signal: the outcome of every case that finished but was not collected yet (``futures``: pairs of a
    future, of a process pool or a Dask cluster, and its case's index), so no finished case is lost."""
    for fut, i in futures:
        if fut.done() and not fut.cancelled():
            outcomes[i] = _outcome(fut)


#: The signals a sweep's workers leave to the parent (:func:`_worker_ignores_signals`).
PARENT_SIGNALS = {signal.SIGINT, signal.SIGTERM}


@contextmanager
def _signals_held():
    """SIGINT and SIGTERM held back in this thread while it forks the pool's workers: a Ctrl-C landing between a
    worker's fork and its initializer raised KeyboardInterrupt in the worker, whose traceback reached the user's
    terminal ('Exception ignored in ... logging ... _releaseLock'). The workers start with them held and unhold
    them once they ignore them; the parent gets a held signal when this ends."""
    if not hasattr(signal, "pthread_sigmask"):  # no per-thread signal mask (Windows)
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, PARENT_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _worker_ignores_signals() -> None:
    """Workers leave SIGINT and SIGTERM to the parent (a Ctrl-C reaches the whole process
    group): the parent stops them, so no worker prints a traceback of its own. A worker's progress
    bars (a disabled one takes the lock too) lock a lock of its own: tqdm's default, forked from the
    parent, is shared with it across processes, and a worker terminated while holding it left the
    parent's bar waiting for it for ever (a sweep stopped by Ctrl-C hung in tqdm's close)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if hasattr(signal, "pthread_sigmask"):  # forked with them held (_signals_held): a Ctrl-C held is now dropped
        signal.pthread_sigmask(signal.SIG_UNBLOCK, PARENT_SIGNALS)
    own = threading.RLock()
    for cls in {tqdm_auto.tqdm, std_tqdm}:  # the classes, not the module's name a test may replace
        cls.set_lock(own)


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """Cancel what has not started and terminate the worker processes this sweep started."""
    procs = list(getattr(pool, "_processes", {}).values())  # no public API for this before 3.14
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    for proc in procs:
        proc.join(timeout=5)


def _check_picklable(run_case: RunCase) -> None:
    try:
        pickle.dumps(run_case)
    except Exception as exc:  # noqa: BLE001 - any pickling failure means the same thing
        raise RunError(f"run_case {run_case!r} cannot be sent to worker processes ({exc}); "
                       "use a module-level function, or workers=1") from None


#: A Dask scheduler address: ``PROTOCOL://HOST[:PORT]`` or ``HOST:PORT``.
SCHEDULER_ADDRESS = re.compile(r"^(?:(?:tcp|tls|inproc|ucx|ws|wss)://[^\s/:]+(?::\d{1,5})?|[^\s/:]+:\d{1,5})/?$")
#: How long to try to reach a Dask scheduler before the sweep is refused [s].
SCHEDULER_TIMEOUT_S = 10


def check_scheduler_address(address: str) -> None:
    """SceneError unless ``address`` reads as a Dask scheduler address."""
    if not SCHEDULER_ADDRESS.match(address):
        raise SceneError(f"--scheduler {address!r}: not a Dask scheduler address; expected "
                         "PROTOCOL://HOST:PORT (e.g. tcp://10.0.0.5:8786) or HOST:PORT")


def _run_dask(run_case: RunCase, scenes: list[Scene], scheduler: Any, progress: bool, outcomes: list) -> None:
    try:
        from distributed import Client
        from distributed import as_completed as dask_completed
    except ImportError:
        raise RunError("a Dask scheduler was given but dask.distributed is not installed; "
                       "install the optional extra: pip install 'grindtwin[distributed]'") from None
    own = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler, timeout=SCHEDULER_TIMEOUT_S) if own else scheduler
    except (OSError, TimeoutError, ValueError) as exc:
        raise RunError(f"cannot reach the Dask scheduler {scheduler!r} within {SCHEDULER_TIMEOUT_S} s: "
                       f"{type(exc).__name__}: {exc}") from None
    futures: list = []
    try:
        futures = [client.submit(run_one, run_case, s, pure=False) for s in scenes]
        index = {f.key: i for i, f in enumerate(futures)}
        with tqdm(total=len(scenes), desc="sweep", unit="case", disable=not progress) as bar:
            for fut in dask_completed(futures):
                outcomes[index[fut.key]] = _outcome(fut)
                bar.update()
    except BaseException:  # as the local pool's: cases finished but not yet collected are kept
        _keep_finished(zip(futures, range(len(scenes))), outcomes)
        raise
    finally:
        if own:
            client.close()


def _outcome(fut) -> tuple[dict | None, str | None]:
    try:
        return fut.result()
    except Exception as exc:  # noqa: BLE001 - a lost worker fails its case, not the sweep
        return None, f"{type(exc).__name__}: {exc}"


def _checked_path(scene_dict: dict, key: str) -> tuple:
    try:
        loc = parse_path(key)
    except ValueError as exc:
        raise SceneError(f"sweep: {exc}") from None
    for n in range(1, len(loc) + 1):
        try:
            type_at(Scene, loc[:n])
        except KeyError as exc:
            step, allowed = exc.args
            where = format_path(loc[:n - 1]) if n > 1 else "the scene"
            raise SceneError(f"sweep: unknown key path {key!r}: {step!r} is not a key of {where}"
                             f"{did_you_mean(step, allowed)}; allowed: {', '.join(allowed)}") from None
        if isinstance(loc[n - 1], int):
            seq = _lookup(scene_dict, loc[:n - 1])
            if not isinstance(seq, list) or loc[n - 1] >= len(seq):
                size = len(seq) if isinstance(seq, list) else 0
                raise SceneError(f"sweep: key path {key!r}: {format_path(loc[:n - 1])} has "
                                 f"{size} entries in the scene file; index {loc[n - 1]} is not one")
    _check_effect_option_path(key, loc)
    return loc


def _check_effect_option_path(key: str, loc: tuple) -> None:
    """The steps of ``loc`` below an ``effect_options`` table, where the scene schema is
    free-form, checked against what the twin declares there: effect names (its registry), an
    effect's options (their :class:`twin.effects.Option` declarations) and the fields of an option
    given as a table (the dataclass it builds: the classification's ``cyclone`` table is read by
    :func:`twin.hydrocyclone_from` into a Hydrocyclone, whose fields it allows, and its ``survey``
    table into a CycloneSurvey, the dataclass's ``tables``). A misspelt step
    is refused here, before any case is built, rather than in every case (values are left to each
    case's validation, the twin's own checks)."""
    if "effect_options" not in loc:
        return
    from twin.effects import EFFECTS

    top = loc.index("effect_options")
    known: list | None = list(EFFECTS)  # the keys allowed at the next step; None: any
    leaf = ""  # what the path names when no key may follow it
    for n in range(top + 1, len(loc)):
        where, step = format_path(loc[:n]), loc[n]
        if known is None:
            return
        if not known:
            raise SceneError(f"sweep: unknown key path {key!r}: {where} {leaf}, with no keys below it; "
                             f"vary {where} itself")
        if step not in known:
            raise SceneError(f"sweep: unknown key path {key!r}: {step!r} is not a key of {where}"
                             f"{did_you_mean(step, known)}; allowed: {', '.join(map(str, known))}")
        depth = n - top
        if depth == 1:
            known = list(EFFECTS[step].options)
        elif depth == 2:
            option = EFFECTS[loc[top + 1]].options[step]
            known = _option_table_fields(option)
            leaf = f"takes {option.allowed()}"
        else:
            nested = _nested_table(EFFECTS[loc[top + 1]].options[loc[top + 2]], step) if depth == 3 else None
            known = [f.name for f in fields(nested)] if nested else []
            leaf = "is a field of a table and takes a value"


def _option_table_fields(option) -> list[str] | None:
    """The keys a table given for ``option`` may have: the fields of the dataclass the table
    builds; ``[]`` when the option takes no table, None when it takes one of any keys."""
    kinds = option.kind if isinstance(option.kind, tuple) else (option.kind,)
    if dict not in kinds:
        return []
    built = [k for k in kinds if is_dataclass(k)]
    return [f.name for k in built for f in fields(k)] + [t for k in built for t in getattr(k, "tables", {})] \
        if built else None


def _nested_table(option, key: str):
    """The dataclass a table under ``key`` of ``option``'s table builds (a Hydrocyclone's ``survey``), or None."""
    kinds = option.kind if isinstance(option.kind, tuple) else (option.kind,)
    return next((k.tables[key] for k in kinds if is_dataclass(k) and key in getattr(k, "tables", {})), None)


def _lookup(data: Any, loc: tuple) -> Any:
    for step in loc:
        if isinstance(data, dict) and step in data:
            data = data[step]
        elif isinstance(data, list) and isinstance(step, int) and step < len(data):
            data = data[step]
        else:
            return None
    return data


def _set(data: dict, loc: tuple, value: Any) -> None:
    node = data
    for step in loc[:-1]:
        if isinstance(node, list):
            node = node[step]
            continue
        if not isinstance(node.get(step), (dict, list)):
            node[step] = {}
        node = node[step]
    node[loc[-1]] = value

