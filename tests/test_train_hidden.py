"""The train's hidden-effect plants (``Benches.EvaporatorTrain.Hidden``) and ``bench evaporator-train --hidden``.

Each plant variant is ``Hidden.Clean`` plus an effect on one named effect of a 3-effect train; each
is simulated for 3 h at the train's nominal inputs (from the plant's own start) and checked against
what its documentation says, computed here from the model's own design parameters: the vent
through the orifice law (1.5 % of the design live steam at 3.5 bar), the shell loss through the
natural-convection law (about 1 % of the effect's duty), nothing on the other effects, and the
direction the effect moves the measured tags against ``Clean`` at the same inputs: steam lost
from a chest or heat lost from a shell makes the train draw more live steam for the same
evaporation and lowers the steam-chest pressures, where fouling would raise them.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from trackingbox.benches import make_bench
from trackingbox.benches.evaporator_train import HIDDEN, NOMINAL, PACKAGE
from trackingbox.errors import TrackingError

N = 3
PKG = f"{PACKAGE}.Hidden"
STOP = 3 * 3600.0
TAIL = STOP - 1800.0
TAGS = {"FI-7020": "FI_steam", "PI-7121": "PI_steamChest[1]", "PI-7221": "PI_steamChest[2]",
        "PI-7111": "PI_vapour[1]", "FI-7125": "FI_condensate[1]", "FI-7225": "FI_condensate[2]",
        "QI-7060": "DI_product"}
PER_EFFECT = [f"effect[{k}].{v}" for k in range(1, N + 1)
              for v in ("m_vent", "Q_loss", "m_flow_vent_internal", "Q_flow_loss_internal", "p_s", "T", "Q",
                        "m_steam")]


def _run(train_fmu, model: str, extra: tuple[str, ...] = ()) -> pd.DataFrame:
    from trackingbox.fmu import FMUModel

    inputs = pd.DataFrame({"time": [0.0, STOP], **{k: [v, v] for k, v in NOMINAL.items()}})
    with FMUModel(train_fmu(N, f"{PKG}.{model}")) as m:
        return m.simulate(stop_time=STOP, output_interval=10.0, inputs=inputs,
                          outputs=[*TAGS.values(), *PER_EFFECT, "Rf_scale[1]", "Rf_scale[2]", "Rf_true[1]",
                                   "DS_product.port.x", *extra])


@pytest.fixture(scope="module")
def runs(train_fmu) -> dict[str, pd.DataFrame]:
    return {"Clean": _run(train_fmu, "Clean"),
            "VentOrifice": _run(train_fmu, "VentOrifice", ("steamDesign",)),
            "ShellLoss": _run(train_fmu, "ShellLoss", ("c", "QDesign[2]", "TLiqDesign[2]")),
            "VentAndLoss": _run(train_fmu, "VentAndLoss", ("steamDesign", "c"))}


def _tail(df: pd.DataFrame, name: str) -> float:
    return float(df[name][df["time"] >= TAIL].mean())


def _diff(runs, model: str, tag: str) -> float:
    return _tail(runs[model], TAGS[tag]) - _tail(runs["Clean"], TAGS[tag])


def test_cases_name_their_models_and_effects():
    from trackingbox.diagnose.library import load_effects

    effects = load_effects()
    assert HIDDEN["clean"].effect is None
    for case in HIDDEN.values():
        assert case.model.startswith(PKG + ".")
        for effect, target in ((case.effect, case.target), *case.others):
            assert effect is None or (effect in effects and target.startswith("effect[")), case.name
    assert HIDDEN["vent-and-loss"].others == (("shell-heat-loss", "effect[2]"),)


@pytest.mark.compile
def test_clean_hides_nothing(runs):
    """Clean: no vent, no loss, no scale on any effect, a true DS meter; fouling alone."""
    clean = runs["Clean"]
    for name in [n for n in PER_EFFECT if n.rsplit(".", 1)[1] in ("m_vent", "Q_loss", "m_flow_vent_internal",
                                                                  "Q_flow_loss_internal")] + ["Rf_scale[1]",
                                                                                              "Rf_scale[2]"]:
        assert np.abs(clean[name]).max() == 0.0, name
    np.testing.assert_allclose(clean["DI_product"], clean["DS_product.port.x"], atol=1e-15)
    # effect 1's fouling: the plant's asymptote 1.5e-4 m2.K/W with its 1-day time constant
    t = clean["time"].to_numpy()
    np.testing.assert_allclose(clean["Rf_true[1]"], 1.5e-4 * (1 - np.exp(-t / 86400.0)), rtol=1e-9, atol=1e-15)


@pytest.mark.compile
def test_vent_orifice_on_effect_1(runs):
    df = runs["VentOrifice"]
    vent = _tail(df, "effect[1].m_flow_vent_internal")
    design = float(df["steamDesign"].iloc[0])
    # the orifice law, and 1.5 % of the design steam at 3.5 bar in the chest
    assert vent == pytest.approx(0.015 * design * math.sqrt((_tail(df, "effect[1].p_s") - 1e5) / 2.5e5), rel=0.01)
    assert 0.013 < vent / _tail(df, "effect[1].m_steam") < 0.017
    for k in (2, 3):
        assert np.abs(df[f"effect[{k}].m_flow_vent_internal"]).max() == 0.0
    # the train draws the vented steam on top (within 10 %), condenses what it did (condensate within 0.2 %),
    # and effect 1's chest falls by more than 5 sensor sigmas (0.1 kPa each)
    assert _diff(runs, "VentOrifice", "FI-7020") == pytest.approx(vent, rel=0.1)
    assert abs(_diff(runs, "VentOrifice", "FI-7125")) < 0.002 * _tail(runs["Clean"], TAGS["FI-7125"])
    assert _diff(runs, "VentOrifice", "PI-7121") < -500.0


@pytest.mark.compile
def test_shell_loss_on_effect_2(runs):
    df = runs["ShellLoss"]
    c = float(df["c"].iloc[0])
    assert c == pytest.approx(0.01 * float(df["QDesign[2]"].iloc[0])
                              / (float(df["TLiqDesign[2]"].iloc[0]) - 298.15) ** 1.25, rel=1e-9)
    loss = _tail(df, "effect[2].Q_flow_loss_internal")
    assert loss == pytest.approx(c * (_tail(df, "effect[2].T") - 298.15) ** 1.25, rel=0.01)
    # "about 1 % of the effect's duty" at the operating point
    assert 0.008 < loss / _tail(df, "effect[2].Q") < 0.016
    for k in (1, 3):
        assert np.abs(df[f"effect[{k}].Q_flow_loss_internal"]).max() == 0.0
    # effect 2 needs more heat for the same evaporation: more condensate out of its chest, more live steam,
    # lower chest pressures in effects 1 and 2
    assert _diff(runs, "ShellLoss", "FI-7225") > 0.5 * loss / 2.3e6
    assert _diff(runs, "ShellLoss", "FI-7020") > 0.0
    assert _diff(runs, "ShellLoss", "PI-7221") < -150.0
    assert _diff(runs, "ShellLoss", "PI-7121") < -300.0


@pytest.mark.compile
def test_vent_and_loss_carries_both(runs):
    df = runs["VentAndLoss"]
    assert _tail(df, "effect[1].m_flow_vent_internal") == pytest.approx(
        _tail(runs["VentOrifice"], "effect[1].m_flow_vent_internal"), rel=0.01)
    assert _tail(df, "effect[2].Q_flow_loss_internal") == pytest.approx(
        _tail(runs["ShellLoss"], "effect[2].Q_flow_loss_internal"), rel=0.01)
    # small effects add: the chest pressures fall by the sum of the two (within 10 %)
    for tag in ("PI-7121", "PI-7221", "FI-7020"):
        both = _diff(runs, "VentAndLoss", tag)
        assert both == pytest.approx(_diff(runs, "VentOrifice", tag) + _diff(runs, "ShellLoss", tag), rel=0.1), tag


def test_unknown_case_and_bad_noise_are_named(tmp_path):
    with pytest.raises(TrackingError, match=r"unknown hidden-effect case 'shell-los' .*did you mean 'shell-loss'"):
        make_bench("evaporator-train", tmp_path / "x", hidden="shell-los", effects=3)
    with pytest.raises(TrackingError, match=r"noise scale must be a number >= 0"):
        make_bench("evaporator-train", tmp_path / "x", hidden="clean", effects=3, noise_scale=float("nan"))
    assert not (tmp_path / "x").exists()


@pytest.mark.compile
def test_bench_writes_a_hidden_train_case(train_fmu, tmp_path):
    """`bench evaporator-train --hidden vent-orifice --effects 3`: the case in truth.json, the suite spec (no
    steam-economy candidates), every effect's fouling declared varying for diagnose, the noise scaled."""
    from trackingbox.spec import load_spec

    plant = train_fmu(N, HIDDEN["vent-orifice"].model)
    twin = train_fmu(N, twin=True)
    case = make_bench("evaporator-train", tmp_path / "v", hours=1.0, hidden="vent-orifice", effects=N,
                      plant_fmu=plant, twin_fmu=twin, noise_scale=2.0, seed=3)
    truth = json.loads(case.truth_file.read_text())
    assert truth["hidden"]["effect"] == "steam-vent" and truth["hidden"]["target"] == "effect[1]"
    assert truth["noise_scale"] == 2.0 and truth["effects"] == N
    spec = load_spec(case.spec)
    names = set(spec.parameter_names)
    assert "ventFractionAll" not in names and "UA_lossAll" not in names
    assert {f"effect[{k}].Rf" for k in range(1, N + 1)} <= names
    assert dict(spec.diagnose.varying) == {f"effect[{k}].Rf": "rising" for k in range(1, N + 1)}
    assert "--hidden vent-orifice" in case.spec.read_text()
    # the plain bench keeps the steam-economy candidates
    plain = make_bench("evaporator-train", tmp_path / "p", hours=1.0, effects=N, plant_fmu=train_fmu(N),
                       twin_fmu=twin, seed=3)
    assert {"ventFractionAll", "UA_lossAll"} <= set(load_spec(plain.spec).parameter_names)


