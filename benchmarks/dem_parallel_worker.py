"""One timed grindtwin run for benchmarks/dem_parallel.py, dem_ab.py and dem_busy.py (a subprocess,
so that the thread count is set by NUMBA_NUM_THREADS before numba starts).

``python benchmarks/dem_parallel_worker.py PACK DT_S STEPS`` runs the compression test's loading
phase on the packing PACK (x y z r per line, as written for Yade) with the Yade-JCFpm mirror
physics and prints one JSON line: steps, wall and CPU seconds of the stepping alone.
``... PACK DT_S full`` runs the whole compression test instead and prints its peak force and energy.
``... drum BALL_D_M SECTION_M STEPS`` times the lab drum's ball charge instead.
``... drop SPHERES J_KG`` times a drop-weight test that breaks an agglomerate of SPHERES spheres
(22 mm, the DEM calibration step's size) at J_KG; most of its steps are taken after the damage.
``... arith ITERS`` times independent floating-point chains in one parallel loop (no memory
traffic, nothing shared): the machine's own two-thread scaling, timed beside the DEM's.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numba
import numpy as np

from dem_common import COUNT, POSITIVE, option_type

# dem_ab.py drives an earlier revision's dem/ with this worker (the same driver on both sides):
# DEM_TREE names that revision's tree, put first on the path before anything imports dem
if os.environ.get("DEM_TREE"):
    sys.path.insert(0, os.environ["DEM_TREE"])

import dem
from dem_mirror import BONDS, MIRROR, PLATEN, ROCK
from dem.agglomerate import Agglomerate, make_agglomerate
from dem.bonds import BondSet, find_bond_pairs
from dem.drum import drum_system
from dem.lab import compression_test, drop_weight_test
from dem.system import PlaneWall, System
import dem.system

# the thread count asked for at every size: the break-even size of System.PARALLEL_MIN_SPHERES
# is what these runs measure
dem.system.PARALLEL_MIN_SPHERES = 0


def read_pack(path: str) -> Agglomerate:
    solid = float(open(path).readline().split()[-1])
    a = np.loadtxt(path, comments="#")
    pos, rad = a[:, :3], a[:, 3]
    d = 2.0 * float(np.max(np.linalg.norm(pos, axis=1) + rad))
    return Agglomerate(pos, rad, find_bond_pairs(pos, rad, 1.3), d, (d / 2,) * 3,
                       math.pi / 6 * d**3, solid, 0.0, 0)


def loading_system(agg: Agglomerate, dt_s: float) -> System:
    pos = agg.pos_m.copy()
    bs = BondSet(agg.bond_pairs, pos, agg.radius_m, BONDS)
    z_lo = float(np.min(pos[:, 2] - agg.radius_m))
    z_hi = float(np.max(pos[:, 2] + agg.radius_m))
    walls = [PlaneWall((0, 0, z_lo), (0, 0, 1)), PlaneWall((0, 0, z_hi), (0, 0, -1), (0, 0, -0.1))]
    return System(pos, agg.radius_m, ROCK, density_kg_m3=2700.0 / agg.solid_fraction, bonds=bs,
                  wall_material=PLATEN, walls=walls, local_damping=0.7, dt_s=dt_s,
                  contact_law="linear_yade", damping_velocity="at_force")


def drum(ball_d_m: float, section_m: float, steps: int) -> dict:
    """The lab drum's ball charge (dem.drum, 0.7 critical, J = 0.35) after 2,000 steps of
    settling from rest (contacts formed), then ``steps`` timed steps."""
    s = drum_system(0.7, 0.35, ball_diameter_m=ball_d_m, section_length_m=section_m).system
    s.run(2000)
    w0, c0 = time.perf_counter(), time.process_time()
    s.run(steps)
    return {"steps": steps, "wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0,
            "threads": numba.get_num_threads(), "threading_layer": numba.threading_layer(),
            "n_spheres": s.n, "n_pairs": int(s.pairs.i.shape[0])}


#: chains of :func:`_arithmetic`: many more than threads, an even split on 1 or 2 threads
ARITH_CHAINS = 64


@numba.njit(parallel=True)
def _arithmetic(chains, iters):
    """Four independent multiply-adds per iteration in each chain, all in registers."""
    out = np.empty(chains)
    for c in numba.prange(chains):
        x0 = x1 = x2 = x3 = 1.0 + c
        for _ in range(iters):
            x0 = x0 * 0.9999999 + 1e-9
            x1 = x1 * 0.9999998 + 1e-9
            x2 = x2 * 0.9999997 + 1e-9
            x3 = x3 * 0.9999996 + 1e-9
        out[c] = x0 + x1 + x2 + x3
    return out


def arith(iters: int) -> dict:
    """:func:`_arithmetic` of :data:`ARITH_CHAINS` chains of ``iters`` iterations (compiled first)."""
    _arithmetic(ARITH_CHAINS, 1)
    w0, c0 = time.perf_counter(), time.process_time()
    _arithmetic(ARITH_CHAINS, iters)
    return {"steps": iters, "wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0,
            "threads": numba.get_num_threads(), "threading_layer": numba.threading_layer()}


def drop(spheres: int, energy_J_kg: float) -> dict:
    """A drop-weight test (1 kg weight, the mirror's bonds and rock) of a 22 mm agglomerate."""
    agg = make_agglomerate(0.022, spheres, random_state=3)
    w0, c0 = time.perf_counter(), time.process_time()
    r = drop_weight_test(agg, BONDS, energy_J_kg, drop_mass_kg=1.0, material=ROCK)
    return {"steps": r.n_steps, "wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0,
            "threads": numba.get_num_threads(), "broken_fraction": r.broken_fraction, "n_bonds": r.n_bonds}


USAGE = ("%(prog)s PACK DT_S {STEPS,full}\n       %(prog)s drum BALL_D_M SECTION_M STEPS\n"
         "       %(prog)s drop SPHERES J_KG\n       %(prog)s arith ITERS")
STEPS_OR_FULL = option_type(lambda t: t if t == "full" else int(t), lambda v: v == "full" or v >= 1,
                            "an integer >= 1 or 'full'")


def options(argv=None) -> argparse.Namespace:
    """The callers' positional arguments: ``PACK DT_S STEPS|full`` or ``drum BALL_D_M SECTION_M STEPS``."""
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], usage=USAGE)
    if argv[:1] == ["drum"]:
        ap.add_argument("pack", choices=["drum"], help="the drum's ball charge instead of a packing")
        ap.add_argument("ball_d_m", metavar="BALL_D_M", type=POSITIVE, help="ball diameter, m")
        ap.add_argument("section_m", metavar="SECTION_M", type=POSITIVE, help="slice length, m")
        ap.add_argument("steps", metavar="STEPS", type=COUNT, help="timed steps")
        return ap.parse_args(argv)
    if argv[:1] == ["drop"]:
        ap.add_argument("pack", choices=["drop"], help="a drop-weight test instead of a packing")
        ap.add_argument("spheres", metavar="SPHERES", type=COUNT, help="spheres of the agglomerate")
        ap.add_argument("energy", metavar="J_KG", type=POSITIVE, help="specific impact energy, J/kg")
        return ap.parse_args(argv)
    if argv[:1] == ["arith"]:
        ap.add_argument("pack", choices=["arith"], help="independent arithmetic instead of a packing")
        ap.add_argument("iters", metavar="ITERS", type=COUNT, help="iterations of each chain")
        return ap.parse_args(argv)
    ap.add_argument("pack", metavar="PACK", help="packing, x y z r per line as written for Yade (or 'drum')")
    ap.add_argument("dt_s", metavar="DT_S", type=POSITIVE, help="time step, s")
    ap.add_argument("steps", metavar="STEPS", type=STEPS_OR_FULL,
                    help="timed steps of the loading phase, or 'full' for the whole compression test")
    o = ap.parse_args(argv)
    if not os.path.isfile(o.pack):
        ap.error(f"PACK {o.pack!r}: no such file (the drum case is 'drum BALL_D_M SECTION_M STEPS')")
    return o


