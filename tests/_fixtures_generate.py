"""Small twin libraries and specs for the code-generation tests (written to tmp_path).

``Mini`` is a one-state heater whose exchanger offers the conditional-input
pattern for ``kht``; ``Plain`` is the same model without it (for the refusal
and ``--rewrite`` paths); ``Units`` is ``Mini`` with SI units on every
variable plus a tank whose level takes a correction flow (for ``[[states]]``). Steady state of both:
``T = Tc + Qin/(kht*A)`` with ``Tc = 300 K``, ``A = 10 m2``, ``Qin = 50 kW``,
so ``dT/dkht = -Qin/(kht^2 A) = -0.005 K per W/(m2.K)`` at ``kht = 1000`` and
the ``kht`` that gives a measured ``T`` is ``50000/(10 (T - 300))``.
"""
from __future__ import annotations

from pathlib import Path

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
