"""Events: discrete variables, when-clauses, relations that switch, time events.

The embedded backend gives a hybrid Modelica model its meaning (MLS 8.5, 8.6) with the
usual machinery of model-exchange FMUs:

* every **relation** on continuous-time values outside ``noEvent`` (``x > 0``, ``time >= t0``,
  ``if v < vmin then ...``) and every ``integer``/``floor``/``ceil`` of a continuous-time value
  is *frozen*: between events the equations see a held value (a hidden discrete variable), and
  an **event indicator** (``x - 0``; for ``floor(e)``: ``e - n`` and ``n + 1 - e``) tells the
  integrator where it changes, so it stops there (a state event);
* **discrete variables** (``discrete`` Reals, Integers, Booleans, Reals assigned in a
  when-clause) hold their values between events; ``pre(v)`` is the value before the event
  iteration's current step;
* a **when-clause** fires when its condition becomes true (``c and not pre(c)``; for a vector of
  conditions, any element); its equations ``v = e`` then define ``v`` (else ``v = pre(v)``),
  ``elsewhen`` branches in order, its ``reinit(x, e)`` sets a state; ``when initial()`` fires at
  initialisation, any other when-clause never does;
* ``sample(start, interval)`` is true at the instants ``start + k*interval`` (time events that
  the FMU announces as its next event time; once the instant is over, the FMU makes it false
  again when it leaves event mode);
* at an event (and at the end of initialisation) the FMU runs the **event iteration** (MLS 8.6):
  each of its steps takes ``pre(v) := v`` for every discrete variable, then solves the model's
  equations with these ``pre`` values held, the continuous ones included (a mixed system such as
  the MSL's friction elements, whose ``locked``/``startForward`` depend on the path torque ``sa``
  that in turn depends on them and on ``pre(mode)``): it recomputes the relations from the
  continuous-time values of the current iterate, the when conditions and the discrete variables
  (in dependency order), re-evaluates the continuous part with them, and repeats until the discrete
  values no longer change; the step's re-initialisations are applied. The steps are repeated until
  a step changes nothing (``pre(v) == v`` for all); at most 100 steps. Passes that cycle (40 in
  a step) are resolved by a search over the relations that changed in them (every combination,
  fewest changes first, at most 12 relations) for one that the discrete and continuous values it
  leads to reproduce, up to ties: a relation whose operands come out equal within the indicators'
  hysteresis keeps the value it was given (the MSL's ``LossyGear`` with equal sliding and
  break-away torques, where either value of ``sa > tau0_max`` selects the other); where there is
  none, the step falls back to its first pass and another step
  follows (the MSL's ``OneWayClutch`` leaves its stuck state through ``pre(startForward)`` of the
  step before).
  Between events ``pre(v) == v``: the FMU holds each ``pre(v)`` as a hidden variable, equal to
  ``v`` outside the event iteration.
* ``pre(y)`` of a continuous-time ``y`` (allowed in a when-clause, MLS 3.7.5) is ``y``'s left limit:
  a hidden variable too, set to ``y`` at each step of the event iteration, the first from the
  states at the event and the discrete values before it (the MSL's ``TriggeredTrapezoid`` starts
  its ramp from ``pre(y)``). At initialisation it is ``y``'s start value until the initial
  equations are solved, then ``y``. It is not compared for the end of the iteration (``y`` is no
  discrete variable: only those settle it); between events it is left as it was (the front end
  refuses ``pre(y)`` of a continuous ``y`` outside a when-clause, so nothing reads it there).

:class:`EventSystem` is that structure for :mod:`.fmi_export`; it is built by
:class:`.flatten.FlatTranslator`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca

MAX_EVENT_ITERATIONS = 100
"""Steps of an event iteration before the FMU reports that it does not converge."""


@dataclass
class Condition:
    """A frozen relation or rounding: ``sym`` holds its value between events.

    ``kind`` is ``"rel"`` (``value`` = the relation, evaluated anew at events) or
    ``"floor"``/``"ceil"``/``"integer"`` (``value`` = the rounded value); ``indicators`` are the
    event indicators whose sign change marks a change of the value.
    """

    sym: ca.MX
    kind: str
    value: ca.MX
    indicators: list[ca.MX]
    text: str


@dataclass
class Sample:
    """``sample(start, interval)``: ``sym`` is true at the instants ``start + k*interval``."""

    sym: ca.MX
    start: ca.MX
    interval: ca.MX


@dataclass
class WhenCondition:
    """One (scalar) condition of a when-clause: ``sym`` holds its value; it fires on a rising edge."""

    sym: ca.MX
    pre: ca.MX
    value: ca.MX
    initial: bool  # the condition is initial(): it fires at initialisation


@dataclass
class EventSystem:
    """What the FMU's event iteration computes (see the module docstring).

    ``discrete`` are the model's discrete variables (name, symbol, start value); ``updates``
    are the assignments of one event-iteration step in order: first every condition's and
    sample's new value (from the continuous-time values), then the when conditions and the
    discrete variables; ``pre`` maps each discrete variable's name to its ``pre`` symbol;
    ``reinits`` give a state's value after the step.
    """

    initial: ca.MX
    discrete: list[tuple[str, ca.MX, float]] = field(default_factory=list)
    conditions: list[Condition] = field(default_factory=list)
    samples: list[Sample] = field(default_factory=list)
    whens: list[WhenCondition] = field(default_factory=list)
    updates: list[tuple[ca.MX, ca.MX]] = field(default_factory=list)
    pre: dict[str, ca.MX] = field(default_factory=dict)
    reinits: list[tuple[ca.MX, ca.MX]] = field(default_factory=list)
    pre_continuous: list[tuple[ca.MX, ca.MX, float]] = field(default_factory=list)

    @property
    def indicators(self) -> list[ca.MX]:
        return [z for c in self.conditions for z in c.indicators]

    def pres(self) -> list[tuple[ca.MX, ca.MX, float]]:
        """``(pre symbol, symbol of v, start)`` for every ``pre(v)`` of a discrete variable or a when
        condition, then (the last :attr:`pre_continuous`) of a continuous-time variable: held by the
        FMU, set to ``v`` at each step of the event iteration (the first of an event: ``v`` at the
        event, from the states and the discrete values before it, its left limit)."""
        starts = {name: start for name, _, start in self.discrete}
        syms = {name: sym for name, sym, _ in self.discrete}
        out = [(p, syms[name], starts[name]) for name, p in self.pre.items() if name in syms]
        out += [(w.pre, w.sym, 0.0) for w in self.whens]
        return out + list(self.pre_continuous)

    def internal(self) -> list[tuple[str, ca.MX, float]]:
        """The hidden discrete variables (name, symbol, start): conditions, samples, when conditions,
        the flag of initial() (1 from instantiation until the end of initialisation), the pre values."""
        out = [(c.sym.name(), c.sym, 0.0) for c in self.conditions]
        out += [(s.sym.name(), s.sym, 0.0) for s in self.samples]
        out += [(w.sym.name(), w.sym, 0.0) for w in self.whens]
        out.append((self.initial.name(), self.initial, 1.0))  # true until initialisation ends
        out += [(p.name(), p, start) for p, _, start in self.pres()]
        return out


__all__ = ["Condition", "EventSystem", "MAX_EVENT_ITERATIONS", "Sample", "WhenCondition"]
