"""A fitted effect parameter at a bound is *pinned* only when the data hold it there beyond noise.

The expectation is worked by hand from ordinary least squares: a residual ``r = a t + e`` with
``e`` made orthogonal to ``t`` has the free slope ``a`` exactly, with standard error
``se = sigma / sqrt(sum t**2)`` (``sigma**2 = sum e**2 / n``), and the likelihood-ratio statistic of
holding the slope at the bound instead is ``(a / se)**2``; the candidate's parameter sits at a bound
that the free slope lies ``z = a / se`` standard errors beyond.
"""
from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from trackingbox.diagnose import candidates as cd
from trackingbox.diagnose import judge as jd


def _where(n: int) -> NS:
    # no spec candidates (an empty Jacobian), no varying ones: the parameter's column alone is fitted
    return NS(jacobian=({}, {}), noise={"y": 1.0}, problem=None, x=None, varying=None)


def _residual(z: float, n: int = 2000, seed: int = 3) -> tuple[np.ndarray, np.ndarray, float]:
    """``(r, t, se)``: noise orthogonal to ``t`` plus a slope ``z`` standard errors from 0."""
    rng = np.random.default_rng(seed)
    t = np.linspace(-1.0, 1.0, n)
    e = rng.normal(0.0, 0.3, n)
    e -= (e @ t) / (t @ t) * t                       # the free slope is exactly the one added
    sigma = math.sqrt(e @ e / n)
    se = sigma / math.sqrt(t @ t)
    return z * se * t + e, t, se


@pytest.mark.parametrize("z", [-1.0, -2.5, -4.0])
def test_evidence_against_a_lower_bound_is_the_squared_standard_errors_beyond_it(z):
    r, t, _ = _residual(z)
    w = _where(r.size)
    ev = cd.freed_evidence(w, ({"y": r}, {"y": r}), ({"y": t}, {"y": t}), side=-1)
    # n_eff counts the freed residual's lag-one correlation (white here: a few per cent at most)
    assert ev == pytest.approx(z * z, rel=0.1)


def test_a_free_move_back_inside_is_no_evidence():
    r, t, _ = _residual(+4.0)                        # at the lower bound, the data want it higher: inside
    assert cd.freed_evidence(_where(r.size), ({"y": r}, {"y": r}), ({"y": t}, {"y": t}), side=-1) == 0.0
    # the same residual at an upper bound is held there: 16 = 4 standard errors squared
    ev = cd.freed_evidence(_where(r.size), ({"y": r}, {"y": r}), ({"y": t}, {"y": t}), side=+1)
    assert ev == pytest.approx(16.0, rel=0.1)


def test_pinned_only_when_the_bound_binds_beyond_noise():
    bounds = {"g": (-0.1, 0.1), "d": (-1e-8, 1e-8)}
    values = {"g": 0.07, "d": -1e-8}
    # one standard error beyond the bound (evidence 1): within noise, not pinned
    r1, t, _ = _residual(-1.0)
    ev1 = cd.freed_evidence(_where(r1.size), ({"y": r1}, {"y": r1}), ({"y": t}, {"y": t}), side=-1)
    assert cd.pinned_at_bounds(values, bounds, {"d": ev1}) == []
    # three standard errors beyond (evidence 9 > 4): the data hold it there
    r3, _, _ = _residual(-3.0)
    ev3 = cd.freed_evidence(_where(r3.size), ({"y": r3}, {"y": r3}), ({"y": t}, {"y": t}), side=-1)
    assert cd.pinned_at_bounds(values, bounds, {"d": ev3}) == ["d"]
    # without evidence a parameter at a bound counts as pinned (as before); a zero lower bound never does
    assert cd.pinned_at_bounds(values, bounds) == ["d"]
    assert cd.pinned_at_bounds({"k": 0.0}, {"k": (0.0, 1.0)}, {"k": 100.0}) == []
    # inside its bounds: never pinned, whatever the evidence
    assert cd.pinned_at_bounds({"d": 0.0}, bounds, {"d": 100.0}) == []
    # a bound of a parameter that cannot be 0 inside its range limits the form (a levelling at its largest is
    # a step): pinned there whatever the evidence
    assert cd.pinned_at_bounds({"c": 1e-3}, {"c": (0.0, 1e-3)}, {"c": ev1}) == ["c"]
    assert cd.pinned_at_bounds({"tau": 900.0}, {"tau": (1.0, 900.0)}, {"tau": 0.0}) == ["tau"]


