"""An array of records used whole or sliced (issue 35: Modelica.Fluid's pipes set their protected
``Medium.ThermodynamicState[nFM+1] statesFM`` by ``statesFM[2:n+1] = mediums[1:n].state``): the
embedded translation keeps each element's fields as variables of their own (``sFM[1].p``) and builds
no array of record values, so it refuses the construct naming it and the array's declaration, never
an "unknown variable" error."""
from __future__ import annotations

import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import UnsupportedConstructError

pytestmark = pytest.mark.compile

SLICED = """model C
  record S
    Real p;
    Real T;
  end S;
  model Vol
    S state;
    parameter Real k = 1;
  equation
    state.p = k*time;
    state.T = 2*k;
  end Vol;
  Vol vols[2](k = {1, 3});
  S[3] sFM "as Modelica.Fluid's pipes' statesFM";
  Real y = sFM[2].p + sFM[3].T;
equation
  sFM[1].p = 0;
  sFM[1].T = 0;
  sFM[2:3] = vols[1:2].state;
end C;
"""


def test_a_sliced_array_of_records_is_refused_at_its_declaration(tmp_path):
    src = tmp_path / "C.mo"
    src.write_text(SLICED)
    with pytest.raises(UnsupportedConstructError) as info:
        compile_model(src, "C", backend="embedded", output=tmp_path / "c.fmu")
    msg = str(info.value)
    assert "an array of records used whole or sliced (`sFM`" in msg
    assert f"{src}:14" in msg  # the line `S[3] sFM ...` (counted by hand)
