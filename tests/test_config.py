"""The settings registry (``trackingbox.config``): one place for every ``TRACKINGBOX_*`` switch.

Independent expectations: the variable names the package's source mentions (found by a regular
expression over the files, not by asking the registry), values set in the environment of a test,
and the README's text.
"""
from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import pytest

from trackingbox import cli, config
from trackingbox.estimation.objective import runs_native as _runs_native
from trackingbox.fmu import FMUModel

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "pyside" / "trackingbox"


def test_every_variable_the_package_names_is_in_the_registry_and_none_is_left_out() -> None:
    named = set()
    for path in PACKAGE.rglob("*.py"):
        named |= set(re.findall(r"TRACKINGBOX_[A-Z][A-Z0-9_]*[A-Z0-9]", path.read_text(encoding="utf-8")))
    registered = {s.env for s in config.SETTINGS}
    assert named <= registered, named - registered
    # the registry builds each variable's name from the setting's; the source names all but two itself
    # (the OPC UA user and password are read through the registry only)
    assert len(named) >= len(registered) - 2


def _reads_environment(node: ast.AST) -> bool:
    """``os.environ.get(...)``, ``os.getenv(...)``, ``os.environ[...]`` read (not written)."""
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
        f = node.func
        if f.attr == "getenv" and isinstance(f.value, ast.Name) and f.value.id == "os":
            return True
        if f.attr == "get" and isinstance(f.value, ast.Attribute) and f.value.attr == "environ":
            return True
    return (isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Load)
            and isinstance(node.value, ast.Attribute) and node.value.attr == "environ")


def test_no_module_but_the_registry_reads_a_trackingbox_variable() -> None:
    offending = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == PACKAGE / "config.py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if _reads_environment(node) and "TRACKINGBOX_" in ast.unparse(node) + _constants(tree, node):
                offending.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: {ast.unparse(node)}")
    assert offending == []


def _constants(tree: ast.AST, node: ast.AST) -> str:
    """The module-level string constants *node* names (``os.environ.get(NOTE_ENV)`` reads a variable too)."""
    names = {n.id for n in ast.walk(node) if isinstance(n, ast.Name)}
    found = []
    for stmt in getattr(tree, "body", []):
        if isinstance(stmt, ast.Assign) and isinstance(stmt.value, ast.Constant) and isinstance(stmt.value.value, str):
            if any(isinstance(t, ast.Name) and t.id in names for t in stmt.targets):
                found.append(stmt.value.value)
    return " ".join(found)


def test_values_parse_by_type_and_an_empty_variable_is_the_default() -> None:
    env = {"TRACKINGBOX_FMU_TIMEOUT": " 2.5 ", "TRACKINGBOX_NATIVE": "off", "TRACKINGBOX_NATIVE_ROWS": "",
           "TRACKINGBOX_FMU_MAX_BYTES": "1024", "TRACKINGBOX_CANARY": "Yes"}
    assert config.get("fmu_timeout", env) == 2.5
    assert config.get("native", env) is False
    assert config.get("native_rows", env) is True and config.source("native_rows", env) == "default"
    assert config.get("fmu_max_bytes", env) == 1024
    assert config.get("canary", env) is True
    assert config.get("supervise", {}) is True and config.source("supervise", {}) == "default"
    assert config.source("native", env) == "env"


@pytest.mark.parametrize(("variable", "value", "says"), [
    ("TRACKINGBOX_FMU_TIMEOUT", "soon", "a number of seconds > 0"),
    ("TRACKINGBOX_FMU_TIMEOUT", "-3", "a number of seconds > 0"),
    ("TRACKINGBOX_FMU_TIMEOUT", "inf", "a number of seconds > 0"),
    ("TRACKINGBOX_NATIVE", "maybe", "one of 1/0"),
    ("TRACKINGBOX_FMU_MAX_BYTES", "2.5", "a number of bytes > 0"),
    ("TRACKINGBOX_CC_OPT", "-O9", "a gcc optimisation flag"),
])
def test_a_value_a_setting_does_not_take_is_an_error_naming_the_variable(variable: str, value: str,
                                                                          says: str) -> None:
    name = variable.removeprefix("TRACKINGBOX_").lower()
    with pytest.raises(config.ConfigError) as err:
        config.get(name, {variable: value})
    assert str(err.value).startswith(f"{variable}={value!r} is not ") and says in str(err.value)


def test_the_config_command_lists_values_and_sources(monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    for s in config.SETTINGS:
        monkeypatch.delenv(s.env, raising=False)
    monkeypatch.setenv("TRACKINGBOX_NATIVE", "0")
    monkeypatch.setenv("TRACKINGBOX_FMU_TIMEOUT", "7")
    monkeypatch.setenv("TRACKINGBOX_OPCUA_PASSWORD", "hunter2")
    assert cli.main(["config", "--json"]) == 0
    out = capsys.readouterr().out
    assert "hunter2" not in out  # a secret is never shown
    doc = {r["env"]: r for r in json.loads(out)["settings"]}
    assert set(doc) == {s.env for s in config.SETTINGS}
    assert doc["TRACKINGBOX_NATIVE"]["value"] is False and doc["TRACKINGBOX_NATIVE"]["source"] == "env"
    assert doc["TRACKINGBOX_FMU_TIMEOUT"]["value"] == 7.0
    assert doc["TRACKINGBOX_OPCUA_PASSWORD"]["value"] == "(set)"
    assert (doc["TRACKINGBOX_SUPERVISE"]["value"], doc["TRACKINGBOX_SUPERVISE"]["source"]) == (True, "default")
    assert doc["TRACKINGBOX_FMU_MAX_BYTES"]["value"] == 2 * 1024**3
    assert cli.main(["config"]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:4] == ["name", "value", "source", "variable"]
    assert any(line.split()[:4] == ["native", "false", "env", "TRACKINGBOX_NATIVE"] for line in table)
    assert any(line.split()[:4] == ["fmu_timeout", "7.0", "env", "TRACKINGBOX_FMU_TIMEOUT"] for line in table)


def test_an_invalid_variable_stops_every_command_with_one_error_line(monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str],
                                                                     tmp_path: Path) -> None:
    monkeypatch.setenv("TRACKINGBOX_FMU_MAX_BYTES", "lots")
    assert cli.main(["inspect", str(tmp_path / "none.fmu")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: TRACKINGBOX_FMU_MAX_BYTES='lots' is not a number of bytes > 0"]
    assert cli.main(["config"]) == 2
    assert capsys.readouterr().err.strip() == "error: TRACKINGBOX_FMU_MAX_BYTES='lots' is not a number of bytes > 0"


def test_the_native_switch_is_read_in_one_way_everywhere(monkeypatch: pytest.MonkeyPatch, first_order_fmu: Path
                                                         ) -> None:
    """TRACKINGBOX_NATIVE was parsed twice (only "0" meant off); now every spelling of off is off for the stepper."""
    monkeypatch.setenv("TRACKINGBOX_NATIVE", "false")
    with FMUModel(first_order_fmu) as model:
        model.stepper(start_time=0.0)
        assert model.native_reason == "TRACKINGBOX_NATIVE=0"
    with FMUModel(first_order_fmu) as model:
        assert _runs_native(model) is False


def test_the_readme_lists_the_settings_as_the_registry_has_them() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert config.markdown_table() in readme
