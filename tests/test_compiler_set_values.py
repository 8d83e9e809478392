"""The embedded backend's FMU keeps its cached evaluation when the importer sets a value it already
holds, bit for bit (fmpy's CVODE sets the states twice at each output point to the same values:
:mod:`trackingbox.compiler.fmi_export`, ``_SET_FLOAT64_PATCHED``), and evaluates again whenever any
value set differs. Checked by setting states and a parameter through the FMI 3 C API and reading an
output and the derivatives, against values worked by hand."""
from __future__ import annotations

import ctypes
import math
import shutil

import fmpy
import pytest
from fmpy.fmi3 import FMU3Model

from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile

MODEL = """
model Two
  parameter Real k = 2;
  Real x1(start = 1, fixed = true);
  Real x2(start = 2, fixed = true);
  output Real y;
equation
  der(x1) = -k*x1;
  der(x2) = x1 - x2;
  y = x1 + 10*x2;
end Two;
"""


def test_setting_states_and_parameters_reevaluates_exactly_when_a_value_changes(tmp_path):
    src = tmp_path / "Two.mo"
    src.write_text(MODEL)
    fmu = compile_model(src, "Two", backend="embedded", output=tmp_path / "two.fmu").fmu
    md = fmpy.read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = fmpy.extract(str(fmu), unzipdir=str(tmp_path / "two"))
    model = FMU3Model(guid=md.guid, unzipDirectory=unzipped,
                      modelIdentifier=md.modelExchange.modelIdentifier, instanceName="two")
    model.instantiate()
    try:
        model.enterInitializationMode()
        model.exitInitializationMode()
        model.enterContinuousTimeMode()
        model.setTime(0.0)

        def after(states: list[float]) -> tuple[float, list[float]]:
            model.setContinuousStates((ctypes.c_double * 2)(*states), 2)
            ders = (ctypes.c_double * 2)()
            model.getContinuousStateDerivatives(ders, 2)
            return model.getFloat64([vr["y"]])[0], list(ders)

        # hand-worked: y = x1 + 10 x2, der(x1) = -k x1, der(x2) = x1 - x2, k = 2
        assert after([1.0, 2.0]) == (21.0, [-2.0, -1.0])
        assert after([1.0, 2.0]) == (21.0, [-2.0, -1.0])  # the same values again
        assert after([1.0, 3.0]) == (31.0, [-2.0, -2.0])  # only the second state changes
        assert after([4.0, 3.0]) == (34.0, [-8.0, 1.0])   # only the first
        y, d = after([-0.0, 3.0])                            # -0.0 after 4.0, then after 0.0
        assert (y, d) == (30.0, [0.0, -3.0])
        y, d = after([math.nan, 3.0])
        assert math.isnan(y) and math.isnan(d[0])
        assert after([5.0, 3.0]) == (35.0, [-10.0, 2.0])  # from NaN back to a number
        model.setFloat64([vr["k"]], [3.0])                     # a parameter set to a new value
        assert after([5.0, 3.0]) == (35.0, [-15.0, 2.0])
        model.setFloat64([vr["k"]], [3.0])                     # and to the same one
        assert after([5.0, 3.0]) == (35.0, [-15.0, 2.0])
        model.setTime(1.0)                                      # time does not enter: unchanged values
        assert after([5.0, 3.0]) == (35.0, [-15.0, 2.0])
    finally:
        model.terminate()
        model.freeInstance()
        shutil.rmtree(unzipped, ignore_errors=True)