def test_at_bound_sides():
    assert cd.at_bound(1e-8, -1e-8, 1e-8) == 1
    assert cd.at_bound(-1e-8, -1e-8, 1e-8) == -1
    assert cd.at_bound(0.0, -1e-8, 1e-8) == 0
    assert cd.at_bound(0.0, 0.0, 1.0) == 0           # the "no effect" bound


def test_a_candidate_within_noise_of_its_bound_is_judged_on_the_rest():
    """The judge refuses a pinned candidate, and only that: the same figures unpinned pass."""
    c = cd.Candidate("ds-meter", "DS_product", "process", "fit", 17711.0, 0.6, 40.0, tags=("Q",),
                     noise_gains={"Q": 40.0}, material=("Q",))
    assert jd.reasons_against(c, 4000) == []
    pinned = cd.Candidate("ds-meter", "DS_product", "process", "fit", 17711.0, 0.6, 40.0, tags=("Q",),
                          noise_gains={"Q": 40.0}, material=("Q",), pinned=("d",))
    assert jd.reasons_against(pinned, 4000) == ["pinned at a bound: d"]


def test_the_levelling_uses_the_patched_twins_sensitivity_to_the_varying_candidate(monkeypatch):
    """A meter reading ``(1 + g) x`` with ``x = -45 Rf + u(t)``: d(reading)/dRf = -45 (1 + g), by hand."""
    from trackingbox.diagnose import fit as ft
    from trackingbox.diagnose import residuals as rs
    from trackingbox.diagnose.varying import VaryingBasis

    t = np.arange(0.0, 3600.0, 10.0)
    u = 0.77 + 0.01 * np.sin(t / 600.0)

    def series(problem, window, x, inputs, history=()):
        rf, g = float(x[0]), float(x[1])
        return rs.WindowResiduals(window, t, {"Q": u}, {"Q": (1.0 + g) * (-45.0 * rf + u), "P": 3.0 * rf + 0 * t}, {})

    monkeypatch.setattr(ft, "window_series", series)
    null_problem = NS(names=["effect.Rf"], lower=np.array([0.0]), upper=np.array([6e-4]))
    patched = NS(names=["effect.Rf", "g"], lower=np.array([0.0, -0.1]), upper=np.array([6e-4, 0.1]))
    basis = VaryingBasis(("effect.Rf",), ("rising",), (0,), 1800.0, np.zeros((t.size, 2)), np.zeros((t.size, 2)),
                         (6e-4,))
    null_jac = {"Q": np.full((t.size, 1), -45.0), "P": np.full((t.size, 1), 3.0)}
    where = rs.WhereResult(None, {}, {}, (), None, None, {"Q": 1.0, "P": 1.0}, problem=null_problem,
                           jacobian=(null_jac, dict(null_jac)), varying=basis)
    x = np.array([5e-5, 0.069])
    at_x = [series(patched, w, x, {}) for w in ("training", "validation")]
    out = ft.patched_varying(where, patched, ("training", "validation"), x, {}, at_x)
    for jac in out.jacobian:
        assert jac["Q"][:, 0] == pytest.approx(np.full(t.size, -45.0 * 1.069), rel=1e-6)
        assert jac["P"][:, 0] == pytest.approx(np.full(t.size, 3.0), rel=1e-6)   # a tag the meter does not read
    assert where.jacobian[0]["Q"][0, 0] == -45.0                                   # the null's own is left as it was
