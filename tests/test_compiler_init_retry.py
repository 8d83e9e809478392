"""An initial solve whose start value lies outside a function's domain (issue 35: MSL
``Fluid.Examples.AST_BatchPlant.BatchPlant_StandardWater``): the FMU retries with the guess moved
(``compiler.fmi_runtime.INIT_RETRIES``) and says so in a warning; a problem with no solution still fails.

MSL declares ``BaseProperties.h`` as ``input SI.SpecificEnthalpy`` with no start value, so Newton starts
at 0 J/kg; at 1 atm that is below IF97's region 1 (the liquid at 273.15 K has 61.01 J/kg, ``iapws``), where
MSL's ``waterBaseProp_ph`` asserts and the traced function gives NaN, and below 1 kJ/kg ``aux.h :=
max(h, 1e3)`` leaves T(p, h) flat. Expectations: the closed form e exp(-t) of ``log(x) = 1`` from a
start where ``log`` is undefined, and the ``iapws`` package's IAPWS-IF97 (an independent implementation)
for the water model."""
from __future__ import annotations

import math

import fmpy
import numpy as np
import pytest
from _fixtures_msl import need_msl

from trackingbox.compiler import compile_model
from trackingbox.compiler.fmi_runtime import INIT_RETRIES

pytestmark = pytest.mark.compile


def _simulate(fmu, names, stop=1.0):
    messages = []

    def logger(*args):
        m = args[-1]
        messages.append(m.decode(errors="replace") if isinstance(m, bytes) else str(m))

    out = fmpy.simulate_fmu(str(fmu), stop_time=stop, output_interval=0.25, output=names, logger=logger,
                            relative_tolerance=1e-8)
    return out, messages


def test_a_start_outside_the_domain_is_moved_and_the_root_found(tmp_path):
    src = tmp_path / "LogStart.mo"
    src.write_text("""model LogStart "log(x) = 1 from x = -1, where log is undefined"
  Real x(start = -1);
initial equation
  log(x) = 1;
equation
  der(x) = -x;
end LogStart;
""")
    fmu = compile_model(src, "LogStart", backend="embedded", output=tmp_path / "ls.fmu").fmu
    out, messages = _simulate(fmu, ["x"])
    assert np.allclose(out["x"], math.e * np.exp(-out["time"]), rtol=1e-6)
    # -1 + 1 = 0 (log gives -inf) and -1 - 1 fail; -1 + 10 = 9 converges
    assert any("from the start values the solve gives x = nan; solved from the guess x = 9 instead" in m
               for m in messages), messages


def test_a_problem_without_solution_still_fails(tmp_path):
    src = tmp_path / "NoRoot.mo"
    src.write_text("""model NoRoot "x*x = -1 has no real root"
  Real x(start = 0.5);
initial equation
  x*x + 1 = 0;
equation
  der(x) = -x;
end NoRoot;
""")
    fmu = compile_model(src, "NoRoot", backend="embedded", output=tmp_path / "nr.fmu").fmu
    messages = []
    with pytest.raises(Exception, match="fmi3ExitInitializationMode"):
        fmpy.simulate_fmu(str(fmu), stop_time=1.0, logger=lambda *a: messages.append(str(a[-1])))
    assert any("initialisation failed" in m for m in messages), messages


def test_msl_if97_medium_initialised_by_its_temperature_from_h_0_matches_iapws(tmp_path):
    """B5's medium as in ``BatchPlant_StandardWater`` (``Modelica.Media.Water.StandardWater`` at
    101325 Pa, ``medium.T = 293.15`` initially), heated at 1 kW per kg."""
    iapws = pytest.importorskip("iapws", reason="the iapws package (a test dependency) is not installed")
    msl = need_msl().parent
    src = tmp_path / "Tank.mo"
    src.write_text("""model Tank
  replaceable package Medium = Modelica.Media.Water.StandardWater
    constrainedby Modelica.Media.Interfaces.PartialTwoPhaseMedium;
  Medium.BaseProperties medium(preferredMediumStates = true, p(start = 101325), T(start = 293.15));
  Real U;
equation
  medium.p = 101325;
  U = medium.h;
  der(U) = 1000;
initial equation
  medium.T = 293.15;
end Tank;
""")
    fmu = compile_model(src, "Tank", backend="embedded", output=tmp_path / "tank.fmu", libraries=[msl]).fmu
    out, messages = _simulate(fmu, ["medium.h", "medium.T", "medium.d"])
    assert any("from the start values the solve gives medium.h = nan" in m for m in messages), messages
    assert out["medium.T"][0] == pytest.approx(293.15, abs=1e-6)
    assert np.allclose(np.diff(out["medium.h"]), 250.0, rtol=1e-6)  # 1 kW/kg for 0.25 s
    for row in out:
        ref = iapws.IAPWS97(P=0.101325, h=float(row["medium.h"]) / 1000)
        assert ref.region == 1
        # IF97's backward equation T(p, h) agrees with the basic equation to 25 mK in region 1
        assert row["medium.T"] == pytest.approx(ref.T, abs=0.025)
        slope = abs(iapws.IAPWS97(P=0.101325, T=ref.T + 0.01).rho - iapws.IAPWS97(P=0.101325, T=ref.T - 0.01).rho) / 0.02
        assert row["medium.d"] == pytest.approx(ref.rho, abs=slope * 0.025 + 1e-6 * ref.rho)
    assert INIT_RETRIES >= 7  # 0 + 1000 J/kg (the seventh guess) is the first where T(p, h) has a slope
