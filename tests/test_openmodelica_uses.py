"""The ``uses`` annotation parser of the OpenModelica backend, on inline sources.

Expectations are read off the sources by hand: which entries a modeller wrote
in a class's ``annotation(uses(...))``, on which line, and which look-alikes
(comments, strings, nested modifiers) are not uses.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from trackingbox.compiler.omc_uses import LibraryUse, library_uses, merge_uses, parse_uses
from trackingbox.errors import CompileError


def names(uses):
    return [(u.name, u.version, u.line) for u in uses]


def test_one_library_with_version():
    text = 'package P\nannotation(uses(Modelica(version="4.0.0")));\nend P;\n'
    assert names(parse_uses(text, "P.mo")) == [("Modelica", "4.0.0", 2)]


def test_several_libraries_over_lines_and_next_to_other_annotations():
    text = '''within;
package Plant "A plant"
  model M
    Real x annotation(Dialog(group="uses(Fake(version=\\"1\\"))"));
  equation
    der(x) = -x;
  end M;
  annotation (
    Documentation(info="<html>annotation(uses(Doc(version=\\"0.1\\")))</html>"),
    Icon(graphics={Text(extent={{-100,-100},{100,100}}, textString="uses(X)")}),
    uses(Modelica(version = "4.0.0"),
         Buildings(version="11.0.0"),
         ModelicaServices(version="4.0.0")),
    version="1.2.0");
end Plant;
'''
    assert names(parse_uses(text, "Plant/package.mo")) == [
        ("Modelica", "4.0.0", 11), ("Buildings", "11.0.0", 12), ("ModelicaServices", "4.0.0", 13)]


def test_comments_are_not_uses():
    text = '''package P
  // annotation(uses(Commented(version="1.0")))
  /* annotation(uses(Block(version="2.0")));
     more */
  annotation(uses(Modelica(version="3.2.3") /* not (uses(Y)) */));
end P;
'''
    assert names(parse_uses(text)) == [("Modelica", "3.2.3", 5)]


def test_uses_nested_in_another_modifier_is_not_a_use():
    text = 'package P annotation(__Vendor(uses(Other(version="1"))), uses(Modelica(version="4.0.0"))); end P;'
    assert names(parse_uses(text)) == [("Modelica", "4.0.0", 1)]


def test_entry_without_version_and_escaped_quote_in_version():
    text = 'package P annotation(uses(Modelica, Lib(version="1.0 \\"beta\\""))); end P;'
    assert [(u.name, u.version) for u in parse_uses(text)] == [("Modelica", None), ("Lib", '1.0 "beta"')]


def test_no_annotation_no_uses():
    assert parse_uses("model M\n  Real x = 1;\nend M;\n") == ()


@pytest.mark.parametrize("text, line", [
    ('package P\nannotation(uses(Modelica(version="4.0.0"));\nend P;', 2),   # annotation never closes
    ('package P annotation(uses(Modelica(version=4)));\nend P;', 1),          # version is not a string
    ('package P\n annotation(uses("Modelica"));\nend P;', 2),                  # not a name
])
def test_malformed_uses_names_file_and_line(text, line):
    with pytest.raises(CompileError, match=rf"P\.mo:{line}:"):
        parse_uses(text, "P.mo")


def test_merge_keeps_one_per_library_and_skips_provided():
    f = Path("a.mo")
    uses = [LibraryUse("Modelica", "4.0.0", f, 1), LibraryUse("TrackingBox", None, f, 2),
            LibraryUse("Modelica", None, f, 3), LibraryUse("Buildings", "11.0.0", f, 4)]
    assert names(merge_uses(uses, {"TrackingBox"})) == [("Modelica", "4.0.0", 1), ("Buildings", "11.0.0", 4)]


def test_unversioned_then_versioned_takes_the_version():
    f = Path("a.mo")
    merged = merge_uses([LibraryUse("Modelica", None, f, 1), LibraryUse("Modelica", "4.0.0", f, 7)])
    assert names(merged) == [("Modelica", "4.0.0", 7)]


def test_conflicting_versions_name_both_places():
    uses = [LibraryUse("Modelica", "4.0.0", Path("lib/package.mo"), 3),
            LibraryUse("Modelica", "3.2.3", Path("src.mo"), 9)]
    with pytest.raises(CompileError, match=r"Modelica: '4\.0\.0' at lib/package\.mo:3 and '3\.2\.3' at src\.mo:9"):
        merge_uses(uses)


def test_library_uses_reads_package_mo(tmp_path):
    lib = tmp_path / "Lib"
    lib.mkdir()
    (lib / "package.mo").write_text('package Lib\nannotation(uses(Modelica(version="4.0.0")));\nend Lib;\n')
    assert names(library_uses(lib)) == [("Modelica", "4.0.0", 2)]
    with pytest.raises(CompileError, match="has no package.mo"):
        library_uses(tmp_path)