@pytest.fixture(scope="module")
def vent_case(train_fmu, tmp_path_factory):
    """A 1-hour 3-effect vent-orifice case (its spec's twin: the 3-effect wrapper in twin_source.mo)."""
    return make_bench("evaporator-train", tmp_path_factory.mktemp("train-vent") / "case", hours=1.0,
                      hidden="vent-orifice", effects=N, plant_fmu=train_fmu(N, HIDDEN["vent-orifice"].model),
                      twin_fmu=train_fmu(N, twin=True))


def test_each_effect_of_the_train_is_a_target(vent_case):
    """The library's process entries apply to the train's whole effect array and to each effect on its own."""
    from trackingbox.diagnose import library
    from trackingbox.spec import load_spec

    spec = load_spec(vent_case.spec)
    effects = library.load_effects()
    for entry in ("steam-vent", "shell-heat-loss", "soluble-scale"):
        found = library.targets(effects[entry], spec)
        assert {"effect", "effect[1]", "effect[2]", "effect[3]"} <= set(found), entry
        assert "effect[4]" not in found
    # one hook drives one element per patch: a second element's vent in the same patch is refused by name
    with pytest.raises(Exception, match=r"already uses the hook 'use_vent_in' of 'effect'"):
        library.render_patch(spec, [library.Finding("steam-vent", "effect[1]"),
                                    library.Finding("steam-vent", "effect[3]")])


