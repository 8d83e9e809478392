"""Parameters reached through an ``outer`` component, where the front end evaluates them structurally
(an if-equation's condition, an array size), take the ``inner`` declaration's modifications
(issue 35: rumoca 0.10.2 took the class defaults, so every Modelica.Fluid example that sets
``system(energyDynamics = ...FixedInitial)`` lost its vessels' initial equations; see
:mod:`trackingbox.compiler.inner_defaults`). Expected values worked by hand:
der(x) = k - x from x(0) = 2 gives x = k + (2 - k) exp(-t)."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.inner_defaults import patches
from trackingbox.compiler.library import index_for
from trackingbox.compiler.source import resolve_source

pytestmark = pytest.mark.compile

PACKAGE = """package K
  type E = enumeration(Free, Fixed, Steady);
  model Sys
    parameter E dyn = E.Free;
    parameter Real k = 1;
    parameter Integer n = 1;
  end Sys;
  model Sub
    outer Sys system;
    parameter E dyn = system.dyn;
    Real x[system.n](each start = 0);
  initial equation
    if dyn == E.Fixed then
      x = fill(2, system.n);
    elseif dyn == E.Steady then
      der(x) = zeros(system.n);
    end if;
  equation
    der(x) = fill(system.k, system.n) - x;
  end Sub;
  model M
    inner Sys system(dyn = K.E.Fixed, k = 5, n = 3);
    Sub s;
  end M;
end K;
"""


def test_an_outer_parameter_has_the_inner_modification_in_conditions_and_sizes(tmp_path):
    src = tmp_path / "K.mo"
    src.write_text(PACKAGE)
    res = compile_model(src, "K.M", backend="embedded", output=tmp_path / "m.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=2.0, output_interval=0.25, relative_tolerance=1e-9,
                            output=["s.x[1]", "s.x[2]", "s.x[3]"])
    expected = 5 + (2 - 5) * np.exp(-out["time"])
    for i in (1, 2, 3):
        assert np.allclose(out[f"s.x[{i}]"], expected, rtol=1e-5, atol=1e-6)


def test_the_class_defaults_stay_where_the_class_has_other_instances(tmp_path):
    src = tmp_path / "K.mo"
    src.write_text(PACKAGE)
    assert patches(index_for(resolve_source(src), ()), "K.M", {src})  # the inner's class is patched ...
    other = tmp_path / "other" / "K.mo"
    other.parent.mkdir()
    other.write_text(PACKAGE.replace("    Sub s;\n  end M;", "    Sub s;\n    Sys plain;\n  end M;"))
    assert "Sys plain;" in other.read_text()
    assert patches(index_for(resolve_source(other), ()), "K.M", {other}) == {}  # ... not where it has another use


NAMED = """package L
  type E = enumeration(Free, Fixed, Steady);
  package Liquid
    constant Boolean singleState = SINGLE;
  end Liquid;
  model Sys
    parameter E other = E.Fixed;
    parameter E dyn = other;
  end Sys;
  model Sub
    outer Sys system;
    parameter E dyn = system.dyn;
    Real x(start = 2);
  initial equation
    if dyn <> E.Steady then
      x = 2;
    end if;
  equation
    if dyn == E.Steady then
      x = 3;
    elseif dyn == E.Free then
      der(x) = 1 - x;
    else
      der(x) = 5 - x;
    end if;
  end Sub;
  model M
    replaceable package Medium = Liquid;
    parameter E chosen = if Medium.singleState then E.Steady else E.Free;
    inner Sys system(dyn = chosen);
    Sub s;
  end M;
end L;
"""


@pytest.mark.parametrize("single, expected", [("true", lambda t: 3 + 0 * t), ("false", lambda t: 1 + np.exp(-t))],
                         ids=["singleState", "two-states"])
def test_an_inner_modification_naming_a_parameter_reaches_the_outer_conditions(tmp_path, single, expected):
    """``system(massDynamics = systemMassDynamics)`` as Modelica.Fluid.Examples.IncompressibleFluidNetwork
    has it, the model's parameter bound to ``if Medium.singleState then ...``: the outer component takes
    the branch of that value, here one with another structure (rumoca 0.10.2 alone took Sys's default,
    E.Fixed: der(x) = 5 - x). By hand: E.Steady gives x = 3; E.Free, der(x) = 1 - x from x(0) = 2,
    gives x = 1 + exp(-t)."""
    src = tmp_path / "L.mo"
    src.write_text(NAMED.replace("SINGLE", single))
    res = compile_model(src, "L.M", backend="embedded", output=tmp_path / "m.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=2.0, output_interval=0.25, relative_tolerance=1e-9,
                            output=["s.x"])
    assert np.allclose(out["s.x"], expected(out["time"]), rtol=1e-5, atol=1e-6)
