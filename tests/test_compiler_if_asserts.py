"""An ``assert`` in an if-equation keeps its meaning on the embedded path.

rumoca 0.10.2 drops such an assert without a word; :mod:`trackingbox.compiler.if_asserts` has it
read outside the if-equation with its branch's guard. Checked against times worked by hand (the
assert holds only in its branch; x = time), a warning-level assert that must not stop the run,
asserts guarded by ``initial()`` (checked at initialisation only), and the MSL's own
``LimIntegrator`` check of its start value (``Blocks/Continuous.mo``), which stops the run with the
MSL's message.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler.if_asserts import call_equations, if_asserts_outside
from trackingbox.errors import AssertionFailed

BRANCHES = """
package Branches
  model Stops "fails once x = time passes 0.7, which the branch active after t = 0.5 forbids"
    Real x = time;
  equation
    if time > 0.5 then
      assert(x < 0.7, "x passed 0.7 after t = 0.5");
    end if;
  end Stops;
  model Else "the else branch's assert fails from t = 0.3; the first branch's never (x > 0.2 there)"
    Real x = time;
    Real y;
  equation
    if x > 0.4 then
      y = 1;
      assert(x > 0.2, "never");
    elseif x < 0.1 then
      y = 2;
    else
      y = 3;
      assert(x < 0.3, "else branch: x reached 0.3");
    end if;
  end Else;
  model Runs "each assert would fail outside its branch, none inside"
    Real x = time;
    Real y;
  equation
    if time > 0.5 then
      y = 1;
      assert(x > 0.5, "first branch");
    else
      y = 0;
      assert(x <= 0.5, "else branch");
    end if;
    for i in 1:2 loop
      if i == 2 then
        assert(x <= 0.5*i, "loop branch");
      end if;
    end for;
  end Runs;
  model Warns
    Real x = time;
  equation
    if time > 0.5 then
      assert(x < 0.7, "x above 0.7 (a warning)", AssertionLevel.warning);
    end if;
  end Warns;
  model AtInit "y = 2 + time fails y < 1 at initialisation"
    parameter Boolean check = true;
    Real y = 2 + time;
  equation
    if initial() and check then
      assert(y < 1, "y too large at initialisation");
    end if;
  end AtInit;
  model OnlyAtInit "x = time fails x < 0.5 from t = 0.5, after initialisation: no stop"
    Real x = time;
  equation
    if initial() and true then
      assert(x < 0.5, "checked at initialisation only");
    end if;
  end OnlyAtInit;
  model InitialSection "an initial equation's assert holds at initialisation (x = 0), fails after t = 0.5"
    parameter Boolean p = true;
    Real x = time;
  initial equation
    if p then
      assert(x < 0.5, "initial equation only");
    end if;
  end InitialSection;
end Branches;
"""

LIMITS = """
model Limits "LimIntegrator started above its limit with limitsAtInit = false: the MSL asserts"
  Modelica.Blocks.Continuous.LimIntegrator lim(k = 1, outMax = 0.5, outMin = -1, y_start = 2,
    initType = Modelica.Blocks.Types.Init.InitialOutput, limitsAtInit = false);
equation
  lim.u = 1;
