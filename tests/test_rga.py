"""Relative gain array: textbook and hand-solved cases."""
from __future__ import annotations

import math

import numpy as np
import pytest

from trackingbox.analysis.rga import (
    condition_number,
    parameter_ranges,
    rank_report,
    relative_gain_array,
    scale_gains,
    variable_ranges,
)
from trackingbox.errors import AnalysisError


def test_2x2_wood_berry_column():
    # Wood & Berry distillation column steady-state gains; the textbook RGA has
    # lambda_11 = g11 g22 / (g11 g22 - g12 g21) ~= 2.01.
    g11, g12, g21, g22 = 12.8, -18.9, 6.6, -19.4
    lam = g11 * g22 / (g11 * g22 - g12 * g21)  # = -248.32 / -123.58
    assert round(lam, 2) == 2.01
    L = relative_gain_array([[g11, g12], [g21, g22]])
    assert np.allclose(L, [[lam, 1 - lam], [1 - lam, lam]])


def test_2x2_doctest_numbers_by_hand():
    # G = [[1, 2], [3, 4]]: lambda_11 = 4 / (4 - 6) = -2
    assert np.allclose(relative_gain_array([[1.0, 2.0], [3.0, 4.0]]), [[-2, 3], [3, -2]])


def test_3x3_cyclic_by_hand():
    # G = [[1,1,0],[0,1,1],[1,0,1]], det = 2, cofactor matrix C = [[1,1,-1],[-1,1,1],[1,-1,1]],
    # (G^-1)^T = C / 2, so Lambda = G o C / 2.
    G = [[1, 1, 0], [0, 1, 1], [1, 0, 1]]
    assert np.allclose(relative_gain_array(G), [[0.5, 0.5, 0], [0, 0.5, 0.5], [0.5, 0, 0.5]])


def _det2(a, b, c, d):
    return a * d - b * c


def test_3x3_ogunnaike_ray_column_by_cofactors():
    # Ogunnaike-Lemaire-Morari-Ray distillation column gains. Independent route:
    # lambda_ij = (-1)^(i+j) g_ij det(M_ij) / det(G), minors written out by hand.
    g = [[0.66, -0.61, -0.0049], [1.11, -2.36, -0.012], [-34.68, 46.2, 0.87]]
    minors = [[_det2(*[g[r][c] for r in range(3) if r != i for c in range(3) if c != j])
               for j in range(3)] for i in range(3)]
    det = sum((-1) ** j * g[0][j] * minors[0][j] for j in range(3))
    expected = [[(-1) ** (i + j) * g[i][j] * minors[i][j] / det for j in range(3)] for i in range(3)]
    L = relative_gain_array(g)
    assert np.allclose(L, expected)
    # the published RGA of this column has lambda_11 ~ 1.96 and lambda_33 ~ 1.5
    assert abs(L[0, 0] - 1.96) < 0.02
    assert L[2, 2] > 1.4


def test_tall_matrix_by_hand_and_sum_properties():
    # G = [[1,0],[0,1],[1,1]]: G^T G = [[2,1],[1,2]], G+ = 1/3 [[2,-1,1],[-1,2,1]]
    G = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    L = relative_gain_array(G)
    assert np.allclose(L, [[2 / 3, 0], [0, 2 / 3], [1 / 3, 1 / 3]])
    # full column rank: G+ G = I, so every column of Lambda sums to 1;
    # rows are the diagonal of the projector G G+: in [0, 1], summing to n.
    rng = np.random.default_rng(7)
    T = rng.normal(size=(5, 3))
    LT = relative_gain_array(T)
    assert np.allclose(LT.sum(axis=0), 1.0)
    rows = LT.sum(axis=1)
    assert np.all(rows >= -1e-12) and np.all(rows <= 1 + 1e-12)
    assert math.isclose(rows.sum(), 3.0)


def test_wide_matrix_is_transpose_of_tall():
    rng = np.random.default_rng(3)
    T = rng.normal(size=(4, 2))
    assert np.allclose(relative_gain_array(T.T), relative_gain_array(T).T)
    assert np.allclose(relative_gain_array(T.T).sum(axis=1), 1.0)


def test_square_rga_is_independent_of_scaling():
    G = np.array([[0.66, -0.61, -0.0049], [1.11, -2.36, -0.012], [-34.68, 46.2, 0.87]])
    S = scale_gains(G, variable_ranges=[2.0, 0.5, 30.0], parameter_ranges=[300.0, 0.01, 7.0])
    assert np.allclose(relative_gain_array(S), relative_gain_array(G))


def test_singular_square_names_dependent_parameter_and_variable():
    with pytest.raises(AnalysisError) as info:
        relative_gain_array([[1.0, 2.0], [2.0, 4.0]], variables=["TI-1", "TI-2"],
                            parameters=["hx.kht", "pipe.k"])
    msg = str(info.value)
    assert "rank 1" in msg
    assert "'hx.kht'" in msg  # column [1, 2] is half of [2, 4]
    assert "'TI-1'" in msg


def test_tall_with_zero_column_is_reported():
    with pytest.raises(AnalysisError, match="'p2'"):
        relative_gain_array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]], parameters=["p1", "p2"])


def test_non_finite_gain_is_reported():
    with pytest.raises(AnalysisError, match="non-finite"):
        relative_gain_array([[1.0, np.nan], [0.0, 1.0]])


def test_rank_report_three_columns_one_combination():
    # column 2 = column 0 + column 1
    rep = rank_report([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0], [2.0, 1.0, 3.0]])
    assert rep.rank == 2 and not rep.full
    assert len(rep.dependent_columns) == 1


def test_condition_number_by_hand():
    # G^T G = [[10, 14], [14, 20]]: eigenvalues 15 +- sqrt(221)
    expected = math.sqrt((15 + math.sqrt(221)) / (15 - math.sqrt(221)))
    assert math.isclose(condition_number([[1.0, 2.0], [3.0, 4.0]]), expected)
    assert math.isclose(condition_number(np.diag([10.0, 0.1])), 100.0)
    assert condition_number([[1.0, 2.0], [2.0, 4.0]]) > 1e15


def test_scaling_helpers():
    G = [[-0.004, 2.0], [0.01, 0.0]]
    S = scale_gains(G, variable_ranges=[10.0, 0.5], parameter_ranges=parameter_ranges([(850, 1150), (0, 0.01)]))
    # -0.004 K per W/m2K * 300 W/m2K / 10 K = -0.12 ; 2 * 0.01 / 10 = 0.002 ; 0.01 * 300 / 0.5 = 6
    assert np.allclose(S, [[-0.12, 0.002], [6.0, 0.0]])
    assert np.allclose(variable_ranges([[300.0, 1.0], [310.0, np.nan], [305.0, 1.0]], floor=0.1), [10.0, 0.1])
    with pytest.raises(AnalysisError, match="positive"):
        scale_gains(G, variable_ranges=[0.0, 1.0])
