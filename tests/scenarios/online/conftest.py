"""Fixtures of the online tests: a small scene and its tag map, free loopback ports,
certificates made for the test run (never shipped), and the lock-step driver of a virtual
plant and a served controller in one event loop."""

from __future__ import annotations

import socket

import pytest

import scenarios.online as online
from scenarios.scene import load_scene

#: A small scene (7 classes, one mixer, horizon 5) whose NMPC builds in seconds; noisy
#: analysers so that the freeze checks see live signals.
SMALL_SCENE = """\
effects = ["breakage", "transport", "holdup", "speed", "power", "sensor_delay"]
calibration_mismatch_ok = true  # a lean, coarse model for fast service tests, not the calibration's
[scene]
name = "online_small"
duration_h = 3.0
sample_period_h = 0.05
seed = 3
[mill]
preset = "industrial"
n_mixers = 1
size_classes = { top_um = 6700.0, ratio = 2.5, count = 7 }
[ores.B]
type = "B"
[ores.D]
type = "D"
[feed]
blend = { B = 1.0 }
feed_tph = 16.0
speed_frac_critical = 0.70
p80_um = 3200.0
[[feed.schedule]]
at_h = 1.0
kind = "ramp"
ramp_h = 0.25
blend = { B = 0.6, D = 0.4 }
[effect_options.sensor_delay]
dead_time_h = 0.1
[controller]
kind = "nmpc"
target_p80_um = 210.0
horizon_steps = 5
rk4_substeps = 2
preview_lead_h = 0.25
solver = "rti"
[controller.bounds]
feed_tph_min = 8.0
feed_tph_max = 30.0
speed_min = 0.60
speed_max = 0.85
feed_rate_max_tph_per_h = 10.0
speed_rate_max_per_h = 0.10
[sensors]
p80_noise_um = 3.0
p80_dead_time_h = 0.1
p80_sample_period_h = 0.05
power_noise_kw = 5.0
load_noise_frac = 0.01
"""

#: The small scene's tag map: the virtual plant's nodes, limits and fallbacks from the scene
#: except a short P80 hold (three samples) so a test sees it.
SMALL_TAGS = """\
[measurements.p80_um]
node = "ns=2;s=Mill.Analyser.P80_um"
max_age_h = 0.15
frozen_after_h = 0.2
[measurements.power_kw]
node = "ns=2;s=Mill.Power_kW"
[measurements.load_frac]
node = "ns=2;s=Mill.Load_frac"
[measurements.feed_tph]
node = "ns=2;s=Mill.Feed.Actual_tph"
[measurements.speed_frac_critical]
node = "ns=2;s=Mill.Speed.Actual_frac_critical"
[belt_analyser]
nodes = { B = "ns=2;s=Belt.B_frac", D = "ns=2;s=Belt.D_frac" }
[mode]
node = "ns=2;s=APC.Mode"
[setpoints.feed_tph]
node = "ns=2;s=Mill.Feed.Setpoint_tph"
[setpoints.speed_frac_critical]
node = "ns=2;s=Mill.Speed.Setpoint_frac_critical"
[heartbeat]
node = "ns=2;s=APC.Heartbeat"
[status]
node = "ns=2;s=APC.Status"
[soft_sensor]
p80_um = "ns=2;s=Soft.P80_um"
specific_energy_kwh_t = "ns=2;s=Soft.SE_kWh_t"
[fallback]
p80_hold_after_h = 0.15
[connection]
request_timeout_s = 1.0
reconnect_initial_s = 0.05
reconnect_max_s = 0.2
"""


def free_port() -> int:
    """A loopback port free now (the OS picks it)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def url() -> str:
    return f"opc.tcp://127.0.0.1:{free_port()}"


@pytest.fixture(scope="session")
def small_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("online_small")
    (d / "scene.toml").write_text(SMALL_SCENE)
    (d / "tags.toml").write_text(SMALL_TAGS)
    return d / "scene.toml", d / "tags.toml"


@pytest.fixture(scope="session")
def small_scene(small_files):
    return load_scene(small_files[0])


@pytest.fixture(scope="session")
def small_tags(small_files, small_scene):
    return online.load_tags(small_files[1], small_scene)


@pytest.fixture(scope="session")
def small_parts(small_scene):
    """The small scene's twins, NMPC, EKF and soft sensor, built once (reset per test)."""
    return online.build_parts(small_scene, soft_sensor=True)


@pytest.fixture(scope="session")
def pki(tmp_path_factory):
    """Certificates for a test run: the server's, a trusted client's (copied into the server's
    trust folder), an untrusted client's, and a users file with one user."""
    d = tmp_path_factory.mktemp("pki")
    online.make_certificate(d / "server.pem", d / "server-key.pem", "plant", "urn:test:plant", server=True)
    online.make_certificate(d / "client.pem", d / "client-key.pem", "serve", "urn:test:serve", server=False)
    online.make_certificate(d / "rogue.pem", d / "rogue-key.pem", "rogue", "urn:test:rogue", server=False)
    (d / "trust").mkdir()
    (d / "trust" / "client.pem").write_bytes((d / "client.pem").read_bytes())
    (d / "users.toml").write_text(f'[users.apc]\npassword_scrypt = "{online.hash_password("s3cret-apc")}"\n')
    return d


def server_security(pki) -> online.ServerSecurity:
    return online.ServerSecurity(False, pki / "server.pem", pki / "server-key.pem", pki / "trust", pki / "users.toml")


def client_security(pki, cert="client", user="apc", password="s3cret-apc") -> online.ClientSecurity:
    return online.ClientSecurity(False, pki / f"{cert}.pem", pki / f"{cert}-key.pem", pki / "server.pem", user,
                                 password)


class LockStep:
    """A virtual plant and a served controller on one manual clock: each :meth:`step` advances
    the plant one sample and runs one service cycle (deterministic, no wall-clock timing)."""

    def __init__(self, scene, tags, parts, url, audit_dir, warmup_h=0.2, hold_h=0.5, speedup=3600.0,
                 plant_security=None, client_security=None):
        parts.reset()
        self.clock = online.ManualClock(speedup)
        self.plant = online.PlantServer(scene, tags, online.PlantServerSettings(
            url, plant_security or online.ServerSecurity(insecure=True), hold_h=hold_h), models=parts.models,
            clock=self.clock)
        self.service = online.Service(parts, tags, online.ServeSettings(
            url, client_security or online.ClientSecurity(insecure=True), audit_dir, warmup_h=warmup_h),
            clock=self.clock)
        self.dt = scene.scene.sample_period_h
        self.rows: list[dict] = []

    async def start(self):
        await self.plant.start()
        await self.service.connect()

    async def step(self, n: int = 1):
        for _ in range(n):
            self.clock.advance(self.dt)
            await self.plant.tick()
            self.rows.append(await self.service.cycle())
        return self.rows[-1]

    async def stop(self):
        await self.service.shutdown("test end")
        await self.plant.stop_server()
