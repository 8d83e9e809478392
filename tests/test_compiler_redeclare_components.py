"""Class redeclarations with a modification that names a parameter (``redeclare model M =
Base(k = kk*2)``): compiled with their Modelica meaning through a modification of the component,
or refused naming the redeclaration's line (see ``trackingbox.compiler.redeclare_components``).

The expected values are worked by hand from the models below (MLS 7.2.4: the declaration's own
modification wins over the redeclared class's; the redeclaration's expressions are read in the
scope where it stands), never taken from the compiler.
"""
from __future__ import annotations

from pathlib import Path

import fmpy
from fmpy import read_model_description
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import UnsupportedConstructError

pytestmark = pytest.mark.compile

REDECLARED = """
package Redecl
  model Base
    parameter Real k = 1;
    parameter Real j = 2;
    Real y = k*j*(1 + time);
  end Base;
  model Holder
    replaceable model M = Base constrainedby Base;
    M m(j = 3);
  end Holder;
  model Holder2
    extends Holder;
    M n;
  end Holder2;
  model Named "h.m.k = kk*2, h.m.j = 3 (the declaration's)"
    parameter Real kk = 5;
    Holder h(redeclare model M = Base(k = kk*2));
    Real z = h.m.y;
  end Named;
  model TwoComponents "both components of M take the redeclaration's k"
    parameter Real kk = 2;
    Holder2 h(redeclare model M = Base(k = kk + 1));
    Real z = h.m.y + 10*h.n.y;
  end TwoComponents;
  model DeclarationWins "m's declaration gives j = 3: a rewrite to h(m(j = kk)) would give j = kk"
    parameter Real kk = 5;
    Holder h(redeclare model M = Base(j = kk));
  end DeclarationWins;
  model OuterToo "h's own modification of m as well"
    parameter Real kk = 5;
    Holder h(redeclare model M = Base(k = kk), m(j = 4));
  end OuterToo;
  model ThroughExtends
    parameter Real kk = 5;
    extends Holder(redeclare model M = Base(k = kk));
  end ThroughExtends;
  model HolderArray
    replaceable model M = Base;
    M m[2];
  end HolderArray;
  model ArrayOfM "M types an array of components"
    parameter Real kk = 5;
    HolderArray h(redeclare model M = Base(k = kk));
  end ArrayOfM;
end Redecl;
"""


@pytest.fixture(scope="module")
def package(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("redecl") / "Redecl"
    root.mkdir()
    (root / "package.mo").write_text(REDECLARED)
    return root


def _simulate(package: Path, model: str, out: Path, starts: dict | None = None):
    res = compile_model(package, f"Redecl.{model}", backend="embedded", output=out)
    names = {v.name: v for v in read_model_description(str(res.fmu)).modelVariables}
    result = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["z"],
                               start_values=starts or {})
    return names, result


def test_a_named_value_in_a_redeclaration_reaches_the_component_and_stays_tunable(package, tmp_path):
    names, out = _simulate(package, "Named", tmp_path / "n.fmu")
    assert names["kk"].causality == "parameter" and names["kk"].variability == "tunable"
    assert np.allclose(out["z"], 10 * 3 * (1 + out["time"]))  # k = 5*2, j = 3
    _, out = _simulate(package, "Named", tmp_path / "n.fmu", {"kk": 7.0})
    assert np.allclose(out["z"], 14 * 3 * (1 + out["time"]))  # k = 7*2


def test_every_component_of_the_redeclared_class_takes_the_modification(package, tmp_path):
    _, out = _simulate(package, "TwoComponents", tmp_path / "t.fmu")
    # m: k = kk + 1 = 3, j = 3 (its declaration's); n (Holder2): k = 3, j = 2 (Base's default)
    assert np.allclose(out["z"], (3 * 3 + 10 * 3 * 2) * (1 + out["time"]))


@pytest.mark.parametrize("model,line", [
    ("DeclarationWins", 28), ("OuterToo", 32), ("ThroughExtends", 36), ("ArrayOfM", 44),
])
def test_redeclarations_that_would_mean_something_else_stay_refused(package, tmp_path, model, line):
    with pytest.raises(UnsupportedConstructError) as info:
        compile_model(package, f"Redecl.{model}", backend="embedded", output=tmp_path / "r.fmu")
    assert "class redeclaration with a modification" in str(info.value)
    assert f"package.mo:{line}" in str(info.value)
    assert not (tmp_path / "r.fmu").exists()
