"""``[diagnose] varying``: the null model lets a tracked parameter move in time as tracking would.

The residuals here are built by hand: a parameter that really rises as
``R(t) = 2e-4 (1 - exp(-t/1 d))`` seen through constant output sensitivities,
plus white noise. A null that holds the parameter constant leaves the rise's
curvature as a trend in every tag (the trend a drifting sensor would explain); a
null that lets it rise, piecewise linear with knots every 3 h, leaves white noise,
on training and on validation. A falling trend is not a rising fouling: the
``rising`` kind leaves it in the residual for an effect to explain.
"""
from __future__ import annotations

import textwrap

import numpy as np
import pytest

from trackingbox.diagnose.linear import fit_windows
from trackingbox.diagnose.varying import VaryingBasis, ramps
from trackingbox.errors import SpecError
from trackingbox.spec import dump_spec, load_spec, loads_spec

SIGMA = 1.0
#: output sensitivity of each tag to the parameter (per m2.K/W): two tags moving in opposite senses; the
#: rise moves PI by 80 noise levels over the record (the evaporator's PI-6152: 740 Pa against 200 Pa)
SENS = {"PI": 4e5, "TI": -2e3}


def _windows(rise, seed=0):
    rng = np.random.default_rng(seed)
    t_tr = np.arange(0.0, 12 * 3600.0, 10.0)
    t_va = np.arange(12 * 3600.0, 24 * 3600.0, 10.0)
    r0 = float(np.mean(rise(t_tr)))  # the constant a null without trajectories fits on training
    out = []
    for t in (t_tr, t_va):
        jac = {tag: np.full((t.size, 1), s) for tag, s in SENS.items()}
        res = {tag: s * (rise(t) - r0) + SIGMA * rng.standard_normal(t.size) for tag, s in SENS.items()}
        out.append((t, jac, res))
    return out


def _basis(t_tr, t_va, kind="rising"):
    return VaryingBasis(("effect.Rf",), (kind,), (0,), 3 * 3600.0, ramps(t_tr, 3 * 3600.0), ramps(t_va, 3 * 3600.0),
                        (6e-4,), (0.0,), (6e-4,))


def _rms(d):
    return float(np.sqrt(np.mean(np.concatenate([np.asarray(v) ** 2 for v in d.values()]))))


def test_rising_fouling_is_followed_not_left_as_a_trend():
    (t_tr, j_tr, r_tr), (t_va, j_va, r_va) = _windows(lambda t: 2e-4 * (1 - np.exp(-t / 86400.0)))
    noise = {tag: SIGMA for tag in SENS}
    bounds = (np.array([-1e-4]), np.array([5e-4]))
    held = fit_windows(r_tr, r_va, (j_tr, j_va), noise, bounds=bounds, x=[1e-4])
    moving = fit_windows(r_tr, r_va, (j_tr, j_va), noise, bounds=bounds, varying=_basis(t_tr, t_va), x=[1e-4])
    # held constant: the rise stays (PI about 25 noise levels off on validation, where it keeps rising)
    assert _rms(held.after_valid) > 10 * SIGMA
    # followed: white noise is left on both windows (the 3 h chords of the exponential are within
    # 2e-4/(1 d)^2 * (3 h)^2 / 8 = 4e-7 of it: 0.16 noise levels on PI)
    assert _rms(moving.after_train) == pytest.approx(SIGMA, rel=0.05)
    assert _rms(moving.after_valid) == pytest.approx(SIGMA, rel=0.05)
    assert np.all(moving.varying_train >= 0.0)  # a rising kind's increments


def test_a_falling_trend_is_not_taken_for_a_rising_fouling():
    (t_tr, j_tr, r_tr), (t_va, j_va, r_va) = _windows(lambda t: -2e-4 * t / 86400.0)
    noise = {tag: SIGMA for tag in SENS}
    rising = fit_windows(r_tr, r_va, (j_tr, j_va), noise, varying=_basis(t_tr, t_va, "rising"), x=[3e-4])
    free = fit_windows(r_tr, r_va, (j_tr, j_va), noise, varying=_basis(t_tr, t_va, "free"), x=[3e-4])
    assert _rms(rising.after_train) > 5 * SIGMA  # left for an effect to explain
    assert _rms(free.after_train) == pytest.approx(SIGMA, rel=0.05)


