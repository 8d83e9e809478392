"""The MSL harness (scripts/msl): its comparison with reference results, its grouping of refusals,
and a whole run on a small library whose references are closed-form solutions (issue 35, item 3)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from trackingbox.compiler.msl_harness import (Reference, compare, construct_of, default_reference, deviation,
                                              load_reference, main, table)


def test_deviation_is_relative_to_the_signal_range():
    t = np.linspace(0.0, 10.0, 101)
    ref = 100.0 + 5.0 * np.sin(t)  # range about 10
    ours = ref + 0.02  # 0.02 off everywhere: 2e-3 of the range
    rng = ref.max() - ref.min()
    assert deviation(t, ref, t, ours, 1e-3) == pytest.approx(0.02 / rng, rel=1e-9)


def test_deviation_of_a_constant_signal_is_relative_to_its_magnitude():
    t = np.linspace(0.0, 1.0, 11)
    assert deviation(t, np.full(11, 50.0), t, np.full(11, 50.05), 1e-4) == pytest.approx(1e-3)


def test_a_range_the_reference_does_not_resolve_counts_as_constant():
    # a tank temperature constant in Modelica's meaning that the reference's solver (relative
    # tolerance 1e-6) moved by 1e-4 K: a range of 3e-7 of its magnitude, below 10 x 1e-6
    t = np.linspace(0.0, 100.0, 101)
    ref = 323.15 + 1e-4 * t / 100.0
    ours = np.full(101, 323.15 + 1.2e-3)
    # judged against its magnitude: (1.2e-3 - 1e-4 at the end .. 1.2e-3 at the start) / 323.15
    assert deviation(t, ref, t, ours, 1e-4, tolerance=1e-6) == pytest.approx(1.2e-3 / (323.15 + 1e-4), rel=1e-9)
    # without the reference's tolerance the same drift is a range, and 1.2e-3 K is 12 of it
    assert deviation(t, ref, t, ours, 1e-4) == pytest.approx(12.0, rel=1e-9)
    # a range the reference resolves keeps it: a pressure of 1 bar moving by 50 Pa (5e-4 of it)
    p = 1e5 + 50.0 * t / 100.0
    assert deviation(t, p, t, p + 1.0, 1e-4, tolerance=1e-6) == pytest.approx(1.0 / 50.0, rel=1e-9)


def test_an_emptying_tank_of_the_msl_reference_is_constant_and_the_filling_one_is_not():
    if not (default_reference() / "Modelica" / "Fluid").is_dir():
        pytest.skip(f"the MSL reference results are not at {default_reference()} (set TRACKINGBOX_MSL_REFERENCE)")
    # AST_BatchPlant.Test.TwoTanks: tank1 (50 degC) only drains into tank2 (100 degC), so its
    # temperature stays at 323.15 K while tank2's falls; the reference was made at tolerance 1e-6
    ref = load_reference(default_reference(), "Modelica.Fluid.Examples.AST_BatchPlant.Test.TwoTanks")
    assert ref is not None and ref.tolerance == pytest.approx(1e-6)
    t1, t2 = ref.values["tank1.medium.T"], ref.values["tank2.medium.T"]
    off = 1e-3  # a millikelvin everywhere
    assert deviation(ref.time, t1, ref.time, t1 + off, 1e-4, ref.tolerance) == pytest.approx(off / t1.max())
    assert deviation(ref.time, t2, ref.time, t2 + off, 1e-4, ref.tolerance) == pytest.approx(off / (t2.max() - t2.min()))


def test_an_event_a_hair_later_is_not_a_deviation_but_a_missing_jump_is():
    # reference: a step at t = 0.5 recorded twice (before and after); ours finds it 1e-6 later
    ref_t = np.array([0.0, 0.25, 0.5, 0.5, 0.75, 1.0])
    ref_y = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])
    our_t = np.array([0.0, 0.25, 0.500001, 0.500001, 0.75, 1.0])
    our_y = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])
    assert deviation(ref_t, ref_y, our_t, our_y, 1e-4) == 0.0
    never = np.zeros(6)  # the step never happens: off by the whole range
    assert deviation(ref_t, ref_y, our_t, never, 1e-4) == pytest.approx(1.0)


def test_a_ramp_an_event_starts_a_hair_later_is_not_a_deviation_but_a_wrong_slope_or_a_late_event_is():
    """PumpingSystem's pump speed: a trapezoid rising at 400 rpm/s to 1200 rpm from an on/off controller's
    switch, which ours finds 4.6 ms after the reference (a pressure crossing its threshold at 7 Pa/s): read at
    the reference's points alone, 1.8 rpm (1.5e-3 of the range) along the ramp; within the window (0.2 s,
    1e-4 of the 2000 s horizon) the same trajectory, a hair later, is no deviation."""
    def trapezoid(t, start, rate=400.0):
        return np.clip((t - start) * rate, 0.0, 1200.0)
    ref_t = np.round(np.arange(0.0, 2000.0001, 0.2), 10)
    ref_y = trapezoid(ref_t, 1905.11886)
    our_t = np.sort(np.r_[ref_t, 1905.11886 + 0.0046, 1905.11886 + 0.0046 + 3.0])
    window = 1e-4 * 2000.0
    assert deviation(ref_t, ref_y, our_t, trapezoid(our_t, 1905.11886 + 0.0046), 0.0) == pytest.approx(
        0.0046 * 400 / 1200, rel=1e-6)
    assert deviation(ref_t, ref_y, our_t, trapezoid(our_t, 1905.11886 + 0.0046), window) == 0.0
    # the switch 0.5 s late: 0.3 s of it beyond the window, 120 rpm
    assert deviation(ref_t, ref_y, our_t, trapezoid(our_t, 1905.61886), window) == pytest.approx(0.1, rel=1e-6)
    # a ramp 10 % too slow: at its end (3 s in) 1/11 of it is 0.27 s, beyond the window
    slow = trapezoid(our_t, 1905.11886, rate=400.0 / 1.1)
    assert deviation(ref_t, ref_y, our_t, slow, window) > 1e-2


def test_compare_names_the_worst_signal_and_the_missing_ones():
    t = np.linspace(0, 1, 5)
    ref = Reference(("a", "b", "c"), t, {"a": t, "b": 2 * t, "c": t}, Path("x.csv"))
    worst, where, missing = compare(ref, t, {"a": t + 0.01, "b": 2 * t + 0.1})
    assert where == "b" and worst == pytest.approx(0.05)
    assert missing == ["c"]


def test_load_reference_reads_signals_and_columns(tmp_path):
    folder = tmp_path / "Lib" / "Examples" / "Decay"
    folder.mkdir(parents=True)
    (folder / "comparisonSignals.txt").write_text("time\nx\n")
    (folder / "Decay.csv").write_text('"time","x","y"\n0,1,5\n1,0.5,6\n')
    ref = load_reference(tmp_path, "Lib.Examples.Decay")
    assert ref is not None and ref.signals == ("x",)
    assert list(ref.time) == [0.0, 1.0] and list(ref.values["x"]) == [1.0, 0.5]
    assert load_reference(tmp_path, "Lib.Examples.Other") is None
    (folder / "comparisonSignals.txt").write_text("time\nz\n")
    with pytest.raises(ValueError, match="lacks the comparison signals z"):
        load_reference(tmp_path, "Lib.Examples.Decay")


def test_the_reference_tolerance_is_read_and_simulated_with(tmp_path, monkeypatch):
    """The Modelica Association made its references with the experiment's Tolerance times 0.1 (1e-6
    without one) and says so in creation.txt: the harness integrates with the same tolerance (it used
    the experiment's own, ten times looser, e.g. 1e-6 for FluidHeatFlow's WaterPump made with 1e-7)."""
    import fmpy

    from trackingbox.compiler import msl_harness

    folder = tmp_path / "Lib" / "Examples" / "Decay"
    folder.mkdir(parents=True)
    (folder / "comparisonSignals.txt").write_text("time\nx\n")
    (folder / "Decay.csv").write_text('"time","x"\n0,1\n1,0.5\n')
    assert load_reference(tmp_path, "Lib.Examples.Decay").tolerance is None  # no creation.txt
    (folder / "creation.txt").write_text("StopTime=1 // from model\n"
                                         "Tolerance=1e-07 // used annotation from model, multiplied by 0.1\n")
    ref = load_reference(tmp_path, "Lib.Examples.Decay")
    assert ref.tolerance == 1e-7
    assert msl_harness.relative_tolerance(1e-6, None) == 1e-7  # the same rule without a creation.txt
    assert msl_harness.relative_tolerance(1e-3, None) == 1e-6  # never looser than 1e-6
    assert msl_harness.relative_tolerance(None, None) == 1e-6

    class Experiment:  # what fmpy reads from a DefaultExperiment with Tolerance = 1e-6
        startTime, stopTime, tolerance, stepSize = "0", "1", "1e-6", None

    class Description:
        defaultExperiment = Experiment()
        modelVariables = []

    used = {}

    def fake_simulate(fmu, **kwargs):
        used.update(kwargs)
        return np.array([(0.0,), (1.0,)], dtype=[("time", float)])

    monkeypatch.setattr(fmpy, "read_model_description", lambda _: Description())
    monkeypatch.setattr(fmpy, "simulate_fmu", fake_simulate)
    msl_harness.simulate(tmp_path / "x.fmu", ref)
    assert used["relative_tolerance"] == 1e-7
    msl_harness.simulate(tmp_path / "x.fmu", None)
    assert used["relative_tolerance"] == 1e-7  # the experiment's 1e-6, times 0.1


def test_refusals_group_by_construct_without_names_or_places():
    a = {"model": "P.A", "outcome": "refused", "message": "unsupported Modelica construct in P.A: when-clause at "
         "/x/P/A.mo:12. The embedded backend cannot compile it; use --backend openmodelica"}
    b = {"model": "P.B", "outcome": "refused", "message": "unsupported Modelica construct in P.B: when-clause at "
         "/x/P/Lib.mo:7, /x/P/B.mo:3. The embedded backend cannot compile it"}
    c = {"model": "P.C", "outcome": "refused", "message": "unsupported Modelica construct in P.C: discrete variable "
         "'c.y' at /x/P/C.mo:4: only Real variables are supported"}
    d = {"model": "P.D", "outcome": "error", "message": "P.D is structurally singular: 12 equations for 13 "
         "unknowns; variables not determined by any equation: x"}
    assert construct_of(a) == construct_of(b) == "when-clause"
    assert construct_of(c) == "discrete variable …"
    assert construct_of(d) == "<model> is structurally singular: N equations for N unknowns"


LIBRARY = {
    "package.mo": "package Lib\nend Lib;\n",
    "Examples/package.mo": "within Lib;\npackage Examples\nend Examples;\n",
    "Examples/Decay.mo": ("within Lib.Examples;\nmodel Decay\n  parameter Real k = 1.5;\n"
                          "  Real x(start = 2, fixed = true);\nequation\n  der(x) = -k*x;\n"
                          "  annotation(experiment(StopTime = 2, Interval = 0.01));\nend Decay;\n"),
    "Examples/Off.mo": ("within Lib.Examples;\nmodel Off\n  extends Decay;\n"
                        "  annotation(experiment(StopTime = 2, Interval = 0.01));\nend Off;\n"),
    "Examples/NoReference.mo": ("within Lib.Examples;\nmodel NoReference\n  extends Decay(k = 0.5);\n"
                                "  annotation(experiment(StopTime = 1));\nend NoReference;\n"),
    "Examples/Foreign.mo": ("within Lib.Examples;\nmodel Foreign\n  function f\n    input Real u;\n"
                            "    output Real y;\n    external \"C\" y = lib_f(u);\n  end f;\n  Real y;\n"
                            "equation\n  y = f(time);\n  annotation(experiment(StopTime = 1));\nend Foreign;\n"),
    "Examples/Partial.mo": ("within Lib.Examples;\npartial model Partial\n  Real z;\n"
                            "  annotation(experiment(StopTime = 1));\nend Partial;\n"),
}


def _reference(root: Path, model: str, k: float) -> None:
    folder = root.joinpath(*model.split("."))
    folder.mkdir(parents=True)
    (folder / "comparisonSignals.txt").write_text("time\nx\n")
    t = np.linspace(0.0, 2.0, 401)
    rows = "\n".join(f"{float(a)!r},{2.0 * math.exp(-k * float(a))!r}" for a in t)  # the closed form of der(x) = -k x
    (folder / f"{model.rsplit('.', 1)[-1]}.csv").write_text('"time","x"\n' + rows + "\n")


@pytest.mark.compile
def test_a_run_classifies_each_example_and_resumes(tmp_path, capsys):
    lib = tmp_path / "Lib"
    for rel, text in LIBRARY.items():
        (lib / rel).parent.mkdir(parents=True, exist_ok=True)
        (lib / rel).write_text(text)
    ref = tmp_path / "ref"
    _reference(ref, "Lib.Examples.Decay", 1.5)
    _reference(ref, "Lib.Examples.Off", 1.6)  # the model decays at 1.5: about 3.5e-2 of the range off
    out = tmp_path / "res.jsonl"
    args = ["--msl", str(lib), "--reference", str(ref), "--package", "Lib.Examples", "--out", str(out),
            "--timeout", "300"]
    assert main([*args, "--list"]) == 0
    listed = capsys.readouterr().out.split()
    assert listed == ["Lib.Examples.Decay", "Lib.Examples.Foreign", "Lib.Examples.NoReference", "Lib.Examples.Off"]
    assert main([*args, "--match", "Decay"]) == 0
    capsys.readouterr()
    assert main([*args, "--resume"]) == 0
    printed = capsys.readouterr().out
    results = {json.loads(line)["model"]: json.loads(line) for line in out.read_text().splitlines()}
    assert len(out.read_text().splitlines()) == 4  # Decay was not run again
    outcome = {m.rsplit(".", 1)[-1]: r["outcome"] for m, r in results.items()}
    assert outcome == {"Decay": "match", "Off": "wrong", "NoReference": "simulated", "Foreign": "refused"}
    assert results["Lib.Examples.Decay"]["deviation"] < 1e-4
    assert 2e-2 < results["Lib.Examples.Off"]["deviation"] < 5e-2
    assert "external function" in results["Lib.Examples.Foreign"]["construct"]
    assert results["Lib.Examples.Decay"]["peak_mb"] > 0 and results["Lib.Examples.Decay"]["compile_s"] > 0
    assert "Lib.Examples" in printed and "external function" in printed
    # the table of the file alone gives the same counts
    assert main(["--table", str(out)]) == 0
    again = capsys.readouterr().out
    assert again.strip() == table(list(results.values()), ["Lib.Examples"]).strip()


@pytest.mark.compile
def test_the_harness_gives_cvode_the_steps_a_fast_oscillation_needs(tmp_path):
    """x'' = -(2 pi 2000)^2 x over 0.5 s with the experiment's 0.1 s output steps: 1000 periods per
    output step, beyond fmpy's 500 CVODE steps per interval: fmpy's own call stops early, the
    harness's simulation reaches the end with finite values."""
    import fmpy

    from trackingbox.compiler import compile_model
    from trackingbox.compiler.msl_harness import simulate

    src = tmp_path / "Fast.mo"
    src.write_text("model Fast\n  Real x(start = 1, fixed = true);\n  Real v(start = 0, fixed = true);\n"
                   "equation\n  der(x) = v;\n  der(v) = -(2*3.141592653589793*2000)^2*x;\n"
                   "  annotation(experiment(StopTime = 0.5, Interval = 0.1));\nend Fast;\n")
    fmu = compile_model(src, "Fast", backend="embedded", output=tmp_path / "f.fmu").fmu
    with pytest.raises(Exception, match="mxstep|CVode"):
        fmpy.simulate_fmu(str(fmu), stop_time=0.5, output_interval=0.1, relative_tolerance=1e-6)
    time_, _, problem = simulate(fmu, None)  # finite values to the end (no reference: no signals back)
    assert problem == "" and time_[-1] == pytest.approx(0.5)


@pytest.mark.compile
def test_a_failed_simulation_says_what_the_fmu_logged(tmp_path):
    """x^2 + p = 0 has no real root: the FMU stops in fmi3ExitInitializationMode and logs why; the
    harness's simulation keeps that message (a sim-failed line used to say only which call failed)."""
    from trackingbox.compiler import compile_model
    from trackingbox.compiler.msl_harness import simulate

    src = tmp_path / "G.mo"
    src.write_text("model G\n  parameter Real p = 0.5;\n  Real x(start = 0.3);\ninitial equation\n  x^2 + p = 0;\n"
                   "equation\n  der(x) = -x;\nend G;\n")
    fmu = compile_model(src, "G", backend="embedded", output=tmp_path / "g.fmu").fmu
    errors: list[str] = []
    with pytest.raises(Exception, match="fmi3ExitInitializationMode"):
        simulate(fmu, None, errors)
    assert any("initialisation failed at t = 0 s" in e for e in errors), errors
