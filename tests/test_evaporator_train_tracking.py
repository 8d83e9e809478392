"""Tracking the evaporator train (issue 11): a 2-effect case pairs, tracks, and gives a TrackingBox
that compiles and agrees with the Python runtime.

Expectations are independent of the code under test: the plant's own fouling trajectory
(``truth.json``, the plant FMU's ``Rf_true[k]``) says which way each effect's fouling goes, and the
generated Modelica is checked against hand-written modifier text.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from trackingbox.generate.generator import _fill_equations, _modifier_lines
from trackingbox.generate.source import ParameterSite


def _site(name: str) -> ParameterSite:
    component, leaf = name.rsplit(".", 1)
    return ParameterSite(name=name, component=component, leaf=leaf, flag=f"{component}.use_{leaf}_in",
                         input=f"{component}.{leaf}_in", has_pattern=True)


FLAGS = {f"effect[{k}].use_Rf_in": {} for k in (1, 2, 3)}


@pytest.mark.parametrize("names, modifiers, fills", [
    # every element driven: one `each` modifier, nothing to fill
    (["effect[1].Rf", "effect[2].Rf", "effect[3].Rf"], ("effect(each use_Rf_in = true)",), ()),
    # one element driven: the whole array switched, the others fed from their own parameter
    (["effect[2].Rf"], ("effect(each use_Rf_in = true)",),
     ("effect[1].Rf_in = effect[1].Rf;", "effect[3].Rf_in = effect[3].Rf;")),
    # a scalar component beside the array keeps its own modifier
    (["hx.kht", "effect[3].Rf"], ("effect(each use_Rf_in = true),", "hx(use_kht_in = true)"),
     ("effect[1].Rf_in = effect[1].Rf;", "effect[2].Rf_in = effect[2].Rf;")),
])
def test_component_array_modifiers(names, modifiers, fills):
    sites = [_site(n) for n in names]
    assert _modifier_lines(sites, FLAGS) == modifiers
    assert _fill_equations(sites, FLAGS) == fills


HOURS = 8.0


@pytest.fixture(scope="module")
def train(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The 2-effect, 8 h case: the constants held at the plant's values (what the demo's estimate
    stands for; ``[fixed]``), pair the fouling resistances from the step tests alone (8 h is too short
    for the data checks of 3 h loops: they leave every tag out there; the demo's 1-day case runs them),
    track on the validation window with 3 h loops, gen-trackingbox and compile, validate the box."""
    from trackingbox import generate, pair, track, validate
    from trackingbox.analysis.pair_stage import PairSettings, spec_pairs
    from trackingbox.benches import make_bench
    from trackingbox.benches.evaporator import fix_parameters, load_truth, slow_pairs
    from trackingbox.generate.generator import compile_generated
    from trackingbox.spec import write_pairs

    root = tmp_path_factory.mktemp("train")
    case = make_bench("evaporator-train", root / "case", seed=0, hours=HOURS, effects=2)
    spec = fix_parameters(case.spec, {k: v for k, v in case.truth.items() if not k.endswith("].Rf")})
    res = pair(spec, PairSettings(data_checks=False))
    spec = write_pairs(spec.path, spec_pairs(spec, res))
    spec = slow_pairs(spec.path)
    tr = track(spec, out_dir=root / "track", window="validation")
    gen = generate(spec, root / "generated")
    compiled = compile_generated(gen)
    val = validate(spec, compiled.fmu, work_dir=root / "validate")
    return {"spec": spec, "pair": res, "track": tr, "gen": gen, "compiled": compiled, "validate": val,
            "truth": load_truth(case.truth_file)}


@pytest.mark.compile
@pytest.mark.long
def test_every_effects_fouling_pairs_and_its_gains_have_the_physical_sign(train):
    """Fouling effect 1 (the product effect) lowers the product dry solids; fouling effect 2 needs a
    larger temperature difference, so its steam chest (effect 1's vapour) runs at a higher pressure."""
    spec, st = train["spec"], train["pair"].steptest
    assert sorted(p.parameter for p in spec.pairs) == ["effect[1].Rf", "effect[2].Rf"]

    def gain(tag: str, name: str) -> float:
        return float(st.gains[st.variables.index(tag)][st.parameters.index(name)])

    assert gain("QI-7060", "effect[1].Rf") < 0.0
    assert gain("PI-7221", "effect[2].Rf") > 0.0


