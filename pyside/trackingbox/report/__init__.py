"""Stage reports: Markdown + PNG plots through shared helpers, and the demo's HTML page.

Each stage has one writer, ``write_<stage>_report(spec, result, out, ...)``,
that puts its PNG plots and a Markdown file into *out* and returns a
:class:`StageReport`, whose :class:`~trackingbox.report.document.Document` the
demo combines into one self-contained HTML page (:func:`write_html`).

The writers share :mod:`~trackingbox.report.plots` (one look for measured,
untracked, tracked and Python-runtime series, parameter bounds and the plant's
true value where a bench case knows it) and
:mod:`~trackingbox.report.document` (tables, lists, images; Markdown and HTML).
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from ..io import write_text_atomic
from .diagnose import write_diagnose_report
from .document import Document, StageReport, fmt, html_page
from .estimate import write_estimate_report
from .pair import write_pair_report
from .track import write_track_report
from .validate import write_validate_report

__all__ = ["StageReport", "Document", "fmt", "html_page", "write_html", "write_estimate_report",
           "write_pair_report", "write_track_report", "write_validate_report", "write_diagnose_report"]


def write_html(path: str | os.PathLike[str], title: str, documents: Sequence[Document]) -> Path:
    """Write one self-contained HTML page of *documents* (plots embedded) to *path*, atomically."""
    path = Path(path)
    write_text_atomic(path, html_page(title, documents))
    return path
