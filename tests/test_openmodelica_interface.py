"""The interface check of OpenModelica builds, on a real FMU of the embedded path.

One small heater is compiled with the embedded backend; copies of its FMU with
variables renamed, turned local or made ``fixed`` in ``modelDescription.xml``
stand for a build that lost names. The expected differences are the edits made.
"""
from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.omc_interface import ExpectedInterface, compare_interface
from trackingbox.errors import CompileError

pytestmark = pytest.mark.compile

HEATER = """
model Heater "Lumped heater: C dT/dt = Q - UA (T - Tamb)"
  parameter Real UA(unit = "W/K") = 50 "Heat loss coefficient";
  parameter Real C(unit = "J/K") = 4000 "Heat capacity";
  parameter Real Tamb(unit = "K") = 293.15 "Ambient temperature";
  input Real Q(unit = "W", start = 500) "Heater power";
  output Real T(unit = "K", start = 293.15, fixed = true) "Temperature";
equation
  C*der(T) = Q - UA*(T - Tamb);
end Heater;
"""


@pytest.fixture(scope="module")
def heater_fmu(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("heater")
    (root / "Heater.mo").write_text(HEATER)
    return compile_model(root / "Heater.mo", "Heater", backend="embedded", output=root / "Heater.fmu").fmu


def edited(fmu: Path, dest: Path, *edits: tuple[str, str]) -> Path:
    """A copy of *fmu* whose modelDescription.xml has each (old, new) text replaced once."""
    with zipfile.ZipFile(fmu) as src:
        xml = src.read("modelDescription.xml").decode()
        for old, new in edits:
            assert xml.count(old) >= 1, f"{old!r} not in the model description"
            xml = xml.replace(old, new, 1)
        with zipfile.ZipFile(dest, "w") as out:
            for item in src.infolist():
                out.writestr(item, xml if item.filename == "modelDescription.xml" else src.read(item.filename))
    return dest


SPEC_NAMES = ExpectedInterface(parameters=("UA", "C"), inputs=("Q",), outputs=("T",))


def test_embedded_fmu_has_the_spec_names(heater_fmu):
    report = compare_interface(heater_fmu, SPEC_NAMES)
    assert report.ok, report.problems
    assert set(ExpectedInterface.from_fmu(heater_fmu).parameters) == {"UA", "C", "Tamb"}


def test_renamed_and_removed_names_are_each_reported(heater_fmu, tmp_path):
    other = edited(heater_fmu, tmp_path / "other.fmu",
                   ('name="UA"', 'name="hx_UA"'),            # renamed (omc-style underscores)
                   ('name="C"', 'name="Cap"'),               # renamed
                   ('causality="output"', 'causality="local"'))  # output no longer an output
    report = compare_interface(other, ExpectedInterface.from_fmu(heater_fmu))
    lines = [str(p) for p in report.problems]
    assert sorted((p.name, p.problem) for p in report.problems) == [
        ("C", "missing"), ("T", "causality"), ("UA", "missing")]
    assert any("parameter 'UA' is not in the FMU (did you mean 'hx_UA'?)" == s for s in lines), lines
    assert "output 'T' is a local variable in the FMU" in lines
    with pytest.raises(CompileError, match=r"other\.fmu does not expose the expected variables \(3 differences\):"
                                           r"\n  parameter 'UA'.*\n  parameter 'C' is not in the FMU\n  output 'T'"):
        report.raise_for_problems()


def _fixed(xml: str, name: str) -> str:
    """*xml* with the variable *name* made ``fixed`` instead of ``tunable``."""
    start = xml.index(f'name="{name}"')
    end = xml.index(">", start)
    assert 'variability="tunable"' in xml[start:end], f"{name} is tunable in the embedded FMU"
    return xml[:start] + xml[start:end].replace('variability="tunable"', 'variability="fixed"') + xml[end:]


def test_input_expected_but_missing_and_fixed_parameter(heater_fmu, tmp_path):
    xml = zipfile.ZipFile(heater_fmu).read("modelDescription.xml").decode()
    changed = _fixed(xml, "Tamb").replace('name="Q"', 'name="P"', 1)
    other = edited(heater_fmu, tmp_path / "fixed.fmu", (xml, changed))
    expected = ExpectedInterface(parameters=("Tamb",), inputs=("Q",), outputs=("T",))
    report = compare_interface(other, expected)
    assert [(p.name, p.problem, p.found) for p in report.problems] == [
        ("Tamb", "not_tunable", "fixed"), ("Q", "missing", "")]
    assert "parameter 'Tamb' is fixed in the FMU, not tunable" in str(report.problems[0])
    assert [p.name for p in compare_interface(other, expected, require_tunable=False).problems] == ["Q"]


def _spec(path: Path, output: str) -> Path:
    path.write_text(f"""twin = "Heater.fmu"
measurements = "m.csv"
sample_time = 10.0
[inputs]
JI-1 = "Q"
[outputs]
TI-1 = "{output}"
[[parameters]]
name = "UA"
start = 50.0
min = 10.0
max = 100.0
[windows]
training = [0.0, 100.0]
validation = [100.0, 200.0]
""")
    return path


def test_compile_command_checks_the_spec_names_on_the_embedded_path(tmp_path, capsys):
    """``compile --spec``: the same name check whatever the backend; a wrong name is an error naming
    it, exit 2, and no FMU is left behind."""
    from trackingbox.cli import main

    (tmp_path / "Heater.mo").write_text(HEATER)
    ok = tmp_path / "ok.fmu"
    assert main(["compile", str(tmp_path / "Heater.mo"), "--model", "Heater", "--backend", "embedded",
                 "-o", str(ok), "--spec", str(_spec(tmp_path / "good.toml", "T"))]) == 0
    assert ok.exists()
    bad = tmp_path / "bad.fmu"
    code = main(["compile", str(tmp_path / "Heater.mo"), "--model", "Heater", "--backend", "embedded",
                 "-o", str(bad), "--spec", str(_spec(tmp_path / "bad.toml", "Tout"))])
    err = capsys.readouterr().err
    assert code == 2
    assert "output 'Tout' is not in the FMU" in err
    assert not bad.exists()
