"""An array of components whose size is a parameter of another component (issue 35:
``Modelica.Fluid.Examples.BranchingDynamicPipes`` declares ``FixedHeatFlow[pipe2.nNodes] heat2``).
rumoca 0.10.2 sizes the array's variables but instantiates its class's equations once, so the model
comes back "unbalanced" (4 equations short there, nNodes = 5: one per element after the first); it is
refused naming the declaration. The same model with the size as a parameter of the model itself is
read right; its values are worked by hand."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import UnsupportedConstructError

pytestmark = pytest.mark.compile

PACKAGE = """package H
  connector HP
    Real T;
    flow Real Q_flow;
  end HP;
  model HT
    parameter Integer n = 1;
    input Real[n] Ts;
    output Real[n] Q_flows;
    HP[n] heatPorts;
  equation
    Q_flows = heatPorts.Q_flow;
    Q_flows = {2*(heatPorts[i].T - Ts[i]) for i in 1:n};
  end HT;
  model Pipe "as Modelica.Fluid's pipes: conditional heat ports connected to the heat transfer's"
    parameter Boolean use = true;
    parameter Integer nNodes = 3;
    HP[nNodes] heatPorts if use;
    HT heatTransfer(n = nNodes, Ts = {300 + 10*i for i in 1:nNodes});
  equation
    connect(heatPorts, heatTransfer.heatPorts);
  end Pipe;
  model Src
    HP port;
    parameter Real Q = 10;
  equation
    port.Q_flow = -Q;
  end Src;
  model Top
    Pipe pipe;
    Src[pipe.nNodes] heat;
  equation
    connect(heat.port, pipe.heatPorts);
  end Top;
  model TopN "the size as a parameter of the model itself"
    parameter Integer N = 3;
    Pipe pipe(nNodes = N);
    Src[N] heat;
  equation
    connect(heat.port, pipe.heatPorts);
  end TopN;
  model PipeX "nNodes given by an extends clause: not the declaration's value"
    extends Pipe(nNodes = 3);
  end PipeX;
  model TopX
    PipeX pipe;
    Src[pipe.nNodes] heat;
  equation
    connect(heat.port, pipe.heatPorts);
  end TopX;
end H;
"""


@pytest.fixture
def pkg(tmp_path):
    path = tmp_path / "H.mo"
    path.write_text(PACKAGE)
    return path


def test_an_array_sized_by_another_components_parameter_is_refused_at_its_declaration(pkg, tmp_path):
    """TopX: the pipe's class takes nNodes from an extends clause, which compiler.component_sizes
    does not read (H.Top, where Pipe's declaration fixes it, is read as its number: below)."""
    with pytest.raises(UnsupportedConstructError) as info:
        compile_model(pkg, "H.TopX", backend="embedded", output=tmp_path / "t.fmu")
    msg = str(info.value)
    assert "an array of components whose size is a parameter of another component" in msg
    assert f"{pkg}:47 (`heat`)" in msg  # `Src[pipe.nNodes] heat;` (line counted by hand)
    assert "balance = -2" in msg  # 3 elements, one equation each, instantiated once


@pytest.mark.parametrize("model", ["H.TopN", "H.Top"])
def test_the_same_array_sized_by_the_models_own_parameter_is_read_right(pkg, tmp_path, model):
    """TopN: the size a parameter of the model; Top: pipe.nNodes as Pipe declares it (3)."""
    res = compile_model(pkg, model, backend="embedded", output=tmp_path / "n.fmu")
    names = [f"pipe.heatTransfer.heatPorts[{i}].T" for i in (1, 2, 3)]
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=names)
    # each source pushes 10 W into its port: 10 = 2 (T_i - Ts_i), Ts_i = 300 + 10 i
    for i, name in enumerate(names, start=1):
        assert np.allclose(out[name], 300 + 10 * i + 5.0)


def test_the_readme_lists_the_construct():
    from pathlib import Path

    from trackingbox.compiler.embedded import COMPONENT_SIZED_ARRAY

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    assert "an array of components whose size is a" in readme and "`FixedHeatFlow[pipe2.nNodes] heat2`" in readme
    assert COMPONENT_SIZED_ARRAY.startswith("an array of components whose size is a parameter of another component")