def test_shell_loss_bounds_scale_with_each_effects_area(vent_case, tmp_path):
    """shell-heat-loss's UA bound is per m2 of the target effect's A (per_range of the entry), A read from the
    twin FMU after its initialisation (A = ADesign[k] has no start value); a flash tank keeps the absolute
    bounds; a per-variable the target lacks is a SpecError naming the entry, the parameter and the target."""
    from trackingbox.diagnose import library
    from trackingbox.errors import SpecError
    from trackingbox.fmu import FMUModel
    from trackingbox.spec import load_spec

    spec = load_spec(vent_case.spec)
    entry = library.load_effects()["shell-heat-loss"]
    ua = entry.parameter("UA")
    start, lo, hi = ua.per_range
    with FMUModel(spec.twin) as m:
        st = m.stepper(start_time=0.0)
        areas = list(st.get([f"effect[{k}].A" for k in range(1, N + 1)]))
        design = st.get([f"QDesign[{k}]" for k in range(1, N + 1)] + [f"UDesign[{k}]" for k in range(1, N + 1)]
                        + ["dTDesign"])
    # the design sizing A = Q/(U*dT) (PartialTrain), independently of the FMU's effect[k].A
    np.testing.assert_allclose(areas, design[:N] / (design[N:2 * N] * design[-1]), rtol=1e-9)
    assert len(set(areas)) == N and min(areas) > 10.0
    for k in range(1, N + 1):
        (p,) = library.render_patch(spec, [library.Finding("shell-heat-loss", f"effect[{k}]")]).parameters
        assert (p.min, p.max) == pytest.approx((lo * areas[k - 1], hi * areas[k - 1]), rel=1e-12)
        assert p.start == pytest.approx(start * areas[k - 1], rel=1e-12)
    (p,) = library.render_patch(spec, [library.Finding("shell-heat-loss", "effect")]).parameters
    assert p.max == pytest.approx(hi * max(areas), rel=1e-12)
    (p,) = library.render_patch(spec, [library.Finding("shell-heat-loss", "flash")]).parameters
    assert (p.min, p.max) == (ua.min, ua.max)
    with pytest.raises(SpecError, match=r"value 1000000.0 of 'UA' is outside its bounds"):
        library.render_patch(spec, [library.Finding("shell-heat-loss", "effect[2]", {"UA": 1e6})])
    # an entry whose per-variable the effects lack
    folder = tmp_path / "shell-heat-loss"
    folder.mkdir()
    toml = (entry.folder / "effect.toml").read_text().replace('= "A" }', '= "Asurf" }')
    (folder / "effect.toml").write_text(toml)
    (folder / "patch.mo.jinja").write_text((entry.folder / "patch.mo.jinja").read_text())
    bad = library.read_effect(folder)
    assert bad.parameter("UA").per == {"TrackingBox.Evaporation.Effect": "Asurf"}
    with pytest.raises(SpecError, match=r"effect 'shell-heat-loss', parameter 'UA'.*'Asurf'.*"
                                        r"target 'effect\[2\]' has no 'Asurf'"):
        library.render_patch(spec, [library.Finding("shell-heat-loss", "effect[2]")],
                             effects={"shell-heat-loss": bad})


