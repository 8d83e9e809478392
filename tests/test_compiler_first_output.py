"""A call of a function with several outputs inside an expression is its first output (MLS 12.4.3).

rumoca 0.10.2 evaluates such a call in a parameter's binding as the array of all outputs, so a
binding like ``if p > 2 then ...`` over it failed ("type mismatch: expected comparable, got
Array"); the MSL's LossyGear does this with ``Modelica.Math.Vectors.interpolate``. The front end
reads each such function with its first output only and calls a ``__tuple`` copy where a call takes
every output (:func:`trackingbox.compiler.rewrite.first_output_functions`). Checked against values
worked out by hand, and ``Modelica.Math.Matrices.isEqual`` (read with an equivalent body, see
:data:`~trackingbox.compiler.rewrite.LIBRARY_BODIES`) against numpy.
"""
from __future__ import annotations

import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler.rewrite import first_output_functions, tuple_function_names


TWO = """package Two
  function f "two outputs"
    input Real x;
    output Real y "first";
    // a comment between the outputs
    output Integer k = 3 "second";
  algorithm
    y := 2*x;
    k := k + 1;
  end f;
  model M
    parameter Real a = 1.5;
    parameter Real p = f(a);
    parameter Real q = if p > 2 then 10 else 20;
    parameter Real r = if f(a/3) > 2 then 10 else 20;
    Real z(start = 0, fixed = true);
    Real w;
    Integer j;
  equation
    der(z) = q + p;
    (w, j) = f(time);
  end M;
end Two;
"""


def test_the_rewrite_keeps_every_line_and_renames_only_calls_taking_all_outputs(tmp_path):
    src = tmp_path / "Two.mo"
    src.write_text(TWO)
    names = tuple_function_names([src])
    assert names == frozenset({b"f"})
    new, lines = first_output_functions(TWO.encode(), names)
    assert lines == [2]
    old_lines, new_lines = TWO.encode().split(b"\n"), new.split(b"\n")
    assert len(new_lines) == len(old_lines)
    # the second output is protected in f, the copy holds both, on the line of f's end
    assert b"output Integer k" not in b"\n".join(new_lines[:9])
    assert new_lines[6].strip().startswith(b"protected Integer k = 3")
    assert new_lines[9].startswith(b"  end f; function f__tuple")
    assert new_lines[9].count(b"; output ") == 2
    # the parameter bindings still call f, the equation taking both outputs calls the copy
    assert new_lines[12].strip() == b"parameter Real p = f(a);"
    assert new_lines[20].strip() == b"(w, j) = f__tuple(time);"
    # without the names (a call taking all outputs could not be renamed), f keeps its outputs
    alone, lines = first_output_functions(TWO.encode())
    assert lines == [] and b"output Integer k" in alone and b"f__tuple(time)" not in alone


def test_a_name_a_function_holding_functions_also_has_is_left_with_all_its_outputs(tmp_path):
    """Modelica.Fluid.Pipes has two Internal.m_flow_of_dp_fric with two outputs, one of them holding
    functions of its own (which gets no copy): a call taking both outputs of that one was renamed to a
    copy that did not exist ('unresolved component reference: Internal.m_flow_of_dp_fric__tuple')."""
    src = tmp_path / "N.mo"
    src.write_text("package N\n  package A\n    function f\n      input Real x;\n      output Real y;\n"
                   "      output Real d;\n    algorithm\n      y := x;\n      d := 1;\n    end f;\n  end A;\n"
                   "  package B\n    function f\n      input Real x;\n      output Real y;\n      output Real d;\n"
                   "    protected\n      function g\n        input Real u;\n        output Real v;\n"
                   "      algorithm\n        v := 2*u;\n      end g;\n    algorithm\n      y := g(x);\n"
                   "      d := 2;\n    end f;\n  end B;\nend N;\n")
    assert b"f" not in tuple_function_names([src])
    new, lines = first_output_functions(src.read_bytes(), tuple_function_names([src]))
    assert lines == [] and b"output Real d" in new


def test_a_name_another_function_also_has_is_left_with_all_its_outputs(tmp_path):
    a = tmp_path / "A.mo"
    a.write_text(TWO)
    b = tmp_path / "B.mo"
    b.write_text("package B\n  function f\n    input Real x;\n    output Real y;\n  algorithm\n"
                 "    y := x;\n  end f;\nend B;\n")
    assert tuple_function_names([a, b]) == frozenset()


@pytest.mark.compile
def test_first_output_in_parameter_bindings_and_all_outputs_in_a_tuple_equation(tmp_path):
    """p = f(1.5) = 3, so q = 10; f(1.5/3) = 1, so r = 20; z' = q + p = 13; (w, j) = (2 t, 4)."""
    import fmpy

    from trackingbox.compiler import compile_model

    src = tmp_path / "Two.mo"
    src.write_text(TWO)
    res = compile_model(src, "Two.M", backend="embedded", output=tmp_path / "m.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.25,
                            output=["p", "q", "r", "z", "w", "j"])
    assert np.allclose(out["p"], 3.0) and np.allclose(out["q"], 10.0) and np.allclose(out["r"], 20.0)
    assert np.allclose(out["z"], 13.0 * out["time"], rtol=1e-6, atol=1e-9)
    assert np.allclose(out["w"], 2.0 * out["time"]) and np.all(out["j"] == 4)


