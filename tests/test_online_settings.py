"""The online mode's settings, credentials and published results (no plant server needed)."""
from __future__ import annotations

import asyncio
import datetime as dt
import math
from pathlib import Path

import pytest

from _fixtures_online import free_port
from _fixtures_tracking import spec_text
from trackingbox.errors import LiveError, SpecError
from trackingbox.online.live import LiveSettings, _Inbox, _Publisher, _Record, _Tracker
from trackingbox.online.opcua import Credentials, check_endpoint, read_credentials, read_users
from trackingbox.spec import loads_spec

BASE = spec_text(0.003)


def _spec(live: str):
    return loads_spec(BASE + "\n[live]\n" + live, "/plant/spec.toml", check_files=False)


def test_live_section_defaults_and_node_ids() -> None:
    spec = _spec('nodes = { TI = "ns=3;s=Plant.TI" }\nstale_after = 30\n')
    assert spec.live.node("TI") == "ns=3;s=Plant.TI"
    assert spec.live.node("FI") == "ns=2;s=FI"  # the replay server's layout
    assert spec.live.stale_after == 30.0 and spec.live.auth == "anonymous" and spec.live.security is None
    secure = _spec('security = "Basic256Sha256"\ncertificate = "pki/client.der"\nprivate_key = "pki/client.pem"\n')
    assert secure.live.certificate == Path("/plant/pki/client.der")  # relative to the spec


def test_live_section_problems_are_reported_together() -> None:
    with pytest.raises(SpecError) as err:
        _spec('password = "hunter2"\nauth = "usr"\nnodes = { TX = "ns=2;s=TX" }\nsecurity = "Basic256Sha256"\n'
              'stale_after = -1\npublish = "http://x"\nbogus = 1\n')
    text = str(err.value)
    for expected in ("credentials are never kept in the spec", "'auth' in [live]", "unknown tag 'TX' in [live.nodes]",
                     "needs 'certificate' and 'private_key'", "'stale_after' in [live] must be > 0",
                     "'publish' in [live] must be an opc.tcp://", "unknown key 'bogus' in [live]"):
        assert expected in text
    assert "hunter2" not in text  # a secret is never echoed


def test_credentials_from_a_private_file_or_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("TRACKINGBOX_OPCUA_USER", "TRACKINGBOX_OPCUA_PASSWORD", "TRACKINGBOX_OPCUA_CREDENTIALS"):
        monkeypatch.delenv(name, raising=False)
    assert read_credentials() is None
    monkeypatch.setenv("TRACKINGBOX_OPCUA_USER", "op")
    with pytest.raises(LiveError, match="set both"):
        read_credentials()
    monkeypatch.setenv("TRACKINGBOX_OPCUA_PASSWORD", "pw")
    assert read_credentials() == Credentials("op", "pw")
    assert "pw" not in repr(read_credentials())
    f = tmp_path / "cred"
    f.write_text("# plant login\nuser = alice\npassword = p=w\n")
    f.chmod(0o644)
    with pytest.raises(LiveError, match="readable by others"):
        read_credentials(f)
    f.chmod(0o600)
    assert read_credentials(f) == Credentials("alice", "p=w")  # a file wins over the environment
    f.write_text("user = alice\n")
    with pytest.raises(LiveError, match="needs both"):
        read_credentials(f)
    users = tmp_path / "users"
    users.write_text("a:1\nb:2\n")
    users.chmod(0o600)
    assert read_users(users) == {"a": "1", "b": "2"}


@pytest.mark.parametrize("url", ["opc.tcp://h", "http://h:4840", "opc.tcp://h:0", "opc.tcp://h:99999", "h:4840"])
def test_bad_endpoints_are_refused(url: str) -> None:
    with pytest.raises(SpecError, match="not an OPC UA endpoint"):
        check_endpoint(url)
    with pytest.raises(SpecError):
        LiveSettings(url)


