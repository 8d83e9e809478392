"""An FMU whose relation is flipped back by its own event (``der(x) = if x > 0 then -1 else 1``:
at x = 0 each event reverses the slope, the next crossing comes 1e-10 later, and an integrator
would creep on for ever) stops with an error that says the model chatters, where it does, instead
of hanging; a model with many events that are not a burst runs to its end."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.fmi_runtime import CHATTER_EVENTS

pytestmark = pytest.mark.compile


def test_a_chattering_switch_stops_the_run_with_an_error_naming_the_time(tmp_path, capsys):
    src = tmp_path / "Chatter.mo"
    src.write_text("model Chatter\n  Real x(start = 1, fixed = true);\nequation\n"
                   "  der(x) = if x > 0 then -1 else 1;\nend Chatter;\n")
    res = compile_model(src, "Chatter", backend="embedded", output=tmp_path / "c.fmu")
    messages: list[str] = []

    def logger(*args):
        messages.append(args[-1].decode() if isinstance(args[-1], bytes) else str(args[-1]))

    with pytest.raises(Exception, match="fmi3UpdateDiscreteStates"):
        fmpy.simulate_fmu(str(res.fmu), stop_time=2.0, output_interval=0.1, logger=logger)
    text = " ".join(messages) + capsys.readouterr().out
    found = [m for m in text.split("[ERROR]") if "chatters" in m] or [text]
    assert "the model chatters at t = 1.000000" in found[0], text[-500:]  # x reaches 0 at t = 1
    assert f"{CHATTER_EVENTS} events in a row" in found[0]


def test_many_events_spread_out_are_not_chattering(tmp_path):
    """A relation on sin(2 pi 50 t) switches 1200 times in 12 s (more than a burst's count, 10 ms
    apart); the held value integrates to the square wave's mean, t/2 at every whole period."""
    src = tmp_path / "Square.mo"
    src.write_text("model Square\n  Real x(start = 0, fixed = true);\nequation\n"
                   "  der(x) = if sin(2*3.141592653589793*50*time) > 0 then 1 else 0;\nend Square;\n")
    res = compile_model(src, "Square", backend="embedded", output=tmp_path / "s.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=12.0, output_interval=0.002, relative_tolerance=1e-8)
    whole = np.isclose(out["time"], np.round(out["time"]), atol=1e-9) & (out["time"] > 0)
    assert whole.sum() >= 12 and 1200 > CHATTER_EVENTS
    assert np.allclose(out["x"][whole], out["time"][whole] / 2, atol=1e-4)
