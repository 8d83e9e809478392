"""Events in the embedded compiler (issue 35, item 2): when-clauses, reinit, discrete variables, pre,
edge, initial(), sample(), relations and integer() that switch, each checked against a closed-form
solution; the FMU's event indicators and discrete variables as FMI 3 describes them."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
import zipfile

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile

MODELS = """
package Ev
  model Ball "a ball dropped from 1 m bounces with a restitution of 0.8"
    parameter Real e = 0.8;
    parameter Real g = 9.81;
    Real h(start = 1, fixed = true);
    Real v(start = 0, fixed = true);
    Integer bounces(start = 0);
    discrete Real last(start = -1);
  equation
    der(h) = v;
    der(v) = -g;
    when h < 0 then
      reinit(v, -e*pre(v));
      bounces = pre(bounces) + 1;
      last = time;
    end when;
  end Ball;
  model Thermostat "two-point control: heating on below 1, off above 2"
    Real x(start = 1.5, fixed = true);
    Boolean on(start = true, fixed = true);
    Integer switches(start = 0);
  equation
    der(x) = if on then 1 else -1;
    on = if pre(on) then x < 2 else x < 1;
    when change(on) then
      switches = pre(switches) + 1;
    end when;
  end Thermostat;
  model Clock "sample(): a counter at t = 0.5, 0.75, 1.0, ...; initial(); integer() of a continuous value"
    Real x(start = 0, fixed = true);
    Integer ticks(start = 0);
    Integer n;
    discrete Real x0;
    Real y;
  equation
    der(x) = 2;
    when sample(0.5, 0.25) then
      ticks = pre(ticks) + 1;
    end when;
    n = integer(time/0.3);
    when initial() then
      x0 = x + 7;
    end when;
    y = if x > 1.1 then 1 else 0;
  end Clock;
  model Bound "discrete variables given by their declaration's binding"
    parameter Boolean on = true;
    Boolean late = time > 0.5;
    Boolean both = late and on;
    Integer n = if both then 2 else 1;
  end Bound;
  model Latch "a when-statement in an algorithm keeps x where it passed 1"
    Real x(start = 0, fixed = true);
    discrete Real m(start = 0);
  algorithm
    when x > 1 then
      m := x;
    end when;
  equation
    der(x) = 1;
  end Latch;
