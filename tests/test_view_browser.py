"""The live view in a real browser: a replayed case tracked live, its page in headless Chromium.

``replay --serve`` serves the first-order case (601 rows of 10 s, TI of bad
quality from 2500 s to 3000 s) at 150x real time; ``track --live --view
127.0.0.1:0`` tracks it and serves the view; Debian's Chromium, driven over
the DevTools protocol (:mod:`trackingbox.view.browser`), opens the page. The
references are ``tracking.csv`` as the tracker wrote it at that moment, the
case's own bad-quality span and the server this test kills: the page must
show the CSV's values, the hold and the lost and regained connection. Every
wait is a poll of the page with a generous time-out, never a timed assertion.

Chromium is installed with apt-get where it is missing and the test runs as
root (CI); the test skips, saying why, only where no browser can be had.
"""
from __future__ import annotations

import csv
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from _fixtures_online import free_port, kill, start_replay
from _fixtures_tracking import K_PLANT, make_case

pytestmark = pytest.mark.compile

SPEED = 150.0
WAIT = 90.0  # s: the longest wait for the page (a loaded 2-core machine), never reached when things work


def _install_chromium() -> str | None:
    """Debian's chromium: on PATH, else apt-get install it (as root); the reason it cannot be had otherwise."""
    from trackingbox.view.browser import find_chromium

    found = find_chromium()
    if found:
        return found
    if os.geteuid() != 0 or shutil.which("apt-get") is None:
        pytest.skip("no chromium on PATH and apt-get cannot install it here (not root, or no apt-get)")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for args in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", "chromium"]):
        done = subprocess.run(args, capture_output=True, text=True, env=env, timeout=1500)
        if done.returncode != 0:
            pytest.skip(f"chromium is not installed and `{' '.join(args)}` failed: {done.stderr.strip()[-400:]}")
    found = find_chromium()
    if not found:
        pytest.skip("apt-get installed chromium but no chromium is on PATH")
    return found


@pytest.fixture(scope="module")
def chromium() -> str:
    return _install_chromium()


def _csv_rows(path: Path) -> list[dict[str, str]]:
    """The complete rows of tracking.csv now (a torn last line is left out, as the view leaves it)."""
    text = path.read_bytes()
    text = text[:text.rfind(b"\n") + 1].decode()
    return list(csv.DictReader(text.splitlines()))


def _shown(page) -> dict:
    return page.evaluate("""(() => {
        const t = document.querySelector('#last-row');
        const cells = {}, text = {};
        for (const td of t.querySelectorAll('td[data-col]')) { cells[td.dataset.col] = td.dataset.raw;
                                                            text[td.dataset.col] = td.textContent; }
        return {time: t.dataset.time, rows: Number(document.body.dataset.rows), cells, text,
                link: document.querySelector('#link').dataset.link,
                reconnects: document.querySelector('#reconnects').textContent,
                loop: (r => r ? {state: r.dataset.state, why: r.dataset.why} : null)(
                    document.querySelector('#loops tr[data-tag="TI"]'))};
    })()""")


def _check_against_csv(page, csv_path: Path) -> dict:
    """The page's last row is a row of tracking.csv, cell for cell, once it has caught up with the CSV."""
    n_csv = len(_csv_rows(csv_path))
    page.wait_for(f"Number(document.body.dataset.rows) >= {n_csv}", timeout=WAIT)
    shown = _shown(page)
    rows = {r["time"]: r for r in _csv_rows(csv_path)}
    assert shown["time"] in rows, f"the page shows t = {shown['time']}, not a row of tracking.csv"
    row = rows[shown["time"]]
    assert shown["cells"] == row  # the exact cells
    for col, text in shown["text"].items():  # and what a person reads: the same numbers to 6 digits
        if col.startswith(("measured:", "tracked:", "untracked:", "parameter:")):
            assert float(text) == pytest.approx(float(row[col]), rel=1e-5, abs=1e-12), col
        elif col.startswith("mode:"):
            assert text == row[col]
    assert shown["rows"] >= n_csv
    return shown


