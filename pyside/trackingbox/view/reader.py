"""An output folder read while the tracker writes it: complete rows only, never a lock, never a wait.

The tracker appends whole lines to ``tracking.csv`` and replaces its JSON files
atomically (``live_status.json``, ``checkpoint.json``, ``live.json``). The
reader keeps an offset into the CSV and takes only the complete lines after it
(a partly written last line is left for the next look); a file that was
replaced, truncated (``--resume`` cuts the CSV back to its checkpoint) or
rewritten under the offset is read again from its start, and the page is sent
a fresh snapshot. A JSON file that cannot be parsed (an older or foreign file)
keeps the last good reading.

For the charts it keeps at most :data:`MAX_POINTS` rows per run: row ``i`` is
kept while ``i % stride == 0``, and the stride doubles when the kept rows
exceed the limit (the page applies the same rule to the rows it is sent, so
both hold the same points). Everything else (the last row, the loop states
and their changes, each tag's last valid sample) is taken from every row.

Band columns: a parameter ``NAME``'s uncertainty band is read from the first
pair of columns present among ``lo:NAME``/``hi:NAME``, ``lower:NAME``/
``upper:NAME``, ``band_lo:NAME``/``band_hi:NAME``,
``parameter_lo:NAME``/``parameter_hi:NAME``, ``parameter:NAME_lo``/
``parameter:NAME_hi`` and ``NAME_lo``/``NAME_hi`` (:func:`band_columns`).
"""
from __future__ import annotations

import csv
import json
import logging
import math
import os
import time
from collections import deque
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import TrackingError
from ..spec.parse import load_spec

log = logging.getLogger(__name__)

TRACKING = "tracking.csv"
STATUS = "live_status.json"
LIVE = "live.json"
CHECKPOINT = "checkpoint.json"
#: Chart rows kept per run (beyond it the stride doubles).
MAX_POINTS = 8000
#: Bytes read from the CSV in one look (a long file is caught up with in several).
READ_CHUNK = 4 << 20
#: Entries kept in the event log.
MAX_EVENTS = 400
#: Hold intervals kept per loop.
MAX_HOLDS = 300
#: Seconds between two looks at checkpoint.json's events (it may be large).
CHECKPOINT_EVERY = 5.0

_BAND_FORMS = (("lo:{}", "hi:{}"), ("lower:{}", "upper:{}"), ("band_lo:{}", "band_hi:{}"),
               ("parameter_lo:{}", "parameter_hi:{}"), ("parameter:{}_lo", "parameter:{}_hi"),
               ("{}_lo", "{}_hi"))


def band_columns(columns: Sequence[str], name: str) -> tuple[str, str] | None:
    """The (lower, upper) band columns of parameter *name* in *columns*, by the module's rule, or None.

    >>> band_columns(["time", "parameter:k", "lower:k", "upper:k"], "k")
    ('lower:k', 'upper:k')
    >>> band_columns(["time", "parameter:k", "k_lo"], "k") is None
    True
    """
    have = set(columns)
    for lo, hi in _BAND_FORMS:
        if lo.format(name) in have and hi.format(name) in have:
            return lo.format(name), hi.format(name)
    return None


def _float(text: str) -> float:
    try:
        return float(text) if text else math.nan
    except ValueError:
        return math.nan


def _json_number(x: float) -> float | None:
    return x if math.isfinite(x) else None