@pytest.mark.compile
@pytest.mark.long
def test_tracked_fouling_moves_toward_the_plants_in_every_paired_effect(train):
    """The plant fouls from its start (truth.json): each tracked effect's resistance, clean (0) at
    the start, ends on the plant's side of it and closer to the plant's value than the clean start,
    and in the last hour lags the plant's by no more than a working closed loop lags a ramp."""
    from trackingbox.benches.evaporator import truth_on

    df = pd.read_csv(train["track"].csv)
    t = df["time"].to_numpy(float)
    last = t >= t[-1] - 3600.0
    for p in train["spec"].pairs:
        if not p.parameter.endswith("].Rf"):
            continue
        truth = truth_on(train["truth"], p.parameter, t)
        assert truth is not None and truth[-1] > truth[0] > 0.0  # the plant fouls
        tracked = df[f"parameter:{p.parameter}"].to_numpy(float)
        assert tracked[0] == 0.0
        assert np.mean(tracked[last]) > 0.0, p.parameter
        error = abs(np.mean(tracked[last] - truth[last]))
        assert error < np.mean(truth[last]), p.parameter
        # The plant's fouling is a ramp over the last hour (its own change there: slope); a closed loop
        # of time constant T (slow_pairs: lambda * tau = 3 h) follows a ramp with a lag of slope * T
        # once its start has died away. A working tracker lags at most half again that (a plant that is
        # not first order, the start-up offset's remainder). Measured (seed 0, 2 effects, 8 h): effect 1
        # lags 1.02e-5 m2.K/W against slope * T = 2.04e-5 (0.50x), effect 2 3.75e-6 against 3.11e-6
        # (1.21x); the former bound (the plant's value itself) was 8.5e-5 and 1.26e-5.
        slope = (truth[last][-1] - truth[last][0]) / (t[last][-1] - t[last][0])
        lag = slope * p.lambda_ * p.time_constant
        assert error <= 1.5 * lag, (p.parameter, error, lag)


@pytest.mark.compile
@pytest.mark.long
def test_the_compiled_box_agrees_with_the_python_runtime(train):
    gen, compiled, val = train["gen"], train["compiled"], train["validate"]
    assert compiled.fmu.is_file()
    assert {c.parameter for c in gen.controllers} == {p.parameter for p in train["spec"].pairs}
    assert len(gen.states) == 5  # every level: 2 effects, 2 condensate tanks, the flash tank
    assert val.agreement <= 0.01


@pytest.mark.parametrize("argv, message", [
    (["--bench", "heat-exchanger", "--effects", "3"], "--effects applies to --bench evaporator-train"),
    (["--bench", "evaporator-train", "--effects", "1"], "--effects must be an integer in 2..12"),
])
def test_demo_refuses_a_bad_number_of_effects_and_writes_nothing(tmp_path, capsys, argv, message):
    from trackingbox.demo import main

    out = tmp_path / "demo"
    assert main([*argv, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_every_train_candidate_is_a_component_parameter_with_its_conditional_input(tmp_path):
    """gen-trackingbox drives a tracked parameter through its component's ``use_<leaf>_in`` flag and
    ``<leaf>_in`` input; a parameter of the twin itself cannot be driven (issue 11: the train's valve
    and pump factors and boiling-point offsets were top-level). Names written out by hand."""
    from trackingbox.benches.evaporator_train import candidates, train_models
    from trackingbox.generate.source import load_twin, parameter_site

    models = train_models(2)
    source = tmp_path / "twin_source.mo"
    source.write_text(models.wrapper)
    twin = load_twin(source, models.twin)
    names = ["effect[1].Rf", "effect[2].Rf", "effect[1].dBPR", "effect[2].dBPR", *candidates(2)]
    assert sorted(candidates(2)) == sorted(["inletValve.capacity", "outletValve.capacity", "productPump.dp0",
                                            "transferValve[1].capacity", "transferPump[1].head"])
    expected = {
        "effect[1].Rf": ("effect[1].use_Rf_in", "effect[1].Rf_in"),
        "effect[2].Rf": ("effect[2].use_Rf_in", "effect[2].Rf_in"),
        "effect[1].dBPR": ("effect[1].use_dBPR_in", "effect[1].dBPR_in"),
        "effect[2].dBPR": ("effect[2].use_dBPR_in", "effect[2].dBPR_in"),
        "inletValve.capacity": ("inletValve.use_capacity_in", "inletValve.capacity_in"),
        "outletValve.capacity": ("outletValve.use_capacity_in", "outletValve.capacity_in"),
        "productPump.dp0": ("productPump.use_dp0_in", "productPump.dp0_in"),
        "transferValve[1].capacity": ("transferValve[1].use_capacity_in", "transferValve[1].capacity_in"),
        "transferPump[1].head": ("transferPump[1].use_head_in", "transferPump[1].head_in"),
    }
    for name in names:
        site = parameter_site(twin, name, "test")
        assert site.has_pattern, name
        assert (site.flag, site.input) == expected[name]
    # the former top-level factors are gone from the twin
    for gone in ("inletValveCapacity", "outletValveCapacity", "transferValveCapacity[1]", "transferPumpHead[1]",
                 "dBPREffect[1]"):
        assert gone not in twin.variables
