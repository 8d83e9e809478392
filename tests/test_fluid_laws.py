"""Pipe and pump laws of ``TrackingBox.Fluid``: the linear (twin) laws against the
quadratic (plant) ones, on ``Fluid.Validation.CurveLaws`` (one ramp of flow through
each law).

The expectations are geometric, not the formulas again: every law meets the
quadratic one at the design point; the secants go through zero loss (pipe) or the
shut-off head (pump); the tangents have the quadratic law's numerical slope there
and lie on the outer side of the curve (below the convex pipe loss, above the
concave pump head).
"""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

pytestmark = pytest.mark.compile

MODEL = "TrackingBox.Fluid.Validation.CurveLaws"
K, DP_REF, U_RISE, R, SPEED = 0.005, 1e6, 40000.0, 1.5, 0.8


@pytest.fixture(scope="module")
def laws(fmu_cache):
    names = [f"pipe{v}.{q}" for v in "QST" for q in ("dp", "x")] + \
            [f"pump{v}.{q}" for v in "QST" for q in ("dpRise", "x")]
    return fmpy.simulate_fmu(str(fmu_cache(MODEL)), output=names, output_interval=0.25)


def _slope_at(x: np.ndarray, y: np.ndarray, x0: float) -> float:
    return float(np.interp(x0, x, np.gradient(y, x)))


def _line(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Slope, intercept and worst deviation of a straight-line fit."""
    a, b = np.polyfit(x, y, 1)
    return float(a), float(b), float(np.max(np.abs(a * x + b - y)))


def test_pipe_laws_meet_at_nominal_flow(laws):
    x = laws["pipeQ.x"]
    assert x.min() < 0.5 and x.max() > 1.4
    quad, sec, tan = laws["pipeQ.dp"], laws["pipeS.dp"], laws["pipeT.dp"]
    for dp in (quad, sec, tan):
        assert np.interp(1.0, x, dp) == pytest.approx(K * DP_REF, rel=1e-5)  # interpolation error ~1e-6
    # the quadratic law: doubling the flow quadruples the loss
    assert np.interp(1.4, x, quad) / np.interp(0.7, x, quad) == pytest.approx(4.0, rel=1e-4)
    # secant: a straight line through zero loss at zero flow
    a, b, dev = _line(x, sec)
    assert abs(b) < 1e-6 * K * DP_REF and dev < 1e-6 * K * DP_REF
    # tangent: a straight line with the quadratic law's slope at nominal flow, below the convex curve
    a, b, dev = _line(x, tan)
    assert dev < 1e-6 * K * DP_REF
    assert a == pytest.approx(_slope_at(x, quad, 1.0), rel=2e-3)
    assert np.all(tan <= quad + 1e-9 * K * DP_REF)
    # near nominal flow the tangent is the closer linear law, far off it the secant
    near = np.abs(x - 1.0) < 0.25
    assert np.max(np.abs(tan - quad)[near]) < 0.5 * np.max(np.abs(sec - quad)[near])


def test_pump_laws_meet_at_the_affinity_point(laws):
    x = laws["pumpQ.x"]
    assert x.min() < 0.5 * SPEED and x.max() > 1.4 * SPEED
    quad, sec, tan = laws["pumpQ.dpRise"], laws["pumpS.dpRise"], laws["pumpT.dpRise"]
    design = U_RISE * SPEED**2  # the design point moved along the affinity laws
    for dp in (quad, sec, tan):
        assert np.interp(SPEED, x, dp) == pytest.approx(design, rel=1e-3)
    # secant: straight, through the shut-off head at zero flow
    a, b, dev = _line(x, sec)
    assert dev < 1e-6 * U_RISE and b == pytest.approx(R * design, rel=1e-6)
    # tangent: straight, the quadratic curve's slope at x = speed, above the concave curve
    a, b, dev = _line(x, tan)
    assert dev < 1e-6 * U_RISE
    assert a == pytest.approx(_slope_at(x, quad, SPEED), rel=2e-3)
    assert np.all(tan >= quad - 1e-9 * U_RISE)
    near = np.abs(x / SPEED - 1.0) < 0.25
    assert np.max(np.abs(tan - quad)[near]) < 0.5 * np.max(np.abs(sec - quad)[near])
