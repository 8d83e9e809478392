"""A headless Chromium driven over the DevTools protocol (CDP): open a page, evaluate, take a picture.

Debian's ``chromium`` is started with its own empty profile and no network of
its own (the flags of :data:`FLAGS`), and spoken to over the browser's CDP
websocket (aiohttp's client) with flattened target sessions. Used by the view's
tests and by ``trackingbox view --screenshot``; nothing is downloaded.

>>> find_chromium() is None or find_chromium().endswith(("chromium", "chromium-browser", "chrome"))
True
"""
from __future__ import annotations

import asyncio
import base64
import json
import logging
import os
import re
import shutil
import subprocess
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .. import config
from ..errors import TrackingError

# aiohttp is imported in the functions that use it (every command line imports this module: see .server)

log = logging.getLogger(__name__)

#: Flags for a headless Chromium that reaches nothing but the pages it is sent to.
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--hide-scrollbars", "--mute-audio", "--disable-extensions",
         "--disable-default-apps", "--no-default-browser-check")


class BrowserError(TrackingError):
    """The browser could not be started or did not answer."""


def find_chromium() -> str | None:
    """The Chromium to drive: ``$TRACKINGBOX_CHROMIUM``, else ``chromium``/``chromium-browser`` on PATH."""
    given = config.get("chromium")
    if given:
        return given
    for name in ("chromium", "chromium-browser"):
        found = shutil.which(name)
        if found:
            return found
    return None


