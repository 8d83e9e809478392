"""Small twin libraries and specs for the code-generation tests (written to tmp_path).

``Mini`` is a one-state heater whose exchanger offers the conditional-input
pattern for ``kht``; ``Plain`` is the same model without it (for the refusal
and ``--rewrite`` paths); ``Units`` is ``Mini`` with SI units on every
variable plus a tank whose level takes a correction flow (for ``[[states]]``). Steady state of both:
``T = Tc + Qin/(kht*A)`` with ``Tc = 300 K``, ``A = 10 m2``, ``Qin = 50 kW``,
so ``dT/dkht = -Qin/(kht^2 A) = -0.005 K per W/(m2.K)`` at ``kht = 1000`` and
the ``kht`` that gives a measured ``T`` is ``50000/(10 (T - 300))``.

``BENCH_PAIRS`` and :func:`box_against_runtime` compare a compiled box with the Python runtime
on the benches (``test_generate``, ``test_tracking_continuous``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

MINI = '''within;
package Mini "Small test library"
  connector RealInput = input Real "Real input signal";

  model Exchanger "Lumped exchanger with a trackable heat-transfer coefficient"
    parameter Real A = 10.0 "Area (m2)";
    parameter Real kht(min = 0) = 1000.0 "Heat-transfer coefficient (W/(m2.K))";
    parameter Boolean use_kht_in = false "Take kht from input kht_in";
    parameter Real C = 4.0e5 "Heat capacity (J/K)";
    RealInput kht_in if use_kht_in "Heat-transfer coefficient from outside";
    input Real Tc "Cold-side temperature (K)";
    input Real Qin "Heat input (W)";
    output Real T(start = 350.0, fixed = true) "Hot-side temperature (K)";
  protected
    RealInput kht_internal "kht actually used";
  equation
    connect(kht_in, kht_internal);
    if not use_kht_in then
      kht_internal = kht;
    end if;
    C*der(T) = Qin - kht_internal*A*(T - Tc);
  end Exchanger;

  model Twin "Heater twin"
    input Real Qin(start = 50000.0) "Heater power (W)";
    output Real ThOut "Hot temperature (K)";
    Exchanger hx(kht = 1000.0);
  equation
    hx.Qin = Qin;
    hx.Tc = 300.0;
    ThOut = hx.T;
  end Twin;
end Mini;
'''

PLAIN = '''within;
package Plain "Library without the conditional-input pattern"
  connector RealInput = input Real "Real input signal";

  model Exchanger "Lumped exchanger"
    parameter Real A = 10.0 "Area (m2)";
    parameter Real kht = 1000.0 "Heat-transfer coefficient (W/(m2.K))";
    parameter Real C = 4.0e5 "Heat capacity (J/K)";
    input Real Tc "Cold-side temperature (K)";
    input Real Qin "Heat input (W)";
    output Real T(start = 350.0, fixed = true) "Hot-side temperature (K)";
  equation
    // kht times area is the conductance
    C*der(T) = Qin - kht*A*(T - Tc);
  end Exchanger;

  model Twin "Heater twin"
    input Real Qin(start = 50000.0) "Heater power (W)";
    output Real ThOut "Hot temperature (K)";
    Exchanger hx(kht = 1000.0);
  equation
    hx.Qin = Qin;
    hx.Tc = 300.0;
    ThOut = hx.T;
  end Twin;
end Plain;
'''

UNITS = '''within;
package Units "Small test library with units and a tank"
  connector RealInput = input Real "Real input signal";

  model Exchanger "Lumped exchanger with a trackable heat-transfer coefficient"
    parameter Real A(unit = "m2") = 10.0 "Area";
    parameter Real kht(unit = "W/(m2.K)", min = 0) = 1000.0 "Heat-transfer coefficient";
    parameter Boolean use_kht_in = false "Take kht from input kht_in";
    parameter Real C(unit = "J/K") = 4.0e5 "Heat capacity";
    RealInput kht_in(unit = "W/(m2.K)") if use_kht_in "Heat-transfer coefficient from outside";
    input Real Tc(unit = "K") "Cold-side temperature";
    input Real Qin(unit = "W") "Heat input";
    output Real T(unit = "K", start = 350.0, fixed = true) "Hot-side temperature";
  protected
    RealInput kht_internal(unit = "W/(m2.K)") "kht actually used";
  equation
    connect(kht_in, kht_internal);
    if not use_kht_in then
      kht_internal = kht;
    end if;
    C*der(T) = Qin - kht_internal*A*(T - Tc);
  end Exchanger;

  model Tank "Tank whose level integrates inflow, correction and a level-proportional outflow"
    parameter Real area(unit = "m2") = 2.0 "Cross-section";
    parameter Real rho(unit = "kg/m3") = 1000.0 "Density";
    parameter Real kOut(unit = "kg/(s.m)") = 2.0 "Outflow per metre of level";
    parameter Real m_flow_corr(unit = "kg/s") = 0.0 "Correction flow";
    parameter Boolean use_m_flow_corr_in = false "Take the correction flow from input m_flow_corr_in";
    RealInput m_flow_corr_in(unit = "kg/s") if use_m_flow_corr_in "Correction flow from outside";
    input Real m_flow_in(unit = "kg/s") "Inflow";
    output Real level(unit = "m", start = 1.0, fixed = true) "Level";
  protected
    RealInput m_flow_corr_internal(unit = "kg/s") "Correction flow actually used";
  equation
    connect(m_flow_corr_in, m_flow_corr_internal);
    if not use_m_flow_corr_in then
      m_flow_corr_internal = m_flow_corr;
    end if;
    rho*area*der(level) = m_flow_in + m_flow_corr_internal - kOut*level;
  end Tank;

  model Twin "Heater and tank twin"
    input Real Qin(unit = "W", start = 50000.0) "Heater power";
    input Real m_flow_in(unit = "kg/s", start = 2.0) "Tank inflow";
    output Real ThOut(unit = "K") "Hot temperature";
    output Real LI_100(unit = "m") "Tank level";
    Exchanger hx(kht = 1000.0);
    Tank tank;
  equation
    hx.Qin = Qin;
    hx.Tc = 300.0;
    ThOut = hx.T;
    tank.m_flow_in = m_flow_in;
    LI_100 = tank.level;
  end Twin;
end Units;
'''

STATES = '''
[[states]]
tag = "LI-100"
variable = "LI_100"
correction = "tank.m_flow_corr"
gain = 5.0
'''

SPEC = '''twin = "twin.fmu"
measurements = "measurements.csv"
sample_time = 10.0
{source}
[inputs]
"QI-100" = "Qin"

[outputs]
"TI-102" = "ThOut"

[[parameters]]
name = "{parameter}"
start = 1000.0
min = 800.0
max = 1200.0

[windows]
training = [0.0, 3600.0]
validation = [3600.0, 7200.0]
{pairs}'''

PAIR = '''
[[pairs]]
variable = "TI-102"
parameter = "{parameter}"
gain = -0.005
time_constant = 40.0
lambda = 1.0
{gains}'''


def write_case(root: Path, *, library: str = "Mini", pairs: bool = True, source: bool = True,
               parameter: str = "hx.kht", gains: str = "kp = 0.5\nti = 60.0\n") -> Path:
    """Write the library (``Mini``, ``Plain`` or ``Units``) and a spec into *root*; return the spec path."""
    root.mkdir(parents=True, exist_ok=True)
    lib = root / library
    lib.mkdir(exist_ok=True)
    (lib / "package.mo").write_text({"Mini": MINI, "Plain": PLAIN, "Units": UNITS}[library])
    src = f'\n[source]\npath = "{library}"\nmodel = "{library}.Twin"\n' if source else "\n"
    pair_text = PAIR.format(parameter=parameter, gains=gains) if pairs else ""
    spec = root / "spec.toml"
    text = SPEC.format(source=src, parameter=parameter, pairs=pair_text)
    if library == "Units":  # the tank level is measured and compensated
        text = text.replace('"TI-102" = "ThOut"', '"TI-102" = "ThOut"\n"LI-100" = "LI_100"') + STATES
    spec.write_text(text)
    return spec


def harness(stage: Path, package: str, tracked: str, *, meas: float, hold: float = 0.0, own_hold: float = 0.0) -> Path:
    """A package ``Harness`` beside the generated one that binds the tracked model's inputs (*own_hold*:
    the pair's own hold, ``TI_102_hold``)."""
    h = stage / "Harness"
    h.mkdir(exist_ok=True)
    (h / "package.mo").write_text(
        "within;\npackage Harness\n  model Run\n"
        f"    {package}.{tracked} tracked(Qin = 50000.0, TI_102_meas = {meas!r}, hold = {hold!r}, "
        f"TI_102_hold = {own_hold!r});\n"
        "  end Run;\nend Harness;\n")
    return h / "package.mo"


