#!/usr/bin/env python3
"""Check (not a test): why ``Modelica.Fluid.Examples.HeatingSystem``'s FMU does not initialise.

Translates the example (rumoca's flat model cached in ``--cache``), takes the whole-system initial solve
as the compiler builds it (.flat_systems._whole_initial_solution: the initial equations with the model's
own, blocks in order, the explicit ones evaluated at the parameters' and start values), and at its first
algebraic loop of more than ``--min-size`` unknowns prints: the tearing variables and their start values,
the singular values of Newton's matrix there, plain Newton from the start values, and plain Newton from
the same start with the volumes' pressures at the MSL reference's initial values (``--reference``) and the
two port pressures torn (whose start is the default 1e5 Pa) at the pump's set point, 130000 Pa, and at the
reference's radiator pressure + 5 Pa: a start with the small pressure drops along the flow.

Example::

    scripts/check_heating_start --cache /tmp/hs/flat.json
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import casadi as ca
import numpy as np

MODEL = "Modelica.Fluid.Examples.HeatingSystem"
REFERENCE_P = {"heater.mediums[1].p": "heater.mediums[1].p", "pipe.mediums[1].p": "pipe.mediums[1].p",
               "pipe.mediums[2].p": "pipe.mediums[2].p", "radiator.mediums[1].p": "radiator.mediums[1].p"}


def newton(f, jac, x, iterations=60, tol=1e-8):
    for i in range(iterations):
        r = np.array(f(x)).ravel()
        if np.all(np.isfinite(r)) and np.max(np.abs(r)) < tol:
            return x, f"converged in {i} iterations (largest residual {np.max(np.abs(r)):.2e})"
        try:
            x = x + np.linalg.solve(np.array(jac(x)), -r)
        except np.linalg.LinAlgError:
            return x, f"Newton's matrix singular at iteration {i}"
        if not np.all(np.isfinite(x)):
            return x, f"non-finite iterate at iteration {i}"
    return x, f"no convergence in {iterations} iterations (largest residual {np.max(np.abs(r)):.3g})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--msl", default="../shared/msl/Modelica")
    ap.add_argument("--reference", default="../shared/msl-reference")
    ap.add_argument("--cache", type=Path, default=None, help="rumoca's flat model as JSON (written if absent)")
    ap.add_argument("--min-size", type=int, default=100)
    args = ap.parse_args()
    from trackingbox.compiler import resolve_source
    from trackingbox.compiler import flat_systems
    from trackingbox.compiler.causalize import blt
    from trackingbox.compiler.embedded import flatten
    from trackingbox.compiler.expandable import drop_absent_members
    from trackingbox.compiler.flat_builtins import solve_scalar_linear
    from trackingbox.compiler.flatten import FlatTranslator
    from trackingbox.compiler.library import one_look, resolve_libraries
    from trackingbox.compiler.msl_harness import load_reference

    seen: dict = {}
    whole = flat_systems.SystemAssembly._whole_initial_solution

    def kept(self, residuals, exprs, blocks, unknowns, guesses):
        seen.update(tr=self, residuals=residuals, unknowns=unknowns)
        return whole(self, residuals, exprs, blocks, unknowns, guesses)

    flat_systems.SystemAssembly._whole_initial_solution = kept
    src = resolve_source(args.msl)
    with one_look():
        libs, missing = resolve_libraries(src, MODEL, ())
        if args.cache is not None and args.cache.exists():
            flat = json.loads(args.cache.read_text())
        else:
            flat = flatten(src, MODEL, libs, missing)
            drop_absent_members(flat)
            if args.cache is not None:
                args.cache.write_text(json.dumps(flat))
        FlatTranslator(flat, src, MODEL, libs).translate()
    tr = seen["tr"]
    m_res, m_unk = tr._model_system
    taken = {u.name() for u in seen["unknowns"]}
    syms = list(seen["unknowns"]) + [u for u in m_unk if u.name() not in taken]
    eqs = [r for r, _ in seen["residuals"]] + [r for r, _ in m_res]
    position = {u.name(): i for i, u in enumerate(syms)}
    blocks = blt([sorted({position[v.name()] for v in ca.symvar(e) if v.name() in position}) for e in eqs], len(syms))
    start = {n: tr._start_of(tr.scalars[n]) if n in tr.scalars else 0.0 for n in position}
    preferred = {n for n, s in tr._state_select().items() if s in ("Always", "Prefer")}
    conditions = {c.sym.name(): c for c in tr.events.conditions}
    value: dict[str, float] = {"time": 0.0}

    def known(sym):
        name = sym.name()
        if name not in value:
            if name in conditions:  # a relation, at the values known so far (start values otherwise)
                expr = conditions[name].value
                inner = ca.symvar(expr)
                value[name] = float(ca.evalf(ca.substitute([expr], inner, [ca.MX(known(s)) for s in inner])[0]))
            else:
                value[name] = tr._start_of(tr.scalars[name])
        return value[name]

    for block in blocks:
        res = [eqs[i] for i in block.equations]
        unk = [syms[j] for j in block.unknowns]
        names = {u.name() for u in unk}
        others = {s.name(): s for r in res for s in ca.symvar(r) if s.name() not in names}
        res = ca.substitute(res, list(others.values()), [ca.MX(known(s)) for s in others.values()])
        if len(unk) == 1:
            sol = solve_scalar_linear(res[0], unk[0])
            if sol is not None:
                value[unk[0].name()] = float(ca.evalf(sol))
                continue
        tears, solved, residual = tr._tear(res, unk, {u.name(): start[u.name()] for u in unk}, preferred)
        inner = list(residual)
        for var, expr in reversed(solved):
            inner = ca.substitute(inner, [var], [expr])
        z = ca.vertcat(*tears)
        f = ca.Function("f", [z], [ca.vertcat(*inner)])
        jac = ca.Function("newton_matrix", [z], [ca.jacobian(ca.vertcat(*inner), z)])
        x0 = np.array([start[t.name()] for t in tears], float)
        if len(unk) >= args.min_size:
            break
        x, _ = newton(f, jac, x0)  # a smaller loop: solved as well as plain Newton does, to go on
        bs, bv = list(tears), [ca.MX(float(v)) for v in x]
        for var, expr in solved:
            bv.append(ca.substitute([expr], bs, bv)[0])
            bs.append(var)
        value.update({s.name(): float(ca.evalf(v)) for s, v in zip(bs, bv)})
    else:
        raise SystemExit(f"no loop of {args.min_size} unknowns or more in the whole-system initial solve")
    tear_names = [t.name() for t in tears]
    print(f"loop of {len(unk)} unknowns, {len(tears)} tearing variables:")
    for n_, v in zip(tear_names, x0):
        print(f"  {n_} = {v:g} (start)")
    sv = np.linalg.svd(np.array(jac(x0)), compute_uv=False)
    print("singular values of Newton's matrix at the start:", " ".join(f"{s:.3g}" for s in sv))
    print("Newton from the start values:", newton(f, jac, x0)[1])
    ref = load_reference(Path(args.reference), MODEL)
    x1 = x0.copy()
    for n_ in REFERENCE_P:
        x1[tear_names.index(n_)] = float(ref.values[n_][0])
    x1[tear_names.index("heater.port_a.p")] = 130000.0  # pump.p_b_nominal, its set point (control_m_flow = false)
    x1[tear_names.index("radiator.port_a.p")] = float(ref.values["radiator.mediums[1].p"][0]) + 5.0
    x, how = newton(f, jac, x1)
    print("Newton with the volumes' pressures at the reference's initial values, heater.port_a.p = 130000 "
          "and radiator.port_a.p 5 Pa above the radiator's:", how)
    for n_ in tear_names:
        r = f" (reference {float(ref.values[n_][0]):.4f})" if n_ in REFERENCE_P else ""
        print(f"  {n_} = {x[tear_names.index(n_)]:.4f}{r}")


if __name__ == "__main__":
    main()
