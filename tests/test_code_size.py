"""No module over 900 lines and no function over 150 lines (issue 32's bound for a code base a new
engineer can read), in the package, the scripts and the tests.

Counted from the source: a module's lines are its physical lines (``wc -l``), a function's are
those from its ``def`` (decorators aside) to its last line (``ast`` ``end_lineno``), nested
functions and methods included. ``python tests/test_code_size.py`` prints the largest modules and
functions with their sizes.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: where the bounds hold: the package, the scripts' Python files and the tests
SOURCES = ("pyside/trackingbox", "scripts", "tests")
MODULE_LINES = 900
FUNCTION_LINES = 150


def python_files(root: Path = ROOT) -> list[Path]:
    return sorted(p for where in SOURCES for p in (root / where).rglob("*.py"))


def sizes(path: Path) -> tuple[int, list[tuple[str, int, int]]]:
    """(lines of *path*, [(qualified function name, first line, lines) ...])."""
    text = path.read_text(encoding="utf-8")
    functions: list[tuple[str, int, int]] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    functions.append((name, child.lineno, (child.end_lineno or child.lineno) - child.lineno + 1))
                visit(child, name + ".")
            else:
                visit(child, prefix)

    visit(ast.parse(text, filename=str(path)), "")
    return len(text.splitlines()), functions


def oversized(paths: list[Path], root: Path = ROOT) -> list[str]:
    """One line per module over :data:`MODULE_LINES` and per function over :data:`FUNCTION_LINES`."""
    found = []
    for path in paths:
        lines, functions = sizes(path)
        where = path.relative_to(root)
        if lines > MODULE_LINES:
            found.append(f"{where}: {lines} lines")
        found += [f"{where}:{first} {name}: {n} lines" for name, first, n in functions if n > FUNCTION_LINES]
    return found


def test_no_module_over_900_lines_and_no_function_over_150() -> None:
    paths = python_files()
    assert len(paths) > 150  # the package, the scripts and the tests are all here
    assert oversized(paths) == []


def test_the_measure_sees_a_long_module_and_a_long_nested_function(tmp_path: Path) -> None:
    body = "\n".join(f"            x{i} = {i}" for i in range(FUNCTION_LINES - 1))
    sample = tmp_path / "sample.py"
    # a method's inner function of exactly FUNCTION_LINES lines (not over), inside the method that
    # holds it (over), padded to MODULE_LINES + 1 lines
    text = f"class A:\n    def run(self):\n        def inner():\n{body}\n        return inner\n"
    text += "\n" * (MODULE_LINES + 1 - len(text.splitlines()))
    sample.write_text(text)
    lines, functions = sizes(sample)
    assert lines == MODULE_LINES + 1
    assert dict((name, n) for name, _, n in functions) == {"A.run": FUNCTION_LINES + 2,
                                                         "A.run.inner": FUNCTION_LINES}
    assert oversized([sample], tmp_path) == [f"sample.py: {MODULE_LINES + 1} lines",
                                             f"sample.py:2 A.run: {FUNCTION_LINES + 2} lines"]


if __name__ == "__main__":  # the largest modules and functions, for a reader
    table = []
    for path in python_files():
        lines, functions = sizes(path)
        table.append((lines, str(path.relative_to(ROOT))))
        table += [(n, f"{path.relative_to(ROOT)}:{first} {name}()") for name, first, n in functions]
    limit = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    for n, what in sorted(table, reverse=True)[:limit]:
        print(f"{n:6d}  {what}")
