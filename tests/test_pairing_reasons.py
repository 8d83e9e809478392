"""Every candidate ``pair`` leaves out has a reason; ``[pairing]`` (freeze, scale) in the spec.

The step-test twin (``_fixtures_analysis``, model in ``test_steptest.py``) has an
integral controller ``der(z) = (1 - hold)·ki·(r - x1)`` that holds ``y1 = x1`` at
``r`` while it is active. By hand: with the controller frozen (``hold = 1``),
``G = [[u/0.9, 0.5/0.9], [0.2u/0.9, 10/9]]`` for (Y1, Y2) x (a, b); with it active,
``x1 = r`` whatever ``a`` and ``b`` are, so ``a`` moves nothing
(``x2 = b + 0.2·x1``) and nothing moves Y1.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from trackingbox.analysis.pair_stage import explain_left_out
from trackingbox.analysis.pairing import choose_pairs
from trackingbox.analysis.rga import variable_ranges
from trackingbox.errors import SpecError
from trackingbox.spec import dump_spec, loads_spec


def _every_name_once(pairing, left):
    names = [n for n, _ in left] + [p.variable for p in pairing.pairs] + [p.parameter for p in pairing.pairs]
    assert sorted(names) == sorted([*pairing.variables, *pairing.parameters])
    assert all(reason.strip() for _, reason in left)


def test_every_left_out_candidate_has_its_reason():
    # columns: a (pairs with y1), b (pairs with y2), c = a / 2 (parallel, weaker), d (tiny gains);
    # rows: y1, y2, y3 (moved by nothing), y4 (only a and c move it: a is taken by y1)
    G = np.array([[1.0, 0.0, 0.5, 1e-6],
                  [0.0, 1.0, 0.0, 1e-6],
                  [0.0, 0.0, 0.0, 0.0],
                  [0.5, 0.0, 0.25, 0.0]])
    p = choose_pairs(G, ["y1", "y2", "y3", "y4"], ["a", "b", "c", "d"])
    assert {(x.variable, x.parameter) for x in p.pairs} == {("y1", "a"), ("y2", "b")}
    left = dict(explain_left_out(p, ()))
    _every_name_once(p, explain_left_out(p, ()))
    assert "parallel to that of a" in left["c"]
    assert left["d"].startswith("negligible gain")
    assert left["y3"].startswith("no candidate parameter moves it")
    assert "taken by y1" in left["y4"]
    assert not any("freeze" in r for r in left.values())
    # with controllers frozen, "moves nothing" / "nothing moves it" says it may be the freeze
    frozen = dict(explain_left_out(p, (("holdLevelControllers", 1.0),)))
    for name in ("d", "y3"):
        assert "not observable with this freeze, holdLevelControllers = 1" in frozen[name]
    for name in ("c", "y4"):
        assert frozen[name] == left[name]


def test_variable_ranges_trim_keeps_a_stoppage_from_setting_the_scale():
    # a flow at 2 +/- 0.1 that drops to 0 for 0.5 % of the time: its span in operation is 0.2
    t = np.arange(10000)
    flow = 2.0 + 0.1 * np.sin(t / 300.0)
    flow[5000:5050] = 0.0
    assert variable_ranges(flow)[0] == pytest.approx(2.1)
    assert variable_ranges(flow, trim=0.01)[0] == pytest.approx(0.2, rel=0.02)


# --------------------------------------------------------------------------- [pairing] in the spec

BASE = ('twin = "twin.fmu"\nmeasurements = "m.csv"\nsample_time = 1.0\n\n[inputs]\n"FI" = "u"\n\n'
        '[outputs]\n"Y1" = "y1"\n"Y2" = "y2"\n\n[[parameters]]\nname = "a"\nstart = 1.0\nmin = 0.5\nmax = 1.5\n')


def test_pairing_table_loads_and_writes_back(tmp_path):
    spec = loads_spec(BASE + '\n[pairing]\nfreeze = { hold = 1 }\nscale = { "Y1" = 0.2, Y2 = 5e-3 }\n',
                      tmp_path / "spec.toml", check_files=False)
    assert spec.pairing.freeze == (("hold", 1.0),)
    assert spec.pairing.scale == (("Y1", 0.2), ("Y2", 0.005))
    again = loads_spec(dump_spec(spec), tmp_path / "spec.toml", check_files=False)
    assert again.pairing == spec.pairing
    assert loads_spec(BASE, tmp_path / "spec.toml", check_files=False).pairing.freeze == ()


@pytest.mark.parametrize("table, message", [
    ('freeze = 1', "[pairing] freeze must be a table of NAME = VALUE"),
    ('freeze = { hold = "on" }', "'hold' in [pairing.freeze] must be a number"),
    ('scale = { Y1 = 0 }', "'Y1' in [pairing.scale] must be > 0"),
    ('scale = { Y1x = 1 }', "[pairing] scale names tag 'Y1x', which is not an [outputs] tag (did you mean 'Y1'?)"),
    ('frezze = { hold = 1 }', "frezze"),
])
def test_bad_pairing_table_is_named(tmp_path, table, message):
    with pytest.raises(SpecError) as err:
        loads_spec(BASE + f"\n[pairing]\n{table}\n", tmp_path / "spec.toml", check_files=False)
    assert message in str(err.value)


# --------------------------------------------------------------------------- the command


def _case(tmp_path, step_fmu, pairing: str = ""):
    from _fixtures_analysis import write_pair_case

    spec = write_pair_case(tmp_path, step_fmu, u=1.5)
    if pairing:
        spec.write_text(spec.read_text() + "\n[pairing]\n" + pairing)
    return spec


def test_spec_freeze_is_used_and_the_command_line_replaces_it(tmp_path, step_fmu, capsys):
    from trackingbox.cli import main

    spec = _case(tmp_path, step_fmu, "freeze = { hold = 1 }\n")
    assert main(["pair", str(spec), "--json", "--no-write", "--workers", "1", "--no-data-checks",
                 "--second-point", "none"]) == 0
    doc = json.loads(capsys.readouterr().out)
    G = [[1.5 / 0.9, 0.5 / 0.9], [0.3 / 0.9, 10 / 9]]  # the hand solution with the controller frozen
    assert np.allclose(doc["gain_matrix"]["values"], G, rtol=1e-4)
    assert doc["left_out"] == []
    # a freeze that leaves the controller active: it holds Y1 at r, so a and Y1 are not observable
    assert main(["pair", str(spec), "--json", "--no-write", "--workers", "1", "--no-data-checks",
                 "--second-point", "none", "--freeze", "corr=0"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [(p["variable"], p["parameter"]) for p in doc["pairs"]] == [("Y2", "b")]
    left = {x["name"]: x for x in doc["left_out"]}
    assert set(left) == {"a", "Y1"}
    assert left["a"]["kind"] == "parameter" and left["Y1"]["kind"] == "variable"
    for x in left.values():
        assert "not observable with this freeze, corr = 0" in x["reason"]
    # the printed summary gives the same reasons
    assert main(["pair", str(spec), "--no-write", "--workers", "1", "--no-data-checks", "--second-point",
                 "none", "--no-freeze"]) == 0
    out = capsys.readouterr().out
    assert "left out parameter a: negligible gain" in out
    assert "left out tag Y1: no candidate parameter moves it" in out
    assert "not observable with this freeze" not in out  # nothing was frozen
    assert main(["pair", str(spec), "--no-freeze", "--freeze", "hold=1"]) == 2
    assert "argument --freeze: not allowed with argument --no-freeze" in capsys.readouterr().err


def test_spec_freeze_name_is_checked_against_the_twin(tmp_path, step_fmu, capsys):
    from trackingbox.cli import main

    spec = _case(tmp_path, step_fmu, "freeze = { hodl = 1 }\n")
    before = spec.read_bytes()
    assert main(["pair", str(spec), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "[pairing] freeze names freeze input or parameter 'hodl'" in err and "did you mean 'hold'?" in err
    assert spec.read_bytes() == before


def test_a_tag_whose_pair_the_data_checks_forbid_is_not_said_to_lack_a_relative_gain():
    from trackingbox.analysis.offsets import Residuals

    # y2's only parameter b has lambda 1 with it, but b cannot reach y2's offset from inside its bounds
    t = np.arange(0.0, 2000.0, 10.0)
    rng = np.random.default_rng(0)
    measured = np.vstack([1.0 + 0.01 * rng.standard_normal(t.size), 5.0 + 0.01 * rng.standard_normal(t.size)])
    simulated = np.vstack([np.zeros(t.size), np.zeros(t.size)])
    res = Residuals(("y1", "y2"), t, measured, simulated, 10.0)
    p = choose_pairs([[1.0, 0.0], [0.0, 1.0]], ["y1", "y2"], ["a", "b"], residuals=res,
                     bounds=[(0.0, -2.0, 2.0), (0.0, -0.1, 0.1)])
    left = dict(explain_left_out(p, ()))
    assert [(x.variable, x.parameter) for x in p.pairs] == [("y1", "a")]
    assert "relative gain of at least" not in left["y2"]
    assert left["y2"].startswith("no candidate parameter can close its offset from inside its bounds")


def test_frozen_pairing_judges_the_data_with_the_twin_as_recorded(tmp_path, step_fmu, capsys):
    """``--check-gains``: with a freeze, a second step-test set with nothing frozen judges the data.

    By hand (module docstring): with the integral controller active, ``x1 = r`` whatever
    ``a`` and ``b`` are, so the recorded-way gains of (Y1, Y2) to (a, b) are
    ``[[0, 0], [0, 1]]`` (``x2 = b + 0.2·x1``), while the frozen ones stay those of the
    test above.
    """
    from trackingbox.cli import main

    spec = _case(tmp_path, step_fmu)
    common = ["pair", str(spec), "--json", "--no-write", "--workers", "1", "--second-point", "none"]
    main([*common, "--freeze", "hold=1"])
    doc = json.loads(capsys.readouterr().out)
    assert np.allclose(doc["gain_matrix"]["values"], [[1.5 / 0.9, 0.5 / 0.9], [0.3 / 0.9, 10 / 9]], rtol=1e-4)
    assert np.allclose(doc["gain_matrix_recording"]["values"], [[0.0, 0.0], [0.0, 1.0]], atol=1e-4)
    checks = doc["check_gains"]
    assert checks["source"] == "recording" and checks["freeze"] == {"hold": 1.0}
    assert checks["recording_freeze"] == {} and "nothing frozen" in checks["rule"]
    # the frozen gains alone, on request
    main([*common, "--freeze", "hold=1", "--check-gains", "structure"])
    doc = json.loads(capsys.readouterr().out)
    assert doc["gain_matrix_recording"] is None and doc["check_gains"]["source"] == "structure"
    assert doc["check_gains"]["recording_freeze"] == {"hold": 1.0}
    # nothing frozen: one set serves both, and the printout says which gains judged
    main(["pair", str(spec), "--no-write", "--workers", "1", "--second-point", "none", "--no-freeze"])
    assert "gains: RGA, reach and predicted tracking all from the step tests with nothing frozen" in \
        capsys.readouterr().out
