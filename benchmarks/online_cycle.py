"""One cycle of the served controller (read, estimate, solve, write) on loopback, what the secure
session costs, and the reference transition served on the virtual plant against the in-process
loop over several seeds.

Set-up: ``grindtwin plant-server`` in its own process serves scenarios/reference_transition.toml
over Basic256Sha256 SignAndEncrypt with user authentication (certificates and a user made for
this run in a temporary folder), sped up ``--speedup`` times, after a 2-hour hold at the initial
blend, with the analysers' noise of each seed (``--seed``); a second plant server serves the same
nodes unsecured (``--insecure``, frozen). ``scenarios.online.Service`` runs in this process with
the scene's EKF and NMPC; its cycle starts on each new analyser report (the virtual plant's tag map).

1. Transport, interleaved: the service's read of every tag and its write of the setpoints,
   heartbeat and status, over the secure and the unsecured session in turn (A, B, A, B, ...).
2. Per seed: the in-process loop (mpc.run_closed_loop wired as scenarios.run.closed_loop wires it),
   the served loop in lock step on one manual clock (over OPC UA, no wall-clock timing; each cycle
   ``--late`` of a sample after the plant's sample: 0 is the in-process loop's timing), and the
   whole 8-hour transition served in sped-up real time; KPIs from the plant's record, per-cycle
   times from the audit log, when the moves took effect from the plant's record.
3. docs/online_served_run.png: P80 (plant, analyser, target), setpoints of the first seed's served run.

Writes benchmarks/results/online_cycle.md, online_cycle.csv (per-cycle times of the served runs)
and online_cycle_seeds.csv (KPIs per seed and loop).

    python benchmarks/online_cycle.py [--speedup 180] [--rounds 300] [--seeds 1,2,3,4,5] [--late 0,0.5,0.9]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import asyncua
import matplotlib
import numpy as np
import pandas as pd
from asyncua import ua

import scenarios.online as online
from scenarios.online.plant_server import MIN_PIECE_FRAC
from scenarios.run.closed_loop import ESTIMATOR_WARMUP_H
from scenarios.scene import load_scene

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"
SCENE = ROOT / "scenarios" / "reference_transition.toml"
FIGURE = ROOT / "docs" / "online_served_run.png"
CLI = [sys.executable, "-c", "import sys; from scenarios.cli import main; sys.exit(main(sys.argv[1:]))"]
USER, PASSWORD = "apc", "benchmark-only"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def make_pki(d: Path) -> None:
    online.make_certificate(d / "server.pem", d / "server-key.pem", "plant", "urn:bench:plant", server=True)
    online.make_certificate(d / "client.pem", d / "client-key.pem", "serve", "urn:bench:serve", server=False)
    (d / "trust").mkdir()
    (d / "trust" / "client.pem").write_bytes((d / "client.pem").read_bytes())
    (d / "users.toml").write_text(f'[users.{USER}]\npassword_scrypt = "{online.hash_password(PASSWORD)}"\n')


def start_plant(d: Path, speedup: float, log, seed: int | None = None, secure: bool = True):
    """A frozen plant server: the secure one with the seed's analysers and a record (the served
    runs), or the unsecured one (the transport's comparison)."""
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    cmd = [*CLI, "plant-server", str(SCENE), "--speedup", str(speedup), "--paused", "--quiet", "--opcua", url]
    if secure:
        cmd += ["--hold-h", str(ESTIMATOR_WARMUP_H), "--duration-h", "8", "--seed", str(seed), "--record",
                str(d / f"plant-{seed}"), "--cert", str(d / "server.pem"), "--key", str(d / "server-key.pem"),
                "--trust", str(d / "trust"), "--users", str(d / "users.toml")]
    else:
        cmd += ["--insecure"]
    return subprocess.Popen(cmd, stderr=log), url  # logs to a file, not a pipe: a full pipe would stall a server


def client_security(d: Path) -> online.ClientSecurity:
    return online.ClientSecurity(False, d / "client.pem", d / "client-key.pem", d / "server.pem", USER, PASSWORD)


async def wait_until(predicate, timeout_s: float, what: str) -> None:
    t0 = time.monotonic()
    while not predicate():
        if time.monotonic() - t0 > timeout_s:
            raise RuntimeError(f"timed out waiting for {what}")
        await asyncio.sleep(0.1)


async def connected(url, security, tags, timeout_s=300.0) -> online.PlantConnection:
    """A session with the service's roles, retried while the plant server starts."""
    t0 = time.monotonic()
    while True:
        conn = online.PlantConnection(url, security, tags.read_roles(), tags.write_roles(),
                                      tags.connection.request_timeout_s)
        try:
            await conn.open()
            return conn
        except online.CONNECTION_ERRORS:
            if time.monotonic() - t0 > timeout_s:
                raise
            await asyncio.sleep(1.0)


async def transport(tags, secure, unsecured, rounds: int) -> pd.DataFrame:
    """The service's read and write, secure and unsecured in turn."""
    rows = []
    now = await secure.read()  # the setpoints are written back as they are: the frozen plant stays put
    items = {"setpoints.feed_tph": (now["feed_tph"].value, 0), "heartbeat": (1, 0), "status": ("benchmark", 0),
             "setpoints.speed_frac_critical": (now["speed_frac_critical"].value, 0)}
    for k in range(rounds):
        for name, conn in (("secure", secure), ("unsecured", unsecured)) if k % 2 == 0 else (
                ("unsecured", unsecured), ("secure", secure)):
            t0 = time.perf_counter()
            await conn.read()
            t1 = time.perf_counter()
            await conn.write(items, online.Clock().now())
            t2 = time.perf_counter()
            rows.append({"session": name, "read_s": t1 - t0, "write_s": t2 - t1, "read_write_s": t2 - t0})
    return pd.DataFrame(rows)


async def served(parts, tags, d: Path, url: str, proc, speedup: float, seed: int):
    """The served run on a secure plant server: connect while it is frozen, let it run, serve
    until its run ends. The frozen plant's readings are stale by then, so the estimator starts at
    the plant's first sample, one into the hold (the warm-up is one sample shorter to match)."""
    await (await connected(url, client_security(d), tags)).close()  # it listens: the service connects at once
    service = online.Service(parts, tags, online.ServeSettings(
        url, client_security(d), d / f"audit-{seed}", speedup=speedup,
        warmup_h=ESTIMATOR_WARMUP_H - parts.scene.scene.sample_period_h))
    task = asyncio.create_task(service.run(install_signal_handlers=False))
    await wait_until(lambda: service.conn is not None, 300, "the service's session")
    run = online.PlantConnection(url, client_security(d), {}, {"run": "ns=2;s=Simulation.Run"})
    await run.open()
    await run.write({"run": (True, ua.StatusCodes.Good)}, online.Clock().now())
    await run.close()
    await wait_until(lambda: proc.poll() is not None, 3600, "the end of the plant's run")
    service.request_stop("benchmark end")
    await task


def pct(x, q) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.percentile(x, q)) if x.size else float("nan")


