"""Security of the OPC UA sessions: certificates, user passwords, the server's and the client's set-up.

By default a session is signed and encrypted (security policy Basic256Sha256, mode
SignAndEncrypt; OPC 10000-7 profile "SecurityPolicy [B] - Basic256Sha256"): the plant server
accepts a client only if its application certificate is in the server's trust folder, and only
after user authentication by name and password (scrypt hashes in a users file, RFC 7914); the
client pins the server's certificate. An unsecured endpoint (no security, anonymous users) exists
only when asked for explicitly (``insecure=True``, ``--insecure``).

Certificates and keys are made on the machine that uses them (:func:`make_certificate`, or
``python -m scenarios.online.security cert ...``); no private key ships with grindtwin.
"""

from __future__ import annotations

import argparse
import getpass
import hashlib
import hmac
import ipaddress
import logging
import os
import secrets
import socket
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from asyncua import Server, ua
from asyncua.crypto.cert_gen import dump_private_key_as_pem, generate_private_key, generate_self_signed_app_certificate
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from asyncua.crypto.truststore import TrustStore
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.serialization import Encoding, PublicFormat
from cryptography.x509.oid import ExtendedKeyUsageOID

from scenarios.errors import SceneError

log = logging.getLogger("grindtwin.online.security")

#: Where ``grindtwin serve`` reads the OPC UA user's password when no --password-file is given.
PASSWORD_ENV = "GRINDTWIN_OPCUA_PASSWORD"
#: scrypt cost (RFC 7914: N = 2^14, r = 8, p = 1 is its interactive-login recommendation).
SCRYPT_N, SCRYPT_R, SCRYPT_P = 2**14, 8, 1
#: Days an application certificate made here is valid.
CERT_DAYS = 365


# ------------------------------------------------------------------ certificates
def make_certificate(cert_path: Path, key_path: Path, name: str, app_uri: str, server: bool,
                     hostnames=("localhost", "127.0.0.1"), days: int = CERT_DAYS) -> None:
    """A self-signed OPC UA application certificate (PEM) and its RSA-2048 private key (PEM,
    readable by the owner only), by asyncua's generator on the ``cryptography`` package (OPC
    10000-6, 6.2.2: the application URI in the subject alternative name). Refuses to overwrite."""
    cert_path, key_path = Path(cert_path), Path(key_path)
    for p in (cert_path, key_path):
        if p.exists():
            raise SceneError(f"{p}: exists; certificates and keys are never overwritten")
    sans: list[x509.GeneralName] = [x509.UniformResourceIdentifier(app_uri)]
    for h in dict.fromkeys([*hostnames, socket.gethostname()]):
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            sans.append(x509.DNSName(h))
    usage = [ExtendedKeyUsageOID.SERVER_AUTH] if server else [ExtendedKeyUsageOID.CLIENT_AUTH]
    key = generate_private_key()
    cert = generate_self_signed_app_certificate(key, name, {"organizationName": "grindtwin"}, sans, usage, days)
    cert_path.parent.mkdir(parents=True, exist_ok=True)
    key_path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(key_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "wb") as fh:
        fh.write(dump_private_key_as_pem(key))
    cert_path.write_bytes(cert.public_bytes(Encoding.PEM))


def _certificate(path: Path, option: str = "certificate") -> x509.Certificate:
    """The X.509 certificate in a PEM or DER file; SceneError naming the option if it holds none."""
    data = Path(path).read_bytes()
    try:
        return x509.load_pem_x509_certificate(data) if b"-----BEGIN" in data else x509.load_der_x509_certificate(data)
    except ValueError as exc:
        raise SceneError(f"{option} {path}: not an X.509 certificate (PEM or DER): {exc}") from None


def check_key_pair(cert_path: Path, key_path: Path, cert_option: str, key_option: str) -> None:
    """SceneError unless the private key (PEM or DER, unencrypted, as asyncua loads it) is the key of
    the certificate: with another, every session's handshake fails and the other side only says it
    could not verify a signature (the service retried for ever)."""
    cert = _certificate(cert_path, cert_option)
    data = Path(key_path).read_bytes()
    try:
        load = serialization.load_pem_private_key if b"-----BEGIN" in data else serialization.load_der_private_key
        key = load(data, password=None)
    except (ValueError, TypeError) as exc:
        raise SceneError(f"{key_option} {key_path}: not an unencrypted private key (PEM or DER): {exc}") from None
    if key.public_key().public_bytes(Encoding.DER, PublicFormat.SubjectPublicKeyInfo) != \
            cert.public_key().public_bytes(Encoding.DER, PublicFormat.SubjectPublicKeyInfo):
        raise SceneError(f"{key_option} {key_path} is not the private key of {cert_option} {cert_path}: "
                         "give the key made with that certificate")


