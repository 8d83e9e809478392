"""A CasADi step function applied a fixed number of times, in blocks that are skipped once the
iteration has stopped (the folded ``while`` loops of :mod:`.while_fold`, the damped Gauss-Newton
iteration of :mod:`.loop_solve`).

Both iterations are written as ``step(s, p)`` that returns *s* unchanged once a flag in *s* says
the iteration has stopped, and are applied a bound number of times (100 passes of a loop, 60
damped steps). ``Function.fold`` makes every one of those applications a call of ``step``: once
the iteration has stopped, each remaining application still costs a call, the test of the flag and
copies of the state and of the accumulated outputs. An IF97 property whose Newton iteration ends
after four passes paid for 96 more, and in an algebraic loop's Newton every residual and Jacobian
evaluation pays them again (MSL ``Fluid.Examples.Explanatory.MomentumBalanceFittings``: a third of
its time in those copies).

:func:`repeated` applies *step* the same number of times, grouped into blocks of about
sqrt(times) applications; a block starts with the test of the flag and is skipped as a whole (one
short-circuit ``if_else``) where the iteration has stopped. The result is exactly that of the fold:
a skipped block is a block of applications that would each have returned their argument.
"""
from __future__ import annotations

import math
from typing import Callable

import casadi as ca


def repeated(step: ca.Function, times: int, stopped: Callable[[ca.MX], ca.MX], name: str) -> ca.Function:
    """``f(s, p)``: *step* applied *times* times to *s* (with the same *p* each time), as
    ``step.fold(times)`` gives, where *step* returns its *s* unchanged whenever ``stopped(s)`` holds
    (which the caller guarantees); blocks of applications are skipped once it holds."""
    if times < 1:
        raise ValueError(f"{name}: an iteration repeated {times} times")
    s, p = ca.MX.sym(f"{name}_s", step.size1_in(0), step.size2_in(0)), \
        ca.MX.sym(f"{name}_p", step.size1_in(1), step.size2_in(1))
    size = max(1, math.isqrt(times))

    def block(count: int) -> ca.Function:  # count applications, skipped where stopped at its start
        x = s
        for _ in range(count):
            x = step(x, p)
        run = ca.Function(f"{name}_run{count}", [s, p], [x])
        return ca.Function(f"{name}_block{count}", [s, p], [ca.if_else(stopped(s), s, run(s, p), True)])

    full, rest = divmod(times, size)
    x, whole = s, block(size)
    for _ in range(full):
        x = whole(x, p)
    if rest:
        x = block(rest)(x, p)
    return ca.Function(f"{name}_repeated{times}", [s, p], [x])
