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


def _weights(g: ca.MX, z: ca.MX, z0: ca.MX) -> ca.MX:
    """The norm of the gradient of each equation of the loop's residual g(z, p) at *z0* (1 where that is
    zero or not finite): g divided by them is a distance in z whatever the equations' units."""
    rows = ca.sqrt(ca.sum2(ca.substitute(ca.jacobian(g, z), z, z0) ** 2))
    return ca.if_else(ca.logic_and(rows > 0, rows < ca.inf), rows, 1)


def _nearest(name: str, z: ca.MX, p: ca.MX, z0: ca.MX, scaled: ca.MX) -> tuple[Any, ca.Function, Any]:
    """The nearest solution of the loop whose residual, scaled as by :func:`_weights` at *z0*, is *scaled*
    (see :func:`_or_nearest_solution`): (its rootfinder, in (z, y) with parameters (p, z0); the scaled
    residual's Jacobian (z, p, z0); root(guess, p, z0): the expression of the root nearest *z0* by that
    rootfinder from *guess* with the multipliers that fit it, NaN from a guess that is not finite). The
    guess's derivatives are stopped (it only tells Newton where to start): the root's are the nearest
    solution's. The root is an expression in its caller's function, not a function of its own: the
    model's derivatives through a call of one took a derivative function of it besides (LossyGearDemo1's
    C: 0.97 MB against 0.60 MB inline)."""
    n = z.numel()
    y = ca.MX.sym(f"{name}_y", n)
    jac = ca.jacobian(scaled, z)
    kkt = ca.vertcat(z - z0 + ca.mtimes(jac.T, y), scaled - NEAREST_REGULARISATION * y)
    nearest = ca.rootfinder(f"{name}_nearest", "fast_newton", {"x": ca.vertcat(z, y), "p": ca.vertcat(p, z0), "g": kkt},
                            {"abstol": 1e-10, "max_iter": 100, "error_on_fail": False})
    jacobian = ca.Function(f"{name}_jacobian", [z, p, z0], [jac])

    def root(first: ca.MX, values: ca.MX, anchor: ca.MX) -> ca.MX:
        jac1 = jacobian(first, values, anchor)
        y1 = ca.solve(ca.mtimes(jac1, jac1.T) + NEAREST_REGULARISATION * ca.MX.eye(n), ca.mtimes(jac1, anchor - first))
        # (from a guess that is not finite, e.g. the end of damped steps from where the residual is NaN, its
        # Newton cannot start: skipped, NaN, as it would end)
        return ca.if_else(ca.sumsqr(first) + ca.sumsqr(y1) < ca.inf, nearest(
            ca.stop_diff(ca.vertcat(first, y1), 1), ca.vertcat(values, anchor))[:n], ca.DM.nan(n, 1), True)

    return nearest, jacobian, root


def _loop_tests(name: str, z: ca.MX, p: ca.MX, g: ca.MX, values: ca.MX | ca.DM) -> tuple[Any, Any]:
    """(accepted(sol, guess): whether Newton's iterate *sol* from *guess* is a root (see
    :func:`_or_nearest_solution`), fallback(guess): the loop's solution by the fallbacks from *guess*,
    NaN where none solves). The loop's functions are made once, for both and for every guess."""
    n = z.numel()
    z0 = ca.MX.sym(f"{name}_z0", n)
    weight = _weights(g, z, z0)  # in (p, z0)
    scaled = g / weight
    nearest, jacobian, nearest_root = _nearest(name, z, p, z0, scaled)
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

    # the damped iteration only finds where to start the nearest solution's Newton again (_nearest), a
    # guess whose derivatives are stopped: the model's derivatives (exported with it) do not differentiate
    # through the iteration (which tripled the generated C of TanksWithOverflow). The damped steps take the weights as numbers (computed once, from the guess): the Jacobian of
    # `distance` in z is also differentiated in z0 (zero directions, evaluated all the same), which are
    # second derivatives of the loop's functions, each step (MSL MomentumBalanceFittings: 45% of its time)
    w = ca.MX.sym(f"{name}_w", n)
    divided = ca.Function(f"{name}_divided", [z, p, w], [g / w])
    first = ca.MX.sym(f"{name}_start", n)
    end = _damped_newton(name, divided, n, first, p, ca.Function(f"{name}_weights", [p, z0], [weight])(p, z0))
    damped = ca.Function(f"{name}_damped_solution", [first, p, z0], [nearest_root(end, p, z0)])

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


