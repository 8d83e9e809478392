"""The few OPC UA (asyncua) pieces the online mode shares: endpoints, security, credentials, time.

asyncua is imported lazily, in the functions that use it (here and in :mod:`.live` and
:mod:`.replay`), so that the offline commands do not pay for it: 131 more modules and 0.20 s of CPU
after ``trackingbox.cli`` (measured 2026-11-29, three runs alike).
"""
from __future__ import annotations

import logging
import os
import stat
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from .. import config
from ..errors import LiveError, SpecError

log = logging.getLogger(__name__)

# deferred (start-up): asyncua is imported in the functions that talk OPC UA; it adds 0.37 s to an
# import of the package (python -X importtime, loaded 2-core machine) and only the online mode needs it

#: Environment variables holding the OPC UA user name and password.
USER_ENV = "TRACKINGBOX_OPCUA_USER"
PASSWORD_ENV = "TRACKINGBOX_OPCUA_PASSWORD"
#: Environment variable naming a credentials file (``user = ...`` / ``password = ...`` lines).
CREDENTIALS_ENV = "TRACKINGBOX_OPCUA_CREDENTIALS"
#: Namespace of the replayed plant's tags (index 2 on a fresh server: ``ns=2;s=<tag>``).
PLANT_NAMESPACE = "urn:trackingbox:replay"
#: Namespace of the tracker's published results.
RESULTS_NAMESPACE = "urn:trackingbox:results"
#: The client's application URI (must be in its certificate's subjectAltName).
CLIENT_URI = "urn:trackingbox:client"


def check_endpoint(url: str, what: str = "endpoint") -> tuple[str, int]:
    """``(host, port)`` of an ``opc.tcp://HOST:PORT[/path]`` URL; :class:`SpecError` otherwise."""
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme != "opc.tcp" or not parts.hostname or port is None or not 0 < port < 65536:
        raise SpecError(f"{what} {url!r} is not an OPC UA endpoint opc.tcp://HOST:PORT")
    return parts.hostname, port


@dataclass(frozen=True)
class Credentials:
    """A user name and password (never printed; ``repr`` hides the password)."""

    user: str
    password: str

    def __repr__(self) -> str:
        return f"Credentials(user={self.user!r}, password=***)"


#: The settings (:mod:`trackingbox.config`) holding the OPC UA user, password and credentials file.
OPCUA_KEYS = ("opcua_user", "opcua_password", "opcua_credentials")


def read_credentials(path: str | os.PathLike[str] | None = None, *,
                     keys: tuple[str, str, str] = OPCUA_KEYS) -> Credentials | None:
    """Credentials from *path* (or ``$TRACKINGBOX_OPCUA_CREDENTIALS``), else the environment.

    The file has ``user = NAME`` and ``password = SECRET`` lines (``#``
    comments allowed) and must not be readable by others (mode 0600 or
    stricter). Without a file, ``TRACKINGBOX_OPCUA_USER`` and
    ``TRACKINGBOX_OPCUA_PASSWORD`` are used; ``None`` when neither is set.
    *keys* name the settings of the user, password and file (the live view has its own).
    """
    user_key, password_key, file_key = keys
    path = path or config.get(file_key)
    if path:
        p = Path(path)
        try:
            mode = p.stat().st_mode
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise LiveError(f"credentials file {p} cannot be read ({exc})") from None
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            raise LiveError(f"credentials file {p} is readable by others (mode {stat.S_IMODE(mode):o}); "
                            f"chmod 600 {p}")
        values: dict[str, str] = {}
        for i, line in enumerate(text.splitlines(), start=1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            key, sep, value = line.partition("=")
            if not sep or key.strip() not in ("user", "password"):
                raise LiveError(f"credentials file {p}, line {i}: expected 'user = NAME' or 'password = SECRET'")
            values[key.strip()] = value.strip()
        if "user" not in values or "password" not in values:
            raise LiveError(f"credentials file {p} needs both 'user = ...' and 'password = ...'")
        return Credentials(values["user"], values["password"])
    user, password = config.get(user_key), config.get(password_key)
    if user and password is not None:
        return Credentials(user, password)
    if user or password:
        raise LiveError(f"set both {config.setting(user_key).env} and {config.setting(password_key).env}, "
                        "or neither")
    return None


def read_users(path: str | os.PathLike[str]) -> dict[str, str]:
    """``user:password`` lines of a replay server's users file (mode 0600 or stricter)."""
    p = Path(path)
    try:
        mode = p.stat().st_mode
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise LiveError(f"users file {p} cannot be read ({exc})") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise LiveError(f"users file {p} is readable by others (mode {stat.S_IMODE(mode):o}); chmod 600 {p}")
    users = {}
    for i, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        user, sep, password = line.partition(":")
        if not sep or not user:
            raise LiveError(f"users file {p}, line {i}: expected 'user:password'")
        users[user] = password
    if not users:
        raise LiveError(f"users file {p} has no 'user:password' line")
    return users


def utc(t: datetime) -> datetime:
    """*t* as an aware UTC datetime (OPC UA timestamps are UTC)."""
    return t.replace(tzinfo=timezone.utc) if t.tzinfo is None else t.astimezone(timezone.utc)


def at(origin: datetime, seconds: float) -> datetime:
    """``origin + seconds``, exact to the microsecond for the sample times of a case."""
    return origin + timedelta(microseconds=round(seconds * 1e6))


class _Users:
    """asyncua user manager: a user/password table; anonymous and wrong passwords refused."""

    def __init__(self, users: dict[str, str]) -> None:
        self.users = dict(users)

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> Any:
        from asyncua.crypto.permission_rules import User, UserRole

        if username is not None and self.users.get(username) == password:
            return User(role=UserRole.User, name=username)
        log.warning("refused a session for %s", repr(username) if username else "an anonymous user")
        return None


async def make_server(url: str, *, name: str, users: dict[str, str] | None = None,
                      certificate: Path | None = None, private_key: Path | None = None) -> Any:
    """An initialised asyncua server at *url*: anonymous or users only, no security or Basic256Sha256."""
    from asyncua import Server, ua

    check_endpoint(url)
    server = Server(user_manager=_Users(users) if users else None)
    await server.init()
    server.set_endpoint(url)
    server.set_server_name(name)
    if certificate is not None:
        if private_key is None:
            raise SpecError("a server certificate needs its private key")
        for what, path in (("certificate", certificate), ("private key", private_key)):
            if not Path(path).is_file():
                raise LiveError(f"server {what} {path} does not exist")
        await server.load_certificate(str(certificate))
        await server.load_private_key(str(private_key))
        server.set_security_policy([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
                                    ua.SecurityPolicyType.Basic256Sha256_Sign])
    else:
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
    server.set_identity_tokens([ua.UserNameIdentityToken] if users else [ua.AnonymousIdentityToken])
    return server
