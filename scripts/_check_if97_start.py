#!/usr/bin/env python3
"""Check (not a test): why ``Modelica.Fluid.Examples.AST_BatchPlant.BatchPlant_StandardWater``'s tank B5
failed to initialise ("their solve gives B5.medium.h = nan").

Translates a tank medium built from MSL classes as B5 has it (``Modelica.Media.Water.StandardWater`` at
101325 Pa, ``medium.T = 293.15`` as its initial equation; written to a temporary directory), takes its
initial residual as the compiler builds it (``T_ph(101325, h, phase) - 293.15``), and prints it at a few
enthalpies beside the ``iapws`` package's backward equation T(p, h) (an independent IF97), then Newton from
h = 0 J/kg (MSL gives ``BaseProperties.h`` no start value) and from 1e5 J/kg.

Example::

    scripts/check_if97_start
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

TANK = """model Tank
  replaceable package Medium = Modelica.Media.Water.StandardWater
    constrainedby Modelica.Media.Interfaces.PartialTwoPhaseMedium;
  Medium.BaseProperties medium(preferredMediumStates = true, p(start = 101325), T(start = 293.15));
  Real U;
equation
  medium.p = 101325;
  U = medium.h;
  der(U) = 1000;
initial equation
  medium.T = 293.15;
end Tank;
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--msl", default="../shared/msl/Modelica")
    args = ap.parse_args()
    from iapws.iapws97 import _Backward1_T_Ph
    from trackingbox.compiler import flat_systems, resolve_source
    from trackingbox.compiler.embedded import flatten
    from trackingbox.compiler.expandable import drop_absent_members
    from trackingbox.compiler.flatten import FlatTranslator
    from trackingbox.compiler.library import one_look, resolve_libraries

    seen: dict = {}
    built = flat_systems.SystemAssembly._initial_system

    def kept(self, *a, **k):
        seen["init"] = built(self, *a, **k)
        return seen["init"]

    flat_systems.SystemAssembly._initial_system = kept
    with tempfile.TemporaryDirectory() as tmp:
        src_path = Path(tmp) / "Tank.mo"
        src_path.write_text(TANK)
        src = resolve_source(src_path)
        with one_look():
            libs, missing = resolve_libraries(src, "Tank", (Path(args.msl),))
            flat = flatten(src, "Tank", libs, missing)
            drop_absent_members(flat)
            FlatTranslator(flat, src, "Tank", libs).translate()
    init = seen["init"]
    names = [u.name() for u in init.unknowns]
    assert names == ["medium.h"], names
    known = {k.name(): 1.0 for k in init.knowns}  # medium.phase at its start value 1 (one phase)
    h = init.unknowns[0]
    residual = ca.Function("r", [h] + init.knowns, [init.residual[0]])
    slope = ca.Function("dr", [h] + init.knowns, [ca.jacobian(init.residual[0], h)])
    ks = [known[k.name()] for k in init.knowns]
    print("initial residual of", init.origins[0], ":", str(init.residual[0])[:120])
    print(f"{'h J/kg':>10} {'T_ph (ours) K':>16} {'dT/dh':>10} {'iapws T(p, h) K':>16}")
    for hv in (0, 30, 60, 61, 62, 100, 1000, 2000, 10000, 40000, 83916.07, 90000):
        t = float(residual(hv, *ks)) + 293.15
        ref = _Backward1_T_Ph(0.101325, hv / 1000)
        print(f"{hv:>10g} {t:>16.10f} {float(slope(hv, *ks)):>10.3g} {ref:>16.10f}")
    for h0 in (0.0, 1e5):
        x = h0
        for i in range(30):
            r, d = float(residual(x, *ks)), float(slope(x, *ks))
            if not np.isfinite(r) or d == 0:
                print(f"Newton from h = {h0:g}: stops at iteration {i}, h = {x:g}, residual {r:g}, slope {d:g}")
                break
            if abs(r) < 1e-10:
                print(f"Newton from h = {h0:g}: h = {x:.6f} J/kg in {i} iterations")
                break
            x -= r / d


if __name__ == "__main__":
    main()
