"""The live view's reader and server without a browser: torn lines, restarted files, loop states, credentials.

The expectations are written out by hand from the rows each test writes (the
reader's own output is never the reference); the vendored chart library is
checked against the checksums of the npm package it came from.
"""
from __future__ import annotations

import asyncio
import base64
import hashlib
import json
import os
import re
from pathlib import Path

import pytest

from _fixtures_tracking import spec_text
from trackingbox.errors import LiveError, SpecError
from trackingbox.view import reader as reader_mod
from trackingbox.view.reader import RunReader, band_columns
from trackingbox.view.server import STATIC, Hub, is_loopback, make_app, parse_bind, view_credentials

HEADER = "time,measured:TI,tracked:TI,untracked:TI,parameter:k,mode:TI\n"


def _run(tmp_path: Path, truth: dict | None = None) -> tuple[Path, Path]:
    """A spec (k in [0.001, 0.01], start-up hold 200 s) and an empty output folder."""
    case = tmp_path / "case"
    case.mkdir()
    spec = case / "spec.toml"
    spec.write_text(spec_text(0.003))
    if truth is not None:
        (case / "truth.json").write_text(json.dumps(truth))
    out = tmp_path / "out"
    out.mkdir()
    return spec, out


def test_a_partly_written_last_line_waits_for_its_end(tmp_path: Path) -> None:
    spec, out = _run(tmp_path)
    csv = out / "tracking.csv"
    csv.write_text(HEADER + "0.0,35.7,38.0,38.0,0.003,hold\n10.0,35.8,38.1,38.0,0.003,hold\n20.0,35.9,38.")
    r = RunReader(out, spec)
    restarted, changed = r.poll()
    assert restarted and changed and r.n == 2 and r.last["time"] == "10.0"
    with open(csv, "a") as fh:  # the tracker finishes the line
        fh.write("2,38.2,0.003,hold\n")
    r.poll()
    assert r.n == 3 and r.last == {"time": "20.0", "measured:TI": "35.9", "tracked:TI": "38.2",
                                   "untracked:TI": "38.2", "parameter:k": "0.003", "mode:TI": "hold"}


def test_a_file_cut_back_or_replaced_is_read_again_from_its_start(tmp_path: Path) -> None:
    spec, out = _run(tmp_path)
    csv = out / "tracking.csv"
    rows = [f"{10.0 * i},35.7,38.0,38.0,0.003,hold\n" for i in range(5)]
    csv.write_text(HEADER + "".join(rows))
    r = RunReader(out, spec)
    r.poll()
    assert r.n == 5
    # --resume cuts the CSV back to its checkpoint (3 rows) and writes on: more bytes than before, new values
    with open(csv, "r+") as fh:
        fh.truncate(len(HEADER) + sum(len(x) for x in rows[:3]))
        fh.seek(0, os.SEEK_END)
        fh.write("30.0,35.7,38.0,38.0,0.00555,auto\n40.0,35.7,38.0,38.0,0.00666,auto\n50.0,1,2,3,0.00777,auto\n")
    restarted, _ = r.poll()
    assert restarted and r.n == 6 and r.last["parameter:k"] == "0.00777"
    assert any("started again" in e["text"] for e in r.events)
    # a new run replaces the file (another inode): read from its start
    new = out / "tracking.csv.new"
    new.write_text(HEADER + "0.0,1,2,3,0.004,hold\n")
    os.replace(new, csv)
    restarted, _ = r.poll()
    assert restarted and r.n == 1 and r.last["parameter:k"] == "0.004"