def test_record_keeps_each_sample_once_in_time_order(tmp_path: Path) -> None:
    rec = _Record(tmp_path / "r.csv", ["A", "B"], resume=False)
    t0 = dt.datetime(2026, 1, 1, tzinfo=dt.timezone.utc)
    assert rec.add("A", t0, 1.0) and rec.add("A", t0 + dt.timedelta(seconds=10), 2.0)
    assert not rec.add("A", t0 + dt.timedelta(seconds=10), 2.0)  # the same sample from history and subscription
    assert not rec.add("A", t0, 1.0)
    assert rec.add("B", t0, None)  # bad quality: advances the tag's clock, kept as a historian keeps it
    assert rec.count == 2 and rec.bad["B"] and rec.good["B"] is None
    rec.close()
    lines = (tmp_path / "r.csv").read_text().splitlines()
    assert lines == ["tag,time,value", "A,2026-01-01T00:00:00+00:00,1.0", "A,2026-01-01T00:00:10+00:00,2.0",
                     "B,2026-01-01T00:00:00+00:00,"]  # (an empty value: bad quality, as in a historian's export)
    again = _Record(tmp_path / "r.csv", ["A", "B"], resume=True)  # a resumed run continues the record
    assert again.count == 2 and again.last["A"] == t0 + dt.timedelta(seconds=10)
    assert again.last["B"] == t0 and again.bad["B"] and again.good["B"] is None
    again.close()


def test_the_subscriptions_queue_is_bounded_while_the_history_is_read_and_loses_nothing() -> None:
    from asyncua import ua

    t0 = dt.datetime(2026, 1, 1, tzinfo=dt.timezone.utc)
    # two tags, each at its own times (A every 10 s, B every 7 s), as a historian sends them
    stream = sorted([("A", t0 + dt.timedelta(seconds=10 * i)) for i in range(300)]
                    + [("B", t0 + dt.timedelta(seconds=7 * i + 3)) for i in range(400)], key=lambda x: x[1])

    def dv(stamp: dt.datetime) -> ua.DataValue:
        return ua.DataValue(ua.Variant(1.0, ua.VariantType.Double), SourceTimestamp=stamp)

    live = _Inbox(50)  # live (no back-fill under way): every sample is held until taken
    for tag, stamp in stream[:120]:
        live.add(tag, dv(stamp))
    assert len(live) == 120 and live.dropped == 0 and live.floor is None
    assert [s.SourceTimestamp for _, s in live.take()] == [s for _, s in stream[:120]] and len(live) == 0

    inbox = _Inbox(50)
    inbox.spill = True  # a back-fill under way: at most 50 held, whatever the length of the stream
    held = []
    for tag, stamp in stream:
        inbox.add(tag, dv(stamp))
        held.append(len(inbox))
        if not len(inbox):  # just emptied: the history is to be read up to the newest sample dropped
            assert inbox.edge(2) == stamp
    assert max(held) == 50 and inbox.dropped > 500
    # what the back-fill reads from the history (each tag up to the edge) and what the queue holds
    # together are every sample, each once
    edge = inbox.edge(2)
    queued = [(tag, s.SourceTimestamp) for tag, s in inbox.take()]
    from_history = [(tag, stamp) for tag, stamp in stream if stamp <= edge]
    assert edge >= inbox.floor and set(from_history) | set(queued) == set(stream) and len(set(stream)) == 700
    assert queued == stream[-len(queued):]  # the queue holds the newest samples, in order
    with pytest.raises(ValueError, match="limit"):
        _Inbox(0)


class _WritingServer:
    """A server still writing its tags' samples (every 10 s of plant time): each history read sees the samples
    up to its present, and the present then moves on by *advance* s, the new samples going to the
    subscription's queue (*inbox*) as notifications would. A second tag's read of a stretch thus sees
    further than the first's, as on a loaded machine."""

    def __init__(self, tags: tuple[str, ...], stamps: list[dt.datetime], now: dt.datetime, advance: float,
                 inbox: _Inbox) -> None:
        self.stamps, self.now, self.advance, self.inbox = stamps, now, dt.timedelta(seconds=advance), inbox
        self.nodes = {tag: _HistoryNode(self) for tag in tags}

    def history(self, starttime: dt.datetime, endtime: dt.datetime | None) -> list:
        from asyncua import ua
        seen = [ua.DataValue(ua.Variant(float(i), ua.VariantType.Double), SourceTimestamp=s)
                for i, s in enumerate(self.stamps)
                if starttime <= s <= self.now and (endtime is None or s <= endtime)]
        self.tick()
        return seen

    def tick(self) -> None:
        from asyncua import ua
        before, self.now = self.now, self.now + self.advance
        for i, s in enumerate(self.stamps):
            if before < s <= self.now:
                for tag in self.nodes:
                    self.inbox.add(tag, ua.DataValue(ua.Variant(float(i), ua.VariantType.Double), SourceTimestamp=s))


