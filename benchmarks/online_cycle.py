"""One cycle of the served controller (read, estimate, solve, write) on loopback, and what the
secure session costs; the reference transition served on the virtual plant beside the in-process loop.

Set-up: ``grindtwin plant-server`` in its own process serves scenarios/reference_transition.toml
over Basic256Sha256 SignAndEncrypt with user authentication (certificates and a user made for
this run in a temporary folder), sped up ``--speedup`` times, after a 2-hour hold at the initial
blend; a second plant server serves the same nodes unsecured (``--insecure``, frozen).
``scenarios.online.Service`` runs in this process with the scene's EKF and NMPC.

1. Transport, interleaved: the service's read of every tag and its write of the setpoints,
   heartbeat and status, over the secure and the unsecured session in turn (A, B, A, B, ...).
2. The served run: the whole 8-hour transition in sped-up real time; per-cycle times from the
   audit log, the plant's KPIs from its record, beside the in-process loop (mpc.run_closed_loop
   wired as scenarios.run.closed_loop wires it, same seed and warm-up).
3. docs/online_served_run.png: P80 (plant, analyser, target), setpoints and modes of the served run.

Writes benchmarks/results/online_cycle.md and online_cycle.csv (per-cycle times of the served run).

    python benchmarks/online_cycle.py [--speedup 60] [--rounds 300]
"""

from __future__ import annotations

import argparse
import asyncio
import json
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


def start_plants(d: Path, speedup: float, logs):
    """The secure plant server (frozen until the served run) and the unsecured one (frozen)."""
    secure_url, open_url = f"opc.tcp://127.0.0.1:{free_port()}", f"opc.tcp://127.0.0.1:{free_port()}"
    common = [str(SCENE), "--speedup", str(speedup), "--paused", "--quiet"]
    # logs to files, not pipes: a full pipe would stall a server
    secure = subprocess.Popen([*CLI, "plant-server", *common, "--opcua", secure_url, "--hold-h", str(ESTIMATOR_WARMUP_H),
                               "--duration-h", "8", "--record", str(d / "plant"), "--cert", str(d / "server.pem"),
                               "--key", str(d / "server-key.pem"), "--trust", str(d / "trust"), "--users",
                               str(d / "users.toml")], stderr=logs[0])
    unsecured = subprocess.Popen([*CLI, "plant-server", *common, "--opcua", open_url, "--insecure"], stderr=logs[1])
    return (secure, secure_url), (unsecured, open_url)


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


async def served(parts, tags, d: Path, secure_url: str, proc, speedup: float):
    """The served run on the secure plant server: unfreeze it and serve until its run ends."""
    service = online.Service(parts, tags, online.ServeSettings(secure_url, client_security(d), d / "audit",
                                                               speedup=speedup))
    task = asyncio.create_task(service.run(install_signal_handlers=False))
    await wait_until(lambda: service.conn is not None, 120, "the service's session")
    run = online.PlantConnection(secure_url, client_security(d), {}, {"run": "ns=2;s=Simulation.Run"})
    await run.open()
    await run.write({"run": (True, ua.StatusCodes.Good)}, online.Clock().now())
    await run.close()
    await wait_until(lambda: proc.poll() is not None or (service.conn is None and service.k > 50), 3600,
                     "the end of the plant's run")
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