def test_loop_states_and_why(tmp_path: Path) -> None:
    spec, out = _run(tmp_path)
    (out / "tracking.csv").write_text(HEADER + "\n".join([
        "0.0,35.7,38.0,38.0,0.003,hold",      # start-up hold (hold_until 200 s)
        "200.0,35.7,37.0,38.0,0.004,auto",    # tracking
        "210.0,35.7,36.0,38.0,0.01,auto",     # at its upper bound
        "220.0,,36.0,38.0,0.01,hold",         # no measured value
        "230.0,35.7,36.0,38.0,0.001,auto",    # at its lower bound
        "240.0,35.7,36.0,38.0,0.001,hold",    # held on for another reason: a new interval, the last one ended
        "250.0,,36.0,38.0,0.001,hold",
        "260.0,35.7,36.0,38.0,0.002,auto",
    ]) + "\n")
    r = RunReader(out, spec)
    r.poll()
    texts = [e["text"] for e in r.events if e["kind"] == "loop"]
    assert texts == ["TI → k: held (start-up hold until 200 s)", "TI → k: tracking",
                     "TI → k: saturated (at its upper bound 0.01)",
                     "TI → k: held (no measured value: bad quality or a gap)",
                     "TI → k: saturated (at its lower bound 0.001)",
                     "TI → k: held (an input missing or a solver recovery)",
                     "TI → k: held (no measured value: bad quality or a gap)", "TI → k: tracking"]
    assert r.loops["TI"] == {"state": "tracking", "why": "", "since": 260.0}
    assert list(r.holds["TI"]) == [[0.0, 200.0, "start-up hold until 200 s"],
                                   [220.0, 230.0, "no measured value: bad quality or a gap"],
                                   [240.0, 250.0, "an input missing or a solver recovery"],
                                   [250.0, 260.0, "no measured value: bad quality or a gap"]]
    # a stale tag (the tracker's status says so) is named as such
    (out / "live_status.json").write_text(json.dumps({"written": 1.0, "link": "connected", "connections": 1,
                                                      "tags": {"TI": {"stale": True, "behind": 90.0}}}))
    with open(out / "tracking.csv", "a") as fh:
        fh.write("240.0,,36.0,38.0,0.001,hold\n")
    r.poll()
    assert r.loops["TI"]["why"] == "no sample from the plant: stale"