class _HistoryNode:
    def __init__(self, server: _WritingServer) -> None:
        self.server = server

    async def read_raw_history(self, starttime: dt.datetime, endtime: dt.datetime | None) -> list:
        return self.server.history(starttime, endtime)


class _BackfillOnly:
    """The tracker's back-fill and sample intake alone (its rows are not run)."""
    _backfill = _Tracker._backfill
    take = _Tracker.take

    def __init__(self, record: _Record, start: dt.datetime) -> None:
        self.record, self.settings, self.origin, self.ts = record, LiveSettings("opc.tcp://x:4840", start=start), None, 10.0
        self.done, self.pending, self.arrived = False, [], {}
        self.samples_seen = self.backfilled = 0
        self.last_new = self.last_new_wall = 0.0

    def write_status(self, force: bool = False) -> None:
        pass

    def advance(self) -> int:
        return 0


def test_back_fill_of_a_history_still_being_written_loses_no_sample(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    # two tags every 10 s; the server's present is 45 s into the data when the back-fill starts and moves on
    # 35 s with every history read, so the second tag's read of a stretch sees further than the first's
    # (the online test's loaded-machine failure: FI's samples 2760-2800 s never read, rows held)
    import trackingbox.online.live as live_module
    monkeypatch.setattr(live_module, "BACKFILL_ROWS", 10)
    t0 = dt.datetime(2026, 1, 1, tzinfo=dt.timezone.utc)
    stamps = [t0 + dt.timedelta(seconds=10 * i) for i in range(60)]
    inbox = _Inbox(2)
    inbox.spill = True
    server = _WritingServer(("FI", "TI"), stamps, t0 + dt.timedelta(seconds=45), 35.0, inbox)
    inbox.floor = t0 + dt.timedelta(seconds=40)  # the subscription's first samples were dropped already
    tracker = _BackfillOnly(_Record(tmp_path / "record.csv", ["FI", "TI"], resume=False), t0)
    covered = asyncio.run(tracker._backfill(server.nodes, inbox))
    while server.now <= stamps[-1] + dt.timedelta(seconds=35) or len(inbox):  # the session's loop, to the end
        if covered != inbox.dropped:  # the queue overflowed: its samples from the history
            covered = asyncio.run(tracker._backfill(server.nodes, inbox))
            continue
        for tag, value in inbox.take():
            tracker.take(tag, value)
        server.tick()
    tracker.record.close()
    lines = (tmp_path / "record.csv").read_text().splitlines()[1:]
    for tag in ("FI", "TI"):
        got = [dt.datetime.fromisoformat(line.split(",")[1]) for line in lines if line.startswith(tag + ",")]
        assert got == stamps, f"{tag}: {len(got)} of {len(stamps)} samples, missing " \
                              f"{sorted(set(stamps) - set(got))[:5]}"


def test_published_results_are_readable_over_opc_ua() -> None:
    from asyncua import Client

    url = f"opc.tcp://127.0.0.1:{free_port()}"
    origin = dt.datetime(2026, 1, 1, tzinfo=dt.timezone.utc)

    async def run() -> tuple[float, str, dt.datetime, float]:
        pub = _Publisher(url, ["time", "parameter:k", "tracked:TI", "mode:TI"])
        await pub.start()
        try:
            await pub.publish(origin, [{"time": "0.0", "parameter:k": "0.003", "tracked:TI": "38.5",
                                        "mode:TI": "start-up"},
                                       {"time": "10.0", "parameter:k": "0.0031", "tracked:TI": "",
                                        "mode:TI": "tracking"}])
            async with Client(url) as client:
                k = await client.get_node("ns=2;s=parameter:k").read_data_value()
                mode = await client.get_node("ns=2;s=mode:TI").read_value()
                ti = await client.get_node("ns=2;s=tracked:TI").read_value()
                return k.Value.Value, mode, k.SourceTimestamp, ti
        finally:
            await pub.stop()

    k, mode, stamp, ti = asyncio.run(run())
    assert k == 0.0031 and mode == "tracking" and math.isnan(ti)
    assert stamp.replace(tzinfo=dt.timezone.utc) == origin + dt.timedelta(seconds=10)


def test_rows_wait_for_every_tag_but_a_stale_one(tmp_path: Path) -> None:
    from trackingbox.online.live import _Tracker

    spec = loads_spec(BASE + "\n[live]\nstale_after = 30\n", tmp_path / "spec.toml", check_files=False)
    tracker = _Tracker(spec, LiveSettings("opc.tcp://127.0.0.1:4840"), tmp_path / "out", resume=False, progress=None)
    t0 = dt.datetime(2026, 1, 1, tzinfo=dt.timezone.utc)

    def sample(tag: str, seconds: float) -> None:
        tracker.record.add(tag, t0 + dt.timedelta(seconds=seconds), 1.0)

    for s in range(0, 71, 10):
        sample("FI", s)
    assert tracker._rows_ready() == 0  # TI has said nothing yet: nothing can run
    for s in range(0, 51, 10):
        sample("TI", s)
    # sample time 10 s: rows 0..4 need t = 10..50, which both tags have reached; row 5 needs TI at 60
    # (the plant clock is 70 s: TI silent for 20 s, not stale)
    assert tracker._rows_ready() == 5 and not tracker.stale
    for s in range(80, 121, 10):
        sample("FI", s)  # the plant clock is 120 s: TI silent for 70 s > stale_after = 30 s
    import time as _time

    tracker.arrived["TI"] = _time.monotonic()  # ... but TI spoke a moment ago (a burst of FI's came first)
    assert tracker._rows_ready() == 5 and not tracker.stale  # not stale yet: the rows wait for it
    tracker.arrived["TI"] = _time.monotonic() - 60.0  # silent for a minute of wall time too
    assert tracker._rows_ready() == 12 and tracker.stale == {"TI"} and tracker.stale_events == 1
    sample("TI", 130)
    sample("FI", 130)
    assert tracker._rows_ready() == 13 and not tracker.stale  # TI is back
    tracker.record.close()

    # the run's end (--stop-after 200): FI has come to it, TI's sample of the last row not yet (a row
    # read from the server's history while it was written): the last rows wait for TI a moment ...
    end = _Tracker(spec, LiveSettings("opc.tcp://127.0.0.1:4840", stop_after=200.0), tmp_path / "end",
                   resume=False, progress=None)
    tracker = end
    for s in range(0, 201, 10):
        sample("FI", s)
    for s in range(0, 191, 10):
        sample("TI", s)
    end.last_new = end.arrived["TI"] = end.arrived["FI"] = _time.monotonic()
    assert end._rows_ready() == 19  # rows 0..18 (t_k+1 <= 190 s)
    sample("TI", 200)
    assert end._rows_ready() == 21  # ... every tag at the end: the rows to it, the last one (200 s) too
    end.record.close()
    # ... and a tag quiet at the end (nothing more will come) does not hold the last rows up for long
    quiet = _Tracker(spec, LiveSettings("opc.tcp://127.0.0.1:4840", stop_after=200.0), tmp_path / "quiet",
                     resume=False, progress=None)
    tracker = quiet
    for s in range(0, 201, 10):
        sample("FI", s)
    for s in range(0, 191, 10):
        sample("TI", s)
    quiet.last_new = quiet.arrived["TI"] = quiet.arrived["FI"] = _time.monotonic()
    assert quiet._rows_ready() == 19
    quiet.last_new = _time.monotonic() - 60.0  # nothing new for a minute of wall time
    assert quiet._rows_ready() == 21
    quiet.record.close()