def report(tr: pd.DataFrame, cycles: pd.DataFrame, served_k: dict, ref_k: dict, args, load, plant_run) -> str:
    ms = lambda v: f"{1e3 * v:.1f}"  # noqa: E731
    auto = cycles[cycles["mode"] == "auto"]
    comp = [["read", "read_s"], ["estimate (EKF)", "estimate_s"], ["solve (NMPC)", "solve_s"], ["write", "write_s"],
            ["cycle: read, estimate, solve, write", "write_done_s"], ["soft sensor (after the write)", "soft_s"]]
    t1 = table([[name, ms(pct(auto[c], 50)), ms(pct(auto[c], 95)), int(auto[c].notna().sum())] for name, c in comp
                if c in auto] + [["cycle, the service's CPU time", ms(pct(auto["write_done_cpu_s"], 50)),
                                  ms(pct(auto["write_done_cpu_s"], 95)), int(auto["write_done_cpu_s"].notna().sum())]],
               ["part of a cycle (auto)", "median ms", "p95 ms", "cycles"])
    share = {c: pct(auto[c], 50) / pct(auto["write_done_s"], 50) for c in ("read_s", "estimate_s", "solve_s", "write_s")}
    g = tr.groupby("session")
    t2 = table([[s, ms(g.get_group(s)["read_s"].median()), ms(g.get_group(s)["write_s"].median()),
                 ms(g.get_group(s)["read_write_s"].median()), ms(pct(g.get_group(s)["read_write_s"], 95)),
                 len(g.get_group(s))] for s in ("secure", "unsecured")],
               ["session", "read median ms", "write median ms", "read + write median ms", "read + write p95 ms",
                "rounds"])
    ratio = g.get_group("secure")["read_write_s"].median() / g.get_group("unsecured")["read_write_s"].median()
    keys = ["p80_iae_um_h", "p80_within_10um_frac", "p80_max_abs_err_um", "specific_energy_kwh_t", "throughput_t",
            "load_outside_band_frac"]
    t3 = table([[k, f"{ref_k[k]:.4g}", f"{served_k[k]:.4g}"] for k in keys], ["KPI (t >= 0)", "in-process", "served"])
    modes = cycles["mode"].value_counts().to_dict()
    goal = pct(auto["write_done_s"], 95) <= 0.050
    return f"""# Online: one served cycle on loopback, and the reference transition served

Command: `python benchmarks/online_cycle.py --speedup {args.speedup:g} --rounds {args.rounds}`
(plant server in its own process, the service in the benchmark's; both on one 2-core machine shared
with other jobs: load average {load[0]:.1f} at the start, {load[1]:.1f} at the end, so times are upper bounds).
asyncua {asyncua.__version__ if hasattr(asyncua, '__version__') else '?'}, Python {platform.python_version()}.

## One cycle (secure session, the reference scene's EKF and NMPC)

{t1}

Wall-clock times: under the machine's load a process waits for a core, so the wall times are upper
bounds; the CPU time is what the service's own work took. Goal (cycle p95 <= 50 ms wall):
{"met" if goal else "not met"} on this run. Shares of the median cycle: read {share["read_s"]:.0%}, estimate
{share["estimate_s"]:.0%}, solve {share["solve_s"]:.0%}, write {share["write_s"]:.0%}.

## What the secure session costs (interleaved, A B A B ...)

{t2}

Secure / unsecured read + write (medians): {ratio:.2f}x.

## The 8-hour reference transition: served against in-process

Same scene, seed, EKF warm-up ({ESTIMATOR_WARMUP_H:g} h on the running plant) and controller; the served
loop runs on wall-clock timers (a sample every {3600 * 0.05 / args.speedup:.2f} s at x{args.speedup:g}), the
in-process loop in lock step.

{t3}

Served cycles by mode: {modes}, for {plant_run[1]} plant samples; the plant fell behind real time
{plant_run[0]} times (its clock then restarts from the wall clock, while the service's runs on).
Figure: docs/online_served_run.png.
"""


async def benchmark(args, d: Path, plants):
    (sec_proc, sec_url), (open_proc, open_url) = plants
    scene = load_scene(SCENE)
    tags = online.load_tags(online.VIRTUAL_PLANT_TAGS, scene)
    parts = online.build_parts(scene, soft_sensor=True)
    ref_k = online.run_in_process(parts, scene.scene.seed).kpis
    secure = await connected(sec_url, client_security(d), tags)
    unsecured = await connected(open_url, online.ClientSecurity(insecure=True), tags)
    tr = await transport(tags, secure, unsecured, args.rounds)
    await secure.close()
    await unsecured.close()
    await served(parts, tags, d, sec_url, sec_proc, args.speedup)
    return tr, ref_k


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--speedup", type=float, default=60.0, help="x60: a 3-minute sample every 3 s")
    ap.add_argument("--rounds", type=int, default=300)
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        make_pki(d)
        with (d / "secure.log").open("w") as log_s, (d / "unsecured.log").open("w") as log_u:
            plants = start_plants(d, args.speedup, (log_s, log_u))
            try:
                tr, ref_k = asyncio.run(benchmark(args, d, plants))
            finally:
                for proc, _ in plants:
                    if proc.poll() is None:
                        proc.terminate()
                    proc.wait(timeout=120)
        behind = (d / "secure.log").read_text().count("fell")  # the plant fell behind real time
        plant = pd.read_parquet(d / "plant" / "plant.parquet")
        served_k = json.loads((d / "plant" / "plant-kpis.json").read_text())
        cycles = online.read_audit(d / "audit")
    load1 = os.getloadavg()[0]
    OUT.mkdir(parents=True, exist_ok=True)
    cols = [c for c in ("service_time_h", "mode", "read_s", "estimate_s", "solve_s", "write_s", "write_done_s",
                        "write_done_cpu_s", "soft_s", "cycle_s") if c in cycles]
    cycles[cols].to_csv(OUT / "online_cycle.csv", index=False)
    figure(plant, load_scene(SCENE))
    text = report(tr, cycles, served_k, ref_k, args, (load0, load1), (behind, len(plant)))
    (OUT / "online_cycle.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
