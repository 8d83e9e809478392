"""Why the MSL harness calls Modelica.Fluid.Examples.Tanks.ThreeTanks and ControlledTankSystem.ControlledTanks
'close' (issue 35): their tanks' temperatures against the energy balance of their own levels.

    scripts/check_tank_temperatures [--three-tanks FMU] [--controlled-tanks FMU]

Both examples hold ConstantPropertyLiquidWater (h = u = cp*(T - T0), cp = cv = 4184 J/(kg K), d = 995.586 kg/m3,
singleState, so an OpenTank's Wb_flow = 0) in OpenTanks without heat transfer. A tank's temperature then
follows from its mass flows alone, which its level gives (m = d*A*level, mdot = d*A*der(level)); written here
from the MSL's equations (PartialLumpedVessel: Hb_flow = sum(m_flow*actualStream(h_outflow)) +
sum(m_flow*(0.5*v^2 + g*port_height)), v = m_flow/(port area*d)):

    m*cp*der(T) = mdot*(h_in - cp*(T - T0) + 0.5*v^2 + g*port_height)   (h_in = the tank's own h on outflow)

- ThreeTanks: three tanks (area 1 m2, port diameter 0.1 m at the bottom) joined by StaticPipes (height_ab 2, 2,
  -1) at one junction. A StaticPipe adds g*height_ab to what leaves it at port_a and takes it off at port_b;
  the junction mixes ideally what the draining tanks' pipes deliver.
- ControlledTanks: two tanks (area 6 m2, ports of 0.2 m: the inlet at the top, 4 and 5 m, the outlet at the
  bottom) and discrete valves (isenthalpic). While only valve 1 is open (t = 20 to 42.1 s: tank 1 fills
  from the 293.15 K source through its top port) and while only valve 2 is (t = 92.1 to 220 s: tank 1
  drains into tank 2's top port), the balance above is the whole story.

Each level trajectory is interpolated (cubic spline over its output grid; the phases between the events the
reference records) and the balance integrated by scipy at rtol 1e-11. The reference's temperatures are set
against the balance of the reference's own levels; ours (``--three-tanks``/``--controlled-tanks``: an FMU from
``trackingbox compile <MSL>/Modelica --model ... --backend embedded -o FILE``) against the balance of our
levels, simulated as the harness does (CVODE, rtol 1e-6, the reference's grid) and at rtol 1e-10."""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from trackingbox.compiler.msl_harness import default_reference, load_reference

G, CP, D, T0, T_START = 9.80665, 4184.0, 995.586, 273.15, 293.15
THREE = "Modelica.Fluid.Examples.Tanks.ThreeTanks"
CONTROLLED = "Modelica.Fluid.Examples.ControlledTankSystem.ControlledTanks"
FILL = (20.0, 42.10176639)
"""ControlledTanks: start pressed (valve 1 opens) to tank 1 at maxLevel (the reference's events)."""
TRANSFER = (92.1017664, 220.0)
"""ControlledTanks: the wait over (valve 2 opens) to stop pressed."""
EDGE = 0.05
"""Output points this close to a phase's ends are left out of its spline (an event's points)."""


def _rtol(rtol: float) -> dict:
    return {"rtol": rtol, "atol": 1e-13, "method": "DOP853"}


def three_tanks(t: np.ndarray, levels: list[np.ndarray], rtol: float = 1e-11) -> np.ndarray:
    """ThreeTanks' three tank temperatures (3 x len(t)) from their *levels* over *t* (all from 293.15 K)."""
    area_port, height_ab = np.pi / 4 * 0.1 ** 2, np.array([2.0, 2.0, -1.0])
    keep = np.r_[True, np.diff(t) > 0]
    t = t[keep]
    spline = CubicSpline(t, np.array([lev[keep] for lev in levels]), axis=1)
    slope = spline.derivative()

    def rhs(tt, dT):
        temp = T_START + dT
        m, mdot = D * spline(tt), D * slope(tt)
        into_junction = np.maximum(-mdot, 0.0)
        delivered = CP * (temp - T0) + G * height_ab     # what pipe j's port_a hands the junction
        out = np.empty(3)
        for i in range(3):
            others = into_junction.sum() - into_junction[i]
            h = CP * (temp[i] - T0)
            if mdot[i] > 0 and others > 0:
                h = (into_junction @ delivered - into_junction[i] * delivered[i]) / others - G * height_ab[i]
            v = mdot[i] / (area_port * D)
            out[i] = mdot[i] * (h - CP * (temp[i] - T0) + 0.5 * v * v) / (m[i] * CP)
        return out
    sol = solve_ivp(rhs, (t[0], t[-1]), np.zeros(3), t_eval=t, **_rtol(rtol))
    full = np.empty((3, keep.size))
    full[:, keep] = T_START + sol.y
    full[:, ~keep] = full[:, np.flatnonzero(~keep) - 1]
    return full


def _phase(t: np.ndarray, phase: tuple[float, float]) -> np.ndarray:
    return (t > phase[0] + EDGE) & (t < phase[1] - EDGE) & np.r_[np.diff(t) > 0, True]


