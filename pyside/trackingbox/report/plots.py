"""Shared PNG plots of the stage reports (matplotlib, Agg backend, written atomically).

One look for every stage: measured samples as grey dots, simulations as lines
(untracked twin orange, tracked blue, Python runtime green dashed), parameter
bounds as dashed black lines, the plant's true value (bench cases) as a red
dotted line, a start-up hold or a scored window as a grey band.
"""
from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..io import atomic_path

__all__ = ["Line", "pyplot", "save", "safe_name", "series", "parameter", "heatmap", "DPI"]

DPI = 110

#: Colours of the usual lines.
MEASURED, UNTRACKED, TRACKED, PYTHON, TRUTH = "0.5", "tab:orange", "tab:blue", "tab:green", "tab:red"


@dataclass(frozen=True)
class Line:
    """One curve of :func:`series`: values on the plot's x, a label, a matplotlib format."""

    y: npt.ArrayLike
    label: str
    color: str = TRACKED
    style: str = "-"
    width: float = 1.2


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the non-interactive Agg backend."""
    # deferred (start-up): pyplot adds 0.23-0.66 s to an import of the package (python -X importtime),
    # and the Agg backend must be chosen before it loads
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def safe_name(name: str) -> str:
    """A file-name part for a tag or parameter name.

    >>> safe_name("TI-102"), safe_name("hx.kht"), safe_name("a b/c")
    ('TI-102', 'hx.kht', 'a_b_c')
    """
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def save(fig: Any, path: str | os.PathLike[str]) -> Path:
    """Write *fig* as PNG to *path* atomically and close it."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=DPI, bbox_inches="tight")
    pyplot().close(fig)
    return path


def _band(ax: Any, band: tuple[float, float] | None, label: str) -> None:
    if band is not None and band[1] > band[0]:
        ax.axvspan(band[0], band[1], color="0.9", zorder=0, label=label)


def shade(ax: Any, intervals: Sequence[tuple[float, float]], label: str = "stoppage",
          color: str = "#f4d6a0") -> None:
    """Shade each ``(start, stop)`` interval (x units) on *ax*; one legend entry for all."""
    for i, (a, b) in enumerate(intervals):
        if b > a:
            ax.axvspan(a, b, color=color, alpha=0.6, zorder=0, lw=0, label=label if i == 0 else None)


def series(ax: Any, x: npt.ArrayLike, measured: npt.ArrayLike | None, lines: Sequence[Line], *,
           ylabel: str, title: str = "", band: tuple[float, float] | None = None, band_label: str = "",
           xlabel: str | None = "time (h)") -> None:
    """Measured dots and simulated lines on *ax* (one tag over time)."""
    x = np.asarray(x, dtype=float)
    if measured is not None:
        ax.plot(x, np.asarray(measured, dtype=float), ".", ms=2, color=MEASURED, label="measured")
    for ln in lines:
        y = np.asarray(ln.y, dtype=float)
        if np.isfinite(y).any():
            ax.plot(x, y, ln.style, color=ln.color, lw=ln.width, label=ln.label)
    _band(ax, band, band_label)
    ax.set_ylabel(ylabel)
    if xlabel:
        ax.set_xlabel(xlabel)
    if title:
        ax.set_title(title, fontsize=10, loc="left")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)


def parameter(x: npt.ArrayLike, lines: Sequence[Line], *, name: str, lower: float, upper: float,
              truth: float | None = None, band: tuple[float, float] | None = None, band_label: str = "",
              hold: npt.ArrayLike | None = None, title: str = "") -> Any:
    """A figure of a tracking parameter's trajectories with its bounds and, if known, the plant's true value.

    *hold* (booleans on *x*) shades where the controllers were on hold.
    """
    plt = pyplot()
    x = np.asarray(x, dtype=float)
    fig, ax = plt.subplots(figsize=(9, 3.4))
    if hold is not None and np.asarray(hold, dtype=bool).any():
        ax.fill_between(x, lower, upper, where=np.asarray(hold, dtype=bool), color="0.92", step="mid",
                        label="controller on hold")
    for ln in lines:
        ax.plot(x, np.asarray(ln.y, dtype=float), ln.style, color=ln.color, lw=ln.width, label=ln.label)
    ax.axhline(lower, color="k", ls="--", lw=0.8, label="bounds")
    ax.axhline(upper, color="k", ls="--", lw=0.8)
    if truth is not None and np.isfinite(truth):
        ax.axhline(truth, color=TRUTH, ls=":", lw=1.8, zorder=5, label=f"plant truth ({truth:.6g})")
    _band(ax, band, band_label)
    ax.set_xlabel("time (h)")
    ax.set_ylabel(name)
    ax.set_title(title or f"tracking parameter {name}", fontsize=10, loc="left")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return fig


def heatmap(title: str, rows: Sequence[str], cols: Sequence[str], values: npt.ArrayLike,
            boxed: set[tuple[str, str]], *, cmap: str, center: float | None = None) -> Any:
    """A figure of a matrix with its values written in the cells and *boxed* ``(row, col)`` cells framed."""
    plt = pyplot()  # matplotlib loaded, on Agg (see pyplot)
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.patches import Rectangle

    v = np.asarray(values, dtype=float)
    fig, ax = plt.subplots(figsize=(max(5.0, 2.5 + 0.8 * len(cols)), max(3.0, 1.6 + 0.5 * len(rows))))
    finite = v[np.isfinite(v)]
    norm = None
    if center is not None and finite.size and finite.min() < center < finite.max():
        norm = TwoSlopeNorm(vcenter=center, vmin=float(finite.min()), vmax=float(finite.max()))
    im = ax.imshow(np.ma.masked_invalid(v), cmap=cmap, norm=norm, aspect="auto")
    for i, r in enumerate(rows):
        for j, c in enumerate(cols):
            ax.text(j, i, f"{v[i, j]:.2g}" if np.isfinite(v[i, j]) else "", ha="center", va="center", fontsize=8)
            if (r, c) in boxed:
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, lw=2.5, ec="black"))
    ax.set_xticks(range(len(cols)), list(cols), rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(rows)), list(rows), fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.colorbar(im, ax=ax, shrink=0.8)
    return fig


def truth_for(truth: Mapping[str, float] | None, name: str) -> float | None:
    """The plant's true value of *name*, if the caller knows one (bench cases)."""
    return None if truth is None else truth.get(name)
