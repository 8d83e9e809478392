"""The numerics of an algebraic loop's solve, built as CasADi expressions (compiled into the FMU
with the model): Newton's iterate accepted where it is a root, the fallbacks where it is not (the
solution nearest the guess, from where a damped Gauss-Newton iteration ends, moved off a point where
the loop's Jacobian has a zero column), and the warm start of the model's loops
(:func:`warm_solution`): Newton from the loop's last converged solution, which the FMU keeps
(:mod:`.fmi_runtime`), a root outside the tearing variables' declared min/max counting as no solution.
"""
from __future__ import annotations

from typing import Any

import casadi as ca

from .repeat import repeated


LOOP_TOLERANCE = 1e-6
"""The largest residual (2-norm, relative to 1 + |z|) accepted from the nearest-solution fallback;
above it the loop has no solution near the guess and gives NaN."""
NEAREST_REGULARISATION = 1e-10
"""epsilon of the regularised optimality conditions of the nearest solution (see _or_nearest_solution)."""
NEWTON_TOLERANCE = 1e-10
"""The loops' Newton tolerance (largest residual): the rootfinders' abstol."""
DAMPED_ITERATIONS = 60
"""Steps of the damped Gauss-Newton iteration, the last fallback of a loop (see _damped_newton)."""
DAMPED_HALVINGS = 24
"""Step lengths 1, 1/2, ... 1/2**(DAMPED_HALVINGS - 1) tried on each step of the damped iteration."""


def _damped_newton(name: str, distance: ca.Function, n: int, start: ca.MX | ca.DM,
                   values: ca.MX | ca.DM, anchor: ca.MX | ca.DM | None = None) -> ca.MX:
    """A root of the scaled residual *distance(z, p, z0)* by Gauss-Newton steps of minimum norm,
    dz = -J'(J J' + mu I)^-1 r (defined whatever the rank of J), each shortened by halving until the
    residual's square falls by the Armijo fraction (the shortest length tried is taken otherwise, and the
    iteration stops), from *start*, *anchor* the third argument of *distance* in every step (the
    loop's fallbacks pass the weights of its equations at the guess; *start* where not given). Newton's
    full steps swing across the root of a flow law that goes as the square root of a pressure difference (from a flow q ~ sqrt(x), the full step lands at -x, and back):
    e.g. MSL ``Fluid.Examples.Tanks.TanksWithOverflow``'s overflow pipe between two ports above their
    levels. The iteration is a fixed number of steps (one step function, :func:`.repeat.repeated`: the
    steps after it stopped are skipped in blocks), so that it is exported as C like the rest of the model."""
    z = ca.MX.sym(f"{name}_dz", n)
    q = ca.MX.sym(f"{name}_dq", values.numel() + n)
    p, z0 = q[:values.numel()], q[values.numel():]
    r = distance(z, p, z0)
    jac = ca.jacobian(r, z)
    jjt = ca.mtimes(jac, jac.T)
    mu = NEAREST_REGULARISATION * (1 + ca.trace(jjt) / max(n, 1))
    dz = -ca.mtimes(jac.T, ca.solve(jjt + mu * ca.MX.eye(r.numel()), r))
    phi0 = ca.sumsqr(r)

    def trial(j: int) -> ca.MX:  # the first length from 1/2**j on that the residual accepts
        a = 0.5 ** j
        if j == DAMPED_HALVINGS - 1:  # none accepted: the step is taken, and the iteration has stalled
            return ca.vertcat(z + a * dz, 1)
        phi = ca.sumsqr(distance(z + a * dz, p, z0))
        return ca.if_else(phi <= (1 - 1e-4 * a) * phi0, ca.vertcat(z + a * dz, 0), trial(j + 1), True)

    # only the branch taken is evaluated: a step needs as many residuals as lengths it tries, and
    # none (not even the Jacobian) once the residual is far below the accepted one, or once a step
    # found no length that lowers it (a residual that is not finite, or a minimum of its norm that is
    # no root): the remaining steps would each try every length again (DAMPED_HALVINGS residuals of
    # the loop's functions, e.g. IF97 calls, per step) to move the iterate by 2**-23 of a step
    # (a step from there would not move it either: it stops the iteration as a stall does)
    done = phi0 <= (1e-3 * LOOP_TOLERANCE * (1 + ca.norm_2(z))) ** 2
    move = ca.Function(f"{name}_damped_move", [z, q], [ca.if_else(done, ca.vertcat(z, 1), trial(0), True)])
    zs = ca.MX.sym(f"{name}_dzs", n + 1)  # the iterate, then 1 once it stopped (no length lowers, or done)
    step = ca.Function(f"{name}_damped_step", [zs, q], [ca.if_else(zs[n] > 0.5, zs, move(zs[:n], q), True)])
    anchor = start if anchor is None else anchor
    steps = repeated(step, DAMPED_ITERATIONS, lambda s: s[n] > 0.5, f"{name}_damped")
    return steps(ca.vertcat(start, 0), ca.vertcat(values, anchor))[:n]


