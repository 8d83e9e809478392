"""Expandable connectors: a member no connection reaches is not part of the model (MLS 9.1.3).

rumoca 0.10.2 kept such members as unknowns without equations, and the MSL's ``BusUsage`` (whose
``ControlBus`` declares ``realSignal2``, never connected) was refused as structurally singular.
Checked on a hand-written bus whose values are known in closed form, and on ``BusUsage`` itself:
every signal put on the bus arrives where it is read.
"""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model
from trackingbox.compiler.expandable import absent_members

pytestmark = pytest.mark.compile

BUS = """
package Bus
  connector RealInput = input Real;
  connector RealOutput = output Real;
  expandable connector SubBus
    Real myReal;
    Real unused;
  end SubBus;
  expandable connector CBus
    Real r1;
    Real r2 "declared, never connected";
    SubBus sub;
  end CBus;
  block Src
    parameter Real w = 1;
    RealOutput y;
  equation
    y = sin(w*time);
  end Src;
  block Gain
    RealInput u;
    RealOutput y;
  equation
    y = 2*u;
  end Gain;
  model Part
    SubBus sub;
    Src s2(w = 3);
  equation
    connect(s2.y, sub.myReal);
  end Part;
  model M
    Src sine;
    Gain gain;
    Gain gain2;
    Part part;
  protected
    CBus bus;
  equation
    connect(sine.y, bus.r1);
    connect(part.sub, bus.sub);
    connect(gain.u, bus.r1);
    connect(gain2.u, bus.sub.myReal);
  end M;
end Bus;
"""


def test_the_members_nothing_connects_are_the_absent_ones():
    flat = {"variables": {
        "bus.r1": {"from_expandable_connector": True, "connected": True, "binding": None},
        "bus.r2": {"from_expandable_connector": True, "connected": False, "binding": None},
        "bus.r3": {"from_expandable_connector": True, "connected": False, "binding": None},
        "x": {"from_expandable_connector": False, "connected": False, "binding": None}},
        # an equation that reads an unconnected member keeps it (the model is then judged by its equations)
        "equations": [{"residual": {"Binary": {"lhs": {"VarRef": {"name": {"name": "x"}}},
                                               "rhs": {"VarRef": {"name": {"name": "bus.r3"}}}}}}]}
    assert absent_members(flat) == ["bus.r2"]


def test_a_bus_carries_its_signals_and_drops_the_members_nothing_connects(tmp_path):
    src = tmp_path / "Bus.mo"
    src.write_text(BUS)
    fmu = compile_model(src, "Bus.M", backend="embedded", output=tmp_path / "m.fmu").fmu
    names = {v.name for v in fmpy.read_model_description(str(fmu)).modelVariables}
    assert {"bus.r1", "bus.sub.myReal", "part.sub.myReal"} <= names
    assert not names & {"bus.r2", "bus.sub.unused", "part.sub.unused"}
    out = fmpy.simulate_fmu(str(fmu), stop_time=2.0, output_interval=0.01,
                            output=["gain.y", "gain2.y", "bus.r1", "bus.sub.myReal"])
    t = out["time"]
    assert np.max(np.abs(out["bus.r1"] - np.sin(t))) < 1e-12
    assert np.max(np.abs(out["gain.y"] - 2 * np.sin(t))) < 1e-12
    assert np.max(np.abs(out["bus.sub.myReal"] - np.sin(3 * t))) < 1e-12
    assert np.max(np.abs(out["gain2.y"] - 2 * np.sin(3 * t))) < 1e-12


def test_msl_bus_usage_delivers_every_signal_put_on_its_bus(tmp_path):
    """BusUsage: sine (f = 1 Hz) -> bus -> gain (k = 1); an IntegerStep (2, +1 at 0.5 s) and a
    BooleanStep (at 0.5 s) on the bus; a sub-bus with time and time >= 0.5 from ``part``."""
    need_msl()
    fmu = compile_model(MSL, "Modelica.Blocks.Examples.BusUsage", backend="embedded",
                        output=tmp_path / "bus.fmu").fmu
    names = {v.name for v in fmpy.read_model_description(str(fmu)).modelVariables}
    assert "controlBus.realSignal2" not in names  # declared in ControlBus, never connected
    wanted = ["gain.y", "controlBus.realSignal1", "controlBus.integerSignal", "controlBus.booleanSignal",
              "controlBus.subControlBus.myRealSignal", "controlBus.subControlBus.myBooleanSignal"]
    out = fmpy.simulate_fmu(str(fmu), stop_time=2.0, output_interval=0.01, output=wanted)
    t = out["time"]
    assert t[-1] == pytest.approx(2.0)
    assert np.max(np.abs(out["gain.y"] - np.sin(2 * np.pi * t))) < 1e-9
    assert np.max(np.abs(out["controlBus.realSignal1"] - np.sin(2 * np.pi * t))) < 1e-9
    assert np.max(np.abs(out["controlBus.subControlBus.myRealSignal"] - t)) < 1e-9
    away = np.abs(t - 0.5) > 1e-6
    after = t > 0.5
    assert np.array_equal(out["controlBus.integerSignal"][away], np.where(after, 3, 2)[away])
    assert np.array_equal(out["controlBus.booleanSignal"][away].astype(bool), after[away])
    assert np.array_equal(out["controlBus.subControlBus.myBooleanSignal"][away].astype(bool), after[away])
