#!/usr/bin/env python3
"""The soak of the online mode (``scripts/soak_live``; what it checks is in that script's header).

Stages, each timed (wall and the CPU of the processes it ran):

1. the case: ``trackingbox bench evaporator --days D --seed S``, paired (``trackingbox pair``,
   then the evaporator's slow closed loops as the demo sets them), with ``--bursts`` bad-quality
   bursts written into its historian export (a tag's records in a 10-60 min span made empty:
   bad quality), so that the offline and the live run see the same data;
2. the offline run: ``trackingbox track`` on that case (the reference);
3. the live run: ``trackingbox replay --serve`` at ``--speed`` and ``trackingbox track --live``
   (supervision off, so the process sampled is the one tracking), the server SIGKILLed at
   ``--kills`` random moments of plant time and restarted with the same origin after 0.5-5 s;
   the tracker's RSS, peak RSS (VmHWM), open file descriptors and threads sampled every 0.5 s (all of
   them in OUT/memory.csv, the largest per plant day in OUT/soak.json).
"""
from __future__ import annotations

import argparse
import json
import os
import random
import re
import resource
import signal
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

TB = [sys.executable, "-m", "trackingbox.cli"]
DAY = 86400.0


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def stage(name: str, cmd: list[str], log: Path, env: dict[str, str] | None = None) -> tuple[float, float]:
    """Run *cmd* to the end (its output in *log*); (wall s, CPU s). Exit 2 where it fails."""
    c0, w0 = children_cpu(), time.perf_counter()
    with open(log, "ab") as fh:
        done = subprocess.run(cmd, stdout=fh, stderr=fh, env=env)
    wall, cpu = time.perf_counter() - w0, children_cpu() - c0
    if done.returncode != 0:
        print(f"soak_live: {name} failed (exit {done.returncode}); see {log}", file=sys.stderr)
        sys.exit(2)
    print(f"  {name}: {wall:.1f} s wall, {cpu:.1f} s CPU", flush=True)
    return wall, cpu


def proc(pid: int) -> dict[str, float] | None:
    """RSS, peak RSS (MiB), threads, open fds and CPU seconds of process *pid*, or None once it is gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        fds = len(os.listdir(f"/proc/{pid}/fd"))
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    kv = dict(re.findall(r"^(\w+):\s+(\d+)", status, flags=re.M))
    if "VmRSS" not in kv:  # a zombie
        return None
    tick = os.sysconf("SC_CLK_TCK")
    return {"rss": int(kv["VmRSS"]) / 1024, "hwm": int(kv["VmHWM"]) / 1024, "threads": int(kv["Threads"]),
            "fds": fds, "cpu": (int(fields[11]) + int(fields[12])) / tick}


def start_replay(case: Path, url: str, origin: str, speed: float, log: Path) -> tuple[subprocess.Popen, str]:
    start = log.stat().st_size if log.exists() else 0
    fh = open(log, "ab")
    p = subprocess.Popen([*TB, "-v", "replay", str(case), "--serve", url, "--speed", str(speed), "--origin", origin],
                         stdout=fh, stderr=fh, env={**os.environ, "TRACKINGBOX_SUPERVISE": "0"})
    fh.close()
    t0 = time.monotonic()
    while True:
        with open(log, "rb") as f:
            f.seek(start)
            text = f.read().decode(errors="replace")
        m = re.search(r"serving .* origin (\S+)\)", text)
        if m:
            return p, m.group(1)
        if p.poll() is not None or time.monotonic() - t0 > 900:
            print(f"soak_live: the replay server did not start:\n{text[-2000:]}", file=sys.stderr)
            p.kill()
            sys.exit(2)
        time.sleep(0.1)


def kill(p: subprocess.Popen) -> None:
    if p.poll() is None:
        os.kill(p.pid, signal.SIGKILL)
    p.wait()


def add_bursts(case: Path, n: int, rng: random.Random, tags: list[str]) -> list[dict[str, object]]:
    """Make *n* bad-quality bursts in the case's historian export; what was done."""
    path = case / "measurements.csv"
    table = pd.read_csv(path, dtype=str, keep_default_na=False)
    t = pd.to_datetime(table["time"], format="ISO8601", utc=True)
    seconds = (t - t.min()).dt.total_seconds().to_numpy()
    end = float(seconds.max())
    bursts = []
    for i in range(n):
        tag = tags[i % len(tags)]
        a = rng.uniform(0.1, 0.9) * end
        b = a + rng.uniform(600.0, 3600.0)
        hit = (table["tag"].to_numpy() == tag) & (seconds >= a) & (seconds < b)
        table.loc[hit, "value"] = ""
        bursts.append({"tag": tag, "start": round(a, 1), "end": round(b, 1), "records": int(hit.sum())})
    table.to_csv(path, index=False)
    return bursts