FLAT_NUDGE = 1e-3
"""Relative move of an unknown whose column of the loop's Jacobian is zero at the guess (see _flat_kick)."""


def _flat_kick(jacobian: ca.Function, start: ca.MX | ca.DM, values: ca.MX | ca.DM) -> ca.MX:
    """FLAT_NUDGE * (1 + |z|) for each unknown that no residual responds to at *start* (its column of the
    Jacobian exactly zero), 0 for the others. At such a guess every Gauss-Newton step leaves that unknown
    where it is, and Newton's matrix is singular: a loss that goes as m_flow^2 or m_flow*|m_flow|
    (MSL ``Fluid.Fittings.AbruptAdaptor``'s total-pressure balance) from m_flow.start = 0, where the
    loss's derivative vanishes although the loop has roots on both sides. The damped steps start from
    the guess moved off the flat point both ways (:func:`_or_nearest_solution` keeps the root nearer the
    guess). A column that is not finite is left as it is."""
    jac = jacobian(start, values, start)
    flat = ca.sum1(jac * jac).T == 0
    return ca.if_else(flat, FLAT_NUDGE * (1 + ca.fabs(start)), ca.DM.zeros(start.shape[0], 1))


def _or_nearest_solution(name: str, z: ca.MX, p: ca.MX, g: ca.MX, sol: ca.MX, start: ca.MX | ca.DM,
                         values: ca.MX | ca.DM) -> ca.MX:
    """Newton's iterate *sol* of the loop g(z, p) = 0 where it and its residual are finite and it is
    a root (Newton's tolerance met, or the test below); where not (a Jacobian singular at the solution,
    e.g. two stuck friction elements in series, whose torque split no equation determines: MSL
    ``Rotational.Examples.LossyGearDemo2``) the solution nearest the guess z0,
    argmin |z - z0| subject to g(z) = 0, from its optimality conditions regularised so that their
    Jacobian [[I + sum y_i H_i, J'], [J, -eps I]] is nonsingular whatever the rank of J:

        z - z0 + J(z)' y = 0,   g(z) - eps y = 0.

    For a linear g = A z - b this is z = z0 - A'(A A' + eps I)^-1 (A z0 - b), which tends to
    z0 + pinv(A) (b - A z0) as eps -> 0. Each equation is first divided by the norm of its gradient at
    the guess (1 where that is zero), so that eps is small against J J' and the accepted residual
    (LOOP_TOLERANCE) is a distance in z whatever the units: with flows in kg/s over pressures in Pa
    (gradients ~1e-6) eps = 1e-10 held the solution short of a root, and a residual of 0.08 kg/s
    passed 1e-6*(1 + |z|) with |z| ~ 1e5 Pa. Only the branch taken is evaluated (a short-circuit
    if_else). It is first sought from where a damped Gauss-Newton iteration (_damped_newton) ends
    (from the guess, Newton's steps on the optimality conditions can swing across the root of a
    square-root flow law; from a guess where the loop's residuals do not respond to an unknown, from the
    guess moved off that flat point both ways by _flat_kick, the end nearer the guess), then from the guess; a loop that neither solves leaves NaN, so that the
    importer's solver fails rather than going on with values that do not satisfy the equations."""
    accepted, fallback = _loop_tests(name, z, p, g, values)
    return ca.if_else(accepted(sol, start), sol, fallback(start), True)