end Limits;
"""


@pytest.fixture(scope="module")
def branches(tmp_path_factory: pytest.TempPathFactory) -> Path:
    src = tmp_path_factory.mktemp("branches") / "Branches.mo"
    src.write_text(BRANCHES)
    return src


def _fmu(src: Path, model: str, libraries=()) -> Path:
    from trackingbox.compiler import compile_model

    out = src.parent / f"{model}.fmu"
    return compile_model(src, model, backend="embedded", output=out, libraries=list(libraries)).fmu


def _run(fmu: Path, output: str = "x"):
    from trackingbox.fmu import FMUModel

    with FMUModel(fmu) as model:
        return model.simulate(stop_time=1.0, output_interval=0.01, outputs=[output])


def test_the_rewrite_keeps_every_line_strings_and_the_guard_of_each_branch():
    text = BRANCHES.encode()
    new, lines = if_asserts_outside(text)
    assert new.count(b"\n") == text.count(b"\n")
    line_of = {s: BRANCHES.count("\n", 0, BRANCHES.index(s)) + 1
               for s in ('"x passed', '"never"', '"else branch: x', '"loop branch"')}
    assert set(line_of.values()) <= set(lines)
    assert b'assert(if (time > 0.5) then (x < 0.7) else true, "x passed 0.7 after t = 0.5");' in new
    assert (b'assert(if not (x > 0.4) and not (x < 0.1) then (x < 0.3) else true, "else branch: x reached 0.3");'
            in new)
    assert b'assert(if (i == 2) then (x <= 0.5*i) else true, "loop branch");' in new  # inside the loop
    # a for-loop inside the if-equation is written around the assert taken out of it
    src = b"equation\n  if a then\n    for i in 1:n loop\n      assert(x[i] > 0, \"m\");\n    end for;\n  end if;\n"
    loop, at = if_asserts_outside(src)
    assert at == [4] and loop.count(b"\n") == src.count(b"\n")
    assert b'for i in 1:n loop assert(if (a) then (x[i] > 0) else true, "m"); end for;' in loop and b"if a" not in loop
    # an if-equation of asserts only is replaced in place: the first model's text keeps its length
    first = new[:new.index(b"end Stops;")]
    assert len(first) == len(text[:text.index(b"end Stops;")]) and b"if time" not in first
    assert b'assert(if initial() and (p) then (x < 0.5) else true, "initial equation only");' in new
    # a string's line break is written as \n, its blanks kept; a comment in the if-equation goes
    src = b'equation\n  if a > 1 then // c\n    assert(b,\n "two  blanks\nand a break");\n  end if;\n'
    new, lines = if_asserts_outside(src)
    assert lines == [3] and new.count(b"\n") == src.count(b"\n")
    assert b'assert(if (a > 1) then (b) else true, "two  blanks\\nand a break");' in new
    # an assert in an algorithm's if-statement and one in a when-equation are left to rumoca
    src = b"equation\n when x > 1 then\n if y then assert(z, \"m\"); end if;\n end when;\n" \
          b"algorithm\n if y then assert(z, \"m\"); end if;\n"
    assert if_asserts_outside(src) == (src, [])


@pytest.mark.compile
@pytest.mark.parametrize("model,message,at", [("Stops", "x passed 0.7 after t = 0.5", 0.7),
                                              ("Else", "else branch: x reached 0.3", 0.3)])
def test_an_assert_in_a_branch_stops_the_run_when_it_fails_there(branches, model, message, at):
    with pytest.raises(AssertionFailed) as exc:
        _run(_fmu(branches, f"Branches.{model}"))
    assert exc.value.message == message
    assert at - 1e-9 <= exc.value.time <= at + 0.01 + 1e-9  # checked every 0.01 s


@pytest.mark.compile
def test_asserts_that_hold_in_their_branches_do_not_stop_the_run(branches):
    df = _run(_fmu(branches, "Branches.Runs"))
    assert np.isclose(df["time"].iloc[-1], 1.0) and np.isclose(df["x"].iloc[-1], 1.0)


@pytest.mark.compile
def test_a_warning_in_a_branch_is_logged_once_and_the_run_goes_on(branches, caplog):
    with caplog.at_level(logging.WARNING, logger="trackingbox.fmu"):
        df = _run(_fmu(branches, "Branches.Warns"))
    assert np.isclose(df["x"].iloc[-1], 1.0)
    warnings = [r.getMessage() for r in caplog.records if "x above 0.7 (a warning)" in r.getMessage()]
    assert len(warnings) == 1 and "t = 0.7" in warnings[0]


@pytest.mark.compile
def test_an_assert_guarded_by_initial_is_checked_at_initialisation_only(branches):
    with pytest.raises(AssertionFailed) as exc:
        _run(_fmu(branches, "Branches.AtInit"), "y")
    assert exc.value.message == "y too large at initialisation" and exc.value.time == 0.0
    df = _run(_fmu(branches, "Branches.OnlyAtInit"))
    assert np.isclose(df["x"].iloc[-1], 1.0)
    df = _run(_fmu(branches, "Branches.InitialSection"))  # read with initial() in its guard
    assert np.isclose(df["x"].iloc[-1], 1.0)


@pytest.mark.compile
def test_if_initial_of_asserts_only_in_the_models_own_class_is_checked_not_refused(tmp_path):
    # refused before (rumoca dropped it); the assert is false at t = 0 only
    src = tmp_path / "GuardedAssert.mo"
    src.write_text("model GuardedAssert\n  Real x(start = 0, fixed = true);\nequation\n  der(x) = 1;\n"
                   "  if initial() then\n    assert(time > 1, \"must fail at t = 0\");\n  end if;\n"
                   "end GuardedAssert;\n")
    with pytest.raises(AssertionFailed) as exc:
        _run(_fmu(src, "GuardedAssert"))
    assert exc.value.message == "must fail at t = 0" and exc.value.time == 0.0


@pytest.mark.compile
def test_the_msl_lim_integrator_stops_on_its_start_value_check(tmp_path):
    need_msl("Blocks", "Continuous.mo")
    from trackingbox.fmu import FMUModel

    src = tmp_path / "Limits.mo"
    src.write_text(LIMITS)
    with FMUModel(_fmu(src, "Limits", [MSL])) as model, pytest.raises(AssertionFailed) as exc:
        model.simulate(stop_time=1.0, output_interval=0.1, outputs=["lim.y"])
    assert exc.value.message.startswith("LimIntegrator: During initialization the limits have been ignored.")
    assert exc.value.time == 0.0


def test_call_equations_that_rumoca_drops_are_found_for_a_warning():
    """rumoca 0.10.2 drops a call equation of a function without outputs (with the asserts in its
    body): each is named with its line so the compile warns (not yet compiled with its meaning)."""
    src = (b"model M\n  Real x = time;\nequation\n  connect(a, b);\n  Connections.root(f.R);\n"
           b"  P.check(x,\n    2);\n  assert(x < 2, \"m\");\n  when x > 1 then\n    reinit(x, 0);\n"
           b"    P.check(x, 3);\n  end when;\nend M;\n")
    assert call_equations(src) == [(6, "P.check")]
    path = need_msl("Fluid", "Sources.mo")
    text = path.read_text(encoding="utf-8")
    lines = [text.count("\n", 0, k) + 1 for k in range(len(text)) if text.startswith("checkBoundary(", k)]
    assert [at for at, _ in call_equations(path.read_bytes())] == lines and len(lines) == 5
