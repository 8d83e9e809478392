"""Where the MSL harness calls Modelica.Fluid tank temperatures 'wrong' or 'close' (issue 35): the closed
forms of the models as the MSL writes them, the Modelica Association's references, and ours.

    scripts/check_fluid_references [--fmu-dir DIR]

Without FMUs it compares the references (../shared/msl-reference) with the closed forms and with
scipy's integrators at the references' tolerance; with ``--fmu-dir`` holding
``TankWithEmptyingPipe1.fmu`` and ``TwoTanks.fmu`` (``trackingbox compile <MSL>/Modelica --model
Modelica.Fluid.Examples.AST_BatchPlant.Test.<Name> --backend embedded -o DIR/<Name>.fmu``) and
``ControlledTanks.fmu`` (``--model Modelica.Fluid.Examples.ControlledTankSystem.ControlledTanks``) it
simulates them too (each FMU that is there)."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from trackingbox.compiler.msl_harness import default_reference, load_reference

TEST = "Modelica.Fluid.Examples.AST_BatchPlant.Test."
G, CP, D, T_IN, M_FLOW = 9.80665, 4184.0, 995.586, 293.15, 50.0  # ConstantPropertyLiquidWater, system


def rise(level):
    """TankWithEmptyingPipe1: T - T_in = g*height_ab/cp*(1 - m0/m), m = (level + V0/crossArea)*d."""
    return G * 1.0 / CP * (1 - 0.2 * D / ((np.asarray(level) + 0.1) * D))


def emptying_pipe(ref, fmu_dir: Path | None) -> None:
    t, level, temp = ref.time, ref.values["tank1.level"], ref.values["tank1.medium.T"]
    off = np.abs(temp - T_IN - rise(level))
    print("TankWithEmptyingPipe1 (tank1.medium.T; closed form T - T_in = g*height_ab/cp*(1 - m0/m)):")
    print(f"  reference (Dassl, tolerance {ref.tolerance:g}): level vs m0 + m_flow*t "
          f"{np.max(np.abs(level - 0.1 - M_FLOW / D * t)):.2g} m; T vs closed form {off.max():.3g} K at "
          f"t = {t[np.argmax(off)]:.2f} s = {off.max() / np.ptp(temp):.3g} of its {np.ptp(temp):.3g} K range "
          f"(its solver's error scale: tolerance * |T| = {ref.tolerance * T_IN:.2g} K)")
    print(f"  at t = 5 s: closed form {rise(np.interp(5, t, level)):.5g} K, reference "
          f"{np.interp(5, t, temp) - T_IN:.5g} K")

    def rhs(_, y):
        return [M_FLOW / D, M_FLOW * (CP * (T_IN - y[1]) + G * 1.0) / ((y[0] + 0.1) * D * CP)]

    grid = np.linspace(0, 35, 5001)
    for method in ("BDF", "LSODA", "Radau"):
        sol = solve_ivp(rhs, (0, 35), [0.1, T_IN], method=method, rtol=1e-6, atol=1e-6, t_eval=grid)
        err = np.abs(sol.y[1] - T_IN - rise(sol.y[0]))
        print(f"  scipy {method} on the same two equations, rtol = atol = 1e-6: T vs closed form "
              f"{err.max():.3g} K at t = {grid[np.argmax(err)]:.2f} s")
    if fmu_dir is not None and (fmu_dir / "TankWithEmptyingPipe1.fmu").exists():
        import fmpy

        for tol in (1e-6, 1e-10):
            res = fmpy.simulate_fmu(str(fmu_dir / "TankWithEmptyingPipe1.fmu"), stop_time=35, relative_tolerance=tol,
                                    output_interval=0.007, output=["tank1.level", "tank1.medium.T"],
                                    fmi_type="ModelExchange")
            err = np.abs(res["tank1.medium.T"] - T_IN - rise(res["tank1.level"]))
            dev = np.max(np.abs(np.interp(t, res["time"], res["tank1.medium.T"]) - temp))
            print(f"  ours, CVODE rtol {tol:g}: T vs closed form {err.max():.3g} K, vs reference {dev:.3g} K")


def two_tanks(ref, fmu_dir: Path | None) -> None:
    t1 = ref.values["tank1.medium.T"]
    print("TwoTanks (tank1.medium.T; as written it is constant 323.15 K: tank1 only empties, a static pipe "
          "with friction monotone in the flow, so the level difference decays without crossing zero):")
    print(f"  reference (Dassl, tolerance {ref.tolerance:g}): T rises by {np.ptp(t1):.3g} K from t = "
          f"{ref.time[np.argmax(t1 > t1[0] + 1e-9)]:.2f} s; tank1.level goes {ref.values['tank1.level'].min() - 2:.3g} m "
          f"below the final 2 m (reverse flow)")
    if fmu_dir is not None and (fmu_dir / "TwoTanks.fmu").exists():
        import fmpy

        for tol in (1e-4, 1e-6, 1e-8, 1e-10):
            res = fmpy.simulate_fmu(str(fmu_dir / "TwoTanks.fmu"), stop_time=100, relative_tolerance=tol,
                                    output_interval=0.02, output=["tank1.level", "tank1.medium.T", "pipe.port_a.m_flow"],
                                    fmi_type="ModelExchange")
            flow = res["pipe.port_a.m_flow"]
            back = -np.trapezoid(np.minimum(flow, 0), res["time"])
            print(f"  ours, CVODE rtol {tol:g}: T rises by {np.ptp(res['tank1.medium.T']):.3g} K, level "
                  f"{res['tank1.level'].min() - 2:.3g} m below 2 m, {back:.3g} kg flowed back, "
                  f"{int(np.sum(np.diff(np.sign(flow)) != 0))} sign changes of the flow")


def controlled_tanks(ref, fmu_dir: Path | None) -> None:
    """ControlledTanks, tank1 after its first filling (t = 20 s to 42.1 s, valve1 open, valve2 shut):
    the source (2.5e6 Pa) feeds a constant flow through the linear ValveDiscrete, m_flow = 40/1e5*dp,
    dp = 2.5e6 - p_ambient (the inlet port, 4 m up, stays above the level), into port 1 (d = 0.2 m);
    with h = u = cp*(T - T0) the energy balance d(m*cp*(T - T_in)) = m_flow*(v^2/2 + g*4) gives, from
    level 0.05 m to 3.6 m, T - T_in = (1 - 0.05/3.6)*(v^2/2 + 4*g)/cp."""
    m_flow = 40 / 1e5 * (2.5e6 - 101325.0)
    v = m_flow / (D * np.pi / 4 * 0.2 ** 2)
    closed = (1 - 0.05 / 3.6) * (v * v / 2 + 4 * G) / CP
    temp = ref.values["tank1.medium.T"]
    at = float(np.interp(60.0, ref.time, temp)) - T_IN
    print("ControlledTanks (tank1.medium.T at t = 60 s, after the first filling; closed form "
          "T - T_in = (1 - m0/m)*(v^2/2 + g*4)/cp):")
    print(f"  closed form {closed:.6f} K (v = {v:.4f} m/s); reference {at:.6f} K ({at / closed - 1:+.3%}), "
          f"{abs(at - closed) / np.ptp(temp):.3g} of its {np.ptp(temp):.3g} K range")
    if fmu_dir is not None and (fmu_dir / "ControlledTanks.fmu").exists():
        import fmpy

        res = fmpy.simulate_fmu(str(fmu_dir / "ControlledTanks.fmu"), stop_time=60, relative_tolerance=1e-8,
                                output_interval=0.5, output=["tank1.medium.T"], fmi_type="ModelExchange")
        ours = float(res["tank1.medium.T"][-1]) - T_IN
        print(f"  ours, CVODE rtol 1e-8: {ours:.6f} K ({ours / closed - 1:+.3%})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu-dir", type=Path, default=None)
    args = parser.parse_args()
    root = default_reference()
    emptying_pipe(load_reference(root, TEST + "TankWithEmptyingPipe1"), args.fmu_dir)
    two_tanks(load_reference(root, TEST + "TwoTanks"), args.fmu_dir)
    controlled_tanks(load_reference(root, "Modelica.Fluid.Examples.ControlledTankSystem.ControlledTanks"),
                     args.fmu_dir)


if __name__ == "__main__":
    main()
