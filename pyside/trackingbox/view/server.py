"""The live view's HTTP server (aiohttp): the page, its vendored scripts, and the run as server-sent events.

Routes: ``/`` the page; ``/static/...`` its files (from the package, never a
CDN); ``/events`` a server-sent event stream whose first message is a
``snapshot`` of everything the page shows and whose next ones are ``update``
messages (new chart rows, the last row, the loops, the tags, the health, new
log entries), sent after every look at the folder that found a change and at
least every :data:`HEARTBEAT` s; ``/state`` the snapshot as JSON (for scripts).

One poller looks at the folder every :data:`POLL` s (:class:`~.reader.RunReader`)
and hands each message to every open stream; a page whose queue is full (a
stalled browser) is dropped and reconnects to a fresh snapshot
(``EventSource`` reconnects by itself).

A bind to anything but a loopback address needs credentials: HTTP basic auth,
the user and password from ``--credentials FILE`` (``user = ...`` and
``password = ...`` lines, mode 600), ``TRACKINGBOX_VIEW_CREDENTIALS``, or
``TRACKINGBOX_VIEW_USER`` and ``TRACKINGBOX_VIEW_PASSWORD``; without them the
server refuses to start. ``--certificate``/``--private-key`` serve HTTPS.
"""
from __future__ import annotations

import asyncio
import base64
import binascii
import hmac
import ipaddress
import json
import logging
import os
import select
import signal
import ssl
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import config
from ..errors import LiveError, SpecError
from ..online.opcua import Credentials, read_credentials
from .reader import RunReader

# aiohttp is imported in the functions that use it: every command line imports this module (through
# commands/track and commands/view), and aiohttp.web costs 98 more modules and 0.10 s of CPU after
# trackingbox.cli (measured 2026-11-29)

log = logging.getLogger(__name__)

#: Seconds between two looks at the output folder.
POLL = 0.25
#: Longest silence on an event stream (s): an update is sent at least this often (ages tick on).
HEARTBEAT = 1.0
#: Messages queued per page before it is dropped (it reconnects to a snapshot).
QUEUE = 64
#: The view's own credential settings (:mod:`trackingbox.config`; never the OPC UA ones).
VIEW_KEYS = ("view_user", "view_password", "view_credentials")
STATIC = Path(__file__).parent / "static"
#: Default address of the view.
DEFAULT_BIND = "127.0.0.1:8050"


