"""omc's messages parsed into the embedded path's error shape.

The message strings are written here from the format OpenModelica documents for
``getErrorString()`` (``[file:line:col-line:col:writable|readonly] Level: message``,
``Level: message`` without a position), not captured from omc (it is not
installed here); the expected fields are read off each string by hand.
"""
from __future__ import annotations

from pathlib import Path

from trackingbox.compiler.omc_messages import OmcMessage, compile_error, errors_of, parse_error_string
from trackingbox.compiler.openmodelica import ompython_log_to_error_string

REPLY = ('"[/work/plant/Plant.mo:12:5-12:31:writable] Error: Variable hx.khtt not found in scope Plant.\n'
         '[/usr/lib/omlibrary/Modelica 4.0.0/Blocks/Continuous.mo:210:3-211:40:readonly] Warning: '
         'Parameter PI.T has no value, and is fixed during initialization (fixed=true),\n'
         'using available start value (start=1.0) as default value.\n'
         'Error: Failed to load package Buildings (11.0.0) using MODELICAPATH /usr/lib/omlibrary.\n'
         'Notification: Automatically loaded package Complex 4.0.0 due to uses annotation from Modelica.\n"')


def test_positions_levels_and_messages():
    msgs = parse_error_string(REPLY)
    assert msgs[0] == OmcMessage("error", "Variable hx.khtt not found in scope Plant.",
                                 Path("/work/plant/Plant.mo"), 12, 5, 12, 31)
    assert (msgs[1].level, msgs[1].file, msgs[1].line, msgs[1].column, msgs[1].end_line, msgs[1].end_column) == (
        "warning", Path("/usr/lib/omlibrary/Modelica 4.0.0/Blocks/Continuous.mo"), 210, 3, 211, 40)
    assert msgs[1].message.endswith("using available start value (start=1.0) as default value.")
    assert msgs[2] == OmcMessage("error", "Failed to load package Buildings (11.0.0) using MODELICAPATH "
                                          "/usr/lib/omlibrary.")
    assert msgs[3].level == "notification" and msgs[3].file is None
    assert len(msgs) == 4


def test_same_location_format_as_the_embedded_path():
    first = parse_error_string(REPLY)[0]
    assert first.where == "/work/plant/Plant.mo:12:5"
    assert str(first) == "/work/plant/Plant.mo:12:5: error: Variable hx.khtt not found in scope Plant."


def test_windows_path_kind_and_internal_error():
    text = ("[C:/Users/op/Plant/package.mo:3:1-3:9:writable] Translation Error: Class Modelica.Blocks.Continuous.PJ "
            "not found in scope Plant.\nInternal error: Instantiation of Plant failed with no error message.")
    a, b = parse_error_string(text)
    assert (a.file, a.line, a.kind, a.level) == (Path("C:/Users/op/Plant/package.mo"), 3, "translation", "error")
    assert b.level == "internal" and b.file is None
    assert [m.level for m in errors_of((a, b))] == ["error", "internal"]


def test_empty_reply_and_unrecognised_text():
    assert parse_error_string('""') == ()
    assert parse_error_string("") == ()
    (only,) = parse_error_string("omc: something unexpected")
    assert only.level == "error" and only.message == "omc: something unexpected"


def test_escapes_in_the_string_literal_are_undone():
    (m,) = parse_error_string('"Error: Class \\"Foo\\" not found."')
    assert m.message == 'Class "Foo" not found.'


def test_compile_error_wording():
    err = compile_error("Plant", Path("/work/plant/Plant.mo"), "load /work/plant/Plant.mo", parse_error_string(REPLY))
    text = str(err)
    assert text.startswith("cannot compile 'Plant' from /work/plant/Plant.mo: OpenModelica failed to load "
                           "/work/plant/Plant.mo: Variable hx.khtt not found in scope Plant.")
    assert "\n  /work/plant/Plant.mo:12:5: error: Variable hx.khtt" in text
    assert "\n  error: Failed to load package Buildings" in text
    assert "Automatically loaded" not in text  # notifications are not problems


def test_ompython4_exception_text_is_rewritten():
    # the message list of OMPython 4's OMSessionException, in the format its source writes
    exc = ("OMC error occurred for 'sendExpression(expr=loadFile(\"/w/P.mo\"), parsed=False):\n"
           "00: [TRANSLATION:error:1] [/w/P.mo:false:4:3:4:9] Variable y not found in scope P.\n"
           "01: [SCRIPTING:warning:2] [:true:0:0:0:0] Something\nover two lines")
    msgs = parse_error_string(ompython_log_to_error_string(exc))
    assert msgs[0] == OmcMessage("error", "Variable y not found in scope P.", Path("/w/P.mo"), 4, 3, 4, 9)
    assert (msgs[1].level, msgs[1].file, msgs[1].message) == ("warning", None, "Something\nover two lines")


def test_zero_position_of_a_package_notification():
    # the shape of the package manager's notifications in OpenModelica's User's Guide
    (m,) = parse_error_string('"[/tmp/lib/Complex 4.0.0/package.mo:0:0-0:0:readonly] Notification: Package installed '
                              'successfully (SHA 0123abc).\n"')
    assert (m.level, m.file, m.line, m.where) == ("notification", Path("/tmp/lib/Complex 4.0.0/package.mo"), 0,
                                                  "/tmp/lib/Complex 4.0.0/package.mo")
