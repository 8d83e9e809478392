"""The online mode on 127.0.0.1: a bench case replayed over OPC UA, tracked live.

The case is the first-order heat-exchanger case of ``_fixtures_tracking``
(601 rows of 10 s, a CasADi FMU); ``trackingbox replay`` serves it in a
subprocess at 600x real time (the 6000 s case in 10 s, starting LEAD s after
the server is ready, so that the tracker is connected by then and the rows come
live), one free port per test. The expectation is the offline run of ``trackingbox track`` on the same
measurements file: live, the twins restart from their states at every batch
of rows that came together (offline, every 200 rows), so the two agree to the
solver's tolerance, not bit for bit; the parameter trajectory must agree to
1e-4 of the parameter's range (the CVODE tolerance is 1e-6).
"""
from __future__ import annotations

import datetime as dt
import json
import logging
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from _fixtures_online import free_port, kill, make_certificate, replay_server, start_replay
from _fixtures_tracking import make_case
from trackingbox.errors import LiveError
from trackingbox.online import live as live_module
from trackingbox.online.live import LiveSettings, track_live
from trackingbox.online.opcua import CLIENT_URI, Credentials
from trackingbox.spec import load_spec
from trackingbox.tracking.runtime import track

pytestmark = pytest.mark.compile  # builds the CasADi twin once per session; each test serves a case

SPEED = 600.0
K_RANGE = 0.01 - 0.001  # the spec's bounds of k
TOLERANCE = 1e-4 * K_RANGE