def test_the_page_follows_a_live_run_its_hold_and_a_lost_server(chromium: str, first_order_fmu: Path,
                                                                  tmp_path: Path) -> None:
    from trackingbox.view.browser import Browser

    case = make_case(first_order_fmu, tmp_path / "case", nan_span=(2500.0, 3000.0))
    (case.parent / "truth.json").write_text(json.dumps({"parameters": {"k": K_PLANT}}))
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    replay_log, track_log, out = tmp_path / "replay.log", tmp_path / "track.log", tmp_path / "live"
    server, origin = start_replay(case, url, "+8", replay_log, "--linger", "300", speed=SPEED)
    assert origin is not None
    fh = open(track_log, "wb")
    tracker = subprocess.Popen([sys.executable, "-m", "trackingbox.cli", "track", str(case), "--live", url,
                                "--live-from", origin.isoformat(), "--out", str(out), "--stop-after", "6000",
                                "--idle-timeout", "120", "--view", "127.0.0.1:0"], stdout=fh, stderr=fh)
    fh.close()
    shots = Path(os.environ.get("TRACKINGBOX_VIEW_SCREENSHOTS", tmp_path))
    try:
        t0 = time.monotonic()
        while not (found := re.search(r"live view at (http://\S+)", track_log.read_text(errors="replace"))):
            assert tracker.poll() is None, track_log.read_text()[-3000:]
            assert time.monotonic() - t0 < WAIT, "the tracker did not say where its view is"
            time.sleep(0.05)
        with Browser(chromium) as browser:
            page = browser.open(found.group(1))
            page.wait_for("Number(document.body.dataset.rows) > 0", timeout=WAIT)
            # the values shown are tracking.csv's at that moment (twice, the second further on)
            first = _check_against_csv(page, out / "tracking.csv")
            page.wait_for(f"Number(document.body.dataset.rows) > {first['rows'] + 20}", timeout=WAIT)
            _check_against_csv(page, out / "tracking.csv")
            assert page.evaluate("document.querySelector('#link').dataset.link") == "connected"

            # the hold: TI is of bad quality from 2500 s to 3000 s; the page logs it and shades it
            held = page.wait_for("""(() => {
                const li = [...document.querySelectorAll('#log li[data-kind="loop"]')]
                    .find(l => l.textContent.includes('held (no measured value'));
                return li ? li.dataset.plant : ''; })()""",
                                 timeout=WAIT)
            assert float(held) == 2500.0
            resumed = page.wait_for("""[...document.querySelectorAll('#log li[data-kind="loop"]')]
                .filter(l => l.textContent.endsWith('tracking') && Number(l.dataset.plant) > 2500)
                .map(l => l.dataset.plant)[0] || ''""", timeout=WAIT)
            assert float(resumed) == 3000.0
            holds = page.evaluate("JSON.stringify(S.holds.TI)")
            assert [2500.0, 3000.0] in [h[:2] for h in json.loads(holds)]

            # the lost server: killed at ~3500 s of plant time, the page says so; restarted, it says that too
            page.wait_for("Number(document.body.dataset.rows) > 350", timeout=WAIT)
            kill(server)
            page.wait_for("document.querySelector('#link').dataset.link === 'disconnected'", timeout=WAIT)
            assert page.evaluate("""[...document.querySelectorAll('#log li[data-kind="link-lost"]')].length""") >= 1
            page.screenshot(shots / "view-disconnected.png")
            server, again = start_replay(case, url, origin, replay_log, "--linger", "300", speed=SPEED)
            assert again == origin
            # (on a loaded machine the tracker may lose the restarted server once more while it writes its
            # history, or finish the case from the history read back: reconnects >= 1, connected or stopped)
            page.wait_for("""[...document.querySelectorAll('#log li[data-kind="link-up"]')]
                .some(l => l.textContent.includes('reconnected'))""", timeout=WAIT)
            page.wait_for("Number(document.querySelector('#reconnects').textContent) >= 1 && "
                          "['connected', 'stopped'].includes(document.querySelector('#link').dataset.link)",
                          timeout=WAIT)
            _check_against_csv(page, out / "tracking.csv")
            shot = page.screenshot(shots / "view-live.png")
            assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 20_000
            assert page.errors == []  # no script error on the page
        assert tracker.wait(timeout=300) == 0, track_log.read_text()[-3000:]
    finally:
        kill(tracker) if tracker.poll() is None else None
        kill(server)
    # the finished folder through `trackingbox view`: the page's last row is the CSV's last, 601 rows
    from trackingbox.view.server import BackgroundView, ViewSettings

    with BackgroundView(out, ViewSettings(bind="127.0.0.1:0")) as view, Browser(chromium) as browser:
        page = browser.open(view.url)
        page.wait_for("Number(document.body.dataset.rows) === 601", timeout=WAIT)
        shown = _check_against_csv(page, out / "tracking.csv")
        assert shown["time"] == "6000.0" and shown["rows"] == 601
        assert page.evaluate("document.querySelector('#link').dataset.link") == "stopped"
        page.screenshot(shots / "view-finished.png")
        assert page.errors == []
