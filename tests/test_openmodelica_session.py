"""The exact omc command sequence of the OpenModelica backend, through a recording session.

``Recorder`` is our test fixture for the session interface (``sendExpression``,
``close``): it records what the backend sends and answers from a script written
in each test (``true`` unless told otherwise, no messages, and for
``buildModelFMU`` a copy of an FMU the test names). It is not a model of omc's
behaviour: the tests check our sequence and our handling of the replies.
"""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from trackingbox.compiler import compile_model, library_path, omc_available
from trackingbox.compiler.omc_interface import ExpectedInterface
from trackingbox.compiler.openmodelica import build_commands, compile_openmodelica, run_build
from trackingbox.compiler.source import resolve_source
from trackingbox.errors import CompileError

from _fixtures_generate import write_case

BUILD = 'buildModelFMU({model}, version="2.0", fmuType="me_cs", fileNamePrefix="{prefix}", platforms={{"static"}})'
FLAGS = ['setCommandLineOptions("--fmiFilter=internal")', 'setCommandLineOptions("--fmiFlags=s:cvode")']


class Recorder:
    """Records expressions; replies from ``script`` (expression prefix -> (reply, getErrorString reply))."""

    def __init__(self, script: dict[str, tuple[str, str]] | None = None, fmu: Path | None = None):
        self.script = script or {}
        self.fmu = fmu
        self.sent: list[str] = []
        self.closed = False
        self._errors = '""'
        self._cwd: Path | None = None

    def sendExpression(self, expr: str) -> str:  # noqa: N802
        self.sent.append(expr)
        if expr == "getErrorString()":
            errors, self._errors = self._errors, '""'
            return errors
        reply, self._errors = next((v for k, v in self.script.items() if expr.startswith(k)), ("true", '""'))
        if expr.startswith("cd("):
            self._cwd = Path(expr[4:-2])
            return f'"{self._cwd}"'
        if expr.startswith("buildModelFMU(") and self.fmu is not None and reply == "true":
            prefix = re.search(r'fileNamePrefix="(\w+)"', expr).group(1)
            shutil.copyfile(self.fmu, self._cwd / f"{prefix}.fmu")
            return f'"{self._cwd / (prefix + ".fmu")}"'
        return reply

    def close(self) -> None:
        self.closed = True

    def commands(self) -> list[str]:
        """What was sent, without the getErrorString() after every command (checked separately)."""
        assert self.sent[1::2] == ["getErrorString()"] * (len(self.sent) // 2)
        return self.sent[0::2]


def _run(src, model, workdir, libraries=(), **kw):
    rec = Recorder(**kw)
    source = resolve_source(src)
    commands = build_commands(source, model, workdir, tuple(libraries))
    return rec, lambda: run_build(rec, commands, model, source.entry, workdir)


PLANT = '''within;
model Plant "Uses the MSL"
  Modelica.Blocks.Continuous.PI pi(k = 2, T = 10);
  annotation(uses(Modelica(version="4.0.0")), experiment(StopTime = 10));
end Plant;
'''


def test_source_with_uses_loads_the_library_first(tmp_path):
    src = tmp_path / "Plant.mo"
    src.write_text(PLANT)
    rec, run = _run(src, "Plant", tmp_path)
    with pytest.raises(CompileError):  # no FMU scripted: the build step fails, after the full sequence
        run()
    assert rec.commands() == [f'cd("{tmp_path.as_posix()}")', *FLAGS, 'loadModel(Modelica, {"4.0.0"})',
                              f'loadFile("{src.as_posix()}")', BUILD.format(model="Plant", prefix="Plant")]


def test_library_uses_are_loaded_and_libraries_given_as_files_are_not(tmp_path):
    lib = tmp_path / "HeatLib"
    lib.mkdir()
    (lib / "package.mo").write_text('within;\npackage HeatLib\n  annotation(uses(Modelica(version="4.0.0"),\n'
                                    '    Buildings(version="11.0.0")));\nend HeatLib;\n')
    pkg = tmp_path / "Site"
    pkg.mkdir()
    (pkg / "package.mo").write_text('within;\npackage Site\n  model Line\n  end Line;\n'
                                    '  annotation(uses(HeatLib(version="1.0.0"), Modelica(version="4.0.0")));\n'
                                    'end Site;\n')
    rec, run = _run(pkg, "Site.Line", tmp_path / "w", [lib])
    with pytest.raises(CompileError):
        run()
    assert rec.commands() == [f'cd("{(tmp_path / "w").as_posix()}")', *FLAGS, 'loadModel(Modelica, {"4.0.0"})',
                              'loadModel(Buildings, {"11.0.0"})', f'loadFile("{(lib / "package.mo").as_posix()}")',
                              f'loadFile("{(pkg / "package.mo").as_posix()}")',
                              BUILD.format(model="Site.Line", prefix="Site_Line")]


def test_generated_tracked_model_sequence(tmp_path):
    from trackingbox.generate.generator import generate
    from trackingbox.spec import load_spec

    result = generate(load_spec(write_case(tmp_path / "case"), check_files=False), tmp_path / "out")
    libraries = (result.library, library_path())
    rec, run = _run(result.package_dir, result.tracked_model, tmp_path / "w", libraries)
    with pytest.raises(CompileError):
        run()
    assert rec.commands() == [f'cd("{(tmp_path / "w").as_posix()}")', *FLAGS,
                              f'loadFile("{(result.library / "package.mo").as_posix()}")',
                              f'loadFile("{(library_path() / "package.mo").as_posix()}")',
                              f'loadFile("{(result.package_dir / "package.mo").as_posix()}")',
                              BUILD.format(model="TwinTracking.TwinTracked", prefix="TwinTracking_TwinTracked")]


def test_missing_library_stops_with_install_hint(tmp_path):
    src = tmp_path / "Plant.mo"
    src.write_text(PLANT)
    failed = ("false", '"Error: Failed to load package Modelica (4.0.0) using MODELICAPATH /usr/lib/omlibrary.\n"')
    rec, run = _run(src, "Plant", tmp_path, script={"loadModel(Modelica": failed})
    with pytest.raises(CompileError) as err:
        run()
    text = str(err.value)
    assert "OpenModelica failed to load library Modelica 4.0.0: Failed to load package Modelica (4.0.0)" in text
    assert f"(used at {src}:4)" in text
    assert 'installPackage(Modelica, "4.0.0")' in text and "apt install omlib-modelica-4.0.0" in text
    assert rec.commands()[-1] == 'loadModel(Modelica, {"4.0.0"})'  # nothing after the failure


def test_source_error_is_reported_with_file_line_column(tmp_path):
    src = tmp_path / "Plant.mo"
    src.write_text(PLANT)
    failed = ("false", f'"[{src}:3:3-3:49:writable] Error: Class Modelica.Blocks.Continuous.PJ not found."')
    rec, run = _run(src, "Plant", tmp_path, script={"loadFile(": failed})
    with pytest.raises(CompileError, match=rf"failed to load {re.escape(str(src))}: Class .*\n  "
                                           rf"{re.escape(str(src))}:3:3: error: Class"):
        run()


def test_errors_with_a_true_reply_still_fail_a_load(tmp_path):
    src = tmp_path / "Plant.mo"
    src.write_text(PLANT)
    rec, run = _run(src, "Plant", tmp_path, script={"loadFile(": ("true", '"Error: Duplicate class Plant."')})
    with pytest.raises(CompileError, match="Duplicate class Plant"):
        run()


def test_openmodelica_without_omc_says_so(tmp_path):
    if omc_available():
        pytest.skip("omc is installed here: the message for its absence cannot be checked")
    src = tmp_path / "Plant.mo"
    src.write_text(PLANT)
    with pytest.raises(CompileError, match="needs omc on PATH"):
        compile_model(src, "Plant", backend="openmodelica", output=tmp_path / "p.fmu")
    assert not (tmp_path / "p.fmu").exists()


HEATER = """model Heater "C dT/dt = Q - UA (T - Tamb)"
  parameter Real UA = 50 "W/K";
  parameter Real C = 4000 "J/K";
  input Real Q(start = 500) "W";
  output Real T(start = 293.15, fixed = true) "K";
equation
  C*der(T) = Q - UA*(T - 293.15);
end Heater;
"""


@pytest.fixture(scope="module")
def heater(tmp_path_factory):
    root = tmp_path_factory.mktemp("omc-heater")
    (root / "Heater.mo").write_text(HEATER)
    fmu = compile_model(root / "Heater.mo", "Heater", backend="embedded", output=root / "embedded.fmu").fmu
    return root / "Heater.mo", fmu


@pytest.mark.compile
def test_built_fmu_is_checked_and_written(heater, tmp_path):
    src, fmu = heater
    rec = Recorder(fmu=fmu)
    out = tmp_path / "om.fmu"
    text, states, params = compile_openmodelica(resolve_source(src), "Heater", out, session=rec,
                                                expected=ExpectedInterface(("UA", "C"), ("Q",), ("T",)))
    assert out.is_file() and (states, params) == (1, 2)
    assert rec.commands()[-1] == BUILD.format(model="Heater", prefix="Heater")


@pytest.mark.compile
def test_built_fmu_without_the_spec_names_is_refused_and_not_written(heater, tmp_path):
    src, fmu = heater
    out = tmp_path / "om.fmu"
    with pytest.raises(CompileError, match=r"the OpenModelica FMU of Heater does not expose the expected variables "
                                           r"\(2 differences\):\n  parameter 'hx.UA' is not in the FMU \(did you mean "
                                           r"'UA'\?\)\n  input 'T' is an output variable in the FMU"):
        compile_openmodelica(resolve_source(src), "Heater", out, session=Recorder(fmu=fmu),
                             expected=ExpectedInterface(("hx.UA",), ("T",), ("T",)))
    assert not out.exists() and not list(tmp_path.iterdir())


@pytest.mark.compile
def test_failed_build_writes_nothing(heater, tmp_path):
    src, fmu = heater
    out = tmp_path / "om.fmu"
    failed = ("false", '"[/x/Heater.mo:7:3-7:30:writable] Error: Too few equations, under-determined system."')
    with pytest.raises(CompileError, match=r"failed to build an FMU of Heater: Too few equations.*\n  "
                                           r"/x/Heater.mo:7:3: error"):
        compile_openmodelica(resolve_source(src), "Heater", out, session=Recorder({"buildModelFMU": failed}, fmu))
    assert not out.exists()


def test_ompython_session_without_omc_is_a_compile_error():
    from trackingbox.compiler.openmodelica import OMPythonSession

    if omc_available():
        pytest.skip("omc is installed here: the message for its absence cannot be checked")
    with pytest.raises(CompileError, match="could not start omc through OMPython"):
        OMPythonSession()


def test_ompython_adapter_hands_out_the_messages_ompython_raised():
    """OMPython 4 raises on omc's errors (and has already read the messages): the adapter
    answers "" for the command and gives the messages on the next getErrorString()."""
    from trackingbox.compiler.omc_messages import parse_error_string
    from trackingbox.compiler.openmodelica import OMPythonSession

    class Raising:  # scripted like OMPython 4: raises with its message list, then getErrorString() is empty
        def sendExpression(self, expr, parsed=True):  # noqa: N802
            if expr.startswith("loadModel"):
                raise RuntimeError("OMC error occurred for 'sendExpression(expr=loadModel(Modelica), parsed=False):\n"
                                   "00: [SCRIPTING:error:1] [:true:0:0:0:0] Failed to load package Modelica (4.0.0)")
            return '""' if expr == "getErrorString()" else "true"

    session = object.__new__(OMPythonSession)
    session._omc, session._pending = Raising(), []
    assert session.sendExpression('loadModel(Modelica, {"4.0.0"})') == ""
    (msg,) = parse_error_string(session.sendExpression("getErrorString()"))
    assert (msg.level, msg.file, msg.message) == ("error", None, "Failed to load package Modelica (4.0.0)")
    assert session.sendExpression("getErrorString()") == ""
