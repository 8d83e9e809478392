"""FMI calls' failures translated in one place: what an FMU or the solver reported becomes a
:class:`~trackingbox.errors.SimulationError` (or :class:`~trackingbox.errors.AssertionFailed`).

The public internal interface of the FMU layer's drivers: the Python steppers here and the
native stepper (:mod:`trackingbox.fmu.native`) raise through :func:`simulation_failure` and
wrap their FMU calls in :func:`fmu_calls`.
"""
from __future__ import annotations

import collections
import contextlib
import logging
import re
from collections.abc import Iterator
from typing import Any

from ..errors import AssertionFailed, FMUError, SimulationError

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------
# error translation
# ---------------------------------------------------------------------------

Messages = collections.deque  # (status, category, text) logged by an FMU, newest last

_ASSERT_LOG = re.compile(r"assert failed at t = (\S+) s: (.*)", re.S)


def fmi3_logger(name: str, messages: Messages) -> Any:
    """An FMI 3 log callback: keeps (status, category, message) and logs to Python logging."""

    def log_message(env: Any, status: int, category: bytes | None, message: bytes | None) -> None:
        text = (message or b"").decode("utf-8", errors="replace")
        cat = (category or b"").decode("utf-8", errors="replace")
        messages.append((int(status), cat, text))
        # errors become exceptions (and the CLI's error line); log them only for -vv
        level = logging.DEBUG if status >= 3 or status == 0 else logging.WARNING
        log.log(level, "%s: %s", name, text)

    return log_message


def simulation_failure(what: str, cause: object, messages: Messages | None = None, *,
                        solver: bool = False) -> SimulationError:
    """The one place where a failure reported by an FMU or the solver becomes a :class:`SimulationError`.

    *what* says what failed, naming the FMU and the time (``"simulation of
    twin.fmu failed at t = 12 s"``); *cause* is the exception (or solver message)
    that reported it; *messages* are what the FMU logged (FMI 3). A failed
    ``assert`` the FMU logged becomes :class:`AssertionFailed` with the model's
    message and time; otherwise the FMU's last logged error is added to the text.
    With *solver* (the integrator failed), an assert the FMU saw failing at a
    trial point of the failed step (category ``assert-trial``) is the cause.
    Every driver below raises through this function.
    """
    for status, category, text in reversed(messages or ()):
        if solver and category == "assert-trial":
            found = _ASSERT_LOG.match(text)
            if found:
                return AssertionFailed(found.group(2), float(found.group(1)), _fmu_name(what))
        if status < 3:
            continue
        found = _ASSERT_LOG.match(text)
        if found:
            return AssertionFailed(found.group(2), float(found.group(1)), _fmu_name(what))
        return SimulationError(f"{what}: {cause}: {text}")
    return SimulationError(f"{what}: {cause}")


def _fmu_name(what: str) -> str:
    found = re.search(r"(\S+\.fmu)", what)
    return found.group(1) if found else "the FMU"


@contextlib.contextmanager
def fmu_calls(what: str, messages: Messages | None = None) -> Iterator[None]:
    """Translate any exception of the FMU calls in the body (ours pass unchanged); see :func:`simulation_failure`."""
    try:
        yield
    except (FMUError, SimulationError):
        raise
    except Exception as exc:
        raise simulation_failure(what, exc, messages) from None