def parse_bind(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[IPv6]:PORT``) as ``(host, port)``; :class:`SpecError` otherwise. Port 0: any free port.

    >>> parse_bind("127.0.0.1:8050"), parse_bind("[::1]:0")
    (('127.0.0.1', 8050), ('::1', 0))
    """
    host, sep, port = str(text).rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not sep or not host or not 0 <= number < 65536:
        raise SpecError(f"--view/--bind {text!r} is not HOST:PORT (e.g. 127.0.0.1:8050)")
    return host, number


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def view_credentials(path: str | os.PathLike[str] | None, host: str) -> Credentials | None:
    """The credentials the view asks for: required off loopback (:class:`LiveError` without them)."""
    creds = read_credentials(path, keys=VIEW_KEYS)
    if creds is None and not is_loopback(host):
        raise LiveError(f"the live view binds to {host}, which is not a loopback address: it needs credentials "
                        f"(--view-credentials FILE with 'user = ...' and 'password = ...' lines, mode 600, or "
                        f"{config.setting(VIEW_KEYS[0]).env} and {config.setting(VIEW_KEYS[1]).env}); or bind it to 127.0.0.1")
    return creds


def _authorised(header: str | None, creds: Credentials) -> bool:
    if not header or not header.startswith("Basic "):
        return False
    try:
        user, _, password = base64.b64decode(header[6:].strip(), validate=True).decode("utf-8").partition(":")
    except (binascii.Error, UnicodeDecodeError):
        return False
    # both compared, always (no early exit telling which was wrong)
    ok_user = hmac.compare_digest(user.encode(), creds.user.encode())
    ok_password = hmac.compare_digest(password.encode(), creds.password.encode())
    return ok_user and ok_password


class Hub:
    """The poller and the open event streams of one output folder."""

    def __init__(self, reader: RunReader, poll: float = POLL) -> None:
        self.reader = reader
        self.poll = poll
        self.queues: set[asyncio.Queue[bytes | None]] = set()
        self.event_seq = 0
        self.looks = 0

    @staticmethod
    def _message(doc: dict[str, Any]) -> bytes:
        return f"event: {doc['type']}\ndata: {json.dumps(doc, separators=(',', ':'), allow_nan=False)}\n\n".encode()

    def subscribe(self) -> asyncio.Queue[bytes | None]:
        q: asyncio.Queue[bytes | None] = asyncio.Queue(maxsize=QUEUE)
        q.put_nowait(self._message(self.reader.snapshot()))
        self.queues.add(q)
        return q

    def _send(self, message: bytes) -> None:
        for q in list(self.queues):
            try:
                q.put_nowait(message)
            except asyncio.QueueFull:  # a stalled page: dropped, it reconnects to a snapshot
                self.queues.discard(q)
                q.get_nowait()
                q.put_nowait(None)

    async def run(self) -> None:
        last_sent = 0.0
        while True:
            try:
                restarted, changed = self.reader.poll()
            except Exception:  # noqa: BLE001 - the view must outlive anything a file holds
                log.exception("looking at %s failed; trying again", self.reader.out)
                restarted, changed = False, False
            self.looks += 1
            now = time.monotonic()
            if restarted:
                self._send(self._message(self.reader.snapshot()))
                self.reader.update(self.reader.event_seq)  # the rows and events the snapshot had
                self.event_seq = self.reader.event_seq
                last_sent = now
            elif changed or now - last_sent >= HEARTBEAT:
                self._send(self._message(self.reader.update(self.event_seq)))
                self.event_seq = self.reader.event_seq
                last_sent = now
            # a long file is caught up with chunk by chunk, the pages served in between
            await asyncio.sleep(0 if self.reader.behind else self.poll)


def make_app(hub: Hub, credentials: Credentials | None) -> Any:
    from aiohttp import web

    @web.middleware
    async def auth(request: web.Request, handler: Callable[..., Any]) -> Any:
        if credentials is not None and not _authorised(request.headers.get("Authorization"), credentials):
            return web.Response(status=401, text="credentials required",
                                headers={"WWW-Authenticate": 'Basic realm="trackingbox live view", charset="UTF-8"'})
        response = await handler(request)
        response.headers.setdefault("Cache-Control", "no-store")
        response.headers.setdefault("X-Content-Type-Options", "nosniff")
        response.headers.setdefault("Content-Security-Policy",
                                    "default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:")
        return response

    async def index(request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html")

    async def state(request: web.Request) -> web.Response:
        return web.json_response(hub.reader.snapshot(), dumps=lambda d: json.dumps(d, allow_nan=False))

    async def events(request: web.Request) -> web.StreamResponse:
        response = web.StreamResponse(headers={"Content-Type": "text/event-stream", "Cache-Control": "no-store",
                                               "X-Accel-Buffering": "no"})
        await response.prepare(request)
        q = hub.subscribe()
        try:
            await response.write(b"retry: 1000\n\n")
            while True:
                message = await q.get()
                if message is None:
                    break
                await response.write(message)
        except (ConnectionResetError, asyncio.CancelledError):
            pass
        finally:
            hub.queues.discard(q)
        return response

    app = web.Application(middlewares=[auth])
    app.router.add_get("/", index)
    app.router.add_get("/state", state)
    app.router.add_get("/events", events)
    app.router.add_static("/static/", STATIC, show_index=False, follow_symlinks=False)
    return app


@dataclass(frozen=True)
class ViewSettings:
    """Where and how the view is served."""

    bind: str = DEFAULT_BIND
    spec: Path | None = None
    credentials: Path | None = None
    certificate: Path | None = None
    private_key: Path | None = None
    #: stop when this process is gone (the tracker that started the view)
    parent: int | None = None
    poll: float = POLL


async def serve(out: str | os.PathLike[str], settings: ViewSettings,
                ready: Callable[[str], None] | None = None, stop: asyncio.Event | None = None) -> None:
    """Serve the view of *out* until *stop* is set (or the parent process is gone, or SIGTERM/SIGINT)."""
    from aiohttp import web

    host, port = parse_bind(settings.bind)
    creds = view_credentials(settings.credentials, host)
    context = None
    if (settings.certificate is None) != (settings.private_key is None):
        raise SpecError("--view-certificate and --view-private-key go together")
    if settings.certificate is not None:
        context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        try:
            context.load_cert_chain(str(settings.certificate), str(settings.private_key))
        except (OSError, ssl.SSLError) as exc:
            raise LiveError(f"the view's certificate {settings.certificate} or key {settings.private_key} "
                            f"cannot be used: {exc}") from None
    if not Path(out).is_dir():
        raise LiveError(f"output folder {out} does not exist (give the folder track writes: --out)")
    hub = Hub(RunReader(out, settings.spec), settings.poll)
    runner = web.AppRunner(make_app(hub, creds), handle_signals=False, access_log=None, shutdown_timeout=1.0)
    await runner.setup()
    site = web.TCPSite(runner, host, port, ssl_context=context)
    try:
        await site.start()
    except OSError as exc:
        await runner.cleanup()
        raise LiveError(f"the live view cannot listen on {settings.bind}: {exc.strerror or exc}") from None
    sockets = site._server.sockets if site._server is not None else []  # the port chosen for port 0
    bound = sockets[0].getsockname()[1] if sockets else port
    shown = f"[{host}]" if ":" in host else host
    url = f"{'https' if context else 'http'}://{shown}:{bound}/"
    stop = stop or asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        try:
            loop.add_signal_handler(sig, stop.set)
        except (NotImplementedError, RuntimeError, ValueError):  # not the main thread
            pass
    poller = asyncio.create_task(hub.run())
    log.info("live view of %s at %s", out, url)
    if ready is not None:
        ready(url)
    try:
        while not stop.is_set():
            try:
                await asyncio.wait_for(stop.wait(), timeout=1.0)
            except asyncio.TimeoutError:
                pass
            if settings.parent is not None and os.getppid() != settings.parent:
                log.info("the tracker (pid %d) is gone: the view stops", settings.parent)
                break
    finally:
        poller.cancel()
        for q in list(hub.queues):
            q.put_nowait(None) if not q.full() else None
        await runner.cleanup()


def run_view(out: str | os.PathLike[str], settings: ViewSettings,
             ready: Callable[[str], None] | None = None) -> None:
    """Blocking :func:`serve` (``trackingbox view``)."""
    asyncio.run(serve(out, settings, ready))


# --------------------------------------------------------------------------- beside a tracker

class BackgroundView:
    """The view served by a child process beside the tracker (``track --view``); a context manager.

    The child only reads the folder, runs at a lower priority (nice +5) and
    stops with the tracker (it watches its parent), so the tracking loop never
    waits for it and shares no interpreter lock with it. ``url`` is its address.
    """

    def __init__(self, out: Path, settings: ViewSettings, *, timeout: float = 60.0) -> None:
        host, _ = parse_bind(settings.bind)
        view_credentials(settings.credentials, host)  # refused here, before the tracker starts
        args = [sys.executable, "-m", "trackingbox.view", str(out), "--bind", settings.bind,
                "--parent", str(os.getpid()), "--ready-fd", "1"]
        for flag, value in (("--spec", settings.spec), ("--credentials", settings.credentials),
                            ("--certificate", settings.certificate), ("--private-key", settings.private_key)):
            if value is not None:
                args += [flag, str(value)]
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stdin=subprocess.DEVNULL,
                                     preexec_fn=lambda: os.nice(5))
        self.url = self._ready(timeout)

    def _ready(self, timeout: float) -> str:
        assert self.proc.stdout is not None
        deadline = time.monotonic() + timeout
        line = b""
        while not line.endswith(b"\n"):
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.proc.stdout], [], [], left)[0]:
                self.close()
                raise LiveError(f"the live view did not start within {timeout:g} s")
            chunk = os.read(self.proc.stdout.fileno(), 4096)
            if not chunk:
                code = self.proc.wait()
                raise LiveError(f"the live view could not start (exit {code}; its error is above)")
            line += chunk
        text = line.decode(errors="replace").strip()
        if not text.startswith("view "):
            self.close()
            raise LiveError(f"the live view said {text!r} instead of its address")
        return text[5:]

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()

    def __enter__(self) -> BackgroundView:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