def certificate_uri(path: Path) -> str:
    """The application URI in a certificate's subject alternative name."""
    cert = _certificate(path)
    try:
        uris = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value.get_values_for_type(
            x509.UniformResourceIdentifier)
    except x509.ExtensionNotFound:
        uris = []
    if not uris:
        raise SceneError(f"{path}: the certificate names no application URI (subject alternative name)")
    return uris[0]


# ------------------------------------------------------------------ users
def hash_password(password: str, salt: bytes | None = None) -> str:
    """``scrypt$N$r$p$salt$hash`` (hex) of a password."""
    salt = salt or secrets.token_bytes(16)
    h = hashlib.scrypt(password.encode(), salt=salt, n=SCRYPT_N, r=SCRYPT_R, p=SCRYPT_P)
    return f"scrypt${SCRYPT_N}${SCRYPT_R}${SCRYPT_P}${salt.hex()}${h.hex()}"


def verify_password(password: str, stored: str) -> bool:
    """True if ``password`` matches a :func:`hash_password` string (constant-time compare)."""
    try:
        kind, n, r, p, salt, h = stored.split("$")
        got = hashlib.scrypt(password.encode(), salt=bytes.fromhex(salt), n=int(n), r=int(r), p=int(p))
    except ValueError:
        return False
    return kind == "scrypt" and hmac.compare_digest(got, bytes.fromhex(h))


