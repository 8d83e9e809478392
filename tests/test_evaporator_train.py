"""The evaporator-train bench: balances of the N-effect train and the ``bench evaporator-train`` command.

* ``Benches.EvaporatorTrain.Validation.TrainBalance`` (3 effects, 1 h, feed cut by a third,
  oscillating boundaries and correction flows into every vessel): the mass and the
  dry solids of the whole train are conserved, i.e. what the integrators counted in
  and out equals the change of the inventories, within 1e-6 of the feed that
  passed, at every output point.
* The command refuses bad arguments with exit code 2, a message naming the
  argument, and nothing written.
"""
from __future__ import annotations

import numpy as np
import pytest

from trackingbox import cli
from trackingbox.fmu import FMUModel

BALANCE = "TrackingBox.Benches.EvaporatorTrain.Validation.TrainBalance"
N = 3


@pytest.fixture(scope="module")
def balance_run(fmu_cache):
    fmu = fmu_cache(BALANCE)
    vessels = ([f"train.effect[{k}].level" for k in range(1, N + 1)]
               + [f"train.condTank[{k}].level" for k in range(1, N + 1)] + ["train.flash.level"])
    names = ["massIn", "massOut", "solidsIn", "solidsOut", "massInventory", "solidsInventory", "throughput",
             "train.DI_product", *vessels]
    with FMUModel(fmu, tolerance=1e-8) as model:
        result = model.simulate(stop_time=3600.0, output_interval=10.0, outputs=names)
    return result, vessels


@pytest.mark.compile
def test_train_mass_and_dry_solids_balances_close(balance_run):
    r, _ = balance_run
    t = r["time"].to_numpy()
    fed = np.concatenate([[0.0], np.cumsum(np.diff(t) * 0.5 * (r["throughput"].to_numpy()[1:]
                                                                    + r["throughput"].to_numpy()[:-1]))])
    # the run is not trivial: the feed falls from 18 to 12 kg/s, tonnes pass, the inventories move
    assert r["throughput"].iloc[0] > 17.0 and abs(r["throughput"].iloc[-1] - 12.0) < 0.1
    assert fed[-1] > 4.0e4
    mass_change = r["massInventory"].to_numpy() - r["massInventory"].iloc[0]
    solids_change = r["solidsInventory"].to_numpy() - r["solidsInventory"].iloc[0]
    assert np.max(np.abs(solids_change)) > 100.0
    mass_gap = mass_change - (r["massIn"].to_numpy() - r["massOut"].to_numpy())
    solids_gap = solids_change - (r["solidsIn"].to_numpy() - r["solidsOut"].to_numpy())
    scale = np.maximum(fed, fed[1])
    assert np.max(np.abs(mass_gap) / scale) <= 1e-6
    assert np.max(np.abs(solids_gap) / scale) <= 1e-6


@pytest.mark.compile
def test_train_levels_stay_inside_their_vessels(balance_run):
    r, vessels = balance_run
    for name in vessels:
        height = 2.0 if "condTank" in name else 3.0  # H of the condensate tanks, the effects and the flash tank
        level = r[name].to_numpy()
        assert 0.0 < level.min() and level.max() < height, name