BRANCH_STEP = 1e-3
"""Newton from the end of the damped steps (see branch_solution) stays on the branch where it moves
each unknown z by at most BRANCH_STEP * (1 + |z|); further it has crossed to another root."""
SETTLED = 1e-8
"""A point is a root for the branch logic (see branch_solution) where its residual is at most
NEWTON_TOLERANCE, or where two more Newton steps from it each move every unknown z by at most
SETTLED * (1 + |z|): near a fold, a point past the end of the branch has a residual below any
tolerance relative to the unknowns, and Newton cycles there instead of settling (at a corner of a
limiter, the first step on the steep side is tiny, the second, on the flat side, is not)."""
SEARCH_STEPS = 40
"""Steps of the search for another root where the branch has ended (see _other_root), each twice the last."""


def _other_root(name: str, direction: ca.Function, newton: Any, settled: Any, n: int, start: ca.MX,
                values: ca.MX) -> ca.MX:
    """A root of the loop reached from *start* (where no Newton settles: past the end of a branch) along
    the curve on which the residual keeps its direction, g(z) = (1 - t) g(start) (Branin's global Newton
    method: dz/ds = -sign(det J) J^-1 g, which turns at the folds where the branch ends and goes on to the
    next branch), both ways, by steps of 1e-4, 2e-4, ... times (1 + |z|) in the largest unknown, with
    Newton tried from each point; the root reached in fewer steps (NaN where neither way reaches one).
    *direction*(z, p) is -sign(det J) J^-1 g (:func:`branch_solution`'s, of the rows scaled)."""
    z, q = ca.MX.sym(f"{name}_sz", n), ca.MX.sym(f"{name}_sq", values.numel() + 1)
    p, way = q[:values.numel()], q[values.numel()]
    d = direction(z, p)
    d = d / (ca.mmax(ca.fabs(d) / (1 + ca.fabs(z))) + 1e-300)
    state = ca.MX.sym(f"{name}_ss", 2 * n + 3)  # z, root, step length, found, steps taken
    at, h, found, steps = state[:n], state[2 * n], state[2 * n + 1], state[2 * n + 2]
    move = ca.Function(f"{name}_search_dir", [z, q], [d])
    nxt = at + way * h * (1 + ca.fabs(at)) * move(at, q)
    root = newton(nxt, p)
    took = ca.vertcat(nxt, root, 2 * h, settled(root, p), steps + 1)
    step = ca.Function(f"{name}_search_step", [state, q], [ca.if_else(found > 0.5, state, took, True)])
    run = step.fold(SEARCH_STEPS)
    ends = [run(ca.vertcat(start, start, 1e-4, 0, 0), ca.vertcat(values, w)) for w in (1, -1)]
    first = ca.logic_and(ends[0][2 * n + 1] > 0.5, ca.logic_or(ends[1][2 * n + 1] < 0.5,
                                                                ends[0][2 * n + 2] <= ends[1][2 * n + 2]))
    return ca.if_else(first, ends[0][n:2 * n], ca.if_else(ends[1][2 * n + 1] > 0.5, ends[1][n:2 * n],
                                                           ca.DM.nan(n, 1), True), True)


_SWITCHING = {ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE, ca.OP_FMIN, ca.OP_FMAX}


def _relations(g: ca.MX, z: ca.MX) -> list[ca.MX]:
    """The relations (and min/max) left in the loop's residual g(z) whose arguments depend on the
    unknowns z, as nodes of g. One of only the loop's other inputs (parameters, states, time: the
    heat-production twin's fmax(0, T - 273.15) of a medium's validity range, LossyGearDemo1's friction
    direction) has one outcome for each of the loop's solves, in which g is then smooth in z: it makes
    no fold and no branch of the loop (the integrator sees it as any other non-smooth input)."""
    fn = ca.Function("switches", [z], [g], {"allow_free": True})
    return [fn.instruction_MX(k) for k in range(fn.n_instructions())
            if fn.instruction_id(k) in _SWITCHING and ca.depends_on(fn.instruction_MX(k), z)]


def switches(g: ca.MX, z: ca.MX) -> bool:
    """Whether the loop's residual g(z) has a relation (or min/max) of its unknowns left in it
    (:func:`_relations`), as a piecewise (limiting) characteristic written with noEvent has: its
    branches can end at a fold (:func:`branch_solution`). The relations outside noEvent are held
    between events (.events): a loop of those has none left."""
    return bool(_relations(g, z))


def _pieces(name: str, g: ca.MX, z: ca.MX, p: ca.MX) -> ca.Function:
    """(z, p) -> the outcome (0 or 1) of each relation of the unknowns left in the loop's residual g(z, p)
    (:func:`_relations`; for a min or max, whether its first argument is the smaller): the piece of a
    piecewise characteristic that z is on."""
    out = [node.dep(0) <= node.dep(1) if node.is_op(ca.OP_FMIN) or node.is_op(ca.OP_FMAX) else node
           for node in _relations(g, z)]
    return ca.Function(f"{name}_pieces", [z, p], [ca.vertcat(*out) if out else ca.DM.zeros(0, 1)])


