"""A pytest plugin: each test's CPU time (its process and the children it waited for) and wall time,
one JSON line per test appended to ``$PYTEST_CPU_OUT``.

Used to compare two commits' suites test by test (``scripts/compare_test_cpu``), which a loaded machine's
wall times cannot do:

    PYTHONPATH=scripts PYTEST_CPU_OUT=/tmp/a.jsonl scripts/test -p pytest_cpu
"""
from __future__ import annotations

import json
import os
import resource
import time

import pytest


def _cpu() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    cpu, wall = _cpu(), time.monotonic()
    yield
    row = {"id": item.nodeid, "cpu": _cpu() - cpu, "wall": time.monotonic() - wall}
    with open(os.environ["PYTEST_CPU_OUT"], "a") as out:
        out.write(json.dumps(row) + "\n")
