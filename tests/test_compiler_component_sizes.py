"""An array of components sized by another component's parameter (``FixedHeatFlow[pipe8.nNodes] heat8``
in ``Modelica.Fluid.Examples.IncompressibleFluidNetwork``), which rumoca 0.10.2 reads with the class's
equations once for the whole array, is given to the front end as its number where the declarations
fix it (``compiler.component_sizes``). Expectations worked by hand: segment i of the pipe, fed by
heater i, has der(x) = q*(1 + x/2), x(0) = 0, so x = 2*(exp(q*t/2) - 1). The modification
``q = 3*p.w`` of the array of heaters gives heater k the value 3*p.w[k] (MLS 7.2.5)."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import UnsupportedConstructError

LIB = """package S
  connector Port
    Real T;
    flow Real Q;
  end Port;
  model Pipe
    parameter Integer n(min=1) = 3 "segments";
    Real x[n];
    parameter Real w[n] = fill(1/n, n);
    Port ports[n];
  initial equation
    x = zeros(n);
  equation
    for i in 1:n loop
      der(x[i]) = ports[i].Q;
      ports[i].T = x[i];
    end for;
  end Pipe;
  model Pipe4
    extends Pipe(n = 4);
  end Pipe4;
  model Heat
    parameter Real q = 1;
    Port port;
  equation
    port.Q = -q*(1 + 0.5*port.T);
  end Heat;
  model Top
    Pipe p;
    Heat[p.n] h(q = {1, 2, 3});
  equation
    connect(h.port, p.ports);
  end Top;
  model Mod
    Pipe p(n = 2);
    Heat[p.n] h(each q = 1);
  equation
    connect(h.port, p.ports);
  end Mod;
  model Ext
    Pipe4 p;
    Heat[p.n] h(each q = 1);
  equation
    connect(h.port, p.ports);
  end Ext;
  model Scaled "h[k].q = (3*p.w)[k] = 1"
    Pipe p;
    Heat[p.n] h(q = 3*
      p.w);
  equation
    connect(h.port, p.ports);
  end Scaled;
end S;
"""


def _x(q, t):
    return 2 * (np.exp(q * t / 2) - 1)


@pytest.mark.compile
@pytest.mark.parametrize("model, n, q", [("S.Top", 3, [1, 2, 3]), ("S.Mod", 2, [1, 1]),
                                                ("S.Scaled", 3, [1, 1, 1])])
def test_a_size_given_by_a_components_parameter_is_read_as_its_declared_value(tmp_path, model, n, q):
    """Top: Pipe's declared n = 3; Mod: the declaration's own modification n = 2; Scaled: n = 3 and
    the modification q = 3*p.w read element-wise (main: 'expression shape mismatch' for Top and
    Scaled, refused for Mod)."""
    src = tmp_path / "S.mo"
    src.write_text(LIB)
    res = compile_model(src, model, backend="embedded", output=tmp_path / "s.fmu")
    names = [f"p.x[{i + 1}]" for i in range(n)]
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.25, output=names)
    for name, qi in zip(names, q):
        assert np.allclose(out[name], _x(qi, out["time"]), rtol=1e-4, atol=1e-6), name


@pytest.mark.compile
def test_a_size_a_base_class_modifies_stays_refused(tmp_path):
    """Pipe4 extends Pipe(n = 4): the value is not the declaration's; the construct is named."""
    src = tmp_path / "S.mo"
    src.write_text(LIB)
    with pytest.raises(UnsupportedConstructError, match=r"an array of components whose size is a parameter "
                                                        r"of another component .* at .*S.mo:42"):
        compile_model(src, "S.Ext", backend="embedded", output=tmp_path / "e.fmu")