def _loop_tests(name: str, z: ca.MX, p: ca.MX, g: ca.MX, values: ca.MX | ca.DM) -> tuple[Any, Any]:
    """(accepted(sol, guess): whether Newton's iterate *sol* from *guess* is a root (see
    :func:`_or_nearest_solution`), fallback(guess): the loop's solution by the fallbacks from *guess*,
    NaN where none solves). The loop's functions are made once, for both and for every guess."""
    n = z.numel()
    y = ca.MX.sym(f"{name}_y", n)
    z0 = ca.MX.sym(f"{name}_z0", n)
    rows = ca.sqrt(ca.sum2(ca.substitute(ca.jacobian(g, z), z, z0) ** 2))  # each equation's gradient at z0
    weight = ca.if_else(ca.logic_and(rows > 0, rows < ca.inf), rows, 1)  # in (p, z0); 1 where 0 or not finite
    scaled = g / weight
    kkt = ca.vertcat(z - z0 + ca.mtimes(ca.jacobian(scaled, z).T, y), scaled - NEAREST_REGULARISATION * y)
    nearest = ca.rootfinder(f"{name}_nearest", "fast_newton",
                            {"x": ca.vertcat(z, y), "p": ca.vertcat(p, z0), "g": kkt},
                            {"abstol": 1e-10, "max_iter": 100, "error_on_fail": False})
    residual = ca.Function(f"{name}_residual", [z, p], [g])
    distance = ca.Function(f"{name}_distance", [z, p, z0], [scaled])

    # NaN or inf anywhere makes these comparisons false. Newton's iterate counts where it met its own
    # tolerance or is a root by the fallback's test: after its 100 steps, an iterate swinging across
    # the root of a square-root flow law is finite but no root (TanksWithOverflow's overflow pipe:
    # 0.084 kg/s out of a port the equations close)
    def accepted(sol: ca.MX, start: ca.MX | ca.DM) -> ca.MX:
        r_sol = residual(sol, values)
        converged = ca.logic_or(ca.mmax(ca.fabs(r_sol)) <= NEWTON_TOLERANCE, ca.sumsqr(distance(sol, values, start))
                                <= (LOOP_TOLERANCE * (1 + ca.norm_2(sol))) ** 2)
        return ca.logic_and(ca.sumsqr(r_sol) + ca.sumsqr(sol) < ca.inf, converged)

    # the damped iteration only finds where to start the nearest solution's Newton again (with the
    # multipliers that fit it), a guess whose derivatives are stopped: the solution's derivatives are
    # the nearest solution's, and the model's derivatives (exported with it) do not differentiate
    # through the iteration (which tripled the generated C of TanksWithOverflow)
    jacobian = ca.Function(f"{name}_jacobian", [z, p, z0], [ca.jacobian(scaled, z)])
    # the damped steps take the weights as numbers (computed once, from the guess): the Jacobian of
    # `distance` in z is also differentiated in z0 (zero directions, evaluated all the same), which are
    # second derivatives of the loop's functions, each step (MSL MomentumBalanceFittings: 45% of its time)
    w = ca.MX.sym(f"{name}_w", n)
    divided = ca.Function(f"{name}_divided", [z, p, w], [g / w])
    first = ca.MX.sym(f"{name}_first", n)
    end = _damped_newton(name, divided, n, first, p, ca.Function(f"{name}_weights", [p, z0], [weight])(p, z0))
    jac2 = jacobian(end, p, z0)
    y2 = ca.solve(ca.mtimes(jac2, jac2.T) + NEAREST_REGULARISATION * ca.MX.eye(n), ca.mtimes(jac2, z0 - end))
    # (from an end that is not finite, e.g. a residual that is NaN at the guess, its Newton cannot start:
    # skipped, NaN, as it would end)
    end = ca.if_else(ca.sumsqr(end) + ca.sumsqr(y2) < ca.inf,
                     nearest(ca.stop_diff(ca.vertcat(end, y2), 1), ca.vertcat(p, z0))[:n], ca.DM.nan(n, 1), True)
    damped = ca.Function(f"{name}_damped_solution", [first, p, z0], [end])

    def fallback(start: ca.MX | ca.DM) -> ca.MX:
        z1 = nearest(ca.vertcat(start, ca.DM.zeros(n, 1)), ca.vertcat(values, start))[:n]
        solves = ca.sumsqr(distance(z1, values, start)) <= (LOOP_TOLERANCE * (1 + ca.norm_2(z1))) ** 2
        kick = _flat_kick(jacobian, start, values)
        z2 = damped(start + kick, values, start)
        solves2 = ca.sumsqr(distance(z2, values, start)) <= (LOOP_TOLERANCE * (1 + ca.norm_2(z2))) ** 2
        # off a flat point, both ways: the root nearer the guess where both sides reach one
        z3 = ca.if_else(ca.sumsqr(kick) > 0, damped(start - kick, values, start), ca.DM.nan(n, 1), True)
        solves3 = ca.sumsqr(distance(z3, values, start)) <= (LOOP_TOLERANCE * (1 + ca.norm_2(z3))) ** 2
        nearer3 = ca.logic_and(solves3, ca.logic_or(ca.logic_not(solves2), ca.sumsqr(z3 - start) < ca.sumsqr(z2 - start)))
        z2 = ca.if_else(nearer3, z3, z2)
        solves2 = ca.logic_or(solves2, solves3)
        # the damped start first: the damped steps (of minimum norm) end near the solution nearest the
        # guess where the loop is mildly nonlinear, and the nearest solution's Newton from the guess costs
        # most where it fails (100 steps with second derivatives)
        return ca.if_else(solves2, z2, ca.if_else(solves, z1, ca.DM.nan(n, 1), True), True)

    return accepted, fallback