def test_chart_rows_are_thinned_by_a_doubling_stride(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    spec, out = _run(tmp_path, truth={"trajectories": {"k": {"time": [0.0, 1000.0], "value": [0.004, 0.005]}}})
    monkeypatch.setattr(reader_mod, "MAX_POINTS", 10)
    (out / "tracking.csv").write_text(HEADER + "".join(f"{10.0 * i},35.7,38.0,38.0,0.003,auto\n" for i in range(25)))
    r = RunReader(out, spec)
    r.poll()
    # 25 rows, at most 10 kept: stride 1 -> 2 (at the 11th kept row) -> 4 (at row 20)
    assert r.stride == 4 and [row[0] for row in r.kept] == [0, 4, 8, 12, 16, 20, 24]
    assert r.n == 25 and r.last["time"] == "240.0"
    # the truth column is the trajectory of truth.json at the row's time (0.004 + 1e-6 * t)
    assert r.series[-1] == "truth:k"
    assert [row[-1] for row in r.kept] == pytest.approx([0.004 + 1e-6 * 10.0 * i for i in (0, 4, 8, 12, 16, 20, 24)])


def test_band_columns_follow_the_documented_rule() -> None:
    assert band_columns(["parameter:k", "lo:k", "hi:k"], "k") == ("lo:k", "hi:k")
    assert band_columns(["parameter:k", "band_lo:k", "band_hi:k"], "k") == ("band_lo:k", "band_hi:k")
    assert band_columns(["parameter:k", "parameter:k_lo", "parameter:k_hi"], "k") == ("parameter:k_lo",
                                                                                      "parameter:k_hi")
    assert band_columns(["parameter:k", "k_lo", "k_hi"], "k") == ("k_lo", "k_hi")
    assert band_columns(["parameter:k", "lower:kk", "upper:kk"], "k") is None  # another parameter's
    assert band_columns(["parameter:k", "lower:k"], "k") is None  # half a band is no band


def test_a_band_in_the_csv_is_sent_to_the_page(tmp_path: Path) -> None:
    spec, out = _run(tmp_path)
    (out / "tracking.csv").write_text("time,measured:TI,tracked:TI,untracked:TI,parameter:k,lower:k,upper:k,mode:TI\n"
                                      "0.0,35.7,38.0,38.0,0.003,0.0025,0.0035,hold\n")
    r = RunReader(out, spec)
    r.poll()
    meta = r.meta()
    assert meta["pairs"][0]["band"] == ("lower:k", "upper:k")
    assert r.kept[0][meta["series"].index("lower:k") + 1] == 0.0025


def test_link_changes_become_log_entries(tmp_path: Path) -> None:
    spec, out = _run(tmp_path)
    status = out / "live_status.json"
    r = RunReader(out, spec)

    def say(**doc: object) -> None:
        status.write_text(json.dumps({"written": 1.0, "url": "opc.tcp://x:1", **doc}))
        r._status_mtime = None  # same-second writes: look again whatever the mtime says
        r.poll()

    say(link="connected", connections=1, lost=0, backfilled=0, tags={"TI": {"stale": False}})
    say(link="disconnected", connections=1, lost=1, backfilled=0, link_error="connection reset",
        tags={"TI": {"stale": False}})
    say(link="connected", connections=2, lost=1, backfilled=40, tags={"TI": {"stale": True, "behind": 60.0}})
    # lost and back between two looks, then stopped: the counters tell
    say(link="stopped", connections=3, lost=2, backfilled=40, link_error="timeout", tags={"TI": {"stale": True}})
    kinds = [(e["kind"], e["text"]) for e in r.events]
    assert kinds == [("link-up", "connected to opc.tcp://x:1"),
                     ("link-lost", "lost opc.tcp://x:1: connection reset; reconnecting"),
                     ("link-up", "reconnected to opc.tcp://x:1 (connection 2)"),
                     ("backfill", "read back 40 samples from the server's history"),
                     ("stale", "TI stale: nothing for 60 s of plant time"),
                     ("link-lost", "lost opc.tcp://x:1: timeout; reconnecting"),
                     ("link-up", "reconnected to opc.tcp://x:1 (connection 3)"),
                     ("link-stopped", "the tracker stopped")]
    assert r.health()["reconnects"] == 2
    status.write_text("{ half a fil")  # a foreign, torn file keeps the last good reading
    r._status_mtime = None
    r.poll()
    assert r.status["connections"] == 3


def test_vendored_chart_library_is_the_npm_package() -> None:
    table = (STATIC / "VENDORED.md").read_text()
    for name in ("uPlot.iife.min.js", "uPlot.min.css"):
        expected = re.search(rf"\| {re.escape(name)} \| ([0-9a-f]{{64}}) \|", table).group(1)
        assert hashlib.sha256((STATIC / name).read_bytes()).hexdigest() == expected
    assert "MIT License" in (STATIC / "uPlot.LICENSE").read_text()
    # nothing of the page comes from elsewhere: every script and style is under /static/
    page = (STATIC / "index.html").read_text()
    assert sorted(re.findall(r'(?:src|href)="([^"]+)"', page)) == [
        "/static/app.js", "/static/style.css", "/static/uPlot.iife.min.js", "/static/uPlot.min.css"]
    assert not re.search(r"https?://", (STATIC / "app.js").read_text())


def test_bind_addresses_and_credentials(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("TRACKINGBOX_VIEW_USER", "TRACKINGBOX_VIEW_PASSWORD", "TRACKINGBOX_VIEW_CREDENTIALS"):
        monkeypatch.delenv(name, raising=False)
    assert parse_bind("0.0.0.0:8050") == ("0.0.0.0", 8050)
    for bad in ("8050", "host:", "host:99999", ":80"):
        with pytest.raises(SpecError, match="not HOST:PORT"):
            parse_bind(bad)
    assert is_loopback("127.0.0.1") and is_loopback("127.3.4.5") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("10.1.2.3") and not is_loopback("plant-pc")
    assert view_credentials(None, "127.0.0.1") is None  # loopback: none needed
    with pytest.raises(LiveError, match="needs credentials"):
        view_credentials(None, "0.0.0.0")
    f = tmp_path / "view.txt"
    f.write_text("user = op\npassword = s3cret\n")
    f.chmod(0o644)
    with pytest.raises(LiveError, match="readable by others"):
        view_credentials(f, "0.0.0.0")
    f.chmod(0o600)
    assert view_credentials(f, "0.0.0.0").user == "op"
    monkeypatch.setenv("TRACKINGBOX_VIEW_USER", "env-op")
    monkeypatch.setenv("TRACKINGBOX_VIEW_PASSWORD", "pw")
    assert view_credentials(None, "0.0.0.0").user == "env-op"


def test_the_server_asks_for_credentials_when_it_has_them(tmp_path: Path) -> None:
    from aiohttp.test_utils import TestClient, TestServer

    from trackingbox.online.opcua import Credentials

    spec, out = _run(tmp_path)
    (out / "tracking.csv").write_text(HEADER + "0.0,35.7,38.0,38.0,0.003,hold\n")

    async def go() -> dict[str, object]:
        hub = Hub(RunReader(out, spec))
        hub.reader.poll()
        seen: dict[str, object] = {}
        async with TestClient(TestServer(make_app(hub, Credentials("op", "s3cret")))) as client:
            seen["none"] = (await client.get("/")).status
            bad = base64.b64encode(b"op:wrong").decode()
            seen["wrong"] = (await client.get("/state", headers={"Authorization": f"Basic {bad}"})).status
            good = {"Authorization": "Basic " + base64.b64encode(b"op:s3cret").decode()}
            page = await client.get("/", headers=good)
            seen["page"] = (page.status, "uPlot.iife.min.js" in await page.text())
            lib = await client.get("/static/uPlot.iife.min.js", headers=good)
            seen["lib"] = (lib.status, len(await lib.read()))
            state = await client.get("/state", headers=good)
            seen["state"] = (await state.json())["last"]
            seen["escape"] = (await client.get("/static/../reader.py", headers=good)).status
        async with TestClient(TestServer(make_app(hub, None))) as client:
            seen["open"] = (await client.get("/state")).status
        return seen

    seen = asyncio.run(go())
    assert seen["none"] == 401 and seen["wrong"] == 401 and seen["open"] == 200
    assert seen["page"] == (200, True) and seen["lib"] == (200, (STATIC / "uPlot.iife.min.js").stat().st_size)
    assert seen["state"]["parameter:k"] == "0.003"
    assert seen["escape"] in (403, 404)


def test_view_refuses_a_missing_folder_and_a_bad_bind(tmp_path: Path) -> None:
    from trackingbox.cli import main

    assert main(["view", str(tmp_path / "nowhere"), "--bind", "127.0.0.1:0", "--screenshot",
                 str(tmp_path / "x.png")]) == 2
    assert main(["view", str(tmp_path), "--bind", "localhost"]) == 2
    assert main(["view", str(tmp_path), "--bind", "0.0.0.0:0"]) == 2  # off loopback without credentials


def test_https_and_basic_auth_end_to_end(tmp_path: Path) -> None:
    """serve() with a certificate: HTTPS only, the credentials asked for, the page and the state served."""
    import datetime as dt
    import ssl

    import aiohttp
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import rsa
    from cryptography.x509.oid import NameOID

    from trackingbox.view.server import ViewSettings, serve

    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "localhost")])
    now = dt.datetime.now(dt.timezone.utc)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - dt.timedelta(days=1))
            .not_valid_after(now + dt.timedelta(days=2))
            .add_extension(x509.SubjectAlternativeName([x509.DNSName("localhost")]), critical=False)
            .sign(key, hashes.SHA256()))
    pem, key_pem = tmp_path / "view.pem", tmp_path / "view.key"
    pem.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_pem.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.TraditionalOpenSSL,
                                          serialization.NoEncryption()))
    creds = tmp_path / "view.txt"
    creds.write_text("user = op\npassword = s3cret\n")
    creds.chmod(0o600)
    spec, out = _run(tmp_path)
    (out / "tracking.csv").write_text(HEADER + "0.0,35.7,38.0,38.0,0.003,hold\n")

    async def go() -> dict[str, object]:
        stop = asyncio.Event()
        found: dict[str, str] = {}
        settings = ViewSettings(bind="localhost:0", spec=spec, credentials=creds, certificate=pem,
                                private_key=key_pem)
        task = asyncio.create_task(serve(out, settings, ready=lambda url: found.setdefault("url", url), stop=stop))
        while "url" not in found:
            assert not task.done(), task.exception()
            await asyncio.sleep(0.02)
        url = found["url"]
        context = ssl.create_default_context(cafile=str(pem))
        seen: dict[str, object] = {"url": url}
        async with aiohttp.ClientSession() as session:
            seen["none"] = (await session.get(url, ssl=context)).status
            auth = {"Authorization": "Basic " + base64.b64encode(b"op:s3cret").decode()}
            seen["page"] = (await session.get(url, ssl=context, headers=auth)).status
            state = await session.get(url + "state", ssl=context, headers=auth)
            seen["last"] = (await state.json())["last"]["parameter:k"]
            try:
                await session.get(url.replace("https://", "http://"), headers=auth)
                seen["plain"] = "answered"
            except aiohttp.ClientError:
                seen["plain"] = "refused"
        stop.set()
        await task
        return seen

    seen = asyncio.run(go())
    assert seen["url"].startswith("https://localhost:")
    assert seen["none"] == 401 and seen["page"] == 200 and seen["last"] == "0.003"
    assert seen["plain"] == "refused"  # no plain HTTP on the HTTPS port
