"""What every stage shares: the progress protocol and settings built from command-line arguments.

A stage is a module of :mod:`trackingbox.stages` with a frozen settings dataclass
and ``run(spec, settings, *, progress=None) -> Result``, where ``Result`` has
``to_json()`` (the command's ``--json`` document). Nothing in a stage prints:
progress goes to one callable of the :class:`Progress` shape, remarks to
:mod:`logging`.
"""
from __future__ import annotations

import argparse
import dataclasses
from typing import Any, Protocol, TypeVar


class Progress(Protocol):
    """``progress(stage, done, total, detail="", unit="")``: *done* of *total* items of *stage* finished.

    *detail* is a short remark for the status line (``"best NRMSE 0.031"``), *unit*
    what is counted (``"row"``, ``"generation"``). A count that goes back starts the
    stage again. :class:`trackingbox.commands._progress.Progress` draws it.
    """

    def __call__(self, stage: str, done: int, total: int, detail: str = "", unit: str = "") -> None: ...


class Result(Protocol):
    """What a stage returns: a frozen dataclass whose ``to_json()`` is the command's ``--json`` document."""

    def to_json(self) -> dict[str, Any]: ...


S = TypeVar("S")


def settings_from_args(cls: type[S], args: argparse.Namespace, **given: Any) -> S:
    """The settings dataclass *cls* from a command's parsed *args*: the one way every command builds them.

    A field takes, in this order, the value in *given* (an option named or
    computed otherwise, e.g. ``two_sided=not args.one_sided``), the argument of
    the same name, or its default.

    >>> @dataclasses.dataclass(frozen=True)
    ... class S:
    ...     seed: int = 0
    ...     workers: int | None = None
    ...     two_sided: bool = True
    >>> settings_from_args(S, argparse.Namespace(seed=3, workers=2, one_sided=True), two_sided=False)
    S(seed=3, workers=2, two_sided=False)
    >>> settings_from_args(S, argparse.Namespace(), nonsense=1)
    Traceback (most recent call last):
    ...
    TypeError: S has no setting 'nonsense'
    """
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    for name in given:
        if name not in names:
            raise TypeError(f"{cls.__name__} has no setting {name!r}")
    values = {name: given[name] if name in given else getattr(args, name)
              for name in names if name in given or hasattr(args, name)}
    return cls(**values)