SPEC = """\
twin = "twin.fmu"
measurements = "m.csv"
sample_time = 10.0
[outputs]
"TI-1" = "T"
[[parameters]]
name = "effect.Rf"
start = 0.0
min = 0.0
max = 6e-4
"""


def _case(tmp_path, extra):
    (tmp_path / "twin.fmu").write_bytes(b"PK\x05\x06" + b"\0" * 18)
    (tmp_path / "m.csv").write_text("time,TI-1\n0,1.0\n")
    path = tmp_path / "spec.toml"
    path.write_text(SPEC + textwrap.dedent(extra))
    return path


def test_spec_varying_round_trip(tmp_path):
    spec = load_spec(_case(tmp_path, '[diagnose]\nvarying = { "effect.Rf" = "rising" }\n'))
    assert spec.diagnose.varying == (("effect.Rf", "rising"),)
    again = loads_spec(dump_spec(spec), spec.path, check_files=False)
    assert again.diagnose.varying == spec.diagnose.varying


@pytest.mark.parametrize("extra, message", [
    ('[diagnose]\nvarying = { "effect.Rf" = "rizing" }\n', r"varying 'effect.Rf'.*one of rising, falling, free.*"
                                                             r"did you mean 'rising'"),
    ('[diagnose]\nvarying = { "effect.Rg" = "rising" }\n', r"varying 'effect.Rg'.*not a \[\[parameters\]\] entry.*"
                                                             r"did you mean 'effect.Rf'"),
    ('[diagnose]\nvarying = ["effect.Rf"]\n', r"varying in \[diagnose\] must be a table"),
])
def test_spec_varying_errors_name_the_entry(tmp_path, extra, message):
    with pytest.raises(SpecError, match=message):
        load_spec(_case(tmp_path, extra))


def _stacked(res, cols, noise):
    a = np.vstack([cols[t] / noise[t] for t in res])
    b = np.concatenate([res[t] / noise[t] for t in res])
    return a, b


def test_joint_lstsq_equals_the_factorised_samples():
    """Against numpy's SVD least squares and scipy's bounded one on the stacked, noise-weighted samples."""
    from scipy.optimize import lsq_linear

    from trackingbox.diagnose.linear import joint_lstsq

    rng = np.random.default_rng(3)
    n, m = 2000, 9
    cols = {t: rng.standard_normal((n, m)) * np.logspace(-3, 4, m) for t in ("a", "b", "c")}
    res = {t: rng.standard_normal(n) + cols[t][:, 0] * 50 for t in cols}
    noise = {"a": 0.5, "b": 2.0, "c": 1.0}
    a, b = _stacked(res, cols, noise)
    free = np.linalg.lstsq(a, b, rcond=None)[0]
    np.testing.assert_allclose(joint_lstsq(res, cols, noise), free, rtol=1e-9, atol=1e-12 * np.abs(free).max())
    lo, hi = np.full(m, -np.inf), np.full(m, np.inf)
    hi[0] = 20.0  # the free solution's first coefficient is about 50: the bound is active
    bounded = lsq_linear(a, b, bounds=(lo, hi), method="bvls").x
    got = joint_lstsq(res, cols, noise, bounds=(lo, hi))
    assert got[0] == pytest.approx(20.0)
    np.testing.assert_allclose(got, bounded, rtol=1e-7, atol=1e-9 * np.abs(bounded).max())
    # rank-deficient (a repeated column): the minimum-norm solution, as numpy's
    dup = {t: np.hstack([c, c[:, :1]]) for t, c in cols.items()}
    a2, _ = _stacked(res, dup, noise)
    np.testing.assert_allclose(joint_lstsq(res, dup, noise), np.linalg.lstsq(a2, b, rcond=None)[0], rtol=1e-9)