@pytest.mark.parametrize("argv, message", [
    (["--effects", "1"], "--effects: must be an integer >= 2 and <= 12, got '1'"),
    (["--effects", "13"], "--effects: must be an integer >= 2 and <= 12, got '13'"),
    (["--effects", "3.5"], "--effects: must be an integer >= 2 and <= 12, got '3.5'"),
    (["--days", "0"], "--days: must be a finite number > 0, got '0'"),
    (["--days", "1", "--hours", "2"], "give --days or --hours, not both"),
    (["--hidden", "heat-loss"], "unknown hidden-effect case 'heat-loss' of bench 'evaporator-train'"),
    (["--noise-scale", "-1"], "--noise-scale"),
    (["--plant-fmu", "missing-plant.fmu"], "missing-plant.fmu"),
])
def test_bad_arguments_exit_2_and_write_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "case"
    assert _main(["bench", "evaporator-train", "--out", str(out), *argv]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_effects_only_for_the_train(tmp_path, capsys):
    out = tmp_path / "case"
    assert _main(["bench", "evaporator", "--out", str(out), "--effects", "3"]) == 2
    assert "bench 'evaporator' has no number of effects" in capsys.readouterr().err
    assert not out.exists()


def _main(argv: list[str]) -> int:
    """``trackingbox`` on *argv*: its exit code (argparse's refusals exit through SystemExit)."""
    try:
        return cli.main(argv)
    except SystemExit as exc:
        return int(exc.code)


@pytest.mark.compile
@pytest.mark.slow
def test_bench_command_writes_a_3_effect_case(tmp_path, capsys):
    """``bench evaporator-train --effects 3``: compiles the 3-effect wrappers, writes the historian
    export, the spec (every level compensated, every effect's fouling a candidate) and the truth."""
    import json

    import pandas as pd

    from trackingbox.fmu import read_info
    from trackingbox.spec import load_spec

    out = tmp_path / "case"
    assert _main(["bench", "evaporator-train", "--out", str(out), "--effects", "3", "--hours", "1",
                  "--seed", "1", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["bench"] == "evaporator-train" and doc["hours"] == 1.0
    spec = load_spec(out / "spec.toml")
    assert spec.source is not None and spec.source.path == out / "twin_source.mo"
    twin = {v.name: v for v in read_info(out / "twin.fmu").variables}
    # 3 effects x 2 levels + the flash tank: 7 compensated levels, each on its own correction input
    assert sorted(s.tag for s in spec.states) == sorted(
        ["LI-7061"] + [f"LI-7{k}11" for k in (1, 2, 3)] + [f"LI-7{k}25" for k in (1, 2, 3)])
    assert all(twin[s.correction].causality == "input" for s in spec.states)
    names = [p.name for p in spec.parameters]
    assert [n for n in names if n.endswith(".Rf")] == ["effect[1].Rf", "effect[2].Rf", "effect[3].Rf"]
    assert all(twin[n].causality == "parameter" for n in names)
    # 10 common tags + 9 per effect, less the 7 levels
    assert len(spec.outputs) == 10 + 9 * 3 - 7
    truth = json.loads((out / "truth.json").read_text())
    assert truth["effects"] == 3 and sorted(truth["trajectories"]) == names[:3]
    # the plant fouls from clean: every effect's resistance starts at 0 and grows
    for name in names[:3]:
        values = truth["trajectories"][name]["value"]
        assert values[0] >= 0 and values[-1] > values[0]
    history = pd.read_csv(out / "measurements.csv")  # the historian's long form: tag, time, value
    assert {"FI-7010", "QI-7060", "TI-7311", "FIC-7010.SP", "PI-7090"} <= set(history["tag"])
    # the train's steam-economy losses are candidates from the twin's clean 0 (estimated and held), and
    # the truth holds the plant's values as Plant.mo sets them (0.5 % vents, 200 W/K per effect)
    params = {p.name: p for p in spec.parameters}
    assert (params["ventFractionAll"].start, params["ventFractionAll"].min, params["ventFractionAll"].max) == (
        0.0, 0.0, 0.02)
    assert (params["UA_lossAll"].start, params["UA_lossAll"].min, params["UA_lossAll"].max) == (0.0, 0.0, 1000.0)
    assert truth["parameters"]["ventFractionAll"] == 0.005 and truth["parameters"]["UA_lossAll"] == 200.0
    _twin_at_the_plants_constants_is_the_plant(out, truth["parameters"])


def _twin_at_the_plants_constants_is_the_plant(case, constants: dict) -> None:
    """Constant design inputs for 2 h. The plant without its fouling and scale and without the flash
    tank's heat loss (the one loss the twin does not have) against the twin at the plant's constants:
    the same steam-chest and vapour pressures (within the solver's tolerance, 1 Pa). The twin without
    the vents and losses runs effect 1's steam chest higher: the plant then draws about 1 % more live
    steam through the same valve opening (0.5 % vented, and the shell loss of ~0.5 % of the duty), and
    the valve, dropping ~45 kPa at design flow (steam header 4 bar, chest 3.5 bar), drops ~2 % more:
    ~0.9 kPa lower from effect 1's own losses alone; asserted: more than 300 Pa."""
    import pandas as pd

    from trackingbox.benches.evaporator_train import NOMINAL

    t = np.arange(0.0, 7200.0 + 1.0, 60.0)
    inputs = pd.DataFrame({"time": t, **{k: np.full_like(t, v) for k, v in NOMINAL.items()}})
    tags = ["PI_steamChest[1]", "PI_steamChest[2]", "PI_vapour[1]", "PI_vapour[3]"]

    def last(fmu, parameters):
        with FMUModel(fmu) as model:
            r = model.simulate(stop_time=float(t[-1]), output_interval=60.0, inputs=inputs,
                               parameters=parameters, outputs=tags)
        return r[tags].iloc[-1].to_numpy(float)

    no_fouling = {"kScale": 0.0, "UA_lossFlash": 0.0, **{f"RfInf[{k}]": 0.0 for k in (1, 2, 3)}}
    plant = last(case / "plant.fmu", no_fouling)
    twin = last(case / "twin.fmu", constants)
    lossless = last(case / "twin.fmu", {**constants, "ventFractionAll": 0.0, "UA_lossAll": 0.0})
    assert np.max(np.abs(twin - plant)) < 1.0, (twin, plant)
    assert lossless[0] - plant[0] > 300.0, (lossless, plant)


@pytest.mark.compile
def test_stoppage_settle_is_the_liquor_transit_time_of_the_compiled_train(fmu_cache):
    # the settle after a stoppage is each effect's liquor hold-up over the liquor flow leaving it, summed
    # (benches.evaporator_train.stoppage_settle, from the design formulas); the compiled 3-effect train
    # at its start gives both from its own medium (masses at the start levels, flows of its valves)
    from trackingbox.benches.evaporator_train import STOPPAGE_SETTLE, stoppage_settle

    names = [f"train.effect[{k}].M" for k in range(1, N + 1)] + [f"train.FI_liquor[{k}]" for k in range(1, N + 1)]
    with FMUModel(fmu_cache(BALANCE), tolerance=1e-8) as model:
        r = model.simulate(stop_time=20.0, output_interval=10.0, outputs=names)
    transit = sum(float(r[f"train.effect[{k}].M"].iloc[0]) / float(r[f"train.FI_liquor[{k}]"].iloc[0])
                  for k in range(1, N + 1))
    assert stoppage_settle(N) == pytest.approx(transit, rel=0.05)
    assert stoppage_settle(N) > STOPPAGE_SETTLE          # longer than the single effect's 30 min
    assert stoppage_settle(7) > stoppage_settle(N)        # and it grows with the effects
