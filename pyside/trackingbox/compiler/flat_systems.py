"""From residuals to solved systems (:class:`SystemAssembly`, a part of
:class:`.flatten.FlatTranslator`): equations of discrete variables and the event iteration,
index reduction, the initialisation problem, tearing of algebraic loops and their Newton
rootfinders, and the messages naming the equations of a structurally singular system.
"""
from __future__ import annotations

import logging
import re
from typing import Any

import casadi as ca

from ..errors import CompileError
from .causalize import StructuralError, blt
from .events import Condition, EventSystem
from .index import STATE_SELECT, IndexError_, max_matching, reduce_index
from .library import locate
from .source import class_extent, read_text, strip_comments
from .flat_model import REAL, Assertion, InitialSystem, LoopMemory, ScalarVar, string_attr
from .flat_builtins import solve_scalar_linear
from .flat_text import origin_text
from .initial_discrete import InitialDiscreteError, solve_initial_discrete
from .initial_pre import hold_at_initialisation, pre_initial_equations
from .loop_solve import NEWTON_TOLERANCE, _or_nearest_solution, branch_solution, switches, warm_solution

log = logging.getLogger(__name__)


def _owner(name: str) -> str:
    """The component a scalar belongs to: ``pipe.mediums[2]`` of ``pipe.mediums[2].p``."""
    return name.rsplit(".", 1)[0] if "." in name else ""


def _unit(sv: ScalarVar) -> str | None:
    """The ``unit`` of *sv*, where it is a string literal."""
    return string_attr(sv.attrs.get("unit")) if sv.attrs else None


def substituted(exprs: list[ca.MX], assignments: list[tuple[ca.MX, ca.MX]]) -> list[ca.MX]:
    """*exprs* with the assigned variables replaced by their values, a value itself in terms of the
    variables assigned before it: the same as substituting one assignment at a time, latest first, but
    in one pass over the expression graph (one at a time, with a test of which expressions depend on
    each variable, took minutes for a Fluid example whose Media functions are calls of large traced
    functions)."""
    if not assignments or not exprs:
        return list(exprs)
    return list(ca.substitute_inplace([v for v, _ in assignments], [e for _, e in assignments], list(exprs),
                                      False)[1])