@pytest.mark.compile
def test_matrices_is_equal_agrees_with_numpy(tmp_path):
    """Equal where the sizes agree and every pair is within eps (|a - b| <= eps), else false."""
    need_msl("Math", "package.mo")
    import fmpy

    from trackingbox.compiler import compile_model

    a = np.array([[0, 1, 1, 0, 0], [1, 0.5, 2, 3, 4]])
    cases = {  # name: (other matrix, eps)
        "same": (a, 0.0),
        "inside": (a + np.array([[0, 0, 0, 0, 0], [0, 0, 0, 0.25, 0]]), 0.25),
        "beyond": (a + np.array([[0, 0, 0, 0, 0], [0, 0, 0, 0.25, 0]]), 0.2),
        "last": (a + np.array([[0, 0, 0, 0, 0], [0, 0, 0, 0, -1e-3]]), 0.0),
        "rows": (a[:1], 1.0),
        "cols": (a[:, :4], 1.0),
    }

    def lit(m: np.ndarray) -> str:
        return "[" + "; ".join(", ".join(repr(float(v)) for v in row) for row in m) + "]"

    body = "".join(f"  Boolean v_{n};\n" for n in cases)
    eqs = "".join(f"  v_{n} = Modelica.Math.Matrices.isEqual(A, {lit(m)}, {e!r});\n" for n, (m, e) in cases.items())
    src = tmp_path / "Eq.mo"
    src.write_text(f"model Eq\n  parameter Real A[2, 5] = {lit(a)};\n  Real x(start = 0, fixed = true);\n"
                   f"{body}equation\n  der(x) = 1;\n{eqs}end Eq;\n")
    res = compile_model(src, "Eq", backend="embedded", output=tmp_path / "eq.fmu", libraries=[MSL])
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5,
                            output=[f"v_{n}" for n in cases])
    for n, (m, e) in cases.items():
        expect = m.shape == a.shape and bool(np.all(np.abs(a - m) <= e))
        assert bool(out[f"v_{n}"][-1]) == expect, n
    assert [n for n, (m, e) in cases.items() if m.shape == a.shape and np.all(np.abs(a - m) <= e)] == ["same", "inside"]


@pytest.mark.compile
def test_msl_lossy_gear_demo1_loses_power_as_its_efficiency_says(tmp_path):
    """Modelica.Mechanics.Rotational.Examples.LossyGearDemo1 (ratio 2, efficiency 0.5 both ways, no
    bearing friction) over its experiment: where flange_a drives (tau_a w_a > 0) the gear passes on
    eta of the power, tau_b = -ratio eta tau_a; where flange_b drives, tau_a w_a = -eta tau_b w_b, so
    tau_b = -ratio tau_a / eta; the power lost is never negative; w_b = w_a / ratio; and the run goes
    through forward, backward and stuck."""
    need_msl("Mechanics", "Rotational", "Components", "LossyGear.mo")
    import fmpy

    from trackingbox.compiler import compile_model

    res = compile_model(MSL, "Modelica.Mechanics.Rotational.Examples.LossyGearDemo1", backend="embedded",
                        output=tmp_path / "lg.fmu")
    names = ["gear.flange_a.tau", "gear.flange_b.tau", "gear.w_a", "Inertia2.w", "PowerLoss", "gear.mode"]
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=0.5, output_interval=1e-3, output=names)
    ta, tb, wa, wb, loss, mode = (out[n] for n in names)
    ratio, eta = 2.0, 0.5
    assert np.allclose(wb, wa / ratio, atol=1e-12)
    sliding = np.abs(wa) > 1e-4
    a_drives, b_drives = sliding & (ta * wa > 1e-6), sliding & (ta * wa < -1e-6)
    assert a_drives.sum() > 50 and b_drives.sum() > 50 and (~sliding).sum() > 50
    assert np.allclose(tb[a_drives], -ratio * eta * ta[a_drives], atol=1e-9 * np.abs(ta).max())
    assert np.allclose(tb[b_drives], -ratio * ta[b_drives] / eta, atol=1e-9 * np.abs(ta).max())
    assert loss.min() > -1e-6 * loss.max()
    assert set(np.unique(mode)) == {-1.0, 0.0, 1.0}


def test_a_function_another_extends_or_a_replaceable_one_is_left_with_all_its_outputs(tmp_path):
    a = tmp_path / "A.mo"
    a.write_text(TWO)
    b = tmp_path / "B.mo"
    b.write_text("package B\n  function g\n    extends Two.f;\n  end g;\nend B;\n")
    assert tuple_function_names([a, b]) == frozenset()
    c = tmp_path / "C.mo"
    c.write_text(TWO.replace("  function f \"two outputs\"", "  replaceable function f \"two outputs\""))
    assert tuple_function_names([c]) == frozenset()
    d = tmp_path / "D.mo"
    d.write_text(TWO.replace("  end f;", "    annotation(derivative = f_der);\n  end f;").replace(
        "  function f \"two outputs\"", "  function f_der\n    input Real x;\n    input Real dx;\n"
        "    output Real dy;\n    output Real dk;\n  algorithm\n    dy := 2*dx;\n    dk := 0;\n  end f_der;\n"
        "  function f \"two outputs\""))
    assert tuple_function_names([d]) == frozenset({b"f"})  # f_der stays as f's derivative needs it
