"""``trackingbox COMMAND`` imports only what COMMAND needs; ``--help`` still lists every command.

Each check runs in a fresh interpreter (``sys.modules`` of this test process holds whatever
earlier tests imported) and compares module names, never times.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import textwrap

import pytest

from trackingbox import cli
from trackingbox.commands import SUMMARIES

#: Modules a compile never needs: the estimation statistics, the data tables, plotting, FMPy's simulation.
HEAVY = ("pandas", "scipy.stats", "matplotlib", "fmpy.simulation", "trackingbox.estimation", "trackingbox.fmu")

DECAY = "model Decay\n  Real x(start = 1, fixed = true);\nequation\n  der(x) = -x;\nend Decay;\n"


def _loaded_after(code: str, cwd) -> dict:
    """Run *code* in a new interpreter; its result ``rc`` and which of :data:`HEAVY` it loaded."""
    script = textwrap.dedent(code) + textwrap.dedent(f"""
        import json, sys
        print(json.dumps({{"rc": rc, "loaded": [m for m in {HEAVY!r} if m in sys.modules]}}))
    """)
    proc = subprocess.run([sys.executable, "-c", script], cwd=cwd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_the_heavy_modules_are_what_an_analysis_command_loads(tmp_path):
    """The list is not vacuous: importing the estimate command loads each of the stacks named."""
    seen = _loaded_after("import trackingbox.commands.estimate, matplotlib\nrc = 0", tmp_path)
    assert set(seen["loaded"]) == set(HEAVY)


def test_a_compile_loads_none_of_the_analysis_stacks(tmp_path):
    """A whole embedded compile (front end, causalisation, C export, gcc) through the command line."""
    (tmp_path / "Decay.mo").write_text(DECAY)
    seen = _loaded_after("""
        from trackingbox.cli import main
        rc = main(["compile", "Decay.mo", "--model", "Decay", "--backend", "embedded", "-o", "d.fmu"])
    """, tmp_path)
    assert seen == {"rc": 0, "loaded": []}
    assert (tmp_path / "d.fmu").is_file()


def test_a_refused_compile_and_the_help_load_none_of_them(tmp_path):
    seen = _loaded_after("""
        from trackingbox.cli import main
        rc = main(["compile", "missing.mo", "--model", "M", "--backend", "embedded"])
    """, tmp_path)
    assert seen == {"rc": 2, "loaded": []}
    seen = _loaded_after("""
        from trackingbox.cli import main
        try:
            main(["--help"])
        except SystemExit as exc:
            rc = exc.code
    """, tmp_path)
    assert seen == {"rc": 0, "loaded": []}


def test_help_lists_every_command_as_the_full_parser_does():
    """The listing built from the one-line summaries is the one of every command registered in full."""
    full = cli.build_parser().format_help()
    assert cli.build_parser("").format_help() == full
    assert cli.build_parser("compile").format_help() == full
    for name in SUMMARIES:
        assert f"    {name}" in full
    sub = next(a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert {c.dest: c.help for c in sub._choices_actions} == SUMMARIES  # each module registers its summary


@pytest.mark.parametrize("argv", [["frob"], ["-v"], [], ["compile"], ["estimate", "--no-such-option"],
                                  ["compile", "x.mo", "--model", "M", "--backend", "nope"], ["--bogus", "compile"]])
def test_refusals_are_the_full_parsers(argv, capsys):
    """Every usage error: the same one line and exit 2 as the parser with every command registered."""
    with pytest.raises(cli.UsageError) as expected:
        cli.build_parser().parse_args(argv)
    assert cli.main(argv) == 2
    assert capsys.readouterr().err == f"error: {expected.value}\n"