class Tail:
    """The complete lines appended to a file since the last look.

    ``read()`` returns ``(restarted, lines)``: *restarted* when the file was
    replaced, shortened or rewritten below the offset (the 64 bytes before it
    changed), in which case *lines* are read from its start again.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.offset = 0
        self.ident: tuple[int, int] | None = None
        self.sig = b""
        #: bytes still to read after the last look
        self.behind = 0

    def read(self, limit: int = READ_CHUNK) -> tuple[bool, list[bytes]]:
        try:
            fh = open(self.path, "rb")
        except FileNotFoundError:
            restarted = self.offset > 0
            self.offset, self.ident, self.sig, self.behind = 0, None, b"", 0
            return restarted, []
        with fh:
            st = os.fstat(fh.fileno())
            ident = (st.st_dev, st.st_ino)
            restarted = False
            if self.ident is not None and (ident != self.ident or st.st_size < self.offset
                                           or not self._continues(fh)):
                restarted = True
                self.offset, self.sig = 0, b""
            self.ident = ident
            size = st.st_size
            if size <= self.offset:
                self.behind = 0
                return restarted, []
            fh.seek(self.offset)
            data = fh.read(min(limit, size - self.offset))
            end = data.rfind(b"\n") + 1
            while end == 0 and self.offset + len(data) < size:  # one line longer than the chunk
                more = fh.read(limit)
                if not more:
                    break
                data += more
                end = data.rfind(b"\n") + 1
        if end == 0:  # a partly written line: the next look takes it whole
            self.behind = 0
            return restarted, []
        self.offset += end
        self.sig = data[max(0, end - 64):end]
        self.behind = max(0, size - self.offset)
        return restarted, data[:end].splitlines()

    def _continues(self, fh: Any) -> bool:
        if not self.sig:
            return True
        fh.seek(self.offset - len(self.sig))
        return fh.read(len(self.sig)) == self.sig


def _read_json(path: Path) -> tuple[int, Any] | None:
    """``(mtime_ns, document)`` of a JSON file, or None where it is absent or not JSON."""
    try:
        st = path.stat()
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    return st.st_mtime_ns, doc


def _epoch(iso: Any) -> float | None:
    try:
        return datetime.fromisoformat(str(iso)).timestamp()
    except (TypeError, ValueError):
        return None


class RunReader:
    """The state of one output folder for the page; :meth:`poll` takes what changed since the last call."""

    def __init__(self, out: str | os.PathLike[str], spec: str | os.PathLike[str] | None = None) -> None:
        self.out = Path(out)
        self.spec_path = Path(spec) if spec is not None else None
        self.spec: Any = None
        self.csv = Tail(self.out / TRACKING)
        self.events: deque[dict[str, Any]] = deque(maxlen=MAX_EVENTS)
        self.event_seq = 0
        self.status: dict[str, Any] | None = None
        self._status_mtime: int | None = None
        self._ckpt_mtime: int | None = None
        self._ckpt_looked = -math.inf
        self._runtime_seen: set[tuple[Any, ...]] = set()
        self.origin: float | None = None
        self.truth: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._load_spec()
        self._reset_rows()

    # ------------------------------------------------------------------ set-up

    def _load_spec(self) -> None:
        """The spec (given, or the one checkpoint.json names) and the bench's truth.json beside it."""
        path = self.spec_path
        if path is None:
            found = _read_json(self.out / CHECKPOINT)
            if found is not None and isinstance(found[1], dict) and found[1].get("spec"):
                path = Path(found[1]["spec"])
        if path is None or not path.is_file():
            return
        try:
            self.spec = load_spec(path, check_files=False)
        except TrackingError as exc:
            log.warning("the view shows the run without its spec (%s)", exc)
            return
        self.spec_path = path
        truth = path.parent / "truth.json"
        found = _read_json(truth)
        if found is None or not isinstance(found[1], dict):
            return
        doc = found[1]
        for pair in self.spec.pairs:
            name = pair.parameter
            try:
                traj = (doc.get("trajectories") or {}).get(name)
                if traj is not None:
                    t, v = np.asarray(traj["time"], float), np.asarray(traj["value"], float)
                    if t.size and t.size == v.size:
                        self.truth[name] = (t, v)
                elif name in (doc.get("parameters") or {}):
                    self.truth[name] = (np.array([0.0]), np.array([float(doc["parameters"][name])]))
            except (KeyError, TypeError, ValueError):
                log.warning("truth.json beside %s has an unreadable entry for %r; shown without it", path, name)

    def _reset_rows(self) -> None:
        self.columns: list[str] | None = None
        self.series: list[str] = []
        self.n = 0
        self.stride = 1
        self.kept: list[list[Any]] = []
        self.last: dict[str, str] | None = None
        self.pairs: list[dict[str, Any]] = []
        self.loops: dict[str, dict[str, Any]] = {}
        self.holds: dict[str, deque[list[Any]]] = {}
        self.last_valid: dict[str, float] = {}
        self._new_rows: list[list[Any]] = []
        self._index: dict[str, int] = {}

    def _set_header(self, header: list[str]) -> None:
        self.columns = header
        spec = self.spec
        pairs = []
        if spec is not None and [f"mode:{p.variable}" for p in spec.pairs] == [c for c in header
                                                                                 if c.startswith("mode:")]:
            bounds = {p.name: (p.min, p.max) for p in spec.parameters}
            for p in spec.pairs:
                lo, hi = bounds.get(p.parameter, (math.nan, math.nan))
                pairs.append({"tag": p.variable, "parameter": p.parameter, "lower": lo, "upper": hi})
        else:  # without the spec: the CSV's own order pairs mode:TAG with parameter:NAME
            tags = [c[5:] for c in header if c.startswith("mode:")]
            params = [c[10:] for c in header if c.startswith("parameter:")]
            pairs = [{"tag": t, "parameter": n, "lower": math.nan, "upper": math.nan} for t, n in zip(tags, params)]
        for p in pairs:
            p["band"] = band_columns(header, p["parameter"])
            p["truth"] = f"truth:{p['parameter']}" if p["parameter"] in self.truth else None
        self.pairs = pairs
        self.series = [c for c in header if not c.startswith("mode:")] + \
            [p["truth"] for p in pairs if p["truth"]]
        self._index = {c: i for i, c in enumerate(header)}
        self.holds = {p["tag"]: deque(maxlen=MAX_HOLDS) for p in pairs}
        self.loops = {}

    # ------------------------------------------------------------------ meta

    def meta(self) -> dict[str, Any]:
        spec = self.spec
        return {
            "out": str(self.out.resolve()),
            "spec": str(self.spec_path) if self.spec_path else None,
            "sample_time": float(spec.sample_time) if spec is not None else None,
            "hold_until": float(spec.tracking.hold_until) if spec is not None else None,
            "inputs": list(spec.inputs) if spec is not None else [],
            "outputs": list(spec.outputs) if spec is not None else
            [c[9:] for c in (self.columns or []) if c.startswith("measured:")],
            "states": [s.tag for s in spec.states] if spec is not None else [],
            "origin": self.origin,
            "columns": self.columns or [],
            "series": self.series,
            "pairs": [{**p, "lower": _json_number(p["lower"]), "upper": _json_number(p["upper"])}
                      for p in self.pairs],
        }

    # ------------------------------------------------------------------ rows

    def _row(self, fields: list[str]) -> None:
        cols = self.columns
        assert cols is not None
        if len(fields) != len(cols):  # a malformed line (not the tracker's): shown nowhere
            return
        t = _float(fields[0])
        if not math.isfinite(t):
            return
        raw = dict(zip(cols, fields))
        i = self.n
        self.n += 1
        self.last = raw
        for c in cols:
            if c.startswith("measured:") and raw[c] and math.isfinite(_float(raw[c])):
                self.last_valid[c[9:]] = t
        for p in self.pairs:
            self._loop(p, raw, t)
        if i % self.stride == 0:
            values: list[Any] = [i]
            for c in self.series:
                if c.startswith("truth:"):
                    tt, vv = self.truth[c[6:]]
                    x = float(np.interp(t, tt, vv)) if tt.size > 1 else float(vv[0])
                else:
                    x = _float(raw[c])
                values.append(_json_number(x))
            self.kept.append(values)
            self._new_rows.append(values)
            if len(self.kept) > MAX_POINTS:
                self.stride *= 2
                self.kept = [r for r in self.kept if r[0] % self.stride == 0]
                self._new_rows = [r for r in self._new_rows if r[0] % self.stride == 0]

    def _loop(self, p: dict[str, Any], raw: dict[str, str], t: float) -> None:
        """The loop's state at this row (tracking, held, saturated) and why; its changes go to the log."""
        tag, name = p["tag"], p["parameter"]
        mode = raw.get(f"mode:{tag}", "")
        value = _float(raw.get(f"parameter:{name}", ""))
        lo, hi = p["lower"], p["upper"]
        if mode == "hold":
            state, why = "held", self._hold_reason(tag, raw, t)
        elif mode == "auto":
            span = hi - lo if math.isfinite(lo) and math.isfinite(hi) else math.nan
            if math.isfinite(span) and value <= lo + 1e-6 * span:
                state, why = "saturated", f"at its lower bound {lo:g}"
            elif math.isfinite(span) and value >= hi - 1e-6 * span:
                state, why = "saturated", f"at its upper bound {hi:g}"
            else:
                state, why = "tracking", ""
        else:
            state, why = mode or "unknown", ""
        before = self.loops.get(tag)
        if before is None or before["state"] != state or before["why"] != why:
            self.loops[tag] = {"state": state, "why": why, "since": t}
            holds = self.holds[tag]
            if holds and holds[-1][1] is None:  # a hold ends here (or goes on for another reason)
                holds[-1][1] = t
            if state == "held":
                holds.append([t, None, why])
            if before is not None or state != "tracking":
                text = f"{tag} → {name}: {state}" + (f" ({why})" if why else "")
                self.event("loop", text, plant=t)

    def _hold_reason(self, tag: str, raw: dict[str, str], t: float) -> str:
        spec = self.spec
        if spec is not None and t < float(spec.tracking.hold_until) - 1e-9:
            return f"start-up hold until {float(spec.tracking.hold_until):g} s"
        if not math.isfinite(_float(raw.get(f"measured:{tag}", ""))):
            st = (self.status or {}).get("tags", {}).get(tag) or {}
            if st.get("stale"):
                return "no sample from the plant: stale"
            return "no measured value: bad quality or a gap"
        if not math.isfinite(_float(raw.get(f"tracked:{tag}", ""))):
            return "the twin's variable is missing"
        rule = spec.data.stoppage if spec is not None else None
        if rule is not None:
            v = _float(raw.get(f"measured:{rule.tag}", ""))
            if math.isfinite(v) and v < rule.below:
                return f"flow stoppage ({rule.tag} < {rule.below:g})"
            return f"a stoppage's {rule.settle:g} s settling, an input missing or a solver recovery"
        return "an input missing or a solver recovery"

    # ------------------------------------------------------------------ events

    def event(self, kind: str, text: str, *, plant: float | None = None, wall: float | None = None) -> None:
        self.event_seq += 1
        self.events.append({"seq": self.event_seq, "kind": kind, "text": text, "plant": plant,
                            "wall": time.time() if wall is None else wall})

    def _status_changes(self, old: dict[str, Any] | None, new: dict[str, Any]) -> None:
        """Log entries for what changed between two readings of the status (counters: a state the
        tracker passed through between two looks, a short loss say, is not missed)."""
        old = old or {}
        wall = new.get("written")
        url = new.get("url")
        lost = int(new.get("lost") or 0) - int(old.get("lost") or 0)
        if lost > 0 or (new.get("link") == "disconnected" and old.get("link") not in (None, "disconnected")
                        and "lost" not in new):
            times = f" ({lost} times)" if lost > 1 else ""
            self.event("link-lost", f"lost {url}{times}: {new.get('link_error') or 'no reason given'}; "
                       "reconnecting", wall=wall)
        n_old, n_new = int(old.get("connections") or 0), int(new.get("connections") or 0)
        if n_new > n_old:
            self.event("link-up", f"connected to {url}" if n_new <= 1 else
                       f"reconnected to {url} (connection {n_new})", wall=wall)
        if new.get("link") == "stopped" and old.get("link") != "stopped":
            self.event("link-stopped", "the tracker stopped", wall=wall)
        gained = int(new.get("backfilled") or 0) - int(old.get("backfilled") or 0)
        if old and gained > 0:
            self.event("backfill", f"read back {gained} samples from the server's history", wall=wall)
        old_tags, new_tags = old.get("tags") or {}, new.get("tags") or {}
        for tag, st in new_tags.items():
            was = (old_tags.get(tag) or {}).get("stale", False)
            if st.get("stale") and not was:
                self.event("stale", f"{tag} stale: nothing for {st.get('behind') or 0:g} s of plant time", wall=wall)
            elif was and not st.get("stale"):
                self.event("stale", f"{tag} back", wall=wall)

    def _runtime_events(self) -> None:
        now = time.monotonic()
        if now - self._ckpt_looked < CHECKPOINT_EVERY:
            return
        self._ckpt_looked = now
        path = self.out / CHECKPOINT
        try:
            mtime = path.stat().st_mtime_ns
        except OSError:
            return
        if mtime == self._ckpt_mtime:
            return
        found = _read_json(path)
        if found is None:
            return
        self._ckpt_mtime = found[0]
        try:
            events = found[1]["loop"]["events"]
        except (KeyError, TypeError):
            return
        for e in events if isinstance(events, list) else []:
            key = tuple(e) if isinstance(e, list) else (str(e),)
            if key in self._runtime_seen or len(e) != 3:
                continue
            self._runtime_seen.add(key)
            self.event(f"runtime:{e[1]}", str(e[2]), plant=float(e[0]))

    # ------------------------------------------------------------------ looking

    def poll(self) -> tuple[bool, bool]:
        """Take what changed; ``(restarted, changed)``. Restarted: send a new snapshot."""
        restarted = False
        if self.origin is None:
            found = _read_json(self.out / LIVE)
            if found is not None and isinstance(found[1], dict):
                self.origin = _epoch(found[1].get("origin"))
                restarted = self.origin is not None
        changed = restarted
        try:
            mtime = (self.out / STATUS).stat().st_mtime_ns
        except OSError:
            mtime = None
        if mtime is not None and mtime != self._status_mtime:
            found = _read_json(self.out / STATUS)
            if found is not None and isinstance(found[1], dict):
                self._status_mtime = found[0]
                self._status_changes(self.status, found[1])
                self.status = found[1]
                changed = True
        again, lines = self.csv.read()
        if again:
            self._reset_rows()
            self.event("file", f"{TRACKING} was started again (a new run or a resume): read from its start")
            restarted = changed = True
        if lines:
            changed = True
            rows = csv.reader(line.decode("utf-8", errors="replace") for line in lines)
            for fields in rows:
                if self.columns is None:
                    if fields and fields[0] == "time":
                        self._set_header(fields)
                        restarted = True
                    continue
                self._row(fields)
        self._runtime_events()
        return restarted, changed

    @property
    def behind(self) -> int:
        """Bytes of the CSV not read yet (a long file is caught up with over several looks)."""
        return self.csv.behind

    # ------------------------------------------------------------------ messages

    def health(self) -> dict[str, Any]:
        st = self.status or {}
        now = time.time()
        pid = st.get("pid")
        alive = None
        if st:
            alive = st.get("link") != "stopped" and _alive(pid)
        last_wall = st.get("last_sample_wall")
        connections = int(st.get("connections") or 0)
        return {"now": now, "rows": self.n, "live": bool(st), "tracker": alive, "link": st.get("link"),
                "link_since": st.get("link_since"), "link_error": st.get("link_error"),
                "connections": connections, "reconnects": max(0, connections - 1),
                "backfilled": st.get("backfilled"), "samples": st.get("samples"),
                "stale_events": st.get("stale_events"),
                "status_age": now - st["written"] if st.get("written") else None,
                "last_sample_age": now - last_wall if last_wall else None,
                "plant_clock": _epoch(st.get("plant_clock")) if st.get("plant_clock") else None,
                "last_time": _float(self.last["time"]) if self.last else None}

    def tags(self) -> list[dict[str, Any]]:
        """Every tag: its newest sample, how far it is behind, its quality, stale or not."""
        st = self.status or {}
        out = []
        if st.get("tags"):
            for tag, s in st["tags"].items():
                out.append({"tag": tag, "last": _epoch(s.get("last")), "behind": s.get("behind"),
                            "quality": s.get("quality"), "stale": bool(s.get("stale"))})
            return out
        end = _float(self.last["time"]) if self.last else math.nan
        for tag in (self.spec.outputs if self.spec is not None else
                    [c[9:] for c in (self.columns or []) if c.startswith("measured:")]):
            t = self.last_valid.get(tag)
            out.append({"tag": tag, "last": None if t is None else t, "behind": None if t is None else end - t,
                        "quality": None, "stale": None})
        return out

    def snapshot(self) -> dict[str, Any]:
        """Everything the page shows (a new page, or after a restart of the file)."""
        return {"type": "snapshot", "meta": self.meta(), "n": self.n, "stride": self.stride, "rows": self.kept,
                "last": self.last, "loops": self.loops, "holds": {k: list(v) for k, v in self.holds.items()},
                "events": list(self.events), "health": self.health(), "tags": self.tags()}

    def update(self, since_event: int) -> dict[str, Any]:
        """What changed: the kept rows since the last update (the page drops those it has), the rest whole."""
        rows, self._new_rows = self._new_rows, []
        return {"type": "update", "n": self.n, "stride": self.stride, "rows": rows, "last": self.last,
                "loops": self.loops, "holds": {k: list(v) for k, v in self.holds.items()},
                "events": [e for e in self.events if e["seq"] > since_event], "health": self.health(),
                "tags": self.tags()}


def _alive(pid: Any) -> bool | None:
    if not isinstance(pid, int):
        return None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return None  # another user's process, or not ours to ask: unknown
    return True