def box_against_runtime(spec, fmu: Path, runtime_csv: Path) -> dict[str, tuple[float, float]]:
    """Drive the tracked FMU with the samples the Python runtime used; aligned agreement per parameter.

    Returns ``{parameter: (max, 95th percentile)}`` of ``|p_box - p_python| / (max - min)``.

    The twin's inputs come from the same table as in the runtime; the
    measurements, the hold (the runtime's ``mode`` column) and the corrections
    of top-level correction inputs are set once per sample and held over it,
    as the runtime holds them; the measurements are interpolated linearly
    between samples (as ``validate`` feeds them and the runtime's default
    ``"linear"`` error interpolation assumes). The box's value at ``t_k`` is
    compared with the runtime's row ``k`` (as ``test_generate._aligned_agreement`` does),
    after the start-up hold.
    """
    import pandas as pd

    from trackingbox import data
    from trackingbox.fmu import FMUModel
    from trackingbox.generate.filters import modelica_name
    from trackingbox.simulation.initial import apply_states, twin_initial_states

    py = pd.read_csv(runtime_csv)
    grid = py["time"].to_numpy(dtype=float)
    table = data.read_table(spec.measurements, allow_nan=True)
    sampled = data.resample(table[["time", *spec.inputs]], float(table["time"].iloc[0]) + grid,
                            max_gap=spec.data.max_gap)
    tags = [p.variable for p in spec.pairs] + [s.tag for s in spec.states]
    measured = py[[f"measured:{t}" for t in tags]].interpolate().ffill().bfill().to_numpy()
    inputs = pd.DataFrame({"time": grid, **{name: np.asarray(sampled[tag], dtype=float)
                                            for tag, name in spec.inputs.items()},
                           **{f"{modelica_name(t)}_meas": measured[:, j] for j, t in enumerate(tags)}})
    inputs = inputs.ffill().bfill()
    names = [modelica_name(p.parameter) for p in spec.pairs]
    box = np.full((grid.size, len(names)), np.nan)
    held = (py[[f"mode:{p.variable}" for p in spec.pairs]] == "hold").any(axis=1).to_numpy()
    states = None
    if spec.data.initial == "steady":  # the runtime's twins start from their steady state: so does the box's
        twin_inputs = inputs[["time", *spec.inputs.values()]]
        states = twin_initial_states(spec, start_time=float(grid[0]), inputs=twin_inputs,
                                     parameters={**{p.name: p.start for p in spec.parameters}, **spec.fixed})
    with FMUModel(fmu) as model:
        run = model.stepper(start_time=float(grid[0]), inputs=inputs)
        if states:
            assert apply_states(run, states)
        for k in range(grid.size):
            box[k] = run.get(names)
            if k == grid.size - 1:
                break
            values = {"hold": 1.0 if held[k] else 0.0}
            for st in spec.states:
                if st.correction in model.info.inputs:  # a top-level twin input: fed as the runtime fed it
                    values[st.correction] = float(py[f"correction:{st.correction}"].iloc[k])
            run.set(values)
            run.step(float(grid[k + 1]))
    after = grid >= float(spec.tracking.hold_until) - 1e-9
    out = {}
    for j, p in enumerate(spec.pairs):
        par = spec.parameter(p.parameter)
        d = np.abs(box[:, j] - py[f"parameter:{p.parameter}"].to_numpy()) / (par.max - par.min)
        out[p.parameter] = (float(np.nanmax(d[after])), float(np.nanpercentile(d[after], 95.0)))
    return out


# gains measured on the benches' twins (a 50-unit step of the parameter, steady change of the
# variable after an hour); time constants rounded from the step responses
BENCH_PAIRS = {
    "heat-exchanger": '''
[[pairs]]
variable = "TI-102"
parameter = "hx.kht"
gain = -0.0226
time_constant = 70.0
''',
    "heat-production": '''
[[pairs]]
variable = "TI-301"
parameter = "HEX300.kht"
gain = -0.00998
time_constant = 300.0

[[pairs]]
variable = "TI-310"
parameter = "HU300.kht"
gain = -0.0196
time_constant = 300.0

[[pairs]]
variable = "PI-200"
parameter = "Pipe200.k"
gain = 1177460.8
time_constant = 147.7
''',
}
