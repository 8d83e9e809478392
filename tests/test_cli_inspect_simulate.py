"""CLI: ``trackingbox inspect`` and ``trackingbox simulate`` through ``trackingbox.cli.main``."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from _fixtures_fmu import cs2_fmu, me2_fmu, me3_fmu

from trackingbox import cli


@pytest.fixture
def main(monkeypatch):
    """cli.main with only this piece's subcommands registered (others may not exist yet)."""
    monkeypatch.setattr(cli, "COMMANDS", ("inspect", "simulate"))
    return cli.main


def lag(t, x0, u, k, t0=0.0):
    return u + (x0 - u) * np.exp(-k * (np.asarray(t) - t0))


# -- inspect -------------------------------------------------------------------------

def test_inspect_json(main, capsys):
    assert main(["inspect", str(me3_fmu()), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["fmi_version"] == "3.0" and doc["model_name"] == "firstorder"
    assert doc["interfaces"] == ["ModelExchange"]
    by_name = {v["name"]: v for v in doc["variables"]}
    assert set(by_name) >= {"k", "u", "x", "y"}
    assert by_name["k"] == {"name": "k", "causality": "parameter", "variability": "tunable", "start": 2.0,
                            "min": 0.5, "max": 5.0, "nominal": None, "unit": None,
                            "description": "rate constant"}


def test_inspect_json_fmi2_units(main, capsys):
    assert main(["inspect", str(me2_fmu()), "--json", "--causality", "input"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [(v["name"], v["unit"], v["nominal"]) for v in doc["variables"]] == [("u", "K", 300.0)]


def test_inspect_table_is_aligned(main, capsys):
    assert main(["inspect", str(cs2_fmu())]) == 0
    lines = capsys.readouterr().out.splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("name "))
    col = lines[header].index("causality")
    rows = [line for line in lines[header + 2:] if line]
    assert [r.split()[0] for r in rows] == ["k", "x0", "u", "y", "z"]
    assert all(r[col:].split()[0] in {"parameter", "input", "output"} for r in rows)
    assert "FMI 2.0" in lines[0] and "CoSimulation" in lines[0]


def test_inspect_bad_fmu(main, capsys, tmp_path):
    bad = tmp_path / "bad.fmu"
    bad.write_text("no zip")
    assert main(["inspect", str(bad)]) == 2
    assert "not a ZIP archive" in capsys.readouterr().err


# -- simulate ------------------------------------------------------------------------

def test_simulate_with_inputs_and_set(main, tmp_path, capsys):
    inputs = tmp_path / "inputs.csv"
    inputs.write_text("time,u\n0,1\n2,1\n")
    out = tmp_path / "res" / "result.csv"
    assert main(["simulate", str(me3_fmu()), "--inputs", str(inputs), "--set", "k=3", "--step", "0.5",
                 "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["rows"] == 5 and summary["stop"] == 2.0  # default stop = last input time
    df = pd.read_csv(out)
    assert list(df.columns) == ["time", "y"]
    assert np.allclose(df["time"], [0, 0.5, 1.0, 1.5, 2.0])
    assert np.allclose(df["y"], lag(df["time"], 0.5, 1.0, 3.0), rtol=1e-4)


def test_simulate_default_stop_from_default_experiment_and_output_selection(main, tmp_path):
    out = tmp_path / "r.csv"
    assert main(["simulate", str(me2_fmu()), "--set", "u=2", "--output", "y", "--output", "x",
                 "-o", str(out)]) == 0
    df = pd.read_csv(out)
    assert list(df.columns) == ["time", "y", "x"]
    assert df["time"].iloc[-1] == pytest.approx(3.0) and len(df) == 31  # stopTime 3, stepSize 0.1
    assert np.allclose(df["y"], lag(df["time"], 0.5, 2.0, 2.0), rtol=1e-4)


def test_simulate_co_simulation(main, tmp_path):
    out = tmp_path / "r.csv"
    assert main(["simulate", str(cs2_fmu()), "--set", "u=3", "--set", "x0=1", "--stop", "1",
                 "--step", "0.25", "-o", str(out)]) == 0
    df = pd.read_csv(out)
    assert np.allclose(df["y"], lag(df["time"], 1.0, 3.0, 2.0), rtol=1e-9)
    assert np.allclose(df["z"], np.sqrt(df["y"]), rtol=1e-9)


@pytest.mark.parametrize("args, csv, message", [
    (["--set", "k3", "--stop", "1"], None, "--set 'k3': expected NAME=VALUE"),
    (["--set", "k=fast", "--stop", "1"], None, "value 'fast' is not a number"),
    (["--set", "kk=1", "--set", "u=1", "--stop", "1"], None, "unknown variable 'kk' in FMU firstorder.fmu "
                                                              "(did you mean 'k'?)"),
    (["--set", "u=1", "--output", "yy", "--stop", "1"], None, "unknown variable 'yy'"),
    (["--stop", "1"], None, "input(s) 'u' have no values"),
    (["--set", "u=1"], None, "no stop time"),
    ([], "time,v\n0,1\n1,1\n", "column 'v' of inputs.csv is not an input of FMU firstorder.fmu"),
    ([], "time,u\n0,1\n1,\n2,1\n", "column 'u' in inputs.csv has 1 NaN value at 1 s"),
    ([], "time,u\n0,1\n2,1\n1,1\n", "goes backwards: line 4 has 1 s after 2 s"),
    ([], "time\n0\n1\n", "input(s) 'u' have no values"),
])
def test_simulate_bad_input_exits_2_and_writes_nothing(main, tmp_path, capsys, args, csv, message):
    out = tmp_path / "result.csv"
    argv = ["simulate", str(me3_fmu()), *args, "-o", str(out)]
    if csv is not None:
        (tmp_path / "inputs.csv").write_text(csv)
        argv += ["--inputs", str(tmp_path / "inputs.csv")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err
    assert list(tmp_path.glob("result.csv*")) == [] and not any(p.name.endswith(".part") for p in tmp_path.iterdir())


def test_simulate_missing_fmu(main, tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert main(["simulate", str(tmp_path / "nope.fmu"), "--stop", "1", "-o", str(out)]) == 2
    assert "nope.fmu does not exist" in capsys.readouterr().err
    assert not out.exists()


def test_simulation_failure_leaves_no_file(main, tmp_path, capsys):
    # k = 0, p = 1 on the FMI 2 ME model: x = 1/(2 - t) blows up at t = 2 < stop = 3
    out = tmp_path / "r.csv"
    assert main(["simulate", str(me2_fmu()), "--set", "k=0", "--set", "p=1", "--set", "u=0",
                 "-o", str(out)]) == 2
    assert "solver failed" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
