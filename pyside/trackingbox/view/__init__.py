"""The live web view of a tracking run (``trackingbox view OUT``, ``track ... --view HOST:PORT``).

A small HTTP server (:mod:`.server`, aiohttp) reads an output folder as the
tracker writes it (:mod:`.reader`: ``tracking.csv`` by appended complete
lines, ``live_status.json``, ``checkpoint.json``'s events, the bench's
``truth.json``) and pushes what changed to the page over server-sent events.
The page (``static/``: our ``index.html``, ``app.js``, ``style.css`` and the
vendored uPlot chart library) draws each tracked parameter's trajectory (with
the plant's truth and an uncertainty band where they exist), each paired tag's
measured, tracked and untracked values, the state of each loop and why, the
staleness of every tag and the run's health. Nothing is fetched from the
internet.

The server only reads files: it runs in its own process (started by ``track
--view``), so it can never block or slow the tracking loop. :mod:`.browser`
drives a headless Chromium over the DevTools protocol (the tests, screenshots).
"""
from __future__ import annotations
