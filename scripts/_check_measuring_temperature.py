"""Why the MSL harness calls Modelica.Fluid.Examples.Explanatory.MeasuringTemperature 'close' (issue 35):
an independent model of one of its three (hydraulically identical) branches, the reference, and ours.

    scripts/check_measuring_temperature [--fmu FILE]

The branch: ``MassFlowSource_T`` (m_flow = sin(2*pi*t) kg/s at 323.15 K) into a junction with two
``OpenTank`` (cross area 2 m2, one port of 0.05 m at the bottom, zeta_in 1.04, zeta_out 0.5; the cold one
at 0.975 m and 293.15 K, the hot one at 1 m and 353.15 K). Written here from the vessel's equations as
the MSL states them: tank mass M and enthalpy h as states, p_static = p_ambient + M*g/A, the port's
``regSquare2`` pressure loss, kinetic energy at the port, ideal mixing at the junction; water is IF97
region 1 from the ``iapws`` package (a test dependency; forward g1(p, T), and T(p, h) by the backward
equation as StandardWater does). The one-port sensor reads the mixture of the outflows into the
junction. It is integrated by scipy at tight tolerances and, like the reference (Dymola's Dassl at
tolerance 1e-6), at 1e-6 with no step limit; a small shift of the hot tank's initial mass shows how
sensitive the reading is to the tanks' mass difference (the flows are driven by a 14 Pa difference of
two 9.5 kPa heads). With ``--fmu`` (``trackingbox compile <MSL>/Modelica --model
Modelica.Fluid.Examples.Explanatory.MeasuringTemperature --backend embedded -o FILE``) ours too."""
from __future__ import annotations

import argparse
from math import pi, sin, sqrt
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from trackingbox.compiler.msl_harness import WINDOW, default_reference, deviation, load_reference

MODEL = "Modelica.Fluid.Examples.Explanatory.MeasuringTemperature"
G, AREA, P_AMB, M_SMALL = 9.80665, 2.0, 101325.0, 1e-2
PORT = pi / 4 * 0.05 ** 2
ZETA_IN, ZETA_OUT = 1.04, 0.5
GRID = np.round(np.arange(5001) * 0.00022, 10)
PROBES = (0.1, 0.25, 0.45, 0.539, 0.53922, 0.5401, 0.55, 0.7, 1.05)


def _water():
    from iapws.iapws97 import _Backward1_T_Ph, _Region1

    def temperature(p, h):
        return _Backward1_T_Ph(p / 1e6, h / 1e3)

    def density(p, h):
        return 1 / _Region1(temperature(p, h), p / 1e6)["v"]

    def enthalpy(p, temp):
        return _Region1(temp, p / 1e6)["h"] * 1e3
    return temperature, density, enthalpy


T_PH, D_PH, H_PT = _water()


def _cubic(x, xp, yp, ypd, y0d):
    a1 = xp * y0d
    a2 = 3 * yp - xp * ypd - 2 * a1
    a3 = yp - a2 - a1
    xx = x / xp
    return xx * (a1 + xx * (a2 + xx * a3))


def _reg_branch(x, x1, k1, k2):
    """The regularised square for k1 >= k2 inside |x| < x1: two cubics through the origin whose slope
    there makes their second derivatives meet, capped for monotonicity."""
    if x <= -x1:
        return -k2 * x * x
    y1, y2, y1d, y2d = k1 * x1 ** 2, -k2 * x1 ** 2, 2 * k1 * x1, 2 * k2 * x1
    w = -1.0
    y0d = ((3 * y2 + x1 * y2d) / w - (3 * y1 - x1 * y1d) * w) / (2 * x1 * (1 - w))
    y0d = min(y0d, 0.9 * sqrt(5) * min(k1, k2) * x1)
    return _cubic(x, x1, y1, y1d, y0d) if x >= 0 else _cubic(x, -x1, y2, y2d, y0d)


def reg_square(x, x_small, k1, k2):
    """k1*x^2 for x >= x_small, -k2*x^2 for x <= -x_small, smooth (C1, monotone) in between."""
    if x >= x_small:
        return k1 * x * x
    if x <= -x_small:
        return -k2 * x * x
    return _reg_branch(x, x_small, k1, k2) if k1 >= k2 else -_reg_branch(-x, x_small, k2, k1)


def _mixture(streams):
    """Ideal mixing of the streams (outflow into the junction, enthalpy) that flow out; None if none."""
    total = sum(max(m, 0.0) for m, _ in streams)
    return sum(max(m, 0.0) * h for m, h in streams) / total if total > 0 else None


def hydraulics(t, mass, h):
    """(source flow, source enthalpy, junction pressure, flows into the tanks, their inflow enthalpies)."""
    ms = sin(2 * pi * t)
    static = [P_AMB + mass[i] * G / AREA for i in range(2)]
    hs = H_PT(static[0], 323.15)

    def port(i, into, into_other):
        h_in = _mixture([(ms, hs), (-into_other, h[1 - i])]) or h[i]
        k_in = (ZETA_IN - 1 + PORT ** 2 / AREA ** 2) / D_PH(static[i], h_in)
        k_out = (ZETA_OUT + 1 - PORT ** 2 / AREA ** 2) / D_PH(P_AMB, h[i])
        return static[i] + 0.5 / PORT ** 2 * reg_square(into, M_SMALL, k_in, k_out), h_in

    cold = brentq(lambda m: port(0, m, ms - m)[0] - port(1, ms - m, m)[0], -10, 10, xtol=1e-14, rtol=1e-15)
    p, h_cold = port(0, cold, ms - cold)
    _, h_hot = port(1, ms - cold, cold)
    return ms, hs, p, (cold, ms - cold), (h_cold, h_hot)


