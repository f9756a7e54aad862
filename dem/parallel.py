"""Independent DEM runs on several processes: the compression tests of a calibration's
iteration, a set of drop-weight tests. Each run is a pure function of its arguments (its own
packing, seed and bonds), so the answers are those of one process, in the same order, whatever
the number of processes; joblib's loky workers are kept between calls (a worker loads the
compiled kernels once, not at every iteration).
"""

from __future__ import annotations

import os

import numba


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system says it)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _one_kernel_thread(fn, args, kwargs):
    # the processes share the cores: one kernel thread each (the answer does not depend on it)
    numba.set_num_threads(1)
    return fn(*args, **kwargs)


def run_in_processes(fn, calls, workers: int, on_result=None) -> list:
    """``[fn(*args, **kwargs) for args, kwargs in calls]`` on ``workers`` processes (1: in
    this one). ``on_result()`` is called as each answer arrives (a progress tick). A run's
    exception is raised here, as its own type."""
    calls = list(calls)
    out = []
    if workers == 1 or len(calls) <= 1:
        for args, kwargs in calls:
            out.append(fn(*args, **kwargs))
            if on_result is not None:
                on_result()
        return out
    from joblib import Parallel, delayed

    work = Parallel(n_jobs=min(workers, len(calls)), backend="loky", return_as="generator")
    for res in work(delayed(_one_kernel_thread)(fn, args, kwargs) for args, kwargs in calls):
        out.append(res)
        if on_result is not None:
            on_result()
    return out