end Ev;
"""


@pytest.fixture(scope="module")
def ev(tmp_path_factory):
    src = tmp_path_factory.mktemp("ev") / "Ev.mo"
    src.write_text(MODELS)
    return src


def fmu_of(ev, tmp_path, name):
    return compile_model(ev, f"Ev.{name}", backend="embedded", output=tmp_path / f"{name}.fmu").fmu


def test_a_bouncing_ball_bounces_where_the_closed_form_says(ev, tmp_path):
    fmu = fmu_of(ev, tmp_path, "Ball")
    out = fmpy.simulate_fmu(str(fmu), stop_time=2.5, output_interval=0.01, output=["h", "v", "bounces", "last"],
                            relative_tolerance=1e-9, record_events=False)
    g, e = 9.81, 0.8
    impacts = [math.sqrt(2 / g)]
    speed = g * impacts[0] * e
    while impacts[-1] < 2.5:
        impacts.append(impacts[-1] + 2 * speed / g)
        speed *= e
    t = out["time"]
    count = np.searchsorted(impacts, t, side="right")
    assert np.array_equal(out["bounces"], count)
    before = np.where(count > 0, np.array(impacts)[np.maximum(count - 1, 0)], -1.0)
    assert np.allclose(out["last"], before, atol=1e-7)
    # the height between impacts: a parabola from the last impact with speed g t1 e^k
    v0 = np.where(count > 0, g * impacts[0] * e ** count, 0.0)
    dt = np.where(count > 0, t - before, t)
    h = np.where(count > 0, v0 * dt - g / 2 * dt ** 2, 1 - g / 2 * t ** 2)
    assert np.allclose(out["h"], h, atol=1e-6)


def test_a_thermostat_switches_on_its_thresholds(ev, tmp_path):
    fmu = fmu_of(ev, tmp_path, "Thermostat")
    out = fmpy.simulate_fmu(str(fmu), stop_time=4.0, output_interval=0.05, output=["x", "on", "switches"],
                            relative_tolerance=1e-9, record_events=False)
    t = out["time"]
    # from 1.5 rising: 2 at t = 0.5, 1 at 1.5, 2 at 2.5, 1 at 3.5 (a triangle wave)
    phase = np.mod(t - 0.5, 2.0)
    x = np.where(t < 0.5, 1.5 + t, np.where(phase < 1.0, 2.0 - phase, phase))
    assert np.allclose(out["x"], x, atol=1e-6)
    # an output point at a switching instant is recorded before the event there
    assert np.array_equal(out["switches"], np.searchsorted([0.5, 1.5, 2.5, 3.5], t, side="left"))


def test_sample_initial_and_integer_events(ev, tmp_path):
    fmu = fmu_of(ev, tmp_path, "Clock")
    out = fmpy.simulate_fmu(str(fmu), stop_time=2.0, output_interval=0.02, output=["ticks", "n", "x0", "y"],
                            relative_tolerance=1e-9, record_events=False)
    t = out["time"]
    instants = 0.5 + 0.25 * np.arange(7)
    assert np.array_equal(out["ticks"], np.searchsorted(instants, t + 1e-9, side="right"))
    away = np.abs(t / 0.3 - np.round(t / 0.3)) > 1e-6  # points on a switch (0.3, 0.6, ...) may be either side
    assert np.array_equal(out["n"][away], np.floor(t[away] / 0.3))
    assert np.allclose(out["x0"], 7.0)  # when initial(): x(0) + 7
    assert np.array_equal(out["y"], (2 * t > 1.1 + 1e-9).astype(float))


def test_a_when_statement_in_an_algorithm(ev, tmp_path):
    fmu = fmu_of(ev, tmp_path, "Latch")
    out = fmpy.simulate_fmu(str(fmu), stop_time=2.0, output_interval=0.1, output=["m"], relative_tolerance=1e-9,
                            record_events=False)
    # the output point at t = 1 is recorded before the event there
    assert np.allclose(out["m"], np.where(out["time"] < 1.0 + 1e-9, 0.0, 1.0), atol=1e-6)


def test_the_fmu_describes_its_discrete_variables_and_event_indicators(ev, tmp_path):
    fmu = fmu_of(ev, tmp_path, "Ball")
    with zipfile.ZipFile(fmu) as zf:
        root = ET.fromstring(zf.read("modelDescription.xml"))
    variables = {v.get("name"): v for v in root.find("ModelVariables")}
    for name in ("bounces", "last"):
        assert variables[name].get("variability") == "discrete"
        assert variables[name].get("causality") == "local"
    indicators = root.find("ModelStructure").findall("EventIndicator")
    assert len(indicators) == 1  # h < 0
    assert fmpy.read_model_description(str(fmu)).numberOfEventIndicators == 1


def test_the_trackingbox_stepper_runs_an_fmu_with_events(ev, tmp_path):
    from trackingbox.fmu import FMUModel

    fmu = fmu_of(ev, tmp_path, "Thermostat")
    with FMUModel(fmu, tolerance=1e-9) as model:
        res = model.simulate(stop_time=4.0, output_interval=0.5, outputs=["x"])
    t = np.asarray(res["time"])
    x = np.asarray(res["x"])
    phase = np.mod(t - 0.5, 2.0)
    assert np.allclose(x, np.where(t < 0.5, 1.5 + t, np.where(phase < 1.0, 2.0 - phase, phase)), atol=1e-6)


def test_discrete_variables_bound_in_their_declaration(ev, tmp_path):
    fmu = fmu_of(ev, tmp_path, "Bound")
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.1, output=["late", "both", "n"],
                            record_events=False)
    late = (out["time"] > 0.5 + 1e-9).astype(float)
    assert np.array_equal(out["late"], late) and np.array_equal(out["both"], late)
    assert np.array_equal(out["n"], 1 + late)
