"""Helpers for the online-mode tests: a free port, a replay server in a subprocess, self-made certificates."""
from __future__ import annotations

import contextlib
import datetime as dt
import ipaddress
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_replay(case: Path, url: str, origin: dt.datetime | str, log: Path, *extra: str,
                 speed: float = 600.0, timeout: float = 120.0,
                 wait: bool = True) -> tuple[subprocess.Popen[bytes], dt.datetime | None]:
    """``trackingbox replay CASE --serve URL`` in a subprocess, and the origin it serves with.

    *origin* is a time or ``"+SECONDS"`` (after the server is ready). Returns
    once the server serves (its log says so, with the origin); with
    ``wait=False`` at once (origin ``None``: the client's reconnection waits).
    """
    start = len(log.read_text(errors="replace")) if log.exists() else 0
    args = [sys.executable, "-m", "trackingbox.cli", "-v", "replay", str(case), "--serve", url,
            "--speed", str(speed), "--origin", origin if isinstance(origin, str) else origin.isoformat(), *extra]
    fh = open(log, "ab")
    proc = subprocess.Popen(args, stdout=fh, stderr=fh)
    fh.close()
    if not wait:
        return proc, None
    t0 = time.monotonic()
    while True:
        text = log.read_text(errors="replace")[start:]
        found = re.search(r"serving .* origin (\S+)\)", text)
        if found:
            return proc, dt.datetime.fromisoformat(found.group(1))
        if proc.poll() is not None:
            raise AssertionError(f"replay server exited ({proc.returncode}):\n{text[-3000:]}")
        if time.monotonic() - t0 > timeout:
            proc.kill()
            raise AssertionError(f"replay server did not start within {timeout} s:\n{text[-3000:]}")
        time.sleep(0.05)


def kill(proc: subprocess.Popen[bytes]) -> None:
    """SIGKILL *proc* (no clean shutdown) and reap it."""
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)


@contextlib.contextmanager
def replay_server(case: Path, url: str, origin: dt.datetime | str, log: Path, *extra: str,
                  speed: float = 600.0) -> Iterator[dt.datetime]:
    """A running replay server (killed at the end); yields its origin."""
    proc, when = start_replay(case, url, origin, log, *extra, speed=speed)
    assert when is not None
    try:
        yield when
    finally:
        kill(proc)


def make_certificate(directory: Path, name: str, uri: str) -> tuple[Path, Path]:
    """A self-signed certificate (DER) and its RSA key (PEM) for an OPC UA application *uri*."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import rsa
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    now = dt.datetime.now(dt.timezone.utc)
    cert = (
        x509.CertificateBuilder()
        .subject_name(subject).issuer_name(subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(days=1))
        .not_valid_after(now + dt.timedelta(days=30))
        .add_extension(x509.SubjectAlternativeName([
            x509.UniformResourceIdentifier(uri), x509.DNSName("localhost"),
            x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=True, key_encipherment=True,
                                     data_encipherment=True, key_agreement=False, key_cert_sign=False,
                                     crl_sign=False, encipher_only=False, decipher_only=False), critical=True)
        .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]),
                       critical=False)
        .sign(key, hashes.SHA256())
    )
    directory.mkdir(parents=True, exist_ok=True)
    cert_path, key_path = directory / f"{name}.der", directory / f"{name}.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.DER))
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.TraditionalOpenSSL,
                                           serialization.NoEncryption()))
    key_path.chmod(0o600)
    return cert_path, key_path
