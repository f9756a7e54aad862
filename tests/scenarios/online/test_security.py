"""Sessions are signed and encrypted (Basic256Sha256, SignAndEncrypt) with user authentication
by default: a client whose certificate the server does not trust, a wrong password, an
anonymous or an unsecured client are refused; an unsecured endpoint exists only when asked for."""

import asyncio
import re
import subprocess
from pathlib import Path

import pytest
from asyncua import ua

import scenarios.online as online
from scenarios.errors import SceneError
from scenarios.online.security import make_server, verify_password

from .conftest import client_security, server_security

ROOT = Path(__file__).resolve().parents[3]


async def _with_server(sec, url, body):
    """Serve one writable node with the plant server's security set-up and run ``body(node id)``."""
    server = await make_server(sec)
    server.set_endpoint(url)
    idx = await server.register_namespace("urn:test")
    var = await server.nodes.objects.add_variable(idx, "x", 1.5)
    await var.set_writable()
    await server.start()
    try:
        return await body(var.nodeid.to_string())
    finally:
        await server.stop()


async def _session(url, csec, node):
    conn = online.PlantConnection(url, csec, {"x": node}, {"x": node}, timeout_s=2.0, distinct=False)
    await conn.open()
    try:
        got = (await conn.read())["x"].value
        await conn.write({"x": (2.5, ua.StatusCodes.Good)}, online.Clock().now())
        policy = conn.client.security_policy
        return got, (await conn.read())["x"].value, policy.URI, policy.Mode
    finally:
        await conn.close()


async def _refusal(url, csec, node) -> str:
    """How the server refuses a client ('' if it lets it in)."""
    try:
        await _session(url, csec, node)
    except online.CONNECTION_ERRORS as exc:
        return f"{type(exc).__name__}: {exc}"
    return ""


def test_the_secure_server_takes_a_trusted_client_with_its_user_and_refuses_others(pki, url):
    """One server (its start-up is seconds), five clients."""
    async def clients(node):
        return (await _session(url, client_security(pki), node),
                {name: await _refusal(url, csec, node) for name, csec in {
                    "untrusted certificate": client_security(pki, cert="rogue"),
                    "wrong password": client_security(pki, password="guess"),
                    "unknown user": client_security(pki, user="root"),
                    "no security, anonymous": online.ClientSecurity(insecure=True)}.items()})

    (got, after, uri, mode), refusals = asyncio.run(_with_server(server_security(pki), url, clients))
    assert (got, after) == (1.5, 2.5)
    assert uri.endswith("#Basic256Sha256") and mode == ua.MessageSecurityMode.SignAndEncrypt
    assert refusals["untrusted certificate"].startswith("BadCertificateUntrusted")
    assert refusals["wrong password"].startswith("BadUserAccessDenied")
    assert refusals["unknown user"].startswith("BadUserAccessDenied")
    assert "No matching endpoints" in refusals["no security, anonymous"]  # no unsecured endpoint


def test_security_options_are_checked_before_anything_starts(pki):
    with pytest.raises(SceneError, match="a secure endpoint needs --trust, --users"):
        online.ServerSecurity(False, pki / "server.pem", pki / "server-key.pem").check()
    with pytest.raises(SceneError, match="--insecure serves an unsecured endpoint only; drop --cert"):
        online.ServerSecurity(True, pki / "server.pem").check()
    with pytest.raises(SceneError, match="no password for --user apc"):
        client_security(pki, password=None).check()


def test_a_key_of_another_certificate_and_a_bad_users_file_are_refused_before_anything_starts(pki, tmp_path):
    """Each was found only in the handshake (the service retried for ever: 'could not verify a signature') or,
    for a users file, once the plant's models were built (~11 s)."""
    sec = server_security(pki)
    sec.check()  # the fixture's own: the test can pass
    with pytest.raises(SceneError, match=r"--key .*rogue-key.pem is not the private key of --cert .*server.pem"):
        online.ServerSecurity(False, pki / "server.pem", pki / "rogue-key.pem", pki / "trust",
                              pki / "users.toml").check()
    with pytest.raises(SceneError, match=r"--key .*client-key.pem is not the private key of --cert .*rogue.pem"):
        online.ClientSecurity(False, pki / "rogue.pem", pki / "client-key.pem", pki / "server.pem", "apc", "pw").check()
    with pytest.raises(SceneError, match=r"--server-cert .*users.toml: not an X.509 certificate"):
        online.ClientSecurity(False, pki / "client.pem", pki / "client-key.pem", pki / "users.toml", "apc",
                              "pw").check()
    (tmp_path / "users.toml").write_text('[users.apc]\npassword_scrypt = "hunter2"\n')
    with pytest.raises(SceneError, match=r"users.apc.password_scrypt: must be a hash"):
        online.ServerSecurity(False, pki / "server.pem", pki / "server-key.pem", pki / "trust",
                              tmp_path / "users.toml").check()


def test_passwords_are_stored_as_scrypt_hashes():
    h = online.hash_password("correct horse")
    assert h.startswith("scrypt$16384$8$1$") and "correct" not in h
    assert verify_password("correct horse", h) and not verify_password("correct hors", h)
    assert online.hash_password("x") != online.hash_password("x")  # salted


def test_a_piped_password_is_hashed(monkeypatch, capsys):
    # `echo pw | python -m scenarios.online.security hash-password` raised EOFError (getpass read twice)
    import io

    from scenarios.online.security import main

    monkeypatch.setattr("sys.stdin", io.StringIO("correct horse\n"))
    assert main(["hash-password"]) == 0
    entry = capsys.readouterr().out.strip()
    assert entry.startswith('password_scrypt = "scrypt$') and verify_password("correct horse", entry.split('"')[1])


def test_no_private_key_is_shipped(pki):
    assert re.search(rb"-----BEGIN (RSA |EC |ENCRYPTED )?PRIVATE KEY-----", (pki / "client-key.pem").read_bytes())
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    pem = re.compile(rb"-----BEGIN (RSA |EC |ENCRYPTED )?PRIVATE KEY-----")
    keys = [f for f in files if (ROOT / f).is_file() and pem.search((ROOT / f).read_bytes())]
    assert keys == []


def test_a_refused_client_certificate_is_one_log_line_without_its_traceback(pki, url):
    """The plant server logged a traceback for each client it refused (asyncua's trust store logs its
    verification error with exc_info); the line that names the certificate is kept."""
    import argparse
    import io
    import logging

    from scenarios.cli.commands import _online_logging

    _online_logging(argparse.Namespace(quiet=False))
    out = io.StringIO()
    handler = logging.StreamHandler(out)
    handler.setFormatter(logging.Formatter("%(name)s %(levelname)s %(message)s"))
    logging.getLogger("asyncuagds").addHandler(handler)
    try:
        refusal = asyncio.run(_with_server(server_security(pki), url,
                                           lambda node: _refusal(url, client_security(pki, cert="rogue"), node)))
    finally:
        logging.getLogger("asyncuagds").removeHandler(handler)
    assert refusal.startswith("BadCertificateUntrusted")
    assert "Not trusted certificate used: [CN=rogue]" in out.getvalue()
    assert "Traceback" not in out.getvalue()
