"""Sobol indices: analytic test functions, the hand-solved step-test FMU, agreement with RGA."""
from __future__ import annotations

import math

import numpy as np
import pytest

from trackingbox.analysis.executor import make_executor
from trackingbox.analysis.pairing import choose_pairs
from trackingbox.analysis.sobol import (
    SobolResult,
    agreement,
    indices_from_outputs,
    sample_parameters,
    sobol_indices,
)
from trackingbox.analysis.steptest import StepSettings, make_problem
from trackingbox.errors import AnalysisError


def test_ishigami_textbook_indices():
    # Ishigami function, x_i ~ U(-pi, pi), a = 7, b = 0.1: analytic S1 = 0.3139, 0.4424, 0;
    # ST = 0.5576, 0.4424, 0.2437 (Saltelli et al. 2008)
    names = ["x1", "x2", "x3"]
    lo, hi = [-math.pi] * 3, [math.pi] * 3
    n = 1024
    X = sample_parameters(names, lo, hi, n, seed=1)
    assert X.shape == (n * 5, 3)
    Y = np.sin(X[:, 0]) + 7 * np.sin(X[:, 1]) ** 2 + 0.1 * X[:, 2] ** 4 * np.sin(X[:, 0])
    res = indices_from_outputs(["f"], names, lo, hi, Y, n, seed=1)
    assert np.allclose(res.first[0], [0.3139, 0.4424, 0.0], atol=0.05)
    assert np.allclose(res.total[0], [0.5576, 0.4424, 0.2437], atol=0.05)


def test_linear_function_and_constant_output():
    # y = 3 x1 + x2 with x1 ~ U(0, 1), x2 ~ U(0, 2): Var = 9/12 + 4/12, S1 = (9/13, 4/13) = ST
    names, lo, hi, n = ["x1", "x2"], [0.0, 0.0], [1.0, 2.0], 256
    X = sample_parameters(names, lo, hi, n)
    Y = np.column_stack([3 * X[:, 0] + X[:, 1], np.full(len(X), 5.0)])
    res = indices_from_outputs(["y", "flat"], names, lo, hi, Y, n)
    assert np.allclose(res.first[0], [9 / 13, 4 / 13], atol=0.03)
    assert np.allclose(res.total[0], [9 / 13, 4 / 13], atol=0.03)
    assert np.all(res.first[1] == 0) and np.all(res.total[1] == 0)
    assert res.choice() == {"y": "x1"}


def test_sample_size_must_be_power_of_two():
    with pytest.raises(AnalysisError, match="power of two"):
        sample_parameters(["a"], [0.0], [1.0], 100)


def test_twin_steady_state_indices_match_hand_variances(step_fmu):
    # Steady state with the integrator frozen (see test_steptest): y1 = (1.5 a + z + 0.5 b)/0.9,
    # y2 = b + 0.2 y1. a ~ U(0.5, 1.5) (var 1/12), b ~ U(1, 3) (var 4/12):
    # S_a(y1) = 1.5^2 / (1.5^2 + 0.5^2 * 4) = 2.25 / 3.25
    # S_a(y2) = (0.3/0.9)^2 / ((0.3/0.9)^2 + (10/9)^2 * 4)
    fmu = step_fmu
    prob = make_problem(fmu, outputs={"Y1": "y1", "Y2": "y2"},
                        parameters=[("a", 1.0, 0.5, 1.5), ("b", 2.0, 1.0, 3.0)],
                        operating={"u": 1.5}, ranges={"Y1": 1.0, "Y2": 1.0}, freeze={"hold": 1.0})
    settings = StepSettings(freeze=(("hold", 1.0),), interval=1.0, window=50.0, tolerance=1e-6, max_time=2000.0)
    with make_executor(workers=2) as ex:
        res = sobol_indices(prob, settings, n=64, executor=ex)
    sa1 = 2.25 / 3.25
    ca, cb = (0.3 / 0.9) ** 2, (10 / 9) ** 2 * 4
    sa2 = ca / (ca + cb)
    assert res.runs == 64 * 4
    assert np.allclose(res.first, [[sa1, 1 - sa1], [sa2, 1 - sa2]], atol=0.04)
    assert np.allclose(res.total, [[sa1, 1 - sa1], [sa2, 1 - sa2]], atol=0.04)
    # Both methods pair Y1 with a and Y2 with b: the RGA of the hand gains
    # [[1.5/0.9, 0.5/0.9], [0.3/0.9, 10/9]] has lambda_11 = g11 g22 / (g11 g22 - g12 g21) = 10/9
    pairing = choose_pairs([[1.5 / 0.9, 0.5 / 0.9], [0.3 / 0.9, 10 / 9]], ["Y1", "Y2"], ["a", "b"])
    assert pairing.pairs[0].lambda_ == pytest.approx(10 / 9)
    agr = agreement(pairing, res)
    assert agr.agree == 2 and agr.compared == 2 and agr.fraction == 1.0


def test_agreement_reports_disagreement():
    pairing = choose_pairs([[1.0, 0.0], [0.0, 1.0]], ["T1", "T2"], ["p", "q"])
    z = np.zeros((2, 2))
    sob = SobolResult(("T1", "T2"), ("p", "q"), z, np.array([[0.1, 0.9], [0.8, 0.2]]), z, z)
    agr = agreement(pairing, sob)
    assert agr.agree == 0 and agr.compared == 2
    assert agr.rows[0] == ("T1", "p", "q", False)