def main(argv=None):
    o = options(argv)
    if o.pack in ("drum", "drop", "arith"):
        res = {"drum": lambda: drum(o.ball_d_m, o.section_m, o.steps), "drop": lambda: drop(o.spheres, o.energy),
               "arith": lambda: arith(o.iters)}[o.pack]()
        print(json.dumps({**res, "dem": os.path.dirname(dem.__file__)}))
        return
    agg = read_pack(o.pack)
    dt = o.dt_s
    if o.steps == "full":
        s = loading_system(agg, dt)          # only for the critical step of this packing
        r = compression_test(agg, BONDS, time_step_factor=dt / s.critical_dt_s, **MIRROR)
        print(json.dumps({"peak_force_N": r.peak_force_N, "fracture_energy_J": r.fracture_energy_J,
                          "steps": r.n_steps, "wall_s": r.wall_time_s, "dt_s": r.dt_s,
                          "threads": numba.get_num_threads()}))
        return
    steps = o.steps
    s = loading_system(agg, dt)
    s.run(20)                                # kernels from the cache
    w0, c0 = time.perf_counter(), time.process_time()
    s.run(steps)
    print(json.dumps({"steps": steps, "wall_s": time.perf_counter() - w0,
                      "cpu_s": time.process_time() - c0, "threads": numba.get_num_threads(),
                      "dem": os.path.dirname(dem.__file__),
                      "threading_layer": numba.threading_layer(),
                      "n_spheres": agg.n_spheres, "n_bonds": agg.n_bonds}))


if __name__ == "__main__":
    main()