def figure(plant: pd.DataFrame, scene) -> None:
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(9, 7.5), sharex=True, gridspec_kw={"height_ratios": [3, 2, 2]})
    a1.plot(plant["time_h"], plant["p80_um"], label="plant P80 (the twin's truth)")
    a1.plot(plant["time_h"], plant["p80_measured_um"], ".", ms=3, label="analyser (OPC UA)")
    a1.plot(plant["time_h"], plant["p80_target_um"], "k--", lw=1, label="target")
    a1.set_ylabel("P80 [um]")
    a1.legend(loc="upper left", fontsize=8)
    a2.plot(plant["time_h"], plant["feed_tph"], color="C2")
    a2.set_ylabel("feed [t/h]")
    a3.plot(plant["time_h"], plant["speed_frac_critical"], color="C3")
    a3.set_ylabel("speed [frac. critical]")
    a3.set_xlabel("plant time [h]  (before 0: the estimator's warm-up on the running plant)")
    for a in (a1, a2, a3):
        a.axvspan(plant["time_h"].min(), 0.0, color="0.9", zorder=0)
        for ev in scene.feed.schedule:
            a.axvspan(ev.at_h, ev.at_h + ev.ramp_h, color="C1", alpha=0.12, zorder=0)
    a1.set_title("grindtwin serve on the virtual plant over OPC UA (Basic256Sha256 SignAndEncrypt); "
                 "ramp to 60 % B / 40 % D shaded", fontsize=9)
    fig.tight_layout()
    fig.savefig(FIGURE, dpi=110)