BOUND_TOLERANCE = 1e-6
"""A tearing variable counts as outside its declared min (max) when below min - BOUND_TOLERANCE * (1 + |min|)
(above max + ...): a root a rounding away from its bound (a flow of -1e-12 kg/s with min = 0) is inside."""


WARM_STEP = 1e-10
"""The warm-started Newton stops at a step below WARM_STEP * (1 + |z|) in every unknown (see warm_solution)."""


def warm_solution(name: str, z: ca.MX, p: ca.MX, g: ca.MX, memory: ca.MX, start: ca.DM,
                  values: ca.MX | ca.DM, lower: list[float], upper: list[float]) -> ca.MX:
    """The solution of the model's loop g(z, p) = 0 warm-started: Newton from the loop's last converged
    solution *memory* (which the FMU keeps: :mod:`.fmi_runtime`; at the first evaluation after
    initialisation, the start values); where that is no root or a root outside the declared bounds
    [*lower*, *upper*] (a negative density, an unphysical second root of a medium's equation of state:
    MSL ``Fluid.Examples.IncompressibleFluidNetwork``), Newton from the *start* values (where they
    differ from the memory); then the fallbacks of :func:`_or_nearest_solution` from the memory. Where
    those leave NaN, a Newton root outside the bounds is the solution rather than none. Only the branch
    taken is evaluated.

    This Newton runs in the unknowns scaled by 1 + |guess| and stops at a step below WARM_STEP there,
    always after one step at least: the model's rootfinders stop at a residual below 1e-10 in the
    equations' own units, which a loop of pressures in Pa never reaches (MSL
    ``Fluid.Examples.Explanatory.MomentumBalanceFittings``: all 100 iterations at every evaluation),
    and from a guess whose residual already meets it they would not move it at all (a state perturbed
    by an importer's difference quotient would not move the loop's solution)."""
    n = z.numel()
    memory = ca.stop_diff(memory, 1)  # guesses: the model's derivatives (exported with it) do not depend on them
    accepted, fallback = _loop_tests(name, z, p, g, values)
    lo = ca.DM([b - BOUND_TOLERANCE * (1 + abs(b)) for b in lower])
    hi = ca.DM([b + BOUND_TOLERANCE * (1 + abs(b)) for b in upper])

    def inside(sol: ca.MX) -> ca.MX:
        return ca.logic_and(ca.mmin(sol - lo) >= 0, ca.mmin(hi - sol) >= 0)

    x, scale = ca.MX.sym(f"{name}_x", n), ca.MX.sym(f"{name}_scale", n)
    scaled = ca.rootfinder(f"{name}_warm", "fast_newton",
                           {"x": x, "p": ca.vertcat(p, scale), "g": ca.substitute(g, z, scale * x)},
                           {"abstol": 0, "abstolStep": WARM_STEP, "max_iter": 100, "error_on_fail": False})

    def newton(guess: ca.MX | ca.DM) -> ca.MX:
        s = 1 + ca.fabs(guess)
        return s * scaled(guess / s, ca.vertcat(values, s))

    warm = newton(memory)
    cold = ca.if_else(ca.mmax(ca.fabs(memory - start)) > 0, newton(start), ca.DM.nan(n, 1), True)
    warm_root, cold_root, fell = accepted(warm, memory), accepted(cold, start), fallback(memory)
    last = ca.if_else(ca.sumsqr(fell) < ca.inf, fell, ca.if_else(
        warm_root, warm, ca.if_else(cold_root, cold, ca.DM.nan(n, 1), True), True), True)
    after = ca.if_else(ca.logic_and(cold_root, inside(cold)), cold, last, True)
    return ca.if_else(ca.logic_and(warm_root, inside(warm)), warm, after, True)
