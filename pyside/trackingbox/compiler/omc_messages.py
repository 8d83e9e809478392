"""omc's messages in the shape the embedded path reports: file, line, column, level, message.

``getErrorString()`` returns omc's pending messages as text, one message after
another, each ``[file:line:col-line:col:writable] Error: message`` (or
``readonly`` for a file omc treats as read-only, e.g. a system library), or
without the bracket when the message has no position (``Error: Failed to load
package ...``). A message may continue over several lines until the next one
starts. The level is ``Error``, ``Warning``, ``Notification`` or ``Internal
error``, optionally preceded by the kind of message (``Translation Error``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from ..errors import CompileError

__all__ = ["OmcMessage", "compile_error", "errors_of", "parse_error_string"]

Level = Literal["error", "warning", "notification", "internal"]

_POSITION = r"\[(?P<file>[^\n]*?):(?P<l1>\d+):(?P<c1>\d+)-(?P<l2>\d+):(?P<c2>\d+):(?P<rw>readonly|writable)\]"
_KIND = r"(?:(?P<kind>Syntax|Grammar|Translation|Symbolic|Runtime|Scripting|Simulation)\s+)?"
_LEVEL = r"(?P<level>Error|Warning|Notification|Internal error)"
_HEAD = re.compile(rf"^(?:{_POSITION}\s*)?{_KIND}{_LEVEL}:\s?", re.M)


@dataclass(frozen=True)
class OmcMessage:
    """One omc message.

    Attributes
    ----------
    level:
        ``"error"``, ``"warning"``, ``"notification"`` or ``"internal"`` (an internal error of omc).
    message:
        The text, stripped; several lines stay several lines.
    file:
        The file the message is about, or ``None`` when omc gave no position.
    line, column, end_line, end_column:
        The 1-based span omc gave (0 when it gave none).
    kind:
        The kind omc printed before the level (``"translation"``), or ``""``.
    """

    level: Level
    message: str
    file: Path | None = None
    line: int = 0
    column: int = 0
    end_line: int = 0
    end_column: int = 0
    kind: str = ""

    @property
    def where(self) -> str:
        """``file:line:column`` (the embedded path's location format), or ``""`` without a position."""
        if self.file is None:
            return ""
        return f"{self.file}:{self.line}:{self.column}" if self.line else str(self.file)

    def __str__(self) -> str:
        head = f"{self.where}: " if self.where else ""
        return f"{head}{self.level}: {self.message}"


def _level(text: str) -> Level:
    low = text.lower()
    return "internal" if low.startswith("internal") else low  # type: ignore[return-value]


def parse_error_string(text: str) -> tuple[OmcMessage, ...]:
    """The messages of a ``getErrorString()`` reply.

    Parameters
    ----------
    text:
        The reply as omc sends it (the surrounding quotes of the Modelica string
        literal may be present or already removed; ``\\"`` and ``\\n`` escapes
        are undone).

    Returns
    -------
    tuple of OmcMessage
        In omc's order. Text before the first recognised message (rare) becomes
        one ``error`` message without a position, so nothing omc said is lost.
    """
    body = _unquote(text)
    heads = list(_HEAD.finditer(body))
    found: list[OmcMessage] = []
    lead = body[: heads[0].start()].strip() if heads else body.strip()
    if lead:
        found.append(OmcMessage("error", lead))
    for i, head in enumerate(heads):
        end = heads[i + 1].start() if i + 1 < len(heads) else len(body)
        message = body[head.end():end].strip()
        file = head.group("file")
        kind = (head.group("kind") or "").lower()
        if file:
            found.append(OmcMessage(_level(head.group("level")), message, Path(file), int(head.group("l1")),
                                    int(head.group("c1")), int(head.group("l2")), int(head.group("c2")), kind))
        else:
            found.append(OmcMessage(_level(head.group("level")), message, kind=kind))
    return tuple(found)


def _unquote(text: str) -> str:
    s = text.strip()
    if len(s) >= 2 and s[0] == '"' and s[-1] == '"':
        s = s[1:-1]
        s = re.sub(r'\\(["\\n])', lambda m: "\n" if m.group(1) == "n" else m.group(1), s)
    return s


def errors_of(messages: tuple[OmcMessage, ...] | list[OmcMessage]) -> list[OmcMessage]:
    """The error-level messages (errors and omc's internal errors)."""
    return [m for m in messages if m.level in ("error", "internal")]


def compile_error(model: str, entry: Path, step: str, messages: tuple[OmcMessage, ...] | list[OmcMessage],
                  hint: str = "") -> CompileError:
    """A :class:`CompileError` for a failed omc step, worded like the embedded path's.

    ``cannot compile 'M' from /p/M.mo: OpenModelica failed to <step>: <first error>``
    followed by one ``file:line:col: level: message`` line per error and warning.
    """
    shown = [m for m in messages if m.level != "notification"]
    first = next((m for m in shown if m.level in ("error", "internal")), shown[0] if shown else None)
    summary = first.message.splitlines()[0] if first else "omc gave no message"
    detail = "".join(f"\n  {m}" for m in shown)
    return CompileError(f"cannot compile {model!r} from {entry}: OpenModelica failed to {step}: {summary}"
                        f"{detail}{hint}")