def load_users(path: Path) -> dict[str, str]:
    """``[users.NAME] password_scrypt = "scrypt$..."`` -> {name: hash}; SceneError naming the key."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise SceneError(f"{path}: cannot read the users file: {exc}") from None
    users = data.get("users")
    if not isinstance(users, dict) or not users:
        raise SceneError(f"{path}: users: a table [users.NAME] with password_scrypt is required")
    out = {}
    for name, entry in users.items():
        value = entry.get("password_scrypt") if isinstance(entry, dict) else None
        if not (isinstance(value, str) and value.startswith("scrypt$") and value.count("$") == 5):
            raise SceneError(f"{path}: users.{name}.password_scrypt: must be a hash from "
                             f"'python -m scenarios.online.security hash-password' (got {value!r})")
        out[name] = value
    return out


class PasswordUserManager:
    """asyncua user manager: a user whose name and password match the users file, else none
    (the session is refused)."""

    def __init__(self, users: dict[str, str]):
        self.users = dict(users)

    def get_user(self, iserver, username=None, password=None, certificate=None):
        stored = self.users.get(username or "")
        if stored is None or password is None or not verify_password(password, stored):
            log.warning("OPC UA user %r refused", username)
            return None
        return User(role=UserRole.User, name=username)


# ------------------------------------------------------------------ server and client set-up
@dataclass(frozen=True)
class ServerSecurity:
    """The plant server's endpoint: secure (certificate, key, trust folder, users file) or
    ``insecure`` (no security, anonymous)."""

    insecure: bool = False
    certificate: Path | None = None
    private_key: Path | None = None
    trust_dir: Path | None = None
    users_file: Path | None = None

    def check(self) -> None:
        """SceneError naming what is missing, before any server starts."""
        given = {"--cert": self.certificate, "--key": self.private_key, "--trust": self.trust_dir,
                 "--users": self.users_file}
        if self.insecure:
            extra = [k for k, v in given.items() if v is not None]
            if extra:
                raise SceneError(f"--insecure serves an unsecured endpoint only; drop {', '.join(extra)}")
            return
        missing = [k for k, v in given.items() if v is None]
        if missing:
            raise SceneError(f"a secure endpoint needs {', '.join(missing)} (or --insecure for an unsecured one)")
        for k in ("--cert", "--key", "--users"):
            if not Path(given[k]).is_file():
                raise SceneError(f"{k} {given[k]}: file not found")
        if not Path(self.trust_dir).is_dir():
            raise SceneError(f"--trust {self.trust_dir}: folder not found")
        check_key_pair(self.certificate, self.private_key, "--cert", "--key")
        load_users(self.users_file)  # a bad hash was refused only once the models were built


async def make_server(sec: ServerSecurity) -> Server:
    """An initialised asyncua Server with the endpoint and user checks of ``sec``."""
    sec.check()
    if sec.insecure:
        server = Server()
        await server.init()
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        server.set_identity_tokens([ua.AnonymousIdentityToken])
        log.warning("unsecured OPC UA endpoint (--insecure): no encryption, anonymous users")
        return server
    server = Server(user_manager=PasswordUserManager(load_users(sec.users_file)))
    await server.init()
    await server.load_certificate(str(sec.certificate))
    await server.load_private_key(str(sec.private_key))
    await server.set_application_uri(certificate_uri(sec.certificate))
    server.set_security_policy([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt])
    server.set_identity_tokens([ua.UserNameIdentityToken])
    store = TrustStore([Path(sec.trust_dir)], [])
    await store.load()
    server.set_certificate_validator(CertificateValidator(
        CertificateValidatorOptions.TRUSTED_VALIDATION | CertificateValidatorOptions.PEER_CLIENT, store))
    return server


@dataclass(frozen=True)
class ClientSecurity:
    """How ``grindtwin serve`` connects: secure (its certificate and key, the server's
    certificate, a user and password) or ``insecure`` (no security, anonymous)."""

    insecure: bool = False
    certificate: Path | None = None
    private_key: Path | None = None
    server_certificate: Path | None = None
    username: str | None = None
    password: str | None = field(default=None, repr=False)

    def check(self) -> None:
        given = {"--cert": self.certificate, "--key": self.private_key, "--server-cert": self.server_certificate,
                 "--user": self.username}
        if self.insecure:
            extra = [k for k, v in given.items() if v is not None]
            if extra:
                raise SceneError(f"--insecure connects without security or user; drop {', '.join(extra)}")
            return
        missing = [k for k, v in given.items() if v is None]
        if missing:
            raise SceneError(f"a secure session needs {', '.join(missing)} (or --insecure for an unsecured one)")
        if self.password is None:
            raise SceneError(f"no password for --user {self.username}: set {PASSWORD_ENV} or give --password-file")
        for k in ("--cert", "--key", "--server-cert"):
            if not Path(given[k]).is_file():
                raise SceneError(f"{k} {given[k]}: file not found")
        check_key_pair(self.certificate, self.private_key, "--cert", "--key")
        _certificate(self.server_certificate, "--server-cert")


def read_password(password_file: Path | None) -> str | None:
    """The password from a file (first line) or the environment (:data:`PASSWORD_ENV`)."""
    if password_file is not None:
        try:
            return Path(password_file).read_text(encoding="utf-8").splitlines()[0]
        except (OSError, IndexError) as exc:
            raise SceneError(f"--password-file {password_file}: cannot read a password: {exc}") from None
    return os.environ.get(PASSWORD_ENV)


async def secure_client(client, sec: ClientSecurity) -> None:
    """Apply ``sec`` to an asyncua Client before it connects."""
    sec.check()
    if sec.insecure:
        return
    client.application_uri = certificate_uri(sec.certificate)
    await client.set_security(SecurityPolicyBasic256Sha256, certificate=str(sec.certificate),
                              private_key=str(sec.private_key), server_certificate=str(sec.server_certificate),
                              mode=ua.MessageSecurityMode.SignAndEncrypt)
    client.set_user(sec.username)
    client.set_password(sec.password)


# ------------------------------------------------------------------ python -m scenarios.online.security
def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m scenarios.online.security",
                                description="Certificates and password hashes for grindtwin's OPC UA sessions.")
    sub = p.add_subparsers(dest="what", required=True)
    c = sub.add_parser("cert", help="a self-signed application certificate and its private key (PEM)")
    c.add_argument("--out", required=True, help="folder for NAME.pem and NAME-key.pem")
    c.add_argument("--name", required=True, help="application name (file names and the certificate's CN)")
    c.add_argument("--uri", required=True, help="application URI, e.g. urn:plant:grindtwin:serve")
    c.add_argument("--server", action="store_true", help="a server certificate (default: a client's)")
    c.add_argument("--host", action="append", default=[], help="host name or IP the server is reached at")
    sub.add_parser("hash-password", help="read a password (twice) and print its users-file entry")
    args = p.parse_args(argv)
    try:
        if args.what == "cert":
            out = Path(args.out)
            make_certificate(out / f"{args.name}.pem", out / f"{args.name}-key.pem", args.name, args.uri, args.server,
                             hostnames=tuple(args.host) or ("localhost", "127.0.0.1"))
            print(f"{out / (args.name + '.pem')} (share it) and {out / (args.name + '-key.pem')} (keep it private)")
            return 0
        if sys.stdin.isatty():
            first, second = getpass.getpass("password: "), getpass.getpass("again: ")
        else:  # piped (echo pw | ...): getpass raised EOFError on the second read; one line, taken once
            first = second = sys.stdin.readline().rstrip("\n")
        if first != second or not first:
            raise SceneError("the passwords differ or are empty")
        print(f'password_scrypt = "{hash_password(first)}"')
        return 0
    except SceneError as exc:
        sys.stderr.write(f"error: {exc}\n")
        return 2


if __name__ == "__main__":
    sys.exit(main())