@pytest.mark.compile
def test_a_patch_on_one_effect_acts_on_that_effect_only(vent_case, tmp_path):
    """steam-vent@effect[1] and shell-heat-loss@effect[2] compiled into the 3-effect twin: the template's laws
    (vent f*m_c, loss UA*(T - 20 degC)) on those effects, nothing on the others."""
    from trackingbox.diagnose import library
    from trackingbox.fmu import FMUModel
    from trackingbox.spec import load_spec

    spec = load_spec(vent_case.spec)
    patch = library.render_patch(spec, [library.Finding("steam-vent", "effect[1]", {"f": 0.015}),
                                        library.Finding("shell-heat-loss", "effect[2]", {"UA": 800.0})])
    fmu = library.compile_patch(patch, tmp_path).fmu
    stop = 1800.0
    inputs = pd.DataFrame({"time": [0.0, stop], **{k: [v, v] for k, v in NOMINAL.items()}})
    names = [f"effect[{k}].{v}" for k in range(1, N + 1)
             for v in ("m_flow_vent_internal", "Q_flow_loss_internal", "m_c", "T")]
    with FMUModel(fmu) as m:
        df = m.simulate(stop_time=stop, output_interval=60.0, inputs=inputs, outputs=names)
    np.testing.assert_allclose(df["effect[1].m_flow_vent_internal"], 0.015 * df["effect[1].m_c"], rtol=1e-9)
    np.testing.assert_allclose(df["effect[2].Q_flow_loss_internal"], 800.0 * (df["effect[2].T"] - 293.15), rtol=1e-9)
    assert float(df["effect[1].m_flow_vent_internal"].iloc[-1]) > 0.05
    for k in (2, 3):
        assert np.abs(df[f"effect[{k}].m_flow_vent_internal"]).max() == 0.0
    for k in (1, 3):
        assert np.abs(df[f"effect[{k}].Q_flow_loss_internal"]).max() == 0.0


@pytest.mark.compile
def test_a_patch_on_one_effect_keeps_what_the_others_use_without_the_hook(vent_case, tmp_path):
    """bpr-offset@effect[2] (hook use_dBPR_in replaces the offset parameter) and vapour-line@effect[3] (hook
    use_vapourCapacity_in replaces the design capacity 1): the other effects keep their own dBPR, a tunable
    parameter the spec's candidates name, and a vapour line at capacity 1."""
    from trackingbox.diagnose import library
    from trackingbox.fmu import FMUModel, read_info
    from trackingbox.spec import load_spec

    spec = load_spec(vent_case.spec)
    patch = library.render_patch(spec, [library.Finding("bpr-offset", "effect[2]"),
                                        library.Finding("vapour-line", "effect[3]")])
    fmu = library.compile_patch(patch, tmp_path).fmu
    params = {v.name for v in read_info(fmu).variables if v.causality == "parameter"}
    assert {f"effect[{k}].dBPR" for k in range(1, N + 1)} <= params
    stop = 600.0
    inputs = pd.DataFrame({"time": [0.0, stop], **{k: [v, v] for k, v in NOMINAL.items()}})
    with FMUModel(fmu) as m:
        df = m.simulate(stop_time=stop, output_interval=60.0, inputs=inputs, parameters={"effect[1].dBPR": 0.7},
                        outputs=[f"effect[{k}].{v}" for k in range(1, N + 1)
                                 for v in ("dBPR_internal", "vapourCapacity_internal")])
    np.testing.assert_allclose(df["effect[1].dBPR_internal"], 0.7, rtol=1e-12)
    np.testing.assert_allclose(df["effect[3].dBPR_internal"], 0.0, atol=1e-12)
    for k in (1, 2):
        np.testing.assert_allclose(df[f"effect[{k}].vapourCapacity_internal"], 1.0, rtol=1e-12)