def table(rows: list[list], header: list[str]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


KEYS = ["p80_iae_um_h", "p80_within_10um_frac", "p80_max_abs_err_um", "specific_energy_kwh_t", "throughput_t",
        "load_outside_band_frac"]
PARTS = [("read", "read"), ("estimate (EKF)", "estimate"), ("solve (NMPC)", "solve"), ("write", "write"),
         ("cycle: read, estimate, solve, write", "write_done")]


def cycle_table(auto: pd.DataFrame) -> str:
    ms = lambda v: f"{1e3 * v:.1f}"  # noqa: E731
    rows = []
    for name, c in PARTS:
        cpu = auto.get(f"{c}_cpu_s")
        rows.append([name, ms(pct(auto[f"{c}_s"], 50)), ms(pct(auto[f"{c}_s"], 95)),
                     ms(pct(cpu, 50)) if cpu is not None else "", ms(pct(cpu, 95)) if cpu is not None else ""])
    rows.append(["soft sensor (after the write)", ms(pct(auto["soft_s"], 50)), ms(pct(auto["soft_s"], 95)), "", ""])
    return table(rows, ["part of a cycle (auto)", "wall median ms", "wall p95 ms", "CPU median ms", "CPU p95 ms"])


def seeds_table(k: pd.DataFrame, loops: list[str]) -> str:
    rows = []
    for key in KEYS:
        row = [key]
        for loop in loops:
            v = k[k["loop"] == loop][key].to_numpy(float)
            row.append(f"{np.mean(v):.4g} ({np.min(v):.4g}-{np.max(v):.4g})")
        rows.append(row)
    return table(rows, ["KPI (t >= 0), mean (min-max) over seeds", *loops])


def paired_table(k: pd.DataFrame, loops: list[str]) -> str:
    ref = k[k["loop"] == "in-process"].set_index("seed")
    rows = []
    for seed in ref.index:
        row = [seed, f"{ref.loc[seed, 'p80_iae_um_h']:.3f}"]
        for loop in loops:
            o = k[(k["loop"] == loop) & (k["seed"] == seed)].iloc[0]
            row.append(f"{o['p80_iae_um_h']:.3f} ({o['p80_iae_um_h'] - ref.loc[seed, 'p80_iae_um_h']:+.3f}), "
                       f"{100 * (o['specific_energy_kwh_t'] / ref.loc[seed, 'specific_energy_kwh_t'] - 1):+.3f} %")
        rows.append(row)
    return table(rows, ["seed", "in-process IAE um h", *[f"{lp}: IAE (diff), energy diff" for lp in loops]])


def report(tr: pd.DataFrame, cycles: pd.DataFrame, kpis: pd.DataFrame, moves: pd.DataFrame, args, loads) -> str:
    ms = lambda v: f"{1e3 * v:.1f}"  # noqa: E731
    auto = cycles[cycles["mode"] == "auto"]
    g = tr.groupby("session")
    t2 = table([[s, ms(g.get_group(s)["read_s"].median()), ms(g.get_group(s)["write_s"].median()),
                 ms(g.get_group(s)["read_write_s"].median()), ms(pct(g.get_group(s)["read_write_s"], 95)),
                 len(g.get_group(s))] for s in ("secure", "unsecured")],
               ["session", "read median ms", "write median ms", "read + write median ms", "read + write p95 ms",
                "rounds"])
    ratio = g.get_group("secure")["read_write_s"].median() / g.get_group("unsecured")["read_write_s"].median()
    loops = list(dict.fromkeys(kpis["loop"]))
    others = [lp for lp in loops if lp != "in-process"]
    wall95, cpu95 = pct(auto["write_done_s"], 95), pct(auto["write_done_cpu_s"], 95)
    late = moves["setpoint_applied_at_frac"].dropna()
    started = auto["started_by"].value_counts().to_dict()
    load_txt = ", ".join(f"seed {s}: {a:.1f}-{b:.1f}" for s, (a, b) in loads.items())
    return f"""# Online: one served cycle on loopback, and the reference transition served over seeds

Command: `{" ".join(["python benchmarks/online_cycle.py", *sys.argv[1:]])}`
(plant server in its own process, the service in the benchmark's; both on one 2-core machine shared
with other jobs; load average (1 min) at the start and end of each served run: {load_txt}).
asyncua {getattr(asyncua, "__version__", "?")}, Python {platform.python_version()}.

## One cycle (secure session, the reference scene's EKF and NMPC; the served runs' auto cycles)

{cycle_table(auto)}

{len(auto)} cycles in auto over {kpis["seed"].nunique()} seeds; started by {started}.
Goal (cycle p95 <= 50 ms wall): {"met" if wall95 <= 0.050 else "not met"} on this run (wall p95 {ms(wall95)} ms,
the service's CPU p95 {ms(cpu95)} ms). The read and write are round trips: their wall time includes
the plant server's work in its own process, which the service's CPU time does not.

## What the secure session costs (interleaved, A B A B ...)

{t2}

Secure / unsecured read + write (medians): {ratio:.2f}x.

## The 8-hour reference transition: served against in-process, same seeds

Same scene, seeds (the analysers' noise), EKF warm-up ({ESTIMATOR_WARMUP_H:g} h on the running plant) and
controller. "lock step, late F": the served loop over OPC UA on a manual clock, each cycle F of a
sample after the plant's sample (0: the in-process timing). "served": in real time at x{args.speedup:g}
(a sample every {3600 * 0.05 / args.speedup:.2f} s), each cycle started by the analyser's report.

{seeds_table(kpis, loops)}

Per seed (IAE in um h and its difference from the in-process run of the seed; specific energy's
difference):

{paired_table(kpis, others)}

When the served moves took effect (share of a sample after the plant's sample; the plant applies a
write at its next scan mark, {MIN_PIECE_FRAC:.0%} of a sample): median
{late.median():.3f}, p95 {pct(late, 95):.3f}, max {late.max():.3f} ({len(late)} samples with a move).
Figure (seed {kpis["seed"].iloc[0]}): docs/online_served_run.png.
"""


def lock_step_runs(parts, tags, seed: int, lates: list[float], d: Path) -> list[dict]:
    out = [{"loop": "in-process", "seed": seed, **online.run_in_process(parts, seed).kpis}]
    for f in lates:
        plant = asyncio.run(online.run_lock_step(parts, tags, seed, d / f"lock-{seed}-{f}", late_frac=f))
        out.append({"loop": f"lock step, late {f:g}", "seed": seed, **plant.kpis()})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--speedup", type=float, default=180.0, help="x180: a 3-minute sample every second")
    ap.add_argument("--rounds", type=int, default=300, help="transport rounds per session")
    ap.add_argument("--seeds", default="1,2,3,4,5", help="the analysers' noise seeds")
    ap.add_argument("--late", default="0,0.5,0.9", help="lock-step cycles this share of a sample late")
    args = ap.parse_args(argv)
    seeds = [int(x) for x in args.seeds.split(",")]
    lates = [float(x) for x in args.late.split(",") if x.strip()]
    scene = load_scene(SCENE)
    tags = online.load_tags(online.VIRTUAL_PLANT_TAGS, scene)
    parts = online.build_parts(scene, soft_sensor=True)
    kpis, cycles, moves, loads = [], [], [], {}
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        make_pki(d)
        with (d / "plants.log").open("w") as log:
            open_proc, open_url = start_plant(d, args.speedup, log, secure=False)
            for i, seed in enumerate(seeds):
                proc, url = start_plant(d, args.speedup, log, seed)
                try:
                    kpis += lock_step_runs(parts, tags, seed, lates, d)  # while the plant server starts
                    if i == 0:
                        tr = asyncio.run(transport_run(d, tags, url, open_url, args.rounds))
                    loads[seed] = (os.getloadavg()[0], math.nan)
                    asyncio.run(served(parts, tags, d, url, proc, args.speedup, seed))
                    loads[seed] = (loads[seed][0], os.getloadavg()[0])
                finally:
                    stop(proc)
                plant = pd.read_parquet(d / f"plant-{seed}" / "plant.parquet")
                kpis.append({"loop": "served", "seed": seed,
                             **json.loads((d / f"plant-{seed}" / "plant-kpis.json").read_text())})
                cycles.append(online.read_audit(d / f"audit-{seed}").assign(seed=seed))
                moves.append(plant.assign(seed=seed))
                if i == 0:
                    figure(plant, scene)
            stop(open_proc)
    kpis, cycles, moves = pd.DataFrame(kpis), pd.concat(cycles), pd.concat(moves)
    OUT.mkdir(parents=True, exist_ok=True)
    cols = ["seed", "service_time_h", "mode", "started_by"] + [c for c in cycles if c.endswith("_s")]
    cycles[cols].to_csv(OUT / "online_cycle.csv", index=False)
    kpis[["loop", "seed", *KEYS]].to_csv(OUT / "online_cycle_seeds.csv", index=False)
    text = report(tr, cycles, kpis, moves, args, loads)
    (OUT / "online_cycle.md").write_text(text)
    print(text)
    return 0


def stop(proc) -> None:
    if proc.poll() is None:
        proc.terminate()
    proc.wait(timeout=120)


async def transport_run(d: Path, tags, secure_url: str, open_url: str, rounds: int) -> pd.DataFrame:
    secure = await connected(secure_url, client_security(d), tags)
    unsecured = await connected(open_url, online.ClientSecurity(insecure=True), tags)
    try:
        return await transport(tags, secure, unsecured, rounds)
    finally:
        await secure.close()
        await unsecured.close()


if __name__ == "__main__":
    sys.exit(main())