def rhs(t, y):
    """States: the tanks' masses and specific enthalpies; U = M*(h - p_ambient/d(h))."""
    mass, h = y[0:2], y[2:4]
    _, _, _, flows, h_in = hydraulics(t, mass, h)
    dh = []
    for i in range(2):
        m = flows[i]
        h_act = h_in[i] if m > 0 else h[i]
        v = m / PORT / D_PH(P_AMB + mass[i] * G / AREA, h_act)
        du = m * h_act + m * 0.5 * v * v
        u = h[i] - P_AMB / D_PH(P_AMB, h[i])
        e = 1e-3
        du_dh = (2 * e - P_AMB / D_PH(P_AMB, h[i] + e) + P_AMB / D_PH(P_AMB, h[i] - e)) / (2 * e)
        dh.append((du - m * u) / (mass[i] * du_dh))
    return [flows[0], flows[1], dh[0], dh[1]]


def simulate(rtol, method="LSODA", tight=True, hot_mass_shift=0.0):
    """The one-port sensor's temperature on the reference's grid, and the hot tank's flow."""
    h_cold, h_hot = H_PT(P_AMB, 293.15), H_PT(P_AMB, 353.15)
    y0 = [AREA * 0.975 * D_PH(P_AMB, h_cold), AREA * 1.0 * D_PH(P_AMB, h_hot) + hot_mass_shift, h_cold, h_hot]
    kw = {"atol": rtol * np.array([10, 10, 1e3, 1e3]), "max_step": 1e-3} if tight else {"atol": rtol}
    sol = solve_ivp(rhs, (0, 1.1), y0, method=method, rtol=rtol, t_eval=GRID, **kw)
    if sol.status != 0:
        raise RuntimeError(f"scipy {method} at rtol {rtol:g} failed: {sol.message}")
    temp, hot = [], []
    for t, y in zip(sol.t, sol.y.T):
        ms, hs, p, flows, _ = hydraulics(t, y[0:2], y[2:4])
        temp.append(T_PH(p, _mixture([(ms, hs), (-flows[0], y[2]), (-flows[1], y[3])])))
        hot.append(flows[1])
    return np.asarray(temp), np.asarray(hot)


def _reversal(hot):
    """First time after 0.5 s at which the hot tank's flow turns outwards (linear interpolation)."""
    i = int(np.argmax((GRID > 0.5) & (hot < 0)))
    return GRID[i - 1] + (GRID[i] - GRID[i - 1]) * hot[i - 1] / (hot[i - 1] - hot[i])


def _row(name, ref, temp, extra=""):
    probes = " ".join(f"{np.interp(t, GRID, temp) - np.interp(t, ref.time, ref.values['T_onePort.T']):+.4f}"
                      for t in PROBES)
    dev = deviation(ref.time, ref.values["T_onePort.T"], GRID, temp, WINDOW * 1.1, ref.tolerance)
    print(f"  {name:<44} {probes}  harness deviation {dev:.3g}{extra}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", type=Path, default=None)
    args = parser.parse_args()
    ref = load_reference(default_reference(), MODEL)
    signals = ref.values
    back = (ref.time > 0.505) & (ref.time < 0.995)
    print(f"{MODEL}: reference (tolerance {ref.tolerance:g}); while the flow is reversed the three sensors read "
          f"alike (largest difference from T_onePort.T over 0.505-0.995 s: "
          f"{max(float(np.max(np.abs(v - signals['T_onePort.T'])[back])) for v in signals.values()):.2g} K)")
    print("  T_onePort.T minus the reference (K) at t = " + " ".join(f"{t:g}" for t in PROBES))
    temp, hot = simulate(1e-9)
    _row("independent, LSODA rtol 1e-9", ref, temp, f"; hot tank's flow reverses at {_reversal(hot):.5f} s")
    for method in ("BDF", "LSODA"):
        t_loose, _ = simulate(1e-6, method, tight=False)
        _row(f"independent, {method} rtol = atol = 1e-6", ref, t_loose)
    shifted, hot = simulate(1e-9, hot_mass_shift=-0.015)
    _row("independent, 1e-9, hot tank 0.015 kg lighter", ref, shifted,
         f"; reverses at {_reversal(hot):.5f} s")
    if args.fmu is not None:
        import fmpy

        for tol in (1e-6, 1e-8):
            res = fmpy.simulate_fmu(str(args.fmu), stop_time=1.1, relative_tolerance=tol, output_interval=0.00022,
                                    output=["T_onePort.T"], fmi_type="ModelExchange")
            ours = np.interp(GRID, res["time"], res["T_onePort.T"])
            _row(f"ours, CVODE rtol {tol:g}", ref, ours,
                 f"; vs independent 1e-9: {float(np.max(np.abs(ours - temp))):.3g} K")
    print(f"  (the reference's first event after 0.5 s: t = "
          f"{ref.time[np.argmax((np.diff(ref.time) == 0) & (ref.time[:-1] > 0.5))]:.6f} s)")


if __name__ == "__main__":
    main()