def controlled_fill(t: np.ndarray, level1: np.ndarray, rtol: float = 1e-11) -> tuple[np.ndarray, np.ndarray]:
    """ControlledTanks while valve 1 fills tank 1 (from 0.05 m and 293.15 K at t = 20 s): (times, T1)."""
    area, area_port = 6.0, np.pi / 4 * 0.2 ** 2
    k = _phase(t, FILL)
    tt = np.r_[FILL[0], t[k]]
    level = CubicSpline(tt, np.r_[0.05, level1[k]])
    slope = level.derivative()

    def rhs(x, temp):
        mdot = D * area * slope(x)
        v = mdot / (area_port * D)
        return mdot * (CP * (T_START - temp) + 0.5 * v * v + G * 4.0) / (D * area * level(x) * CP)
    sol = solve_ivp(rhs, (tt[0], tt[-1]), [T_START], t_eval=tt[1:], **_rtol(rtol))
    return tt[1:], sol.y[0]


def controlled_transfer(t: np.ndarray, level1: np.ndarray, level2: np.ndarray, temp1: np.ndarray,
                        temp2: np.ndarray, rtol: float = 1e-11) -> tuple[np.ndarray, np.ndarray]:
    """ControlledTanks while valve 2 lets tank 1 drain into tank 2 (from the phase's first output point, its
    temperatures as given): (times, 2 x n temperatures)."""
    area, area_port = 6.0, np.pi / 4 * 0.2 ** 2
    k = _phase(t, TRANSFER)
    tt = t[k]
    s1, s2 = CubicSpline(tt, level1[k]), CubicSpline(tt, level2[k])
    d1, d2 = s1.derivative(), s2.derivative()

    def rhs(x, temp):
        mdot1, mdot2 = D * area * d1(x), D * area * d2(x)
        v1, v2 = mdot1 / (area_port * D), mdot2 / (area_port * D)
        return [mdot1 * 0.5 * v1 * v1 / (D * area * s1(x) * CP),
                mdot2 * (CP * (temp[0] - temp[1]) + 0.5 * v2 * v2 + G * 5.0) / (D * area * s2(x) * CP)]
    sol = solve_ivp(rhs, (tt[0], tt[-1]), [temp1[k][0], temp2[k][0]], t_eval=tt, **_rtol(rtol))
    return tt, sol.y


def departures(model: str, t: np.ndarray, values: dict[str, np.ndarray], scale: dict[str, float]) -> dict:
    """{(phase, signal): largest |T - balance| / the reference's range of the signal} of a trajectory."""
    out = {}
    if model == THREE:
        temps = three_tanks(t, [values[f"tank{i}.level"] for i in (1, 2, 3)])
        for i in (1, 2, 3):
            s = f"tank{i}.medium.T"
            out[("0-200 s", s)] = float(np.max(np.abs(values[s] - temps[i - 1]))) / scale[s]
        return out
    tt, temp = controlled_fill(t, values["tank1.level"])
    s = "tank1.medium.T"
    out[("fill 20-42 s", s)] = float(np.max(np.abs(values[s][_phase(t, FILL)] - temp))) / scale[s]
    tt, temps = controlled_transfer(t, values["tank1.level"], values["tank2.level"], values["tank1.medium.T"],
                                    values["tank2.medium.T"])
    for i, s in enumerate(("tank1.medium.T", "tank2.medium.T")):
        out[("transfer 92-220 s", s)] = float(np.max(np.abs(values[s][_phase(t, TRANSFER)] - temps[i]))) / scale[s]
    return out


def reference(model: str, root: Path | None = None):
    """The model's reference, its last point's repetition (at the stop time) dropped."""
    ref = load_reference(root or default_reference(), model)
    if ref is None:
        raise SystemExit(f"no reference of {model} under {root or default_reference()}")
    keep = np.r_[True, np.diff(ref.time) > 0] if model == THREE else np.ones(ref.time.size, bool)
    return replace(ref, time=ref.time[keep], values={k: v[keep] for k, v in ref.values.items()})


def simulated(fmu: Path, ref, rtol: float | None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """*fmu* simulated as the harness does (*rtol* None) or at *rtol* on the same grid."""
    from trackingbox.compiler.msl_harness import CVODE_MAX_STEPS, _cvode_steps, simulate

    if rtol is None:
        t, values, problem = simulate(fmu, ref)
        if problem:
            raise SystemExit(f"{fmu}: {problem}")
        return t, values
    import fmpy

    interval = float(np.median(np.diff(ref.time)[np.diff(ref.time) > 0]))
    with _cvode_steps(CVODE_MAX_STEPS):
        r = fmpy.simulate_fmu(str(fmu), start_time=float(ref.time[0]), stop_time=float(ref.time[-1]),
                              relative_tolerance=rtol, output_interval=interval, output=list(ref.signals),
                              fmi_type="ModelExchange")
    return np.asarray(r["time"], float), {s: np.asarray(r[s], float) for s in ref.signals}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--three-tanks", type=Path, metavar="FMU", help="our ThreeTanks FMU, checked too")
    p.add_argument("--controlled-tanks", type=Path, metavar="FMU", help="our ControlledTanks FMU, checked too")
    p.add_argument("--reference", type=Path, default=None, help="reference results root")
    args = p.parse_args()
    for model, fmu in ((THREE, args.three_tanks), (CONTROLLED, args.controlled_tanks)):
        ref = reference(model, args.reference)
        scale = {s: float(np.ptp(v)) for s, v in ref.values.items()}
        print(f"{model}: |T - energy balance of the same run's levels| / the reference's range of T")
        rows = {"reference": departures(model, ref.time, ref.values, scale)}
        if fmu is not None:
            for label, rtol in (("ours, as the harness", None), ("ours, rtol 1e-10", 1e-10)):
                t, values = simulated(fmu, ref, rtol)
                rows[label] = departures(model, t, values, scale)
        for label, got in rows.items():
            for (phase, signal), dev in got.items():
                print(f"  {label:22s} {phase:18s} {signal:16s} {dev:.2e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
