"""The Modelica Standard Library the compiler tests read (``../shared/msl``, or ``TRACKINGBOX_MSL``)."""
from __future__ import annotations

from pathlib import Path

import pytest

from trackingbox.compiler.msl_harness import default_msl

MSL = default_msl()


def need_msl(*parts: str) -> Path:
    """``MSL/parts`` (default ``package.mo``), or the test skips saying where the library was looked for."""
    path = MSL.joinpath(*(parts or ("package.mo",)))
    if not path.is_file():
        pytest.skip(f"the Modelica Standard Library is not at {MSL} (set TRACKINGBOX_MSL)")
    return path
