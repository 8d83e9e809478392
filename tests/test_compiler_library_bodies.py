"""Library functions rumoca 0.10.2 cannot take, read by it with an equivalent body
(:data:`trackingbox.compiler.rewrite.LIBRARY_BODIES`): the MSL's ``Modelica.Math.Vectors.interpolate``
(while loops, an output assigned on one branch), which every friction element of the MSL's
mechanics calls. Checked against numpy's piecewise-linear interpolation and against the closed form
of an inertia braked by bearing friction until it sticks."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler.rewrite import LIBRARY_BODIES, replace_library_bodies

MATH = MSL / "Math" / "package.mo"


def _need_msl() -> None:
    need_msl("Math", "package.mo")


def test_interpolate_is_replaced_in_place_keeping_every_line_and_byte_offset():
    _need_msl()
    data = MATH.read_bytes()
    new, done = replace_library_bodies(data)
    assert [name for name, _ in done] == ["Modelica.Math.Vectors.interpolate", "Modelica.Math.Matrices.isEqual"]
    assert len(new) == len(data) and new.count(b"\n") == data.count(b"\n")
    # everything outside the function's protected part and algorithm is untouched
    diff = [k for k in range(len(data)) if data[k] != new[k]]
    head = data.find(b'function interpolate "Interpolate linearly in a vector"')
    end = data.find(b"end interpolate;", head)
    head2 = data.find(b'function isEqual "Compare whether two Real matrices are identical"')
    end2 = data.find(b"end isEqual;", head2)
    assert diff and all(head < k < end or head2 < k < end2 for k in diff)
    assert any(k < end for k in diff) and any(k > head2 for k in diff)
    for a, b in ((head, end), (head2, end2)):
        assert b"while" in data[a:b] and b"while" not in new[a:b]


def test_a_function_whose_text_differs_is_left_alone():
    _need_msl()
    data = MATH.read_bytes()
    head = data.find(b'function interpolate "Interpolate linearly in a vector"')
    edited = data[:head] + data[head:].replace(b"i := i + 1;", b"i := i + 2;", 1)
    assert edited != data
    new, done = replace_library_bodies(edited)
    assert [name for name, _ in done] == ["Modelica.Math.Matrices.isEqual"]
    assert new[head:edited.find(b"end interpolate;", head)] == edited[head:edited.find(b"end interpolate;", head)]
    # the digest is of the code only: a changed comment does not matter
    recommented = data[:head] + data[head:].replace(b"// search forward", b"// forward search", 1)
    assert recommented != data
    assert replace_library_bodies(recommented)[1]
    assert all(len(lib.digest) == len(hashlib.sha256().hexdigest()) for lib in LIBRARY_BODIES)


@pytest.mark.compile
def test_interpolate_matches_numpy_with_extrapolation_and_its_index_output(tmp_path):
    """y = interpolate(x, y, time) over a table with a jump-free but uneven grid, extrapolated
    linearly before the first and after the last point as the MSL documents; iNew the interval."""
    _need_msl()
    import fmpy

    from trackingbox.compiler import compile_model

    src = tmp_path / "Interp.mo"
    src.write_text(
        "model Interp\n"
        "  parameter Real xs[4] = {0, 0.5, 2, 3};\n  parameter Real ys[4] = {1, 2, -1, 0.5};\n"
        "  Real y;\n  discrete Real yd;\n  Integer i;\n"
        "equation\n  y = Modelica.Math.Vectors.interpolate(xs, ys, time - 1, 2);\n"
        "algorithm\n  when sample(0.0625, 0.125) then\n"
        "    (yd, i) := Modelica.Math.Vectors.interpolate(xs, ys, time - 1);\n  end when;\nend Interp;\n")
    res = compile_model(src, "Interp", backend="embedded", output=tmp_path / "i.fmu", libraries=[MSL])
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=5.0, output_interval=0.125, output=["y", "i"])
    xs, ys = np.array([0, 0.5, 2, 3.0]), np.array([1, 2, -1, 0.5])
    t = out["time"] - 1
    k = np.clip(np.searchsorted(xs, t, side="right") - 1, 0, len(xs) - 2)  # the interval, 0-based
    expect = ys[k] + (ys[k + 1] - ys[k]) * (t - xs[k]) / (xs[k + 1] - xs[k])
    inside = (t >= xs[0]) & (t <= xs[-1])
    assert np.allclose(expect[inside], np.interp(t[inside], xs, ys))  # the expectation itself
    assert np.allclose(out["y"], expect, atol=1e-9)
    # i: the interval at the last sample, 0.0625 before each point of the output grid (fmpy also
    # records the sample instants themselves, before and after the event)
    grid = (out["time"] > 0) & np.isclose(out["time"] / 0.125, np.round(out["time"] / 0.125))
    ts = out["time"][grid] - 0.0625 - 1
    ks = np.clip(np.searchsorted(xs, ts, side="right") - 1, 0, len(xs) - 2)
    assert grid.sum() == 40 and np.array_equal(out["i"][grid], ks + 1)


@pytest.mark.compile
def test_interpolate_on_decreasing_abscissae_stops_the_run_with_the_msl_message(tmp_path):
    _need_msl()
    from trackingbox.compiler import compile_model
    from trackingbox.errors import AssertionFailed
    from trackingbox.fmu import FMUModel

    src = tmp_path / "Bad.mo"
    src.write_text(
        "model Bad\n  parameter Real xs[3] = {0, 2, 1};\n  Real y;\n"
        "equation\n  y = Modelica.Math.Vectors.interpolate(xs, {1, 2, 3}, time);\nend Bad;\n")
    res = compile_model(src, "Bad", backend="embedded", output=tmp_path / "b.fmu", libraries=[MSL])
    with FMUModel(res.fmu) as model, pytest.raises(AssertionFailed) as exc:
        model.simulate(stop_time=1.0, output_interval=0.5, outputs=["y"])
    assert exc.value.message == "Abscissa table vector values must be increasing"


@pytest.mark.compile
def test_bearing_friction_brakes_an_inertia_to_a_stop_as_its_closed_form_says(tmp_path):
    """An inertia (J = 1, w0 = 1) on Rotational.Components.BearingFriction with tau_pos = [0, 0.5;
    1, 1] (friction torque 0.5 + 0.5 w): dw/dt = -(1 + w)/2, so w = 2 exp(-t/2) - 1 until it stops
    at t = 2 ln 2 and phi = 4 (1 - exp(-t/2)) - t; then it stays stuck (no torque drives it)."""
    _need_msl()
    import fmpy

    from trackingbox.compiler import compile_model

    src = tmp_path / "Braked.mo"
    src.write_text(
        "model Braked\n"
        "  Modelica.Mechanics.Rotational.Components.Inertia J(J = 1, w(start = 1, fixed = true), "
        "phi(start = 0, fixed = true));\n"
        "  Modelica.Mechanics.Rotational.Components.BearingFriction bf(tau_pos = [0, 0.5; 1, 1]);\n"
        "equation\n  connect(J.flange_b, bf.flange_a);\nend Braked;\n")
    res = compile_model(src, "Braked", backend="embedded", output=tmp_path / "f.fmu", libraries=[MSL])
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=3.0, output_interval=0.05, output=["J.w", "J.phi", "bf.locked"],
                            relative_tolerance=1e-8)
    t = out["time"]
    stop = 2 * np.log(2)
    w = np.where(t < stop, 2 * np.exp(-t / 2) - 1, 0.0)
    phi = 4 * (1 - np.exp(-np.minimum(t, stop) / 2)) - np.minimum(t, stop)
    assert np.max(np.abs(out["J.w"] - w)) < 1e-5
    assert np.max(np.abs(out["J.phi"] - phi)) < 1e-5
    assert not out["bf.locked"][t < stop - 0.01].any() and out["bf.locked"][t > stop + 0.01].all()


@pytest.mark.compile
def test_function_locals_sized_by_an_input_critical_damping_filter_matches_scipy(tmp_path):
    """Blocks.Continuous.Filter (CriticalDamping, low pass, order 3, f_cut = 1 Hz, normalized) computes
    its coefficients in functions whose local arrays are sized by an input (``Real den1[order]``) and
    filled element by element. Normalised critical damping is n equal real poles placed so that the
    gain at f_cut is -3 dB: H(s) = 1/(alpha s/w + 1)^n, alpha = sqrt(10^(0.3/n) - 1), w = 2 pi f_cut.
    Its response to a unit step at t = 0.5 s (steady start at 0) against scipy's."""
    _need_msl()
    import fmpy
    from scipy import signal

    from trackingbox.compiler import compile_model

    src = tmp_path / "Filt.mo"
    src.write_text(
        "model Filt\n"
        "  Modelica.Blocks.Continuous.Filter f(analogFilter = Modelica.Blocks.Types.AnalogFilter.CriticalDamping, "
        "filterType = Modelica.Blocks.Types.FilterType.LowPass, order = 3, f_cut = 1);\n"
        "  Modelica.Blocks.Sources.Step u(startTime = 0.5);\n"
        "equation\n  connect(u.y, f.u);\nend Filt;\n")
    res = compile_model(src, "Filt", backend="embedded", output=tmp_path / "f.fmu", libraries=[MSL])
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=2.5, output_interval=0.01, output=["f.y"],
                            relative_tolerance=1e-8)
    n, w = 3, 2 * np.pi
    tau = np.sqrt(10 ** (0.3 / n) - 1) / w
    den = np.poly1d([tau, 1.0]) ** n
    t = out["time"]
    after = t > 0.5 + 1e-9
    # scipy's step response starts at T[0]: give it the step's own instant first
    _, y = signal.step(signal.lti([1.0], den.coeffs), T=np.concatenate([[0.0], t[after] - 0.5]))
    y = y[1:]
    assert np.max(np.abs(out["f.y"][~after])) < 1e-9
    assert np.max(np.abs(out["f.y"][after] - y)) < 1e-5