def branch_solution(name: str, z: ca.MX, p: ca.MX, g: ca.MX, memory: ca.MX, start: ca.DM, values: ca.MX | ca.DM,
                    lower: list[float], upper: list[float], held: ca.MX) -> tuple[ca.MX, ca.MX]:
    """(the solution of the model's loop g(z, p) = 0, its event indicator): the loop follows the root it
    is on (its branch) between events, and changes to another root only at an event.

    Where *held* (the loop's relation "on its branch", held between events: .events) is true, the
    solution continues the branch of the last solution *memory*: damped Gauss-Newton steps from it
    (the residual's norm falls at each step, so that they do not cross to a far root as Newton's full
    steps do; :func:`_damped_newton`), then Newton from where they end, which must settle within
    BRANCH_STEP of it. Past a fold of the loop's characteristic, where the branch ends (MSL
    ``Electrical.Analog.Examples.OpAmps.Multivibrator``: the op-amp's output held at one supply by the
    positive feedback until the capacitor's voltage crosses the trigger's threshold, then only the other
    supply is a root), the damped steps end at the residual's smallest norm near it, which moves on
    continuously: the integrator's steps neither jump nor chatter at the fold (a jump there without an
    event is a switch that an implicit integrator's corrector cannot converge across: it undoes itself).
    Where *held* is false (at an event, and at initialisation) the solution is :func:`warm_solution`'s,
    or where that does not settle, :func:`_other_root`'s from the memory.

    The indicator is LOOP_TOLERANCE * (1 + |z|) where the solution is a settled root inside the declared
    bounds, minus that where not: it changes sign where the branch ends, the integrator stops there, and
    the event iteration takes the loop's root anew and then holds the relation true again. The FMU keeps
    a loop's solution only where its indicator is positive (:mod:`.fmi_runtime`), never a point past the
    end of a branch."""
    n = z.numel()
    memory = ca.stop_diff(memory, 1)
    z0 = ca.MX.sym(f"{name}_z0", n)
    # the damped steps divide the equations by their weights at the memory, taken as numbers (see _loop_tests)
    wt = ca.MX.sym(f"{name}_bwt", n)
    divided = ca.Function(f"{name}_branch_divided", [z, p, wt], [g / wt])
    weights = ca.Function(f"{name}_branch_weights", [p, z0], [_weights(g, z, z0)])(values, memory)
    residual = ca.Function(f"{name}_branch_residual", [z, p], [g])
    # the steps of the settled test and of the search with each equation divided by the norm of its
    # gradient at the point (the same step, but a linear solve that the equations' units do not spoil:
    # MSL MomentumBalanceFittings' adaptors to a diameter of 1e60 have rows of 1e119 beside rows of 1e-2,
    # where the solve gave NaN, no root settled, the loop's indicator stayed negative from the
    # initialisation on and every evaluation searched for another root). Not the rootfinder's: its
    # equations divided so (numbers at the guess) moved AmplifierWithOpAmpDetailed's roots by rounding
    # enough that CVODE failed at 2e-8 (the harness's tolerance), and the damped steps' fallback finds
    # MomentumBalanceFittings' root where its Newton gives NaN
    jac = ca.jacobian(g, z)
    rows = _weights(g, z, z)
    jac, g_rows = ca.mtimes(ca.diag(1 / rows), jac), g / rows
    jjt = ca.mtimes(jac, jac.T)  # the step of minimum norm: defined whatever the rank of J
    mu = NEAREST_REGULARISATION * (1 + ca.trace(jjt) / max(n, 1))
    exact = ca.solve(jac, g_rows)  # Newton's step; where J is singular (NaN), the step of minimum norm
    step = ca.Function(f"{name}_branch_newton_step", [z, p], [ca.if_else(
        ca.sumsqr(exact) < ca.inf, exact, ca.mtimes(jac.T, ca.solve(jjt + mu * ca.MX.eye(g.numel()), g_rows)), True)])
    direction = ca.Function(f"{name}_branch_direction", [z, p], [-ca.sign(ca.det(jac)) * exact])
    x, scale = ca.MX.sym(f"{name}_bx", n), ca.MX.sym(f"{name}_bscale", n)
    scaled = ca.rootfinder(f"{name}_branch_newton", "fast_newton",
                           {"x": x, "p": ca.vertcat(p, scale), "g": ca.substitute(g, z, scale * x)},
                           {"abstol": 0, "abstolStep": WARM_STEP, "max_iter": 100, "error_on_fail": False})
    lo = ca.DM([b - BOUND_TOLERANCE * (1 + abs(b)) for b in lower])
    hi = ca.DM([b + BOUND_TOLERANCE * (1 + abs(b)) for b in upper])

    def newton(guess: ca.MX, values_: ca.MX) -> ca.MX:
        s = 1 + ca.fabs(guess)
        return s * scaled(guess / s, ca.vertcat(values_, s))

    w = ca.MX.sym(f"{name}_bw", n)

    def steps_settle(at: ca.MX) -> ca.MX:  # two Newton steps from *at*, both within SETTLED
        dz = step(at, p)
        dz2 = step(at - dz, p)
        move = ca.fmax(ca.mmax(ca.fabs(dz) / (1 + ca.fabs(at))), ca.mmax(ca.fabs(dz2) / (1 + ca.fabs(at))))
        return ca.logic_and(move <= SETTLED, ca.sumsqr(dz) + ca.sumsqr(dz2) < ca.inf)

    zero = ca.mmax(ca.fabs(residual(w, p))) <= NEWTON_TOLERANCE  # (only where not: the steps' Jacobians)
    inside = ca.logic_and(ca.mmin(w - lo) >= 0, ca.mmin(hi - w) >= 0)
    settles = ca.Function(f"{name}_branch_settled", [w, p], [ca.logic_and(ca.logic_and(
        ca.if_else(zero, 1, steps_settle(w), True), inside), ca.sumsqr(w) < ca.inf)])  # (mmax, mmin pass over NaN)

    def settled(sol: ca.MX, values_: ca.MX) -> ca.MX:
        return settles(sol, values_)

    # first Newton from the memory, taken where it settles within BRANCH_STEP of it with every relation of
    # the residual as at the memory (the same piece of the characteristic: no fold crossed on the way);
    # else the damped steps. Most evaluations between events are of that kind (MSL
    # ``Electrical.Analog.Examples.SimpleTriacCircuit`` at its tolerance 1e-12: the damped steps and the
    # nearest root at every evaluation made its simulation 20 times slower)
    pieces = _pieces(f"{name}_branch", g, z, p)
    fast = newton(memory, values)
    quick = settled(fast, values)
    if pieces.numel_out(0):  # (a loop with no relation of its unknowns has one piece)
        quick = ca.logic_and(quick, ca.mmax(ca.fabs(pieces(fast, values) - pieces(memory, values))) == 0)
    end = ca.stop_diff(_damped_newton(f"{name}_branch", divided, n, memory, values, weights), 1)
    # the end polished to the root nearest the memory (Newton on the nearest solution's optimality
    # conditions, from the end), where that settles near the end; Newton from the end (or the end, where its
    # residual is below NEWTON_TOLERANCE) where not. The end itself is a root only to the steps'
    # tolerance, and where they stop varies with the inputs, and so does where Newton's own steps from it
    # end along a direction that the residual hardly sees: the loop's solution moved at random from one
    # evaluation to the next (MSL ``Rotational.Examples.LossyGearDemo2``'s stuck gear, whose torque split
    # is nearly undetermined: a friction element's indicator changed sign at random and the event
    # iteration chattered); the root nearest the memory is one.
    nearest = _nearest(f"{name}_branch", z, p, z0, g / _weights(g, z, z0))[2](end, values, memory)
    nearest_on = ca.logic_and(ca.mmax(ca.fabs(nearest - end) / (1 + ca.fabs(end))) <= BRANCH_STEP,
                              settled(nearest, values))
    polished = ca.if_else(nearest_on, nearest, ca.if_else(
        ca.mmax(ca.fabs(residual(end, values))) <= NEWTON_TOLERANCE, end, newton(end, values), True), True)
    near = ca.mmax(ca.fabs(polished - end) / (1 + ca.fabs(end))) <= BRANCH_STEP
    polish = ca.logic_and(near, settled(polished, values))
    # (one conditional for the solution and its flag: each conditional evaluates what its branch uses)
    # (Newton's root, evaluated once: a short-circuit branch evaluates again all it uses)
    slow = ca.if_else(quick, ca.DM.zeros(n + 1, 1), ca.if_else(
        polish, ca.vertcat(polished, 1), ca.vertcat(end, settled(end, values)), True), True)
    follow = ca.if_else(quick, ca.vertcat(fast, 1), slow)
    warm = warm_solution(name, z, p, g, memory, start, values, lower, upper)
    jumped = newton(warm, values)
    landed, was = settled(jumped, values), settled(warm, values)
    other = _other_root(f"{name}_branch", direction, newton, settled, n, memory, values)
    found = ca.sumsqr(other) < ca.inf
    jump = ca.if_else(landed, ca.vertcat(jumped, 1), ca.if_else(was, ca.vertcat(warm, 1), ca.vertcat(
        ca.if_else(found, other, warm), found), True), True)
    both = ca.if_else(held > 0.5, follow, jump, True)
    sol, root = both[:n], both[n] > 0.5
    tol = LOOP_TOLERANCE * (1 + ca.norm_inf(ca.if_else(ca.sumsqr(sol) < ca.inf, sol, ca.DM.zeros(n, 1))))
    return sol, ca.if_else(root, tol, -tol)