@pytest.fixture(scope="module")
def case(first_order_fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_case(first_order_fmu, tmp_path_factory.mktemp("online-case"))


@pytest.fixture(scope="module")
def offline(case: Path, tmp_path_factory: pytest.TempPathFactory) -> pd.DataFrame:
    return pd.read_csv(track(load_spec(case), out_dir=tmp_path_factory.mktemp("offline")).csv)


#: seconds from the replay server's readiness to its first row: the tracker connects meanwhile
LEAD = "+4"


def _with_live(case: Path, directory: Path, live: str) -> Path:
    """A copy of the case's spec with a [live] section (the FMU and data stay where they are)."""
    text = case.read_text()  # the case fixture is the spec's path
    text = text.replace('twin = "twin.fmu"', f'twin = "{case.parent / "twin.fmu"}"')
    text = text.replace('measurements = "measurements.csv"', f'measurements = "{case.parent / "measurements.csv"}"')
    directory.mkdir(parents=True, exist_ok=True)
    spec = directory / "spec.toml"
    spec.write_text(text + "\n[live]\n" + live)
    return spec


def _assert_same_trajectory(live: pd.DataFrame, offline: pd.DataFrame) -> None:
    assert len(live) == len(offline) == 601  # no row lost, none invented
    np.testing.assert_array_equal(live["time"], offline["time"])
    np.testing.assert_array_equal(live["measured:TI"], offline["measured:TI"])
    assert np.max(np.abs(live["parameter:k"] - offline["parameter:k"])) <= TOLERANCE
    assert (live["mode:TI"] == offline["mode:TI"]).all()


def test_live_tracking_of_a_replayed_bench_follows_the_offline_trajectory(case: Path, offline: pd.DataFrame,
                                                                          tmp_path: Path) -> None:
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    with replay_server(case, url, LEAD, tmp_path / "replay.log", "--linger", "60", speed=SPEED) as origin:
        result = track_live(load_spec(case), LiveSettings(url, start=origin, stop_after=6000.0, idle_timeout=120.0,
                                                          poll=0.05, backoff=(0.2, 1.0)), out_dir=tmp_path / "live")
    live = pd.read_csv(result.tracking.csv)
    _assert_same_trajectory(live, offline)
    assert result.samples == 2 * 601 and result.connections == 1
    assert result.backfilled < result.samples  # rows came live, by the subscription, not all from history
    # the record is a historian's long form the offline reader takes: tracking it offline gives the same rows
    record = pd.read_csv(tmp_path / "live" / "live_measurements.csv")
    assert sorted(record["tag"].unique()) == ["FI", "TI"] and len(record) == 2 * 601


def test_server_killed_and_restarted_mid_run_loses_nothing(case: Path, offline: pd.DataFrame,
                                                           tmp_path: Path) -> None:
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    log = tmp_path / "replay.log"
    out = tmp_path / "live"
    server, origin = start_replay(case, url, LEAD, log, "--linger", "60", speed=SPEED)
    assert origin is not None
    box: dict[str, object] = {}
    settings = LiveSettings(url, start=origin, stop_after=6000.0, idle_timeout=120.0, poll=0.05,
                            backoff=(0.2, 1.0))
    worker = threading.Thread(target=lambda: box.setdefault("result", track_live(load_spec(case), settings,
                                                                                 out_dir=out)))
    worker.start()
    try:
        # pull the plug on the server (SIGKILL: no goodbye) at 2400 s of plant time, mid-case
        time.sleep(max(0.0, (origin - dt.datetime.now(dt.timezone.utc)).total_seconds() + 2400.0 / SPEED))
        kill(server)
        rows_at_kill = len((out / "tracking.csv").read_text().splitlines()) - 1 \
            if (out / "tracking.csv").exists() else 0
        time.sleep(1.0)  # rows fall due meanwhile: the restarted server has them in its history only
        server, again = start_replay(case, url, origin, log, "--linger", "60", speed=SPEED)
        assert again == origin
        worker.join(timeout=180)
        assert not worker.is_alive()
    finally:
        kill(server)
    result = box["result"]
    assert rows_at_kill < 600  # the kill happened mid-run
    assert result.connections >= 2 and result.backfilled > 0
    assert "history" in log.read_text()  # the restarted server back-filled its history
    _assert_same_trajectory(pd.read_csv(out / "tracking.csv"), offline)


def test_a_tracker_behind_the_plant_reads_the_history_back_with_a_bounded_queue(
        case: Path, offline: pd.DataFrame, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    # the tracker starts a quarter into the case: it reads the rows before from the history while the
    # rest come live. The subscription may queue 2 samples meanwhile (the 30-day soak's tracker, days
    # behind after a restart, held every one: +35 MiB); the ones past that are read from the history
    # too, a stretch of 10 rows at a time, and no row is lost or repeated
    monkeypatch.setattr(live_module, "QUEUE_LIMIT", 2)
    monkeypatch.setattr(live_module, "BACKFILL_ROWS", 10)
    caplog.set_level(logging.INFO, logger="trackingbox.online.live")
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    with replay_server(case, url, LEAD, tmp_path / "replay.log", "--linger", "60", speed=SPEED) as origin:
        time.sleep(max(0.0, (origin - dt.datetime.now(dt.timezone.utc)).total_seconds() + 1500.0 / SPEED))
        result = track_live(load_spec(case), LiveSettings(url, start=origin, stop_after=6000.0, idle_timeout=120.0,
                                                          poll=0.05, backoff=(0.2, 1.0)), out_dir=tmp_path / "live")
    assert "read from the history instead" in caplog.text  # the queue overflowed during the back-fill
    assert result.backfilled > 0
    _assert_same_trajectory(pd.read_csv(result.tracking.csv), offline)
    # every sample before the last row's, once (the run ends with its last row: a tag's sample at 6000 s
    # may be left unread)
    record = pd.read_csv(tmp_path / "live" / "live_measurements.csv")
    seconds = (pd.to_datetime(record["time"], format="ISO8601") - origin).dt.total_seconds()
    assert (seconds < 6000.0 - 1e-6).sum() == 2 * 600 and not record.duplicated(["tag", "time"]).any()


def test_anonymous_access_is_refused_when_a_user_is_required(case: Path, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    # the spec requires a user but none is given: refused before connecting, naming where to put them
    spec = load_spec(_with_live(case, tmp_path / "user", 'auth = "user"\n'))
    monkeypatch.delenv("TRACKINGBOX_OPCUA_USER", raising=False)
    with pytest.raises(LiveError, match="TRACKINGBOX_OPCUA_USER"):
        track_live(spec, LiveSettings("opc.tcp://127.0.0.1:1"), out_dir=tmp_path / "never")
    # the server takes users only: an anonymous session is refused (not retried), a wrong password too
    users = tmp_path / "users.txt"
    users.write_text("operator:s3cret\n")
    users.chmod(0o600)
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    with replay_server(case, url, LEAD, tmp_path / "replay.log", "--users", str(users), "--linger", "60",
                       speed=SPEED) as origin:
        t0 = time.monotonic()
        with pytest.raises(LiveError, match="refused the session"):
            track_live(load_spec(case), LiveSettings(url, start=origin, idle_timeout=30.0), out_dir=tmp_path / "a")
        assert time.monotonic() - t0 < 25  # refused at once, not retried until the idle time-out
        with pytest.raises(LiveError, match="refused the session"):
            track_live(spec, LiveSettings(url, credentials=Credentials("operator", "wrong"), start=origin,
                                          idle_timeout=30.0), out_dir=tmp_path / "b")
        ok = track_live(spec, LiveSettings(url, credentials=Credentials("operator", "s3cret"), start=origin,
                                           stop_after=600.0, idle_timeout=10.0), out_dir=tmp_path / "c")
    assert ok.tracking.steps >= 61


def test_signed_and_encrypted_connection_with_self_made_certificates(case: Path, offline: pd.DataFrame,
                                                                     tmp_path: Path) -> None:
    server_cert, server_key = make_certificate(tmp_path / "pki", "server", "urn:freeopcua:python:server")
    client_cert, client_key = make_certificate(tmp_path / "pki", "client", CLIENT_URI)
    spec = load_spec(_with_live(case, tmp_path / "secure", (
        'security = "Basic256Sha256"\nmode = "SignAndEncrypt"\n'
        f'certificate = "{client_cert}"\nprivate_key = "{client_key}"\nserver_certificate = "{server_cert}"\n')))
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    with replay_server(case, url, LEAD, tmp_path / "replay.log", "--certificate", str(server_cert),
                       "--private-key", str(server_key), "--linger", "60", speed=SPEED) as origin:
        # the server offers no unsecured endpoint: a plain client is refused
        with pytest.raises(LiveError):
            track_live(load_spec(case), LiveSettings(url, start=origin, idle_timeout=8.0), out_dir=tmp_path / "p")
        result = track_live(spec, LiveSettings(url, start=origin, stop_after=1000.0, idle_timeout=10.0),
                            out_dir=tmp_path / "s")
    live = pd.read_csv(result.tracking.csv)
    assert len(live) >= 101
    n = len(live)
    assert np.max(np.abs(live["parameter:k"] - offline["parameter:k"][:n])) <= TOLERANCE


def test_tracker_killed_and_resumed_loses_nothing(case: Path, offline: pd.DataFrame, tmp_path: Path) -> None:
    import subprocess
    import sys

    url = f"opc.tcp://127.0.0.1:{free_port()}"
    out = tmp_path / "live"
    with replay_server(case, url, LEAD, tmp_path / "replay.log", "--linger", "120", speed=SPEED) as origin:
        args = [sys.executable, "-m", "trackingbox.cli", "track", str(case), "--live", url, "--live-from",
                origin.isoformat(), "--out", str(out), "--stop-after", "6000", "--idle-timeout", "120", "--json"]
        first = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            # SIGKILL the tracker at 2400 s of plant time (or once it has rows, if it started late)
            time.sleep(max(0.0, (origin - dt.datetime.now(dt.timezone.utc)).total_seconds() + 2400.0 / SPEED))
            t0 = time.monotonic()
            while not (out / "checkpoint.json").exists():
                assert time.monotonic() - t0 < 120 and first.poll() is None, "the tracker wrote no checkpoint"
                time.sleep(0.05)
        finally:
            kill(first)
        rows_at_kill = len((out / "tracking.csv").read_text().splitlines()) - 1
        second = subprocess.run([*args, "--resume"], capture_output=True, text=True, timeout=300)
    assert second.returncode == 0, second.stderr[-3000:]
    assert first.returncode == -9 and rows_at_kill < 600
    doc = json.loads(second.stdout)
    assert doc["live"]["rows"] == 601
    _assert_same_trajectory(pd.read_csv(out / "tracking.csv"), offline)
    record = pd.read_csv(out / "live_measurements.csv")
    assert len(record) == 2 * 601 and not record.duplicated(["tag", "time"]).any()


def test_a_tag_with_bad_quality_holds_its_controller_and_resumes_as_offline(first_order_fmu: Path,
                                                                            tmp_path: Path) -> None:
    # TI is bad quality (NaN in the case) from 2500 s to 3000 s: live as offline, the controller holds
    # (mode 'hold') and resumes without a bump, on the same rows
    gap = make_case(first_order_fmu, tmp_path / "case", nan_span=(2500.0, 3000.0))
    expected = pd.read_csv(track(load_spec(gap), out_dir=tmp_path / "offline").csv)
    in_gap = (expected["time"] >= 2500.0) & (expected["time"] < 3000.0)
    assert (expected.loc[in_gap, "mode:TI"] == "hold").all() and expected["measured:TI"][in_gap].isna().all()
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    with replay_server(gap, url, LEAD, tmp_path / "replay.log", "--linger", "60", speed=SPEED) as origin:
        result = track_live(load_spec(gap), LiveSettings(url, start=origin, stop_after=6000.0, idle_timeout=120.0,
                                                         poll=0.05, backoff=(0.2, 1.0)), out_dir=tmp_path / "live")
    live = pd.read_csv(result.tracking.csv)
    _assert_same_trajectory(live, expected)
    k = live.loc[in_gap, "parameter:k"].to_numpy()
    assert np.all(k == k[0])  # frozen while the tag is bad
