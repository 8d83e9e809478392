"""StateGraph-style steps and transitions in the embedded compiler (issue 35): initial equations that
relate only ``pre`` values of several discrete variables (``pre(newActive) = pre(localActive)``),
closed through the model's own equations (``localActive = pre(newActive)``), solved as one discrete
initialisation problem (MLS 8.6), then the Boolean equations of steps and transitions in the event
iteration. The blocks below are small hand-written copies of the structure of Modelica.StateGraph's
PartialStep, InitialStep, Step and PartialTransition; every expected sequence is worked by hand."""
from __future__ import annotations

import re

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import CompileError

pytestmark = pytest.mark.compile

MODELS = """
package SG
  connector StepIn
    output Boolean occupied;
    input Boolean set;
  end StepIn;
  connector StepOut
    output Boolean available;
    input Boolean reset;
  end StepOut;
  connector TransIn
    input Boolean available;
    output Boolean reset;
  end TransIn;
  connector TransOut
    input Boolean occupied;
    output Boolean set;
  end TransOut;
  partial block PartialStep
    output Boolean localActive;
    StepIn inPort;
    StepOut outPort;
    Boolean newActive;
    Boolean oldActive;
  initial equation
    pre(newActive) = pre(localActive);
    pre(oldActive) = pre(localActive);
  equation
    localActive = pre(newActive);
    newActive = inPort.set or localActive and not outPort.reset;
    oldActive = localActive;
    inPort.occupied = localActive;
    outPort.available = localActive;
  end PartialStep;
  block InitialStep
    output Boolean active;
    extends PartialStep;
  initial equation
    active = true;
  equation
    active = localActive;
  end InitialStep;
  block Step
    output Boolean active;
    extends PartialStep;
  initial equation
    active = false;
  equation
    active = localActive;
  end Step;
  block Transition
    input Boolean condition = true;
    parameter Boolean enableTimer = false;
    parameter Real waitTime = 0;
    TransIn inPort;
    TransOut outPort;
    Boolean enableFire;
    Boolean fire;
    discrete Real t_start;
  initial equation
    pre(t_start) = time;
    pre(enableFire) = false;
  equation
    when enableFire then
      t_start = time;
    end when;
    fire = enableFire and (not enableTimer or time >= t_start + waitTime);
    enableFire = condition and inPort.available and not outPort.occupied;
    inPort.reset = fire;
    outPort.set = fire;
  end Transition;
  model Cycle "s0 -> t1 (1 < time < 2) -> s1 -> t2 (time > 2.5) -> s0"
    InitialStep s0;
    Transition t1(condition = time > 1 and time < 2);
    Step s1;
    Transition t2(condition = time > 2.5);
    Real x(start = 0, fixed = true) "time spent in s1";
  equation
    connect(s0.outPort, t1.inPort);
    connect(t1.outPort, s1.inPort);
    connect(s1.outPort, t2.inPort);
    connect(t2.outPort, s0.inPort);
    der(x) = if s1.active then 1 else 0;
  end Cycle;
  model Timed "s0 -> t1 (time > 1) -> s1 -> t2 (0.75 s after s1 became active) -> s2"
    InitialStep s0;
    Transition t1(condition = time > 1);
    Step s1;
    Transition t2(enableTimer = true, waitTime = 0.75);
    Step s2;
    Real x(start = 0, fixed = true) "time spent in s1";
  equation
    connect(s0.outPort, t1.inPort);
    connect(t1.outPort, s1.inPort);
    connect(s1.outPort, t2.inPort);
    connect(t2.outPort, s2.inPort);
    s0.inPort.set = false "not connected";
    s2.outPort.reset = false "not connected";
    der(x) = if s1.active then 1 else 0;
  end Timed;
  model AtStart "the first transition's condition already holds at t = 0: s1 from the start"
    InitialStep s0;
    Transition t1(condition = time < 0.5);
    Step s1;
    Transition t2(condition = time > 2);
    Real x(start = 0, fixed = true) "time spent in s1";
  equation
    connect(s0.outPort, t1.inPort);
    connect(t1.outPort, s1.inPort);
    connect(s1.outPort, t2.inPort);
    connect(t2.outPort, s0.inPort);
    der(x) = if s1.active then 1 else 0;
  end AtStart;
  model Loop "two discrete initial values that only a system of two equations gives"
    discrete Real i;
    discrete Real j;
  initial equation
    i + j = 3;
    i - j = 1;
  equation
    when time > 1 then
      i = pre(i) + 1;
      j = pre(j) + 1;
    end when;
  end Loop;
end SG;
"""


