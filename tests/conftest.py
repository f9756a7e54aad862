"""Settings of the whole suite.

The suite runs on two pytest-xdist workers (pyproject's addopts). A DEM test's two OpenMP
threads then share the two cores with the other worker, and libgomp's default wait at a barrier
spins: a waiting thread burns the core that the thread it waits for needs. In the workers,
OpenMP waits passively (``OMP_WAIT_POLICY``, read when numba first loads OpenMP, after this
file); a run in one process (``-n 0``) and the user's own setting are left as they are.
"""

import os

if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def strict_json(text: str):
    """``json.loads`` that refuses NaN and Infinity (not JSON, though Python writes them)."""
    import json

    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")
    return json.loads(text, parse_constant=refuse)
