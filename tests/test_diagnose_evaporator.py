"""The evaporator effect entries of ``diagnose`` on the evaporator twin (``Benches.Evaporator.Twin``).

One patch carries every evaporator entry on a target it applies to (so the twin is
patched and compiled once); each effect is checked against what its explanation
says it does, derived by hand from the physics rather than read back from the
template: a vent makes the steam that enters the chest exceed the condensate by the
vented fraction once the chest is steady; a shell loss takes UA*(T - 20 degC) out of
the liquor; a boiling-point offset raises the boiling temperature above the vapour's
saturation by eps times the correlation's rise; soluble scale follows
dR/dt = k*sigma((x - xOn)/0.005)*q/q_ref - R/tau (integrated here with scipy from
the simulated dry solids and heat flux); entrained liquor leaves the body's solids
balance at the body's dry solids; a restricted vapour line raises the flash tank's
pressure; a density-calibration error scales the level reading by 1/(1 + e); the
dry-solids meter reads x*(1 + g) + d*t (a wrong liquor constant scales the
reading; its fouling drifts it). A second patch with every effect at zero
gives the unpatched twin's outputs.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from trackingbox.compiler import library_path
from trackingbox.diagnose.library import Finding, load_effects, prefix_for, render_patch, targets
from trackingbox.spec import SourceSpec, Spec

EV = "TrackingBox.Benches.Evaporator.Twin"
EVAPORATOR_EFFECTS = ("bpr-offset", "ds-meter", "entrainment", "level-density", "shell-heat-loss", "soluble-scale",
                      "steam-vent", "vapour-line")
TAGS = {"FI-6150": "FI_product", "FI-6125": "FI_condensate", "PI-6111": "PI_vapour", "PI-6121": "PI_steamChest",
        "PI-6151": "PI_flash", "PI-6152": "PI_pump", "TI-6111": "TI_body", "QI-6150": "DI_product"}

#: every evaporator entry once, on a target it applies to, away from zero
FINDINGS = [
    Finding("steam-vent", "effect", {"f": 0.02}),
    Finding("shell-heat-loss", "effect", {"UA": 800.0}),
    Finding("bpr-offset", "effect", {"eps": 0.1}),
    Finding("soluble-scale", "effect", {"k": 2e-8, "xOn": 0.6, "tau": 3600.0}),
    Finding("entrainment", "effect", {"eps": 0.005}),
    Finding("vapour-line", "flash", {"r": 0.3}),
    Finding("level-density", "LT_flash", {"e": 0.08}),
    Finding("ds-meter", "DS_product", {"g": 0.01, "d": 8e-9}),
]
#: the same findings with every effect switched off by its parameters
ZERO = [Finding(f.effect, f.target, {k: (0.6 if k == "xOn" else 3600.0 if k == "tau" else 0.0) for k in f.values})
        for f in FINDINGS]
STOP = 5400.0


def _run(fmu: Path, outputs: list[str]) -> pd.DataFrame:
    from trackingbox.fmu import FMUModel

    model = FMUModel(fmu)
    try:
        return model.simulate(stop_time=STOP, output_interval=10.0, outputs=outputs)
    finally:
        model.close()


@pytest.fixture(scope="module")
def ev_spec(fmu_cache, tmp_path_factory) -> Spec:
    tmp = tmp_path_factory.mktemp("evspec")
    meas = tmp / "measurements.csv"
    pd.DataFrame({"time": [0.0, 10.0], **{t: [0.0, 0.0] for t in TAGS}}).to_csv(meas, index=False)
    return Spec(path=tmp / "spec.toml", twin=Path(fmu_cache(EV)), measurements=meas, sample_time=10.0,
                source=SourceSpec(Path(library_path()), EV), outputs=dict(TAGS))


@pytest.fixture(scope="module")
def ev_patches(ev_spec, tmp_path_factory) -> dict[str, Path]:
    from trackingbox.diagnose.library import compile_patch

    return {name: Path(compile_patch(render_patch(ev_spec, findings), tmp_path_factory.mktemp(name)).fmu)
            for name, findings in (("on", FINDINGS), ("off", ZERO))}


def test_entries_cite_their_sources_and_bounds():
    effects = load_effects()
    for eid in EVAPORATOR_EFFECTS:
        e = effects[eid]
        assert e.kind == "process" and e.hook and "evaporator-notes.md" in e.sources, eid
        assert all(c.startswith("TrackingBox.Evaporation.") for c in e.classes), eid
    # every finding above lies inside its entry's bounds
    for f in FINDINGS:
        for name, value in f.values.items():
            p = effects[f.effect].parameter(name)
            assert p.min <= value <= p.max, (f.effect, name)


def test_evaporator_targets(ev_spec):
    """Read from PartialSlice by eye: one Effect, one FlashTank, the DS meter, three level transmitters."""
    effects = load_effects()
    for eid in ("steam-vent", "soluble-scale"):
        assert targets(effects[eid], ev_spec) == ["effect"]
    for eid in ("shell-heat-loss", "bpr-offset", "entrainment", "vapour-line"):
        assert targets(effects[eid], ev_spec) == ["effect", "flash"]
    assert targets(effects["ds-meter"], ev_spec) == ["DS_product"]
    assert targets(effects["level-density"], ev_spec) == ["LT_body", "LT_condensate", "LT_flash"]
    # no evaporator entry applies to the other benches' components
    assert all(not c.startswith("TrackingBox.Fluid") for eid in EVAPORATOR_EFFECTS for c in effects[eid].classes)


@pytest.mark.compile
def test_evaporator_patch_effects_act_as_explained(fmu_cache, ev_patches):
    e = "effect"
    names = [f"{e}.m_steam", f"{e}.m_c", f"{e}.m_vent", f"{e}.T", f"{e}.T_b", f"{e}.T_vap", f"{e}.BPR",
             f"{e}.epsBPR", f"{e}.dBPR", f"{e}.Q", f"{e}.x", f"{e}.Q_flow_loss_internal", f"{e}.Q_loss",
             f"{e}.UA_loss", f"{e}.T_amb", f"{e}.dRf_internal", f"{e}.m_ev", f"{e}.m_flow_entrain_internal",
             f"{e}.M_s", f"{e}.port_a.m_flow", f"{e}.port_a.x", f"{e}.port_b.m_flow", f"{e}.m_corr",
             "flash.vapourCapacity_internal", "PI_flash", "LT_flash.y", "LT_flash.dp", "DS_product.y",
             "DS_product.port.x", *TAGS.values()]
    names = list(dict.fromkeys(names))
    df = _run(ev_patches["on"], names)
    t = df["time"].to_numpy()
    last = t > STOP - 600.0
    # vent: what enters the chest and is not condensed leaves it: m_steam = m_c + m_vent + f*m_c when steady
    np.testing.assert_allclose(df[f"{e}.m_steam"][last], ((1.02) * df[f"{e}.m_c"] + df[f"{e}.m_vent"])[last],
                               rtol=2e-3)
    # shell loss: UA*(T - 293.15 K) beside the twin's own loss
    np.testing.assert_allclose(df[f"{e}.Q_flow_loss_internal"], 800.0 * (df[f"{e}.T"] - 293.15), rtol=1e-9)
    np.testing.assert_allclose(df[f"{e}.Q_loss"] - df[f"{e}.UA_loss"] * (df[f"{e}.T"] - df[f"{e}.T_amb"]),
                               800.0 * (df[f"{e}.T"] - 293.15), rtol=1e-9)
    # boiling-point offset: T_b - T_vap = dBPR + (1 + epsBPR + 0.1)*BPR
    np.testing.assert_allclose(df[f"{e}.T_b"] - df[f"{e}.T_vap"],
                               df[f"{e}.dBPR"] + (1 + df[f"{e}.epsBPR"] + 0.1) * df[f"{e}.BPR"], atol=1e-9)
    # soluble scale: integrate the growth law from the simulated dry solids and duty (A = 300 m2)
    x_of = lambda s: np.interp(s, t, df[f"{e}.x"])  # noqa: E731
    q_of = lambda s: np.interp(s, t, df[f"{e}.Q"]) / (300.0 * 5000.0)  # noqa: E731
    sol = solve_ivp(lambda s, r: 2e-8 / (1 + np.exp(-(x_of(s) - 0.6) / 0.005)) * q_of(s) - r / 3600.0,
                    (0.0, STOP), [0.0], t_eval=t, rtol=1e-8, atol=1e-12, max_step=10.0)
    assert df[f"{e}.dRf_internal"].iloc[-1] > 2e-5  # it did grow (x ~ 0.7 > xOn)
    np.testing.assert_allclose(df[f"{e}.dRf_internal"], sol.y[0], atol=0.01 * sol.y[0].max())
    # entrainment: eps*m_ev of liquor leaves, and its solids leave the body's solids balance at the body's x
    np.testing.assert_allclose(df[f"{e}.m_flow_entrain_internal"], 0.005 * df[f"{e}.m_ev"], rtol=1e-9)
    solids = (df[f"{e}.port_a.m_flow"] * df[f"{e}.port_a.x"] + df[f"{e}.port_b.m_flow"] * df[f"{e}.x"]
              + df[f"{e}.x"] * (df[f"{e}.m_corr"] - df[f"{e}.m_flow_entrain_internal"])).to_numpy()
    rate = np.gradient(df[f"{e}.M_s"].to_numpy(), t)
    inner = slice(5, -5)
    np.testing.assert_allclose(rate[inner], solids[inner], atol=2e-3 * np.abs(solids).max() + 1e-4)
    # vapour line: 70 % of the design capacity
    np.testing.assert_allclose(df["flash.vapourCapacity_internal"], 0.7, rtol=1e-12)
    # level transmitter calibrated 8 % denser: reads dp/(1.08*1450*g)
    np.testing.assert_allclose(df["LT_flash.y"], df["LT_flash.dp"] / (1.08 * 1450.0 * 9.81), rtol=1e-9)
    # dry-solids meter: x*(1 + g) + d*t, g = 0.01: the error follows the dry solids the meter sees
    np.testing.assert_allclose(df["DS_product.y"], 1.01 * df["DS_product.port.x"] + 8e-9 * t, atol=1e-12)

    # against the unpatched twin: the vapour line's square-root law at 70 % of its capacity needs 1/0.7^2 of the
    # pressure drop to the 1 bar header for about the same flash vapour; the vent and the loss leave less heat
    # for evaporation (a thinner product at the same feed)
    base = _run(Path(fmu_cache(EV)), ["PI_flash", "DI_product", "DS_product.port.x"])
    ratio = ((df["PI_flash"] - 1e5) / (base["PI_flash"] - 1e5))[last]
    np.testing.assert_allclose(ratio, 1 / 0.7**2, rtol=0.05)
    assert (df["DS_product.port.x"] - base["DS_product.port.x"])[last].max() < -0.002


@pytest.mark.compile
def test_evaporator_hooks_off_change_nothing(fmu_cache, ev_patches):
    """The patched twin with every evaporator effect at zero follows the evaporator twin on every tag as closely
    as the twin follows itself on another output grid (the integrator's own spread: the communication points
    restart its steps; FI-6150 moved by 3e-5 of its value between a 10 s and a 5 s grid)."""
    from trackingbox.fmu import FMUModel

    outputs = list(TAGS.values()) + ["LI_body", "LI_flash", "LI_condensate", "ZI_inlet", "ZI_outlet"]
    base = _run(Path(fmu_cache(EV)), outputs)
    off = _run(ev_patches["off"], outputs)
    with FMUModel(Path(fmu_cache(EV))) as model:
        fine = model.simulate(stop_time=STOP, output_interval=5.0, outputs=outputs).iloc[::2].reset_index(drop=True)
    assert len(fine) == len(base)
    for name in outputs:
        scale = max(1.0, float(np.abs(base[name]).max()))
        spread = float(np.max(np.abs(fine[name].to_numpy() - base[name].to_numpy())))
        gap = float(np.max(np.abs(off[name].to_numpy() - base[name].to_numpy())))
        assert gap <= 3.0 * spread + 1e-7 * scale, (name, gap, spread)


def test_prefixes_are_distinct():
    prefixes = [prefix_for(f.effect, f.target) for f in FINDINGS]
    assert len(set(prefixes)) == len(prefixes)
