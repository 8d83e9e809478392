"""``not`` in a Boolean package constant's binding, which rumoca 0.10.2 leaves unresolved where a model
of the package reads the constant through a component (``Modelica.Media.Incompressible.TableBased``'s
``hasDensity = not (size(tableDensity,1)==0)``), is read as an if-expression
(``compiler.constant_not``). Expectations worked by hand: with ``tab = [0, 3; 1, 5]``, ``hasTab`` is
true, ``c = {3, 5}``, so ``d = 3 + 5*t``; ``noTab = not hasTab and true`` is false, so ``z = 2``;
``odd = not (not hasTab) or false`` is true, so ``w = 7``."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.constant_not import constant_not_as_if

LIB = """package T
  partial package PM
    constant Real[:,2] tab;
    constant Boolean hasTab = not (size(tab,1)==0) "whether the table has rows";
    constant Boolean noTab = not hasTab and true;
    constant Boolean odd = not (not hasTab) // a comment
      or false;
    final constant Real c[:] = if hasTab then {tab[1,2], tab[2,2]} else zeros(2);
    model BP
      Real d;
      Real z = if noTab then 1 else 2;
      Real w = if odd then 7 else 8;
    equation
      assert(hasTab, "no table");
      d = c[1] + c[2]*time;
    end BP;
  end PM;
  package G
    extends PM(tab = [0, 3; 1, 5]);
  end G;
  model Src
    replaceable package M = PM;
    M.BP medium;
  end Src;
  model Top
    Src source(redeclare package M = G);
  end Top;
end T;
"""


def test_the_operand_is_the_relation_after_not_and_lines_stay():
    text = (b'constant Boolean a = not (size(t,1)==0)\n  "desc";\n'
            b'final constant Boolean b[2] = {not x and y, not not_y == 1 or z};  // not here\n'
            b'parameter Boolean p = not q;\n'
            b'constant Boolean c = not (not p) annotation(x = not y);\n')
    out, lines = constant_not_as_if(text)
    assert lines == [1, 3, 5]
    assert out.count(b"\n") == text.count(b"\n")
    assert out.splitlines() == [
        b'constant Boolean a = (if (size(t,1)==0) then false else true)',
        b'  "desc";',
        b'final constant Boolean b[2] = {(if x then false else true) and y, '
        b'(if not_y == 1 then false else true) or z};  // not here',
        b'parameter Boolean p = not q;',
        b'constant Boolean c = (if ((if p then false else true)) then false else true) annotation(x = not y);',
    ]


@pytest.mark.compile
def test_a_package_constant_bound_with_not_is_read_through_a_component(tmp_path):
    src = tmp_path / "T.mo"
    src.write_text(LIB)
    res = compile_model(src, "T.Top", backend="embedded", output=tmp_path / "t.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5,
                            output=["source.medium.d", "source.medium.z", "source.medium.w"])
    assert np.allclose(out["source.medium.d"], 3 + 5 * out["time"])
    assert np.allclose(out["source.medium.z"], 2.0) and np.allclose(out["source.medium.w"], 7.0)
