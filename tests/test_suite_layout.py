"""The test suite's own layout: no test module imports another.

A test module that imports another runs the other's module-level code (its fixtures, its
parametrisations, its marks) as a side effect and ties the two together; shared helpers live
in ``conftest.py`` fixtures or in the ``_fixtures_*.py`` modules beside them. Read from the
source (the AST of every ``tests/*.py``), not from what was imported at run time.
"""
from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def _imported_test_modules(path: Path) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        # a module of this suite is imported by its own name (tests/ is on the path) or as tests.*;
        # a library's test helpers (aiohttp.test_utils) are not the suite's
        found += [f"{path.name}:{node.lineno} imports {n}" for n in names
                  if n.split(".")[0].startswith("test_") or n.startswith("tests.test_")]
    return found


def test_no_test_module_imports_another() -> None:
    modules = sorted(TESTS.glob("*.py"))
    assert len(modules) > 50  # the suite is here
    assert [line for path in modules for line in _imported_test_modules(path)] == []


def test_the_check_sees_an_import_of_a_test_module(tmp_path: Path) -> None:
    sample = tmp_path / "test_sample.py"
    sample.write_text("import os\nfrom _fixtures_generate import write_case\n\n\ndef f():\n"
                      "    from test_generate import BENCH_PAIRS\n    import test_other as o\n"
                      "    from aiohttp.test_utils import TestServer\n    import tests.test_x\n")
    assert _imported_test_modules(sample) == ["test_sample.py:6 imports test_generate",
                                              "test_sample.py:7 imports test_other",
                                              "test_sample.py:9 imports tests.test_x"]
