"""A class that extends a class declared inside itself (the MSL's ``MassWithStopAndFriction``
extends its own ``PartialFrictionWithStop``): valid Modelica that rumoca 0.10.2 rejects, taking
the nested class's references to its own components for the enclosing class's ("reference to
non-constant variable ... from a lexically nested class", MLS 5.3.1). The embedded backend refuses
it naming the ``extends``, its file and line; a nested class that really refers to a non-constant
of its enclosing class keeps rumoca's error."""
from __future__ import annotations

import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import CompileError, UnsupportedConstructError

pytestmark = pytest.mark.compile

SOURCE = """package N
  model SelfExtending
    partial model Inner
      Real s(start = 0, fixed = true);
      Real v(start = 1, fixed = true);
    equation
      v = der(s);
    end Inner;
    extends Inner;
  equation
    der(v) = -s;
  end SelfExtending;
  model ReallyNested
    Real a(start = 1, fixed = true);
    model Inner
      Real b;
    equation
      b = a;
    end Inner;
    Inner inner1;
  equation
    der(a) = -a;
  end ReallyNested;
end N;
"""


def test_extends_of_an_own_nested_class_is_refused_naming_the_extends(tmp_path):
    src = tmp_path / "N.mo"
    src.write_text(SOURCE)
    with pytest.raises(UnsupportedConstructError) as exc:
        compile_model(src, "N.SelfExtending", backend="embedded", output=tmp_path / "m.fmu")
    text = str(exc.value)
    assert "`extends` of a class declared inside the extending class itself" in text
    assert "`extends Inner` in N.SelfExtending" in text
    assert f"{src}:9" in text  # the extends clause's line
    assert not (tmp_path / "m.fmu").exists()


def test_a_nested_class_using_its_enclosing_class_variable_keeps_the_error(tmp_path):
    """MLS 5.3.1: a nested class may use only constants of its enclosing class; ``b = a`` is invalid."""
    src = tmp_path / "N.mo"
    src.write_text(SOURCE)
    with pytest.raises(CompileError) as exc:
        compile_model(src, "N.ReallyNested", backend="embedded", output=tmp_path / "r.fmu")
    assert not isinstance(exc.value, UnsupportedConstructError)
    assert "lexically nested class" in str(exc.value)


def test_the_readme_lists_the_construct():
    from pathlib import Path

    from trackingbox.compiler.embedded import NESTED_EXTENDS

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    assert NESTED_EXTENDS in readme
