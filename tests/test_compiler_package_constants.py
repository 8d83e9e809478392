"""The refusal of a package that extends another with a modified constant while the model also uses
the base (rumoca 0.10.2 would give the base's constant the modified value, .modifiers) counts only
real uses of the base (issue 35: every Modelica.Fluid example with a Media package was refused on
the base's own ``end`` name and on ``replaceable package Medium = PartialMedium``). Expectations
worked by hand from MLS 7.2 and 7.3: the value read through the replacing package is its own."""
from __future__ import annotations

from pathlib import Path

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import UnsupportedConstructError

pytestmark = pytest.mark.compile

LIB = """package Lib
  partial package Base "a medium-like package: partial, its constant modified by its extensions"
    constant Real k = 1;
    replaceable partial function f
      input Real u;
      output Real y;
    end f;
  end Base;
  package Ext
    extends Base(k = 2);
    redeclare function extends f
    algorithm
      y := k*u;
    end f;
  end Ext;
  package Base2 "not partial"
    constant Real k = 1;
  end Base2;
  package Ext2
    extends Base2(k = 3);
  end Ext2;
  model User
    replaceable package Medium = Base constrainedby Base;
    Real y = Medium.f(Medium.k);
  end User;
  model User2
    replaceable package Medium = Base2;
    Real y = Medium.k;
  end User2;
  model Replaced "Base only as the partial default of a replaceable package"
    User user(redeclare package Medium = Ext);
  end Replaced;
  model Direct "Base's constant read by name as well"
    User user(redeclare package Medium = Ext);
    Real z = Base.k;
  end Direct;
  model Replaced2 "a default that is not partial still counts as a use"
    User2 user(redeclare package Medium = Ext2);
  end Replaced2;
end Lib;
"""


def _lib(tmp_path: Path) -> Path:
    src = tmp_path / "Lib.mo"
    src.write_text(LIB)
    return src


def test_a_partial_base_only_as_a_replaceable_default_is_no_use(tmp_path):
    res = compile_model(_lib(tmp_path), "Lib.Replaced", backend="embedded", output=tmp_path / "r.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["user.y"])
    assert np.allclose(out["user.y"], 2.0 * 2.0)  # Ext.f(Ext.k) = k*k with k = 2


@pytest.mark.parametrize("model, base", [("Direct", "Base"), ("Replaced2", "Base2")])
def test_a_base_read_by_name_or_a_default_that_is_not_partial_is_still_refused(tmp_path, model, base):
    with pytest.raises(UnsupportedConstructError, match=rf"extends {base} with a modified constant at .*Lib.mo:\d+"):
        compile_model(_lib(tmp_path), f"Lib.{model}", backend="embedded", output=tmp_path / "x.fmu")