class Page:
    """One tab: :meth:`evaluate` JavaScript, :meth:`wait_for` a condition, :meth:`screenshot`."""

    def __init__(self, browser: Browser, session: str) -> None:
        self.browser = browser
        self.session = session

    def evaluate(self, expression: str, timeout: float = 30.0) -> Any:
        """The value of *expression* in the page (JSON-able values; promises awaited)."""
        res = self.browser.call("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                                     "awaitPromise": True}, session=self.session, timeout=timeout)
        if "exceptionDetails" in res:
            details = res["exceptionDetails"]
            text = details.get("exception", {}).get("description") or details.get("text")
            raise BrowserError(f"the page threw evaluating {expression[:80]!r}: {text}")
        return res.get("result", {}).get("value")

    def wait_for(self, expression: str, timeout: float = 60.0, every: float = 0.1) -> Any:
        """Poll *expression* until it is truthy (its value), at most *timeout* s; :class:`TimeoutError` after."""
        deadline = time.monotonic() + timeout
        value = None
        while True:
            value = self.evaluate(expression)
            if value:
                return value
            if time.monotonic() > deadline:
                raise TimeoutError(f"{expression!r} still {value!r} after {timeout:g} s")
            time.sleep(every)

    def settle(self, frames: int = 3) -> None:
        """Let the page draw (a few animation frames and the charts' deferred redraw)."""
        self.evaluate("new Promise(r => setTimeout(r, 450))")
        for _ in range(frames):
            self.evaluate("new Promise(r => requestAnimationFrame(() => r(true)))")

    def screenshot(self, path: str | os.PathLike[str], width: int = 1400) -> Path:
        """A PNG of the whole page (its full height) at *path*."""
        height = int(self.evaluate("Math.ceil(document.documentElement.scrollHeight)") or 900)
        self.browser.call("Emulation.setDeviceMetricsOverride", {"width": width, "height": min(height, 8000),
                                                                 "deviceScaleFactor": 1, "mobile": False},
                          session=self.session)
        self.settle()
        res = self.browser.call("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True},
                                session=self.session, timeout=60.0)
        out = Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(base64.b64decode(res["data"]))
        return out

    @property
    def errors(self) -> list[str]:
        """JavaScript exceptions and console errors the page reported."""
        return list(self.browser.errors.get(self.session, []))


class Browser:
    """A headless Chromium with a fresh profile; a context manager that ends it (and only it)."""

    def __init__(self, executable: str | None = None, extra: Sequence[str] = (), timeout: float = 60.0) -> None:
        exe = executable or find_chromium()
        if exe is None:
            raise BrowserError("no Chromium found (install Debian's chromium: apt-get install chromium, "
                               f"or name one in {config.setting('chromium').env})")
        self.profile = tempfile.mkdtemp(prefix="trackingbox-chromium-")
        args = [exe, *FLAGS, f"--user-data-dir={self.profile}", "--remote-debugging-port=0",
                "--window-size=1400,1000", *extra, "about:blank"]
        self.proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL)
        self.errors: dict[str, list[str]] = {}
        self._stderr: list[str] = []
        found: dict[str, str] = {}
        ready = threading.Event()

        def drain() -> None:
            assert self.proc.stderr is not None
            for raw in self.proc.stderr:
                line = raw.decode(errors="replace").rstrip()
                self._stderr.append(line)
                del self._stderr[:-200]
                m = re.search(r"DevTools listening on (ws://\S+)", line)
                if m:
                    found["ws"] = m.group(1)
                    ready.set()
            ready.set()

        threading.Thread(target=drain, daemon=True).start()
        if not ready.wait(timeout) or "ws" not in found:
            self.close()
            raise BrowserError(f"{exe} did not open its DevTools endpoint within {timeout:g} s:\n"
                               + "\n".join(self._stderr[-20:]))
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self._thread.start()
        self._id = 0
        self._pending: dict[int, asyncio.Future[Any]] = {}
        self._ws: Any = None
        self._session: Any = None
        self._run(self._connect(found["ws"]), timeout)

    # -- the protocol -------------------------------------------------------
    def _run(self, coro: Any, timeout: float) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    async def _connect(self, url: str) -> None:
        import aiohttp

        self._session = aiohttp.ClientSession()
        self._ws = await self._session.ws_connect(url, max_msg_size=0, heartbeat=None)
        asyncio.get_running_loop().create_task(self._read())

    async def _read(self) -> None:
        import aiohttp

        async for msg in self._ws:
            if msg.type != aiohttp.WSMsgType.TEXT:
                continue
            doc = json.loads(msg.data)
            if "id" in doc:
                fut = self._pending.pop(doc["id"], None)
                if fut is not None and not fut.done():
                    if "error" in doc:
                        fut.set_exception(BrowserError(f"CDP error: {doc['error']}"))
                    else:
                        fut.set_result(doc.get("result", {}))
            elif doc.get("method") == "Runtime.exceptionThrown":
                d = doc["params"]["exceptionDetails"]
                self.errors.setdefault(doc.get("sessionId", ""), []).append(
                    d.get("exception", {}).get("description") or d.get("text", "exception"))
            elif doc.get("method") == "Runtime.consoleAPICalled" and doc["params"].get("type") == "error":
                args = doc["params"].get("args", [])
                self.errors.setdefault(doc.get("sessionId", ""), []).append(
                    " ".join(str(a.get("value", a.get("description", ""))) for a in args))
        for fut in self._pending.values():
            if not fut.done():
                fut.set_exception(BrowserError("the browser closed its DevTools connection"))

    async def _call(self, method: str, params: dict[str, Any], session: str | None) -> Any:
        self._id += 1
        fut: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
        self._pending[self._id] = fut
        doc: dict[str, Any] = {"id": self._id, "method": method, "params": params}
        if session:
            doc["sessionId"] = session
        await self._ws.send_str(json.dumps(doc))
        return await fut

    def call(self, method: str, params: dict[str, Any] | None = None, *, session: str | None = None,
             timeout: float = 30.0) -> Any:
        """One CDP command (of the browser, or of a page's *session*) and its result."""
        try:
            return self._run(self._call(method, params or {}, session), timeout)
        except TimeoutError:
            raise BrowserError(f"the browser did not answer {method} within {timeout:g} s") from None

    # -- pages --------------------------------------------------------------
    def open(self, url: str, timeout: float = 60.0) -> Page:
        """A new tab at *url*, loaded (its ``load`` event or *timeout*)."""
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        self.errors[session] = []
        for method in ("Page.enable", "Runtime.enable"):
            self.call(method, session=session)
        page = Page(self, session)
        self.call("Page.navigate", {"url": url}, session=session, timeout=timeout)
        page.wait_for("document.readyState === 'complete'", timeout=timeout)
        return page

    def close(self) -> None:
        if getattr(self, "_ws", None) is not None:
            try:
                self._run(self._ws.close(), 5.0)
                self._run(self._session.close(), 5.0)
            except Exception:  # noqa: BLE001 - the browser is going anyway
                pass
            self._ws = None
        if getattr(self, "loop", None) is not None:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self._thread.join(timeout=5)
            self.loop.close()
            self.loop = None  # type: ignore[assignment]
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
