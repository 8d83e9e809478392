"""homotopy(actual, simplified) at initialisation (issue 35: MSL ``Fluid.Examples.HeatingSystem``).
rumoca 0.10.2 keeps only ``actual``; a model whose classes call ``homotopy`` and whose FMU does not
initialise at its defaults is refused naming the calls' file and line, the FMU deleted
(``compiler.init_check``), never left to fail with NaN in the importer. Expectations: the line written
below, and the closed form x(t) = 2 exp(-t) of a model that does initialise (x = 2, the actual root
Newton reaches from the start value 1)."""
from __future__ import annotations

import math

import fmpy
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import UnsupportedConstructError

pytestmark = pytest.mark.compile

NO_ROOT = """model HomotopyNoRoot "the actual initial equation has no real root"
  Real x(start = 0.5);
initial equation
  homotopy(x*x + 1, x + 1) = 0;
equation
  der(x) = -x;
end HomotopyNoRoot;
"""

ROOT = """model HomotopyRoot "Newton from the start value 1 reaches the actual root 2"
  Real x(start = 1);
initial equation
  homotopy(x*x - 4, x - 2) = 0;
equation
  der(x) = -x;
end HomotopyRoot;
"""


def test_homotopy_start_without_solution_is_refused_naming_the_call(tmp_path):
    src = tmp_path / "HomotopyNoRoot.mo"
    src.write_text(NO_ROOT)
    out = tmp_path / "n.fmu"
    with pytest.raises(UnsupportedConstructError) as err:
        compile_model(src, "HomotopyNoRoot", backend="embedded", output=out)
    text = str(err.value)
    assert f"homotopy(actual, simplified) at {src}:4" in text
    assert "initialisation failed" in text  # the FMU's own reason
    assert not out.exists()


def test_homotopy_start_that_initialises_is_kept(tmp_path):
    src = tmp_path / "HomotopyRoot.mo"
    src.write_text(ROOT)
    res = compile_model(src, "HomotopyRoot", backend="embedded", output=tmp_path / "r.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["x"], relative_tolerance=1e-9)
    assert out["x"][0] == pytest.approx(2.0, rel=1e-8)
    assert out["x"][-1] == pytest.approx(2.0 * math.exp(-1.0), rel=1e-6)
