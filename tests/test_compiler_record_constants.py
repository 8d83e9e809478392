"""Fields of package constants of a record type (``dryair.R_s`` in ``Modelica.Media.Air.MoistAir``),
which rumoca 0.10.2 leaves unresolved, are given to the front end as the values their declarations
give them (``compiler.record_constants``). Expectations worked by hand from the declarations below
(MLS 4.4.4, 5.3, 7.2): a constant modified by an extending package keeps the existing refusal."""
from __future__ import annotations

from pathlib import Path

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler import record_constants
from trackingbox.compiler.library import LibraryIndex
from trackingbox.errors import UnsupportedConstructError

LIB = """package R
  record Data
    Real MM;
    Real R_s;
    Real Hf;
  end Data;
  package Consts
    constant Data Air(MM = 0.029, R_s = 287.0, Hf = -1.5e2);
    constant Data N2(MM = 0.028, R_s = 296.8, Hf = 0);
  end Consts;
  partial package Base
    replaceable partial function f
      input Real u;
      output Real y;
    end f;
  end Base;
  package Moist "as Modelica.Media.Air.MoistAir: a record constant bound to another"
    extends Base;
    constant Data dryair = Consts.Air;
    constant Real ratio = dryair.MM/0.018;
    redeclare function extends f
    algorithm
      y := dryair.R_s*u + 2 - dryair.Hf + ratio;
    end f;
    function shadowed "an input of the same name: dryair.R_s is the input's"
      input Data dryair;
      output Real y;
    algorithm
      y := dryair.R_s;
    end shadowed;
  end Moist;
  package Other "the constant modified by an extension: its functions see N2"
    extends Moist(dryair = Consts.N2);
  end Other;
  model User
    replaceable package Medium = Base;
    Real y = Medium.f(3);
  end User;
  model Top
    User user(redeclare package Medium = Moist);
  end Top;
  model TopOther
    User user(redeclare package Medium = Other);
  end TopOther;
end R;
"""


def _lib(tmp_path: Path) -> Path:
    src = tmp_path / "R.mo"
    src.write_text(LIB)
    return src


@pytest.mark.compile
def test_a_field_of_a_record_constant_is_read_as_its_declared_value(tmp_path):
    res = compile_model(_lib(tmp_path), "R.Top", backend="embedded", output=tmp_path / "t.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["user.y"])
    # 287*3 + 2 - (-150) + 0.029/0.018
    assert np.allclose(out["user.y"], 287.0 * 3 + 2 + 150.0 + 0.029 / 0.018, rtol=1e-12)


@pytest.mark.compile
def test_a_record_constant_modified_by_an_extension_is_still_refused(tmp_path):
    with pytest.raises(UnsupportedConstructError, match=r"dryair"):
        compile_model(_lib(tmp_path), "R.TopOther", backend="embedded", output=tmp_path / "o.fmu")


def test_only_references_that_find_the_record_constant_are_replaced(tmp_path):
    index = LibraryIndex.build([_lib(tmp_path)])
    found = record_constants.replacements(index, "R.Top")[tmp_path / "R.mo"]
    lines = LIB.splitlines()
    seen = {(lines[line - 1].strip(), ref, value) for line, refs in found.items() for ref, value in refs}
    assert seen == {
        ("constant Real ratio = dryair.MM/0.018;", "dryair.MM", "0.029"),
        ("y := dryair.R_s*u + 2 - dryair.Hf + ratio;", "dryair.R_s", "287.0"),
        ("y := dryair.R_s*u + 2 - dryair.Hf + ratio;", "dryair.Hf", "-1.5e2"),
    }  # not the input of `shadowed` (line of `y := dryair.R_s;`)
    assert record_constants.replacements(index, "R.TopOther") == {}  # Other modifies dryair