def _arguments() -> argparse.Namespace:
    """The command line, checked."""
    ap = argparse.ArgumentParser(prog="soak_live")
    ap.add_argument("--days", type=float, default=30.0)
    ap.add_argument("--speed", type=float, default=2000.0, help="plant seconds per wall second (default 2000)")
    ap.add_argument("--kills", type=int, default=4, help="server kills at random moments (default 4)")
    ap.add_argument("--bursts", type=int, default=3, help="bad-quality bursts in the data (default 3)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="work folder (default runs/soak-live-<days>d)")
    ap.add_argument("--memory-slack", type=float, default=32.0, metavar="MIB",
                    help="peak RSS after the last day at most this above the peak after the first (default 32)")
    ap.add_argument("--view", action="store_true", help="serve the live view beside the tracker (track --view)")
    ap.add_argument("--screenshot", type=Path, metavar="PNG", help="a picture of the view (implies --view)")
    ap.add_argument("--screenshot-at", type=float, default=None, metavar="DAYS",
                    help="plant days into the run to take it (default: half way)")
    ap.add_argument("--recheck", action="store_true",
                    help="only evaluate the checks again on the finished run in --out (its memory.csv, records "
                         "and offline run); soak.json's checks are rewritten")
    args = ap.parse_args()
    if not (args.days > 0 and args.speed > 0 and args.kills >= 0 and args.bursts >= 0):
        ap.error("--days and --speed must be > 0, --kills and --bursts >= 0")
    return args


def _checks(csv_path: Path, offline: pd.DataFrame, live_dir: Path, spec: Any, samples: list[dict[str, float]],
            day1: dict[str, float] | None, stop_after: float, memory_slack: float) -> dict[str, tuple[bool, str]]:
    """The live run against the offline one (rows, trajectory) and against itself over time (memory, fds,
    threads): name -> (passed, figure)."""
    n_rows = len(offline)
    last = samples[-1]
    live = pd.read_csv(csv_path)
    checks: dict[str, tuple[bool, str]] = {}
    t_live, t_off = live["time"].to_numpy(), offline["time"].to_numpy()
    same_rows = len(live) == n_rows and np.array_equal(t_live, t_off)
    dup = int((np.diff(t_live) <= 0).sum())
    record = pd.read_csv(live_dir / "live_measurements.csv", dtype={"tag": str, "time": str})
    rec_dup = int(record.duplicated(["tag", "time"]).sum())
    checks["rows"] = (same_rows and dup == 0 and rec_dup == 0,
                      f"live {len(live)} rows, offline {n_rows}; times equal: "
                      f"{np.array_equal(t_live[:n_rows], t_off[:len(t_live)])}; "
                      f"repeated or backward times {dup}; duplicated samples in the record {rec_dup} of {len(record)}")
    worst = []
    n = min(len(live), n_rows)
    for p in spec.pairs:
        col = f"parameter:{p.parameter}"
        bounds = next(x for x in spec.parameters if x.name == p.parameter)
        span = bounds.max - bounds.min
        dev = float(np.nanmax(np.abs(live[col].to_numpy()[:n] - offline[col].to_numpy()[:n]))) / span
        worst.append((dev, p.parameter))
    dev, name = max(worst)
    checks["trajectory"] = (dev <= 1e-4, f"largest |live - offline| / bound range {dev:.2e} ({name}); "
                            + ", ".join(f"{nm} {d:.1e}" for d, nm in worst))
    # A one-day run ends with its first day: the sampler stops with the tracker, before a sample reaches the
    # last row, so day 1 is its last sample (memory compared with itself; the run says so).
    short = day1 is None
    day1 = last if day1 is None else day1
    grew = last["hwm"] - day1["hwm"]
    checks["memory"] = (grew <= memory_slack, f"peak RSS after day 1 {day1['hwm']:.1f} MiB, after "
                        f"{stop_after / DAY:.2f} days {last['hwm']:.1f} MiB (+{grew:.1f}; slack {memory_slack:g})"
                        + (" (no sample after the first day: a run this short cannot show growth)" if short else ""))
    # The baseline is the first day once rows are tracked: before the first row (plant 0) the tracker is still
    # loading its FMU and has not opened its server connection, record and view (3-5 fds against 10 after).
    first_day = [s for s in samples if 0 < s["plant"] <= DAY] or [s for s in samples if s["plant"] <= DAY]
    last_day = [s for s in samples if s["plant"] >= stop_after - DAY]
    fd1, fdn = statistics.median(s["fds"] for s in first_day), statistics.median(s["fds"] for s in last_day)
    th1, thn = statistics.median(s["threads"] for s in first_day), statistics.median(s["threads"] for s in last_day)
    checks["fds"] = (fdn <= fd1, f"open fds, median over the first day {fd1:g}, over the last {fdn:g} "
                     f"(max over the run {max(s['fds'] for s in samples)})")
    checks["threads"] = (thn <= th1, f"threads, median over the first day {th1:g}, over the last {thn:g} "
                         f"(max over the run {max(s['threads'] for s in samples)})")
    return checks


def _recheck(out: Path, memory_slack: float) -> int:
    """The checks of the finished run in *out* evaluated again from what it saved."""
    from trackingbox.spec import load_spec

    figures = json.loads((out / "soak.json").read_text())
    offline = pd.read_csv(out / "offline" / "tracking.csv")
    samples = pd.read_csv(out / "memory.csv").to_dict("records")
    stop_after = float(offline["time"].iloc[-1])
    day1 = next((s for s in samples if s["plant"] >= min(DAY, stop_after)), None)
    checks = _checks(out / "live" / "tracking.csv", offline, out / "live", load_spec(out / "case" / "spec.toml"),
                     samples, day1, stop_after, memory_slack)
    figures["checks"] = {k: {"ok": ok, "figure": text} for k, (ok, text) in checks.items()}
    (out / "soak.json").write_text(json.dumps(figures, indent=1))
    for k, (ok, text) in checks.items():
        print(f"{'ok  ' if ok else 'FAIL'} {k:10s} {text}")
    return 0 if all(ok for ok, _ in checks.values()) else 1


def main() -> int:
    args = _arguments()
    view = args.view or args.screenshot is not None
    out = (args.out or Path("runs") / f"soak-live-{args.days:g}d").resolve()
    if args.recheck:
        return _recheck(out, args.memory_slack)
    out.mkdir(parents=True, exist_ok=True)
    rng = random.Random(args.seed)
    figures: dict[str, object] = {"days": args.days, "speed": args.speed, "seed": args.seed, "kills": args.kills}
    wall0, cpu0 = time.perf_counter(), children_cpu()
    print(f"soak_live: {args.days:g} days of the evaporator at {args.speed:g}x in {out}", flush=True)

    # 1. the case
    case = out / "case"
    marker = out / "case.json"
    want = {"days": args.days, "seed": args.seed, "bursts": args.bursts}
    if not (marker.exists() and json.loads(marker.read_text()).get("made") == want):
        stage("case (bench evaporator)", [*TB, "bench", "evaporator", "--out", str(case), "--days", f"{args.days:g}",
                                          "--seed", str(args.seed)], out / "case.log")
        stage("case (pair)", [*TB, "pair", str(case / "spec.toml")], out / "case.log")
        from trackingbox.benches.evaporator import CLOSED_LOOP, slow_pairs
        from trackingbox.spec import load_spec

        spec = load_spec(case / "spec.toml")
        slow_pairs(spec.path, spec.pairing.closed_loop_min or spec.pairing.closed_loop or CLOSED_LOOP)
        bursts = add_bursts(case, args.bursts, rng, [p.variable for p in load_spec(case / "spec.toml").pairs])
        (out / "offline").exists() and subprocess.run(["rm", "-rf", str(out / "offline")])
        marker.write_text(json.dumps({"made": want, "bursts": bursts}, indent=1))
    figures["bursts"] = json.loads(marker.read_text())["bursts"]
    from trackingbox.spec import load_spec

    spec = load_spec(case / "spec.toml")
    ts = float(spec.sample_time)

    # 2. the offline run
    if not (out / "offline" / "result.json").exists() or not json.loads(
            (out / "offline" / "result.json").read_text()).get("complete"):
        w, c = stage("offline track", [*TB, "track", str(case / "spec.toml"), "--out", str(out / "offline")],
                     out / "offline.log")
        figures["offline"] = {"wall": w, "cpu": c}
    offline = pd.read_csv(out / "offline" / "tracking.csv")
    n_rows = len(offline)
    stop_after = float(offline["time"].iloc[-1])
    print(f"  offline: {n_rows} rows to {stop_after:g} s", flush=True)

    # 3. the live run
    live_dir = out / "live"
    subprocess.run(["rm", "-rf", str(live_dir)])
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    replay_log, live_log = out / "replay.log", out / "live.log"
    replay_log.write_bytes(b"")
    kills = sorted(rng.uniform(0.3, 0.95) * stop_after for _ in range(args.kills))
    c0, w0 = children_cpu(), time.perf_counter()
    server, origin = start_replay(case, url, "+10", args.speed, replay_log)
    origin_s = pd.Timestamp(origin).timestamp()
    cmd = [*TB, "track", str(case / "spec.toml"), "--live", url, "--live-from", origin, "--out", str(live_dir),
           "--stop-after", f"{stop_after:g}", "--idle-timeout", "1800", "--json"]
    if view:
        cmd += ["--view", "127.0.0.1:0"]
    with open(live_log, "wb") as err, open(out / "live-result.json", "wb") as res:
        tracker = subprocess.Popen(cmd, stdout=res, stderr=err, env={**os.environ, "TRACKINGBOX_SUPERVISE": "0"})
    samples: list[dict[str, float]] = []
    day1: dict[str, float] | None = None
    done_kills: list[dict[str, float]] = []
    csv_path, csv_offset, rows = live_dir / "tracking.csv", 0, 0
    shot_at = (args.screenshot_at if args.screenshot_at is not None else args.days / 2) * DAY
    shot_done = args.screenshot is None
    try:
        while tracker.poll() is None:
            time.sleep(0.5)
            if csv_path.exists():
                with open(csv_path, "rb") as fh:
                    fh.seek(csv_offset)
                    data = fh.read()
                end = data.rfind(b"\n") + 1
                rows += data[:end].count(b"\n")
                csv_offset += end
            plant = max(0, rows - 2) * ts  # rows less the header, to the row's time
            st = proc(tracker.pid)
            if st is None:
                continue
            st.update(plant=plant, wall=time.perf_counter() - w0)
            samples.append(st)
            if day1 is None and plant >= min(DAY, stop_after):
                day1 = dict(st)
                print(f"  day 1 done: peak RSS {st['hwm']:.1f} MiB, {st['fds']} fds, {st['threads']} threads",
                      flush=True)
            if kills and (time.time() - origin_s) * args.speed >= kills[0]:
                k = kills.pop(0)
                kill(server)
                down = rng.uniform(0.5, 5.0)
                time.sleep(down)
                server, again = start_replay(case, url, origin, args.speed, replay_log)
                assert again == origin, (again, origin)
                done_kills.append({"plant": round(k, 1), "down_wall": round(down, 2)})
                print(f"  server killed at {k / DAY:.2f} days of plant time, restarted after {down:.1f} s",
                      flush=True)
            if not shot_done and plant >= shot_at:
                shot_done = True
                found = re.search(r"live view at (http://\S+)", live_log.read_text(errors="replace"))
                if found:
                    from trackingbox.view.browser import Browser

                    with Browser() as browser:
                        page = browser.open(found.group(1))
                        page.wait_for("Number(document.body.dataset.rows) > 0", timeout=120)
                        page.settle()
                        page.screenshot(args.screenshot)
                    print(f"  screenshot of the view at {plant / DAY:.2f} days: {args.screenshot}", flush=True)
        code = tracker.wait()
    finally:
        if tracker.poll() is None:
            kill(tracker)
        kill(server)
    live_wall, live_cpu = time.perf_counter() - w0, children_cpu() - c0
    if code != 0:
        print(f"soak_live: the live tracker failed (exit {code}); see {live_log}", file=sys.stderr)
        return 2
    last = samples[-1]
    figures["live"] = {"wall": live_wall, "cpu_all_processes": live_cpu, "cpu_tracker": last["cpu"],
                       "plant_seconds": stop_after, "speed_achieved": stop_after / live_wall, "kills": done_kills}
    result = json.loads((out / "live-result.json").read_text())
    figures["live"]["result"] = result.get("live")

    checks = _checks(csv_path, offline, live_dir, spec, samples, day1, stop_after, args.memory_slack)
    figures["checks"] = {k: {"ok": ok, "figure": text} for k, (ok, text) in checks.items()}
    figures["memory_by_day"] = {int(d): max(s["hwm"] for s in samples if int(s["plant"] // DAY) == d)
                                for d in sorted({int(s["plant"] // DAY) for s in samples})}
    figures["rss_by_day"] = {int(d): max(s["rss"] for s in samples if int(s["plant"] // DAY) == d)
                             for d in sorted({int(s["plant"] // DAY) for s in samples})}
    pd.DataFrame(samples).to_csv(out / "memory.csv", index=False)  # every sample: plant s, RSS, peak, fds...
    figures["total"] = {"wall": time.perf_counter() - wall0, "cpu_children": children_cpu() - cpu0}
    (out / "soak.json").write_text(json.dumps(figures, indent=1))
    print(f"live: {stop_after / DAY:.2f} plant days in {live_wall:.0f} s wall ({stop_after / live_wall:.0f}x), "
          f"tracker CPU {last['cpu']:.0f} s, all processes {live_cpu:.0f} s; {len(done_kills)} server kills; "
          f"{(result.get('live') or {}).get('connections')} connections, "
          f"{(result.get('live') or {}).get('backfilled')} samples read back")
    for k, (ok, text) in checks.items():
        print(f"{'ok  ' if ok else 'FAIL'} {k:10s} {text}")
    print(f"figures in {out / 'soak.json'}")
    return 0 if all(ok for ok, _ in checks.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
