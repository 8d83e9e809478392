"""The step functions applied a bound number of times in blocks that are skipped once the iteration
stopped (:mod:`trackingbox.compiler.repeat`: the folded ``while`` loops and the damped Gauss-Newton
iteration of an algebraic loop's fallback). Checked against Heron's square root worked out in Python
and against math.sqrt, and by counting the passes the step is actually evaluated."""
from __future__ import annotations

import math

import casadi as ca
import pytest

from trackingbox.compiler.repeat import repeated


class _Heron(ca.Callback):
    """One pass of ``while abs(x*x - a) > 1e-14*a loop x := (x + a/x)/2; end while`` on the state
    (running, x) with parameter a: the state unchanged once running is 0. Counts its evaluations."""

    def __init__(self):
        ca.Callback.__init__(self)
        self.calls = 0
        self.construct("heron", {})

    def get_n_in(self) -> int:
        return 2

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(2, 1) if i == 0 else ca.Sparsity.dense(1, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(2, 1)

    def eval(self, args):
        self.calls += 1
        (running, x), a = [float(v) for v in ca.vertsplit(args[0])], float(args[1])
        if running and abs(x * x - a) > 1e-14 * a:
            return [ca.DM([1.0, 0.5 * (x + a / x)])]
        return [ca.DM([0.0, x])]


def _heron_passes(a: float, x: float) -> tuple[float, int]:
    """Heron's iteration in plain Python: (the root, the passes that changed x)."""
    passes = 0
    while abs(x * x - a) > 1e-14 * a:
        x, passes = 0.5 * (x + a / x), passes + 1
    return x, passes


@pytest.mark.parametrize("times", [1, 7, 60, 100])
@pytest.mark.parametrize("a", [2.0, 1e6])
def test_repeated_gives_what_the_loop_gives_and_skips_the_passes_after_it_ended(times, a):
    expected, passes = _heron_passes(a, a)
    step = _Heron()
    s = ca.MX.sym("s", 2)
    f = ca.Function("f", [s], [repeated(step, times, lambda v: v[0] == 0, "heron")(s, a)])
    got = f(ca.DM([1.0, a]))
    if times > passes:  # the loop ended within the bound: Heron's root, as Python and math give it
        assert float(got[0]) == 0.0
        assert float(got[1]) == expected
        assert abs(float(got[1]) - math.sqrt(a)) <= 1e-12 * math.sqrt(a)
        # the passes up to its end (and one that finds it ended), then at most the rest of that
        # block: never all `times` of them once the bound is well above the passes taken
        block = max(1, math.isqrt(times))
        assert step.calls <= passes + 1 + block
        if times >= passes + 1 + 2 * block:
            assert step.calls < times
    else:  # still running after `times` passes: every pass was taken, as x after `times` passes of Python's
        x = a
        for _ in range(times):
            x = 0.5 * (x + a / x)
        assert float(got[0]) == 1.0 and float(got[1]) == x
        assert step.calls == times


def test_repeated_differentiates_as_the_iteration_does():
    """d sqrt(a)/da = 1/(2 sqrt(a)) through 100 bound passes of Newton's square root (written in
    CasADi expressions, so that it has derivatives), which ends after a few."""
    s, a = ca.MX.sym("s", 2), ca.MX.sym("a")
    x = s[1]
    go = ca.logic_and(s[0], ca.fabs(x * x - a) > 1e-14 * a)
    step = ca.Function("newton", [s, a], [ca.if_else(go, ca.vertcat(1, 0.5 * (x + a / x)), ca.vertcat(0, x), True)])
    root = repeated(step, 100, lambda v: v[0] == 0, "newton")(ca.vertcat(1, a), a)[1]
    d = ca.Function("d", [a], [ca.jacobian(root, a)])
    for value in (2.0, 3e5):
        assert abs(float(d(value)) - 0.5 / math.sqrt(value)) <= 1e-9 / math.sqrt(value)


def test_repeated_refuses_no_repetition():
    s = ca.MX.sym("s")
    with pytest.raises(ValueError, match="repeated 0 times"):
        repeated(ca.Function("f", [s, ca.MX.sym("p")], [s]), 0, lambda v: v[0] == 0, "f")