@pytest.fixture(scope="module")
def sg(tmp_path_factory):
    src = tmp_path_factory.mktemp("sg") / "SG.mo"
    src.write_text(MODELS)
    return src


def run(sg, tmp_path, name, stop, names):
    fmu = compile_model(sg, f"SG.{name}", backend="embedded", output=tmp_path / f"{name}.fmu").fmu
    return fmpy.simulate_fmu(str(fmu), stop_time=stop, output_interval=0.125, output=names,
                             relative_tolerance=1e-8, record_events=False)


def test_the_initial_step_is_active_and_the_steps_follow_their_transitions(sg, tmp_path):
    out = run(sg, tmp_path, "Cycle", 4.0, ["s0.active", "s1.active", "x"])
    t = out["time"]
    # by hand: s0 on [0, 1], s1 on (1, 2.5], s0 again after 2.5 (t1's condition is false by then)
    in_s1 = (t > 1) & (t <= 2.5)
    assert np.array_equal(out["s1.active"].astype(bool), in_s1)
    assert np.array_equal(out["s0.active"].astype(bool), ~in_s1)
    assert np.allclose(out["x"], np.clip(t - 1, 0, 1.5), atol=1e-6)


def test_a_timer_transition_fires_its_wait_time_after_the_step_became_active(sg, tmp_path):
    out = run(sg, tmp_path, "Timed", 3.0, ["s0.active", "s1.active", "s2.active", "x", "t2.t_start"])
    t = out["time"]
    # by hand: s1 from t = 1, t2 enabled then (t_start = 1), fires at 1 + 0.75; s2 from then on
    assert np.array_equal(out["s0.active"].astype(bool), t <= 1)
    assert np.array_equal(out["s1.active"].astype(bool), (t > 1) & (t <= 1.75))
    assert np.array_equal(out["s2.active"].astype(bool), t > 1.75)
    assert np.allclose(out["x"], np.clip(t - 1, 0, 0.75), atol=1e-6)
    assert np.allclose(out["t2.t_start"][t > 1.01], 1.0, atol=1e-6)


def test_a_transition_whose_condition_holds_at_the_start_fires_after_initialisation(sg, tmp_path):
    out = run(sg, tmp_path, "AtStart", 3.0, ["s0.active", "s1.active", "x"])
    t = out["time"]
    # by hand: s0 active at initialisation; the event iteration after it fires t1 (time < 0.5), so s1
    # holds from t = 0 until t2 fires at t = 2; then s0, and t1's condition no longer holds
    assert out["s1.active"][t > 0][0] == 1 and out["s1.active"][t > 2.01].max() == 0
    assert np.allclose(out["x"], np.clip(t, 0, 2), atol=1e-6)


def test_a_loop_among_discrete_initial_values_is_refused_at_its_line(sg, tmp_path):
    with pytest.raises(CompileError) as err:
        compile_model(sg, "SG.Loop", backend="embedded", output=tmp_path / "Loop.fmu")
    msg = str(err.value)
    assert "loop among discrete initial values" in msg
    line = MODELS.splitlines().index("    i + j = 3;") + 1
    assert re.search(rf"SG\.mo:{line}\b", msg), msg
    assert not (tmp_path / "Loop.fmu").exists()