class SystemAssembly:
    """The system part of :class:`.flatten.FlatTranslator` (its state is set up there)."""

    def _split_discrete(self, residuals: list[tuple[ca.MX, str]], continuous: set[str], discrete: list[ScalarVar],
                        initial: bool = False) -> tuple[list[tuple[ca.MX, str]], list[tuple[ca.MX, str]]]:
        """(continuous equations, equations of discrete variables). An equation belongs to a discrete
        variable when no continuous unknown is in it and a discrete variable is (in an initial equation,
        also pre(v), which is v there). The continuous equations keep pre(v): between events the FMU
        holds it equal to v, in the event iteration it is the value before the step (.events)."""
        names = {sv.name for sv in discrete}
        if initial:  # pre(v) = e of a variable with an equation of its own: pre(v) at initialisation (.initial_pre)
            residuals, self._pre_at_start = pre_initial_equations(residuals, self._pre, self._when_targets,
                                                                  continuous | names)
        pres = [(self._pre[n], self.scalars[n].sym) for n in self._pre]
        cont, disc = [], []
        if initial:  # as written, pre(v) kept: for the discrete initialisation problem (.initial_discrete)
            self._discrete_initial_raw = []
        for r, origin in residuals:
            held = ca.substitute([r], [a for a, _ in pres], [b for _, b in pres])[0] if pres else r
            used = {sym.name() for sym in ca.symvar(held)}
            if used & names and not used & continuous and not (initial and used & set(self.der_placeholders)):
                # at an event pre(v) is the value before the step; at initialisation it is v
                disc.append((held if initial else r, origin))
                if initial:
                    self._discrete_initial_raw.append((r, origin))
                    if held is not r and id(r) in self._equation_spans:  # the same equation, pre(v) read as v
                        self._equation_spans[id(held)] = (held, self._equation_spans[id(r)][1])
            else:
                cont.append((held if initial else r, origin))
        return cont, disc

    def _event_system(self, discrete: list[ScalarVar], residuals: list[tuple[ca.MX, str]],
                      initial: list[tuple[ca.MX, str]]) -> EventSystem | None:
        """The event iteration's assignments (.events): conditions and samples first, then the when
        conditions and the discrete variables in dependency order; an initial equation or initial
        algorithm of a discrete variable gives its value at initialisation."""
        ev = self.events
        if not (discrete or ev.conditions or ev.samples or ev.whens or ev.reinits or self._uses_initial):
            return None
        unknowns = [sv.sym for sv in discrete] + [w.sym for w in ev.whens]
        eqs = list(residuals) + [(w.sym - w.value, f"when condition {w.sym.name()}") for w in ev.whens]
        assigned = self._discrete_order(eqs, unknowns, "equations of discrete variables")
        order = self._initial_discrete(initial, [sv.sym for sv in discrete]) if initial else []
        if order is None:  # an initial equation of several discrete variables: all solved together
            self._pre_at_start = self._joint_initial(discrete, residuals)
        at_start = dict(order or [])
        t = self.time
        updates: list[tuple[ca.MX, ca.MX]] = [(c.sym, c.value) for c in ev.conditions]
        for smp in ev.samples:
            eps = 1e-9 * ca.fmax(1, ca.fabs(t))
            k = ca.floor((t - smp.start) / smp.interval + 0.5)
            at = ca.logic_and(t >= smp.start - eps, ca.fabs(t - smp.start - k * smp.interval) <= eps)
            quiet = ca.logic_or(self.quiet, ev.initial)  # sample() is never true at initialisation
            updates.append((smp.sym, ca.logic_and(at, ca.logic_not(quiet))))
        for sym, expr in assigned:
            if sym.name() in {k.name() for k in at_start}:
                expr = ca.if_else(ev.initial, at_start[next(k for k in at_start if k.name() == sym.name())], expr)
            updates.append((sym, expr))
        ev.updates = hold_at_initialisation(updates, getattr(self, "_pre_at_start", {}), ev.initial)
        pres = [(self._pre[n], self.scalars[n].sym) for n in self._pre]
        pres += [(p, self.scalars[n].sym) for n, p in self._pre_continuous.items()]
        if pres:  # between events (where indicators are evaluated) pre(v) is v
            for cond in ev.conditions:
                cond.indicators = ca.substitute(cond.indicators, [a for a, _ in pres], [b for _, b in pres])
        ev.discrete = [(sv.name, sv.sym, self._start_of(sv)) for sv in discrete]
        ev.pre = dict(self._pre)
        ev.pre_continuous = [(p, self.scalars[n].sym, self._start_of(self.scalars[n]))
                             for n, p in self._pre_continuous.items()]
        return ev

    def _discrete_order(self, eqs: list[tuple[ca.MX, str]], unknowns: list[ca.MX], what: str,
                        ) -> list[tuple[ca.MX, ca.MX]]:
        """Solve equations of discrete variables one at a time, each for its variable, in dependency
        order (a loop of discrete variables is refused, naming them)."""
        names = [u.name() for u in unknowns]
        position = {n: i for i, n in enumerate(names)}
        incidence = [sorted({position[s.name()] for s in ca.symvar(r) if s.name() in position}) for r, _ in eqs]
        try:
            blocks = blt(incidence, len(unknowns))
        except StructuralError as exc:
            und = [names[j] for j in exc.unknowns][:8]
            eq = sorted({eqs[i][1] for i in exc.equations})[:8]
            raise CompileError(
                f"the {what} of {self.model} do not determine them: {len(eqs)} equations for {len(unknowns)} "
                f"variables" + (f"; not determined: {', '.join(und)}" if und else "")
                + (f"; equations with no variable left: {', '.join(eq)}" if eq else "")) from None
        out: list[tuple[ca.MX, ca.MX]] = []
        for block in blocks:
            if len(block.unknowns) != 1:
                loop = ", ".join(names[j] for j in block.unknowns[:8])
                raise self.unsupported(f"algebraic loop among discrete variables ({loop})",
                                       span=self._span_of([eqs[i][0] for i in block.equations]))
            r, origin = eqs[block.equations[0]]
            u = unknowns[block.unknowns[0]]
            sol = solve_scalar_linear(r, u)
            if sol is None:
                raise self.unsupported(f"equation of discrete variable {u.name()} that is not explicit in it "
                                       f"({origin})", span=self._span_of([r]))
            out.append((u, sol))
        return out

    def _initial_discrete(self, eqs: list[tuple[ca.MX, str]],
                          unknowns: list[ca.MX]) -> list[tuple[ca.MX, ca.MX]] | None:
        """Initial equations of some discrete variables (``pre(v)`` read as ``v``), each solved for the
        one variable of it not solved yet (``pre(state) = initialState(seed)`` first, then
        ``r = random(pre(state))``), the values already solved substituted into the later ones; None
        where one names several unsolved variables (then :meth:`_joint_initial` solves them all)."""
        position = {u.name(): i for i, u in enumerate(unknowns)}
        incidence = [sorted({position[s.name()] for s in ca.symvar(r) if s.name() in position}) for r, _ in eqs]
        solved: dict[int, ca.MX] = {}
        pending = list(range(len(eqs)))
        while pending:
            ready = [i for i in pending if len(set(incidence[i]) - set(solved)) == 1]
            if not ready:
                return None
            for i in ready:
                left = set(incidence[i]) - set(solved)
                if len(left) != 1:  # another ready equation solved for the same variable
                    raise self.unsupported(f"initial equation of discrete variables that other initial "
                                           f"equations determine ({eqs[i][1]})", span=self._span_of([eqs[i][0]]))
                (j,) = left
                r = eqs[i][0]
                if solved:
                    r = ca.substitute([r], [unknowns[k] for k in solved], list(solved.values()))[0]
                sol = solve_scalar_linear(r, unknowns[j])
                if sol is None:
                    raise self.unsupported(f"initial equation of discrete variable {unknowns[j].name()} that is "
                                           f"not explicit in it ({eqs[i][1]})", span=self._span_of([eqs[i][0]]))
                solved[j] = sol
                pending.remove(i)
        return [(unknowns[j], sol) for j, sol in solved.items()]

    def _joint_initial(self, discrete: list[ScalarVar],
                       residuals: list[tuple[ca.MX, str]]) -> dict[str, tuple[ca.MX, ca.MX]]:
        """The ``pre`` values held at initialisation from the discrete initialisation problem solved
        as a whole (.initial_discrete); a part it cannot solve is refused, naming its equations."""
        held = getattr(self, "_pre_at_start", {}) or {}
        initial = list(self._discrete_initial_raw) + [(p - v, f"initial equation of {n}") for n, (p, v) in held.items()]
        starts = {sv.name: self._start_of(sv) for sv in discrete}
        try:
            values = solve_initial_discrete(initial, residuals, [sv.sym for sv in discrete], dict(self._pre), starts,
                                            self.events)
        except InitialDiscreteError as exc:
            raise self.unsupported(f"initial equations of discrete variables: {exc.what} "
                                   f"({'; '.join(exc.origins[:6])})",
                                   span=self._span_of([initial[i][0] for i in exc.initial])) from None
        return {**held, **values}

    def _span_of(self, residuals: list[ca.MX]) -> dict | None:
        """The source span of the first of *residuals* whose equation's span is known (else None, and
        no other expression's span is taken for it)."""
        for r in residuals:
            known = self._equation_spans.get(id(r))
            if known is not None and known[0] is r:
                return known[1]
        self._span = None
        return None

    def _start_of(self, sv: ScalarVar) -> float:
        """The start value of a variable (0 when it has none), with parameters at their start values."""
        if sv.kind == "parameter" and sv.value is not None and sv.fixed is not False:
            return float(sv.value)
        node = sv.start_node
        if node is None:
            return 0.0
        try:
            return self.numeric(self._element(sv, node, once=True), f"start value of {sv.name!r}")
        except CompileError:
            return 0.0

    def _where(self, origin: Any) -> str:
        text = origin_text(origin)
        return f"of {self.model}" if text == "of component (top level)" else text

    def _unique_asserts(self) -> list[Assertion]:
        """The asserts, each once (a function inlined twice with the same arguments asserts once)."""
        seen: set[tuple[str, str, str]] = set()
        out = []
        for a in self.asserts:
            key = (a.message, a.level, str(a.condition))
            if key not in seen:
                seen.add(key)
                out.append(a)
        return out

    def _needed_optional(self, residuals: list[tuple[ca.MX, str]], optional: list[tuple[ca.MX, str]],
                         states: list[ScalarVar], computed: list[ScalarVar],
                         assignments: list[tuple[ca.MX, ca.MX]]) -> list[tuple[ca.MX, str]]:
        """Those of *optional* initial equations that determine an unknown of the initialisation problem
        (free states, fixed = false parameters) that the others leave undetermined (by structural rank)."""
        free = [s for s in states if s.fixed is not True] + list(computed)
        position = {s.sym.name(): i for i, s in enumerate(free)}
        exprs = [r for r, _ in residuals] + [r for r, _ in optional]
        exprs = substituted(exprs, assignments)
        incid = [sorted({position[v.name()] for v in ca.symvar(e) if v.name() in position}) for e in exprs]
        kept = incid[:len(residuals)]
        rank = max_matching(kept)
        out = []
        for k, (r, origin) in enumerate(optional):
            trial = kept + [incid[len(residuals) + k]]
            if rank < len(free) and max_matching(trial) > rank:
                kept, rank = trial, rank + 1
                out.append((r, origin))
        return out

    def _state_select(self) -> dict[str, str]:
        """``stateSelect`` by scalar name, where a variable has one (Always, Prefer, Default, Avoid, Never)."""
        preference = {}
        for name, v in (self.flat.get("variables") or {}).items():
            select = v.get("state_select") if isinstance(v, dict) else None
            if select:
                for sv in self.vars.get(name, []):
                    preference[sv.name] = str(select)
        return preference

    def preferred_starts(self, states: list[ScalarVar]) -> list[tuple[ca.MX, str]]:
        """The initial equations ``v = start`` of the variables the model prefers as states
        (``stateSelect`` always, then prefer) that have a start value and are not states here. A tool
        choosing its states by ``stateSelect`` integrates such a variable and starts it at its start
        value where no initial equation fixes it; keeping the differentiated variables as states, the
        same initial point is where these equations hold (:meth:`_initial_system` adds those that
        determine a free state the initial equations leave undetermined)."""
        if not any(s.fixed is not True for s in states):
            return []
        preference = self._state_select()
        state_names = {s.name for s in states}
        out = []
        for rank in ("Always", "Prefer"):
            for name, select in preference.items():
                sv = self.scalars.get(name)
                if (select != rank or sv is None or sv.kind != "continuous" or sv.type != REAL
                        or name in state_names or sv.start_node is None):
                    continue
                out.append((sv.sym - self._element(sv, sv.start_node),
                            f"start value of {name} (stateSelect = {rank.lower()}, standing in for a free state)"))
        return out

    def _free_kept_at_start(self, residuals: list[tuple[ca.MX, str]], free: list[ScalarVar],
                            computed: list[ScalarVar], assignments: list[tuple[ca.MX, ca.MX]],
                            mentioned: set[str]) -> list[ScalarVar]:
        """The free states left as unknowns of an initialisation problem with fewer equations than
        unknowns: those named by no initial equation keep their start values, in order, as long as
        the equations stay as determined (structural rank) as with them, until the problem is square."""
        exprs = [r for r, _ in residuals]
        exprs = substituted(exprs, assignments)
        names = [s.sym.name() for s in free] + [s.sym.name() for s in computed]
        syms = [{v.name() for v in ca.symvar(e)} for e in exprs]

        def rank(left: set[str]) -> int:
            position = {n: i for i, n in enumerate(n for n in names if n in left)}
            return max_matching([sorted(position[n] for n in used if n in position) for used in syms])

        left = set(names)
        full = rank(left)
        kept = []
        for s in free:
            if len(residuals) >= len(left):
                break
            if s.name not in mentioned and rank(left - {s.sym.name()}) == full:
                left.discard(s.sym.name())
                kept.append(s.name)
        if kept:
            log.info("%s: states kept at their start values at initialisation (no initial equation "
                     "for them): %s", self.model, ", ".join(kept))
        return [s for s in free if s.sym.name() in left]

    def _without_consistency_conditions(self, residuals: list[tuple[ca.MX, str]],
                                        assignments: list[tuple[ca.MX, ca.MX]],
                                        unknowns: list[ScalarVar]) -> list[tuple[ca.MX, str]]:
        """An overdetermined initialisation problem without the initial equations that the model's
        equations already fix: those in which, once the derivatives and algebraic variables are
        replaced by their causalised expressions, only parameters are left (not those with
        ``fixed = false``, which are *unknowns*) (Modelica.Fluid's
        ``mediums.p = ps_start`` for a pipe volume whose pressure a boundary at its port prescribes:
        ``boundary.p = ps_start[1]``). Each becomes an error-level assert, checked when the FMU
        leaves initialisation mode and after a parameter change: it holds where the parameters are
        consistent (to 1e-9 of the sum of the magnitudes of the parameters in it, plus 1e-9), and
        a run with inconsistent ones stops naming the equation instead of ignoring it."""
        exprs = substituted([r for r, _ in residuals], assignments)
        unknown = {s.sym.name() for s in unknowns}
        kept = []
        for (r, origin), e in zip(residuals, exprs):
            used = ca.symvar(e)
            if any(v.name() in unknown or self.scalars.get(v.name()) is None
                   or self.scalars[v.name()].kind != "parameter" for v in used):
                kept.append((r, origin))
                continue
            scale = 1.0 + sum((ca.fabs(v) for v in used), ca.MX(0.0))
            self.asserts.append(Assertion(
                condition=ca.if_else(ca.fabs(e) <= 1e-9 * scale, 1.0, 0.0), level="error", origin=origin,
                message=f"{origin} is redundant (the model's equations already fix what "
                        "it sets) and holds only for consistent parameters: they are not"))
            log.info("%s: initial equation %s fixes no unknown; checked as a consistency condition on the "
                     "parameters", self.model, origin)
        return kept

    def _reduce_index(self, residuals: list[tuple[ca.MX, str]], states: list[ScalarVar], algebraics: list[ScalarVar],
                      calculated: list[ScalarVar], calc_eqs: list[tuple[ca.MX, str]],
                      extra: list[ScalarVar] | None = None
                      ) -> tuple[list[tuple[ca.MX, str]], list[ScalarVar], list[tuple[ca.MX, str]]] | None:
        """Index reduction (.index) of the continuous equations; None when it cannot help. Returns the
        equations (the parameters' bindings, then the original and differentiated ones), the states
        chosen, and the initial equations v = start of former states with fixed = true, which hold
        where they are needed (a position prescribed elsewhere makes its own start redundant).
        *extra*: algebraic variables offered as states as well (:meth:`_preferred_states`): each gets
        a derivative symbol, and the equations that tie it to the states are differentiated."""
        calc_names = {sv.name for sv in calculated}
        eqs = [(r, o) for r, o in residuals if not any(o == c for _, c in calc_eqs)]
        preference = self._state_select()
        extra = extra or []
        extra_names = {sv.name for sv in extra}
        derivative = {s.name: self.der_placeholders[s.name] for s in states}
        derivative.update({sv.name: ca.MX.sym(f"der({sv.name})") for sv in extra})
        try:
            red = reduce_index(eqs, {s.name: s.sym for s in states + extra}, derivative,
                               {a.name: a.sym for a in algebraics if a.name not in calc_names | extra_names},
                               self.time, {sv.name for sv in self.scalars.values() if sv.kind == "input"},
                               preference)
        except IndexError_ as exc:
            log.info("%s: index reduction not possible: %s", self.model, exc)
            return None
        if extra and not extra_names & set(red.states):
            return None
        chosen = set(red.states)
        for name, sym in red.created:  # derivatives that are algebraic unknowns (dummy derivatives)
            if name in self.scalars or any(sym is d for d in red.derivative.values()):
                continue
            self.scalars[name] = ScalarVar(name=name, kind="continuous", type=REAL, top_level=False, output=False,
                                           start_node=None, binding_node=None, index=(), attrs={},
                                           description="derivative (index reduction)", sym=sym)
        for s in states:  # a former state's derivative symbol is now an algebraic unknown
            if s.name not in chosen and s.name in self.der_placeholders:
                d = self.der_placeholders[s.name]
                self.scalars.setdefault(d.name(), ScalarVar(
                    name=d.name(), kind="continuous", type=REAL, top_level=False, output=False, start_node=None,
                    binding_node=None, index=(), attrs={}, description=f"derivative of {s.name} (dummy)", sym=d))
        self.der_placeholders = dict(red.derivative)
        new_states = [self.scalars[n] for n in red.states]
        optional = [(s.sym - self._element(s, s.start_node), f"start value of {s.name} (fixed = true)")
                    for s in states if s.name not in chosen and s.fixed is True and s.start_node is not None]
        log.info("%s: index reduction differentiated %d equations; states %s", self.model,
                 len(red.differentiated), ", ".join(red.states))
        return list(calc_eqs) + red.residuals, new_states, optional

    def _preferred_states(self, residuals: list[tuple[ca.MX, str]], states: list[ScalarVar],
                          algebraics: list[ScalarVar], calculated: list[ScalarVar],
                          calc_eqs: list[tuple[ca.MX, str]]) -> tuple[Any, ...] | None:
        """A solvable (index-1) system whose states are not the variables the model prefers as states:
        ``stateSelect = always`` or ``prefer`` on an algebraic variable while a state has a weaker
        preference (a Modelica.Fluid volume integrates its mass and energy, ``der(m)``, ``der(U)``,
        and its medium prefers p and h). As Modelica tools do, the equations that tie the preferred
        variables to the states are differentiated and the states chosen by ``stateSelect``
        (:meth:`_reduce_index` with them offered). It matters: the pressure of a liquid read from its
        mass varies 2e9 times the mass's relative error (water's bulk modulus), so a solver's error
        of 1e-6 on the mass moves the pressure by kPa. Offered are the preferred variables of a
        component (a medium) that prefers its pressure (unit Pa) as a state, the case where it
        matters: a level read from a mass is as exact as the mass, and the choice of states changes
        a result within its tolerance (``TanksWithOverflow``: 2.6e-3 of upperTank.medium.h's range
        off its reference with the levels as states, 8.6e-4 with U; 1.5e-3 both at rtol 1e-8).
        Absolute temperatures (unit K) are not offered:
        under a relative tolerance a state T is resolved to 1e-6 of 293 K, 0.3 mK, while the
        internal energy it is read from otherwise counts from the medium's reference state (20 K
        above it for a liquid near 273 K), and a tank's temperature varies by mK
        (``ControlledTanks``: 0.109 of tank2.medium.T's range off its reference with T as the
        state, 0.007 with U). Returns (residuals, states, algebraics,
        unknowns, blocks, optional initial equations), or None: no such variable, or no choice of
        states with one of them (the system is left as it was)."""
        preference = self._state_select()
        calc = {sv.name for sv in calculated}
        wanted = [sv for sv in algebraics if sv.name not in calc and sv.type == REAL
                  and STATE_SELECT.get(preference.get(sv.name, "Default"), 2) <= 1
                  and _unit(sv) != "K"]
        owners = {_owner(sv.name) for sv in wanted if _unit(sv) == "Pa"}
        wanted = [sv for sv in wanted if _owner(sv.name) in owners]
        if not wanted:
            return None
        strongest = min(STATE_SELECT[preference[sv.name]] for sv in wanted)
        if not any(STATE_SELECT.get(preference.get(s.name, "Default"), 2) > strongest for s in states):
            return None
        scalars_before, der_before = set(self.scalars), self.der_placeholders
        reduced = self._reduce_index(residuals, states, algebraics, calculated, calc_eqs, extra=wanted)
        if reduced is not None:
            residuals, states, optional = reduced
            state_names = {s.name for s in states}
            algebraics = [sv for sv in self.scalars.values() if sv.kind == "continuous" and sv.name not in state_names]
            unknowns = self._unknowns(states, algebraics, calculated)
            position = {u.name(): i for i, u in enumerate(unknowns)}
            incidence = [sorted({position[s.name()] for s in ca.symvar(r) if s.name() in position})
                         for r, _origin in residuals]
            try:
                return residuals, states, algebraics, unknowns, blt(incidence, len(unknowns)), optional
            except StructuralError:
                log.info("%s: the states the model prefers leave the system singular; kept", self.model)
        for name in set(self.scalars) - scalars_before:
            del self.scalars[name]
        self.der_placeholders = der_before
        return None

    def _initial_system(self, residuals: list[tuple[ca.MX, str]], states: list[ScalarVar],
                        computed: list[ScalarVar], assignments: list[tuple[ca.MX, ca.MX]],
                        optional: list[tuple[ca.MX, str]] | None = None,
                        preferred: list[tuple[ca.MX, str]] | None = None) -> InitialSystem:
        """Build the initialisation problem (see the module docstring). *optional* initial equations
        (fixed = true starts of former states), then *preferred* ones (:meth:`preferred_starts`), are
        added where they determine an unknown the others leave free; a free state still undetermined
        and named by no initial equation keeps its start value."""
        if optional:
            residuals = list(residuals) + self._needed_optional(residuals, optional, states, computed, assignments)
        mentioned: set[str] = set()
        for r, _ in residuals:
            for sym in ca.symvar(r):
                name = sym.name()
                mentioned.add(name[4:-1] if name.startswith("der(") and name.endswith(")") else name)
        if preferred:
            used = self._needed_optional(residuals, preferred, states, computed, assignments)
            if used:
                log.info("%s: free states determined at initialisation by the start values of variables "
                         "preferred as states: %s", self.model, "; ".join(o for _, o in used))
                residuals = list(residuals) + used
        free = [s for s in states if s.fixed is not True]
        if len(residuals) > len(free) + len(computed):
            residuals = self._without_consistency_conditions(residuals, assignments, free + list(computed))
        if len(residuals) < len(free) + len(computed):
            free = self._free_kept_at_start(residuals, free, computed, assignments, mentioned)
        n_unknowns = len(free) + len(computed)
        if len(residuals) != n_unknowns:
            what = []
            if free:
                what.append("states " + ", ".join(s.name for s in free))
            if computed:
                what.append("parameters with fixed = false " + ", ".join(s.name for s in computed))
            raise CompileError(
                f"the initialisation problem of {self.model} has {len(residuals)} equations for {n_unknowns} "
                f"unknowns ({'; '.join(what) or 'none'}); "
                + ("add initial equations or set fixed = true on start values"
                   if len(residuals) < n_unknowns else
                   "remove initial equations, or fixed = true from the start values they conflict with")
            )
        exprs = [r for r, _ in residuals]
        # replace derivatives and algebraic variables by their causalised expressions, latest first
        exprs = substituted(exprs, assignments)
        unknowns = [s.sym for s in free] + [s.sym for s in computed]
        unknown_names = [u.name() for u in unknowns]
        position = {n: i for i, n in enumerate(unknown_names)}
        knowns: dict[str, ca.MX] = {}
        for e in exprs:
            for sym in ca.symvar(e):
                if sym.name() not in position:
                    knowns.setdefault(sym.name(), sym)
        incidence = [sorted({position[s.name()] for s in ca.symvar(e) if s.name() in position}) for e in exprs]
        try:
            blocks = blt(incidence, len(unknowns))
        except StructuralError as exc:
            eqs = sorted({residuals[i][1] for i in exc.equations})[:8]
            unk = [unknown_names[j] for j in exc.unknowns][:8]
            raise CompileError(
                f"the initialisation problem of {self.model} is structurally singular"
                + (f"; not determined by the initial equations: {', '.join(unk)}" if unk else "")
                + (f"; equations with no unknown left, from: {', '.join(eqs)}" if eqs else "")
            ) from None
        # solve block by block: an explicit assignment where a scalar block is linear in its unknown
        # (so e.g. a mass is found from a level before a temperature divides by it), Newton for loops
        guesses = [ca.MX.sym(f"guess({u.name()})") for u in unknowns]
        full = self._whole_initial_solution(residuals, exprs, blocks, unknowns, guesses)
        if full is not None:
            for sym in ca.symvar(ca.vertcat(*full)):
                if sym.name() not in position and not sym.name().startswith("guess("):
                    knowns.setdefault(sym.name(), sym)
            return InitialSystem(
                unknowns=unknowns, knowns=[knowns[n] for n in sorted(knowns)], residual=list(exprs),
                free_states=[s.name for s in free], computed_parameters=[s.name for s in computed],
                origins=[o for _, o in residuals], guesses=guesses, solution=full)
        done_syms: list[ca.MX] = []
        done_vals: list[ca.MX] = []
        solution: dict[int, ca.MX] = {}
        for k, block in enumerate(blocks):
            res = [exprs[i] for i in block.equations]
            if done_syms:
                res = ca.substitute(res, done_syms, done_vals)
            unk = [unknowns[j] for j in block.unknowns]
            sols = None
            if len(unk) == 1:
                sol = solve_scalar_linear(res[0], unk[0])
                sols = [sol] if sol is not None else None
            if sols is None:
                sols = self._rootfinder(f"init{k}", res, unk, [guesses[j] for j in block.unknowns])
            for j, sol in zip(block.unknowns, sols):
                solution[j] = sol
                done_syms.append(unknowns[j])
                done_vals.append(sol)
        return InitialSystem(
            unknowns=unknowns, knowns=[knowns[n] for n in sorted(knowns)], residual=list(exprs),
            free_states=[s.name for s in free], computed_parameters=[s.name for s in computed],
            origins=[o for _, o in residuals], guesses=guesses, solution=[solution[j] for j in range(len(unknowns))],
        )

    def _whole_initial_solution(self, residuals: list[tuple[ca.MX, str]], exprs: list[ca.MX], blocks: Any,
                                unknowns: list[ca.MX], guesses: list[ca.MX]) -> list[ca.MX] | None:
        """The initial unknowns solved from the initial equations together with the model's own equations
        (all algebraic variables unknowns, from their start values), as a Modelica tool sorts its
        initialisation problem; None where the initial equations' blocks in the unknowns alone (the model's
        causalised assignments substituted) need no Newton iteration in a free state whose start value is 0
        (the default where it has none; the front end gives every variable one). From there: a vessel's mass and internal energy (the embedded path keeps the
        differentiated variables as states) from 0 kg and 0 J, where its medium (p, h) has no solution,
        although the initial equations fix p and h, from which the model's equations give the mass
        explicitly (MSL ``Fluid.Examples.NonCircularPipes``' pipe volumes and ``PumpingSystem``'s tank)."""
        model = getattr(self, "_model_system", None)
        names = [u.name() for u in unknowns]
        unstarted = {n for n in names if n in self.scalars and self._start_of(self.scalars[n]) == 0}
        if model is None or not any(
                (len(b.unknowns) > 1 or solve_scalar_linear(exprs[b.equations[0]], unknowns[b.unknowns[0]]) is None)
                and any(names[j] in unstarted for j in b.unknowns) for b in blocks):
            return None
        m_res, m_unk = model
        taken = set(names)
        syms = list(unknowns) + [u for u in m_unk if u.name() not in taken]
        eqs = [r for r, _ in residuals] + [r for r, _ in m_res]
        position = {u.name(): i for i, u in enumerate(syms)}
        if len(eqs) != len(syms) or len(position) != len(syms):
            return None
        try:
            fblocks = blt([sorted({position[v.name()] for v in ca.symvar(e) if v.name() in position}) for e in eqs],
                          len(syms))
        except StructuralError:
            return None
        start = {n: self._start_of(self.scalars[n]) if n in self.scalars else 0.0 for n in position}
        first: dict[str, Any] = {n: g for n, g in zip(names, guesses)}
        # Newton's guesses are start values: those of the variables the model prefers as states (a
        # medium's p and T: what its modeller starts) before, e.g., a density at its type's start 1
        preferred = {n for n, select in self._state_select().items() if select in ("Always", "Prefer")}
        done_syms: list[ca.MX] = []
        done_vals: list[ca.MX] = []
        for k, block in enumerate(fblocks):
            res = [eqs[i] for i in block.equations]
            if done_syms:
                res = ca.substitute(res, done_syms, done_vals)
            unk = [syms[j] for j in block.unknowns]
            sol = solve_scalar_linear(res[0], unk[0]) if len(unk) == 1 else None
            if sol is not None:
                done_syms.append(unk[0])
                done_vals.append(sol)
                continue
            tears, solved, residual = self._tear(res, unk, {u.name(): start[u.name()] for u in unk}, preferred)
            sols = self._torn_rootfinder(f"initw{k}", residual, tears, solved,
                                         [ca.MX(first.get(t.name(), start[t.name()])) for t in tears])
            block_syms, block_vals = list(tears), list(sols)
            for var, expr in solved:
                block_vals.append(ca.substitute([expr], block_syms, block_vals)[0])
                block_syms.append(var)
            done_syms += block_syms
            done_vals += block_vals
        value = dict(zip((s.name() for s in done_syms), done_vals))
        solution = [value[n] for n in names]
        if any(v.name() in position for v in ca.symvar(ca.vertcat(*solution))):
            return None
        log.info("%s: initialisation solved with the model's equations (a free state starting at 0 in a "
                 "nonlinear block)", self.model)
        return solution

    def _tear(self, res: list[ca.MX], unk: list[ca.MX], guess: dict[str, float] | None = None,
              preferred: set[str] | frozenset[str] = frozenset()
              ) -> tuple[list[ca.MX], list[tuple[ca.MX, ca.MX]], list[ca.MX]]:
        """Greedy tearing of an algebraic loop.

        Repeatedly solve an equation that has one unknown left and is linear in
        it with a coefficient that depends on parameters only (never zero at run
        time by surprise); when none is left, make a tearing variable of an
        unknown with a start value (Newton's first guess; one without may be a
        divisor, e.g. a resistance with no start) that appears in the most
        remaining equations (among those, one named in *preferred* first), else of the unknown that
        appears in the most. Returns the tearing
        variables, the explicit assignments in order, and the residual
        equations (as many as tearing variables) that the rootfinder solves.
        """
        names = [u.name() for u in unk]
        index = {n: i for i, n in enumerate(names)}
        eq_vars = [{index[s.name()] for s in ca.symvar(r) if s.name() in index} for r in res]
        known: set[int] = set()
        remaining = list(range(len(res)))
        tears: list[int] = []
        solved: list[tuple[ca.MX, ca.MX]] = []
        while remaining:
            progress = False
            for e in list(remaining):
                left = eq_vars[e] - known
                if len(left) != 1:
                    continue
                v = next(iter(left))
                sol = self._solve_with_parameter_coefficient(res[e], unk[v])
                if sol is None:
                    continue
                solved.append((unk[v], sol))
                known.add(v)
                remaining.remove(e)
                progress = True
            if progress:
                continue
            unknown = [v for v in range(len(unk)) if v not in known]
            if not unknown:
                break
            counts = {v: sum(1 for e in remaining if v in eq_vars[e]) for v in unknown}
            # a variable with a start value (a guess for Newton) before one without, then the most used
            informed = {v: bool(guess) and abs((guess or {}).get(names[v], 0.0)) > 0 for v in unknown}
            tear = max(unknown, key=lambda v: (informed[v], names[v] in preferred, counts[v], -v))
            tears.append(tear)
            known.add(tear)
        if len(remaining) != len(tears):  # pragma: no cover - counting argument guarantees equality
            raise CompileError(f"tearing of an algebraic loop in {self.model} went wrong "
                               f"({len(remaining)} residuals for {len(tears)} tearing variables)")
        return [unk[t] for t in tears], solved, [res[e] for e in remaining]

    def _solve_with_parameter_coefficient(self, res: ca.MX, v: ca.MX) -> ca.MX | None:
        jac = ca.jacobian(res, v)
        if jac.is_zero():
            return None
        if any(s.name() not in self._parameter_names for s in ca.symvar(jac)):
            return None
        # a coefficient that is zero at the parameters' values (e.g. a zero entry of a parameter
        # matrix in A*y = b) cannot be divided by
        if abs(self.numeric(jac, "coefficient in an algebraic loop")) < 1e-12:
            return None
        r0 = ca.substitute(res, v, ca.MX(0))
        return -r0 / jac

    def _torn_rootfinder(self, k: int, residual: list[ca.MX], tears: list[ca.MX],
                         solved: list[tuple[ca.MX, ca.MX]], guess: list[float]) -> list[ca.MX]:
        """Rootfinder over the tearing variables only; the torn equations are inlined."""
        if not tears and not residual:  # the tearing solved the whole block explicitly
            return []
        inner = list(residual)
        # express the residuals in tearing variables and outer symbols: substitute the
        # explicitly solved unknowns, latest first, so each definition sees the earlier ones
        for var, expr in reversed(solved):
            inner = ca.substitute(inner, [var], [expr])
        return self._rootfinder(k, inner, tears, guess, warm=isinstance(k, int))

    def _rootfinder(self, k: int | str, res: list[ca.MX], unk: list[ca.MX], guess: list[Any],
                    warm: bool = False) -> list[ca.MX]:
        """The loop res(unk) = 0 solved by Newton from *guess*, with the fallbacks (.loop_solve); a loop of
        the model's equations (*warm*) from its last converged solution, kept by the FMU in variables
        ``_tbx_m<j>`` (one per unknown, starting at *guess*: :attr:`ExplicitModel.loop_memory`)."""
        others: dict[str, ca.MX] = {}
        unk_names = {u.name() for u in unk}
        for r in res:
            for s in ca.symvar(r):
                if s.name() not in unk_names:
                    others[s.name()] = s
        other_syms = list(others.values())
        z = ca.MX.sym(f"loop{k}_z", len(unk))
        p = ca.MX.sym(f"loop{k}_p", len(other_syms))
        g = ca.substitute(
            [ca.vertcat(*res)], unk + other_syms,
            [z[i] for i in range(len(unk))] + [p[i] for i in range(len(other_syms))],
        )[0]
        try:
            rf = ca.rootfinder(
                f"loop{k}", "fast_newton", {"x": z, "p": p, "g": g},
                {"abstol": NEWTON_TOLERANCE, "max_iter": 100},
            )
        except RuntimeError as exc:  # its residuals cancel the unknowns out (x - (x - y) is y)
            if "structurally rank-deficient" not in str(exc):
                raise
            held = sorted({s.name() for r in res for s in ca.symvar(r)} - unk_names)[:4]
            raise self.unsupported(
                f"an algebraic loop in {', '.join(u.name() for u in unk)} whose equations do not depend on it "
                f"once the others are substituted: {'; '.join(str(r)[:160] + ' = 0' for r in res[:3])}, a relation "
                f"between variables each of which is also given otherwise (two states for one quantity, which "
                f"index reduction does not see where the dependence cancels only in the expressions)",
                detail="; ".join(self._declared_at(n) for n in held)) from None
        start = ca.vertcat(*guess) if guess and isinstance(guess[0], ca.MX) else ca.DM(guess)
        values = ca.vertcat(*other_syms) if other_syms else ca.DM.zeros(0, 1)
        if warm:
            # the loop's relation "on its branch", held between events, and its indicator (.loop_solve.
            # branch_solution): an event where the branch ends; its value at an event is the indicator's
            # (the FMU variable _tbx_z<i>, which fmi_export names in the order of the indicators)
            # (only a loop with a relation left in it: one of smooth equations keeps Newton from its memory)
            ev, branches = self.events, switches(g, z)
            held = ca.MX.sym(f"_tbx_c{len(ev.conditions) + 1}")
            z_name = f"_tbx_z{len(ev.indicators) + 1}" if branches else ""
            kept = self.__dict__.setdefault("_loop_memory", [])
            memory = [LoopMemory(ca.MX.sym(f"_tbx_m{len(kept) + i + 1}"), float(guess[i]), u.name(), str(k), z_name)
                      for i, u in enumerate(unk)]
            kept.extend(memory)
            lower, upper = zip(*(self._bounds(u.name()) for u in unk))
            mem = ca.vertcat(*(m.sym for m in memory))
            if not branches:
                sol = warm_solution(f"loop{k}", z, p, g, mem, start, values, list(lower), list(upper))
                return [sol[i] for i in range(len(unk))]
            sol, indicator = branch_solution(f"loop{k}", z, p, g, mem, start, values, list(lower), list(upper), held)
            ev.conditions.append(Condition(held, "rel", ca.MX.sym(z_name) > 0, [indicator],
                                           f"algebraic loop {k} on its branch"))
            return [sol[i] for i in range(len(unk))]
        sol = rf(start, values)
        sol = _or_nearest_solution(f"loop{k}", z, p, g, sol, start, values)
        return [sol[i] for i in range(len(unk))]

    def _bounds(self, name: str) -> tuple[float, float]:
        """A variable's declared (min, max), evaluated with the parameters' start values (-inf, inf where
        it declares none or they cannot be evaluated)."""
        sv = self.scalars.get(name)
        out = []
        for key, default in (("min", -float("inf")), ("max", float("inf"))):
            node = sv.attrs.get(key) if sv is not None else None
            try:
                value = default if node is None else self.numeric(self._element(sv, node, once=True), key)
                out.append(float(value))
            except CompileError:
                out.append(default)
        return out[0], out[1]

    def _declared_at(self, scalar: str) -> str:
        """``b.c.e (b declared at file:line)``: a flat variable and where the model's own class
        declares its top-level component (and, if elsewhere, where the variable itself is)."""
        base = scalar.split("[", 1)[0]
        head = re.split(r"[.\[]", base, maxsplit=1)[0]
        own = locate(self.source, self.model, rf"(?<![\w.]){re.escape(head)}\b(?!\s*\()", limit=1, own=True,
                     libraries=self.libraries)
        var = (self.flat.get("variables") or {}).get(base) or {}
        leaf = base.rsplit(".", 1)[-1]
        decl = self.location(rf"(?:[\w.]+\s+)+{re.escape(leaf)}\b", span=var.get("source_span")) if var else []
        where = [f"{head} declared at {own[0]}"] if own else []
        if decl and (not own or str(decl[0]) != str(own[0])):
            where.append(f"{base} at {decl[0]}")
        return f"{scalar} ({'; '.join(where)})" if where else scalar

    def _equation_at(self, origin: str) -> str:
        """An equation's origin text, with the line of the ``connect`` of the model's own class it
        comes from (``connect(a.c.e, b.c.e)`` comes from ``connect(a.c, b.c)``)."""
        conn = re.fullmatch(r"connect\((.+), (.+)\)", origin)
        extent = class_extent(self.source, self.model) if conn else None
        if conn is None or extent is None:
            return origin
        file, first, last = extent

        def within(full: str, part: str) -> bool:
            return full == part or full.startswith(part + ".") or full.startswith(part + "[")

        lines = strip_comments(read_text(file)).splitlines()
        code = "\n".join(lines[first - 1:last])
        for m in re.finditer(r"\bconnect\s*\(\s*([\w.\[\], ]+?)\s*,\s*([\w.\[\]]+)\s*\)", code):
            a, b = (re.sub(r"\s+", "", g) for g in m.groups())
            lhs, rhs = conn.groups()
            if (within(lhs, a) and within(rhs, b)) or (within(lhs, b) and within(rhs, a)):
                return f"{origin} at {file}:{first + code.count(chr(10), 0, m.start())}"
        return origin

    def _structural_message(self, exc: StructuralError, residuals: list[tuple[ca.MX, str]], names: list[str]) -> str:
        n_eq, n_unk = len(residuals), len(names)
        head = f"{self.model} is structurally singular: {n_eq} equations for {n_unk} unknowns"
        eqs = sorted({residuals[i][1] for i in exc.equations})[:8]
        unk = [names[j] for j in exc.unknowns][:8]
        parts = [head]
        if unk:
            parts.append("variables not determined by any equation: "
                         + ", ".join(self._declared_at(u) for u in unk))
        if eqs and n_eq != n_unk or (eqs and unk):
            parts.append("equations with no variable left to solve for, from: "
                         + ", ".join(self._equation_at(e) for e in eqs))
        return "; ".join(parts)

