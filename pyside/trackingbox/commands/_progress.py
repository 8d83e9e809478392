"""The one progress display of the commands (and the demo): a status line on stderr.

On a terminal the line is rewritten in place (at most five times a second);
elsewhere (a log file, CI) a line is written when the stage changes, at the end
of a stage, and otherwise at most every *every* seconds. Each line carries the
elapsed time and, once a stage has made progress, an estimate of the time left
in it (at most: a stage may stop before its budget). The rate behind it is
measured from the stage's first finished item when the stage starts from
nothing (the first items of a parallel batch carry the workers' start-up), and
from where a count starts again (a stage run a second time under the same name).
"""
from __future__ import annotations

import math
import sys
import time
from typing import TextIO

#: fraction of a stage's items done (since its rate's start) before a line estimates the time left
ETA_FRACTION = 0.02


def duration(seconds: float) -> str:
    """``42 s``, ``3 min 05 s``, ``1 h 02 min``.

    >>> duration(42.4), duration(185), duration(3720)
    ('42 s', '3 min 05 s', '1 h 02 min')
    """
    seconds = max(0.0, seconds)
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


class Progress:
    """``progress(stage, done, total, detail="")``: one status line per call worth showing.

    Parameters
    ----------
    every : float
        Seconds between lines when stderr is not a terminal.
    stream : file, optional
        Where the lines go (default ``sys.stderr``).
    """

    def __init__(self, every: float = 5.0, stream: TextIO | None = None) -> None:
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self.every = every
        self.t0 = time.perf_counter()
        self.stage = ""
        self.stage_t0 = self.t0
        self.stage_done0 = 0
        self.prev_done = 0
        self.rebase = False
        self.last = -1.0e9

    def __call__(self, stage: str, done: int, total: int, detail: str = "", unit: str = "") -> None:
        now = time.perf_counter()
        new_stage = stage != self.stage or done < self.prev_done  # a count going back starts again
        if new_stage:
            self.stage, self.stage_t0, self.stage_done0 = stage, now, done
            self.rebase = done == 0
        elif self.rebase and done > self.stage_done0:
            # the first finished items of a stage begun from nothing: their time holds the start-up
            # (workers starting, FMUs extracted, two at once in a parallel batch); the rate starts here
            self.stage_t0, self.stage_done0, self.rebase = now, done, False
        self.prev_done = done
        total = max(total, done)  # a budget's last evaluations may run past it: never "321/320"
        finished = done >= total
        if not (new_stage or finished) and now - self.last < (0.2 if self.tty else self.every):
            return
        self.last = now
        since = done - self.stage_done0
        rate = (now - self.stage_t0) / max(since, 1)
        # no estimate from the first few items: one slow serial run before a parallel batch of 32
        # made the demo's refinement read "at most ~7 h 56 min left" (it took 17 min)
        enough = since >= max(2, math.ceil(ETA_FRACTION * (total - self.stage_done0)))
        left = f", at most ~{duration(rate * (total - done))} left" if enough and not finished else ""
        text = f"{stage}: {unit + ' ' if unit else ''}{done}/{total}{', ' + detail if detail else ''} " \
               f"({duration(now - self.t0)} elapsed{left})"
        if self.tty:
            self.stream.write("\r\033[K" + text + ("\n" if finished else ""))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def counter(self, stage: str, unit: str = "") -> Counter:
        """A ``progress(done, total)`` callable for one stage (tracking rows, step-test runs)."""
        return Counter(self, stage, unit)

    def note(self, text: str) -> None:
        """A line of its own (a stage finished, a file written)."""
        if self.tty:
            self.stream.write("\r\033[K")
        self.stream.write(text + "\n")
        self.stream.flush()


class Counter:
    """``counter(done, total)`` → ``progress(stage, done, total)``."""

    def __init__(self, progress: Progress, stage: str, unit: str = "") -> None:
        self.progress = progress
        self.stage = stage
        self.unit = unit

    def __call__(self, done: int, total: int) -> None:
        self.progress(self.stage, done, total, unit=self.unit)
