"""The fixed part of the bands when several loops track at once (issue 31): the loops' joint steady shift.

The twin, linear with first-order lags (TAU = 100 s, input ``u`` = 10):
``y1 = u + a + 0.5 b + q``, ``y2 = 0.8 a + b``. It tracks ``a`` on Y1 and ``b`` on Y2 and holds ``q`` at its
estimate 0 with the interval ``[-1, 1]``; the plant has ``a = 2``, ``b = 3``, ``q = 0.75``. Worked by hand:

* the gains of the pairs' parameters on their tags are ``G = [[1, 0.5], [0.8, 1]]`` (determinant 0.6);
* the plant reads ``Y1 = 10 + 2 + 1.5 + 0.75 = 14.25`` and ``Y2 = 1.6 + 3 = 4.6``; both loops drive the twin's
  tags there together, ``a + 0.5 b = 4.25`` and ``0.8 a + b = 4.6``: ``a = 3.25`` (1.25 above the truth) and
  ``b = 2.0`` (1.0 below it), though ``q`` does not touch Y2;
* ``q`` at its interval's ends moves Y1 by ``-1`` / ``+1`` and Y2 not at all, so the loops would shift the
  tracked values by ``-G⁻¹ (∓1, 0)``: the truth of ``a`` lies ``+1.667`` / ``-1.667`` from its tracked value
  and that of ``b`` ``-1.333`` / ``+1.333``, which hold the offsets above (``-1.25``, ``+1.0``);
* each pair's own gain (1) alone gives ``a`` ``±1`` and ``b`` nothing: both bands miss.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from _fixtures_casadi import build_casadi_fmu

TAU = 100.0
U = 10.0
A_PLANT, B_PLANT, Q_PLANT = 2.0, 3.0, 0.75
DET = 1.0 - 0.5 * 0.8
A_SETTLED = ((U + A_PLANT + 0.5 * B_PLANT + Q_PLANT - U) - 0.5 * (0.8 * A_PLANT + B_PLANT)) / DET  # 3.25
B_SETTLED = ((0.8 * A_PLANT + B_PLANT) - 0.8 * (A_PLANT + 0.5 * B_PLANT + Q_PLANT)) / DET  # 2.0
A_SHIFT, B_SHIFT = 1.0 / DET, 0.8 / DET  # 1.667, 1.333: |truth - tracked| with q at an end of [-1, 1]
STOP = 20000.0
AFTER = 6000.0


@pytest.fixture(scope="module")
def fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_casadi_fmu(tmp_path_factory.mktemp("joint_fmu"), "joint2", constants={"TAU": TAU}, variables=[
        ("a", ("parameter", "tunable"), {"start": 2.5, "min": 0.0, "max": 6.0}),
        ("b", ("parameter", "tunable"), {"start": 2.5, "min": 0.0, "max": 6.0}),
        ("q", ("parameter", "tunable"), {"start": 0.0, "min": -5.0, "max": 5.0}),
        ("u", ("input",), {"start": U}),
        ("x1", ("local", "continuous"), {"start": 14.0, "initial": "exact"}),
        ("x2", ("local", "continuous"), {"start": 4.5, "initial": "exact"}),
        ("y1", ("output",), {}),
        ("y2", ("output",), {}),
    ], equations=[("der(x1)", "(u + a + 0.5 * b + q - x1) / TAU"), ("der(x2)", "(0.8 * a + b - x2) / TAU"),
                  ("y1", "x1"), ("y2", "x2")])


@pytest.fixture(scope="module")
def spec(fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from trackingbox.fmu import FMUModel

    out = tmp_path_factory.mktemp("joint_plant")
    t = np.arange(0.0, STOP + 1.0, 10.0)
    u = np.full(t.size, U)
    y1, y2 = U + A_PLANT + 0.5 * B_PLANT + Q_PLANT, 0.8 * A_PLANT + B_PLANT
    with FMUModel(fmu) as m:
        sim = m.simulate(stop_time=STOP, output_interval=10.0, inputs=pd.DataFrame({"time": t, "u": u}),
                         parameters={"a": A_PLANT, "b": B_PLANT, "q": Q_PLANT, "x1": y1, "x2": y2},
                         outputs=["y1", "y2"])
    rng = np.random.default_rng(7)
    pd.DataFrame({"time": t, "FI": u, "Y1": sim["y1"].to_numpy() + rng.normal(0.0, 0.02, t.size),
                  "Y2": sim["y2"].to_numpy() + rng.normal(0.0, 0.02, t.size)}).to_csv(out / "m.csv", index=False)
    pairs = "".join(f'[[pairs]]\nvariable = "{tag}"\nparameter = "{p}"\ngain = 1.0\ntime_constant = {TAU!r}\n'
                    "lambda = 1.0\n\n" for tag, p in (("Y1", "a"), ("Y2", "b")))
    params = "".join(f'[[parameters]]\nname = "{p}"\nstart = 2.5\nmin = 0.0\nmax = 6.0\n\n' for p in "ab")
    text = (f'twin = "{fmu}"\nmeasurements = "{out / "m.csv"}"\nsample_time = 10.0\n\n'
            '[inputs]\nFI = "u"\n\n[outputs]\nY1 = "y1"\nY2 = "y2"\n\n' + params
            + "[fixed]\nq = 0.0\n\n[fixed_intervals]\nq = [-1.0, 1.0]\n\n"
            "[windows]\ntraining = [0.0, 10000.0]\nvalidation = [10000.0, 20000.0]\n\n" + pairs
            + "[tracking]\nhold_until = 200.0\n")
    (out / "spec.toml").write_text(text, encoding="utf-8")
    return out / "spec.toml"


@pytest.fixture(scope="module")
def tracked(spec: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[pd.DataFrame, dict]:
    """``trackingbox track SPEC --out OUT``, as the command line runs it: the CSV and result.json."""
    from trackingbox.commands import track as track_command

    out = tmp_path_factory.mktemp("joint_track")
    parser = argparse.ArgumentParser(prog="trackingbox")
    track_command.register(parser.add_subparsers())
    assert track_command.run(parser.parse_args(["track", str(spec), "--out", str(out)])) == 0
    return pd.read_csv(out / "tracking.csv"), json.loads((out / "result.json").read_text())


def _rebanded(df: pd.DataFrame, spec: object, fixed: object, gains: object) -> pd.DataFrame:
    """The bands of a tracking CSV recomputed by :class:`~trackingbox.identify.bands.BandTracker` (causal: the same
    values a run writes) with the fixed part *fixed* and the loops' gain matrix *gains*."""
    from trackingbox.identify.bands import BandTracker

    base = [c for c in df.columns if not c.startswith(("parameter_lo:", "parameter_hi:", "lack_of_fit"))]
    numbers = df[base].copy()
    for c in base:
        if c.startswith("mode:"):
            numbers[c] = (df[c].astype(str) == "hold").astype(float)
    bands = BandTracker(spec, base, fixed=fixed, gains=gains)
    out = pd.DataFrame(bands.rows(numbers.to_numpy(float)), columns=bands.columns)
    out["time"] = df["time"]
    return out


def _coverage(df: pd.DataFrame, name: str, truth: float) -> float:
    rows = df[(df["time"] >= AFTER) & df[f"parameter_lo:{name}"].notna()]
    assert len(rows) > 1000
    return float(((rows[f"parameter_lo:{name}"] <= truth) & (truth <= rows[f"parameter_hi:{name}"])).mean())


def test_two_loops_absorb_a_held_offset_together_and_the_bands_hold_the_truth(
        tracked: tuple[pd.DataFrame, dict]) -> None:
    df, result = tracked
    settled = df[df["time"] >= AFTER]
    # the loops settle where the hand calculation says
    assert float(settled["parameter:a"].mean()) == pytest.approx(A_SETTLED, abs=0.02)
    assert float(settled["parameter:b"].mean()) == pytest.approx(B_SETTLED, abs=0.02)
    # the fixed part is the joint shift -G^-1 dy, not each pair's own -dy/gain
    lo, hi = result["bands"]["a"]["fixed"]["q"]
    assert lo == pytest.approx(A_SHIFT, rel=0.02) and hi == pytest.approx(-A_SHIFT, rel=0.02)
    lo, hi = result["bands"]["b"]["fixed"]["q"]
    assert lo == pytest.approx(-B_SHIFT, rel=0.02) and hi == pytest.approx(B_SHIFT, rel=0.02)
    assert "fixed_note" not in result["bands"]["a"]
    # the loops' interaction: M = G^-1 diag(G) = [[1, -0.5], [-0.8, 1]] / 0.6
    assert result["bands"]["a"]["coupling"] == {"a": pytest.approx(1 / DET, rel=0.01),
                                                "b": pytest.approx(-0.5 / DET, rel=0.01)}
    assert result["bands"]["b"]["coupling"] == {"a": pytest.approx(-0.8 / DET, rel=0.01),
                                                "b": pytest.approx(1 / DET, rel=0.01)}
    assert _coverage(df, "a", A_PLANT) >= 0.95 and _coverage(df, "b", B_PLANT) >= 0.95


def test_each_pairs_own_gain_misses_the_truth_the_joint_shift_holds(spec: Path,
                                                                    tracked: tuple[pd.DataFrame, dict]) -> None:
    """The same step tests read with each pair's own gain (the rule for one pair): the bands recomputed from
    the tracked rows miss both truths; with the joint shift they hold them (without part 5)."""
    from trackingbox.identify.held import measure, shifts
    from trackingbox.spec import load_spec

    df = tracked[0]
    loaded = load_spec(spec)
    found, note = measure(loaded)
    assert note == "" and found is not None and found.gains is not None
    assert found.gains == pytest.approx(np.array([[1.0, 0.5], [0.8, 1.0]]), rel=0.01)
    single, _ = shifts(loaded, found, joint=False)
    assert [(f.at_lower, f.at_upper) for f in single["a"]] == [pytest.approx((1.0, -1.0), rel=0.01)]
    assert [(f.at_lower, f.at_upper) for f in single["b"]] == [pytest.approx((0.0, 0.0), abs=1e-6)]
    for rule, expect in (("single", lambda c: c < 0.05), ("joint", lambda c: c >= 0.95)):
        fixed = single if rule == "single" else shifts(loaded, found)[0]
        out = _rebanded(df, loaded, fixed=fixed, gains=None)
        for name, truth in (("a", A_PLANT), ("b", B_PLANT)):
            assert expect(_coverage(out, name, truth)), (rule, name, _coverage(out, name, truth))


def test_one_pair_measures_no_gain_matrix(spec: Path) -> None:
    """With one pair the rule is the pair's own gain (the bands as before): no gain matrix. The tracked ``a`` is
    stepped all the same for the untracked Y2's gain, the model-error part's (``y2 = 0.8 a + b``: 0.8, and with
    one loop the closed-loop gain is that gain)."""
    import dataclasses

    from trackingbox.identify.held import band_parts, measure, shifts
    from trackingbox.spec import load_spec

    loaded = load_spec(spec)
    one = dataclasses.replace(loaded, pairs=loaded.pairs[:1])
    found, _ = measure(one)
    assert found is not None and found.gains is None
    fixed, note = shifts(one, found)
    assert note == "" and list(fixed) == ["a"]
    assert (fixed["a"][0].at_lower, fixed["a"][0].at_upper) == pytest.approx((1.0, -1.0), rel=0.01)
    assert found.others == ("Y2",) and found.other_gains == pytest.approx(np.array([[0.8]]), rel=0.01)
    assert band_parts(one)[3] == {"Y2": [pytest.approx(0.8, rel=0.01)]}
    assert band_parts(loaded)[3] is None  # both tags paired: nothing untracked


def test_a_singular_gain_matrix_falls_back_to_each_pairs_gain_and_says_so(spec: Path) -> None:
    import dataclasses

    from trackingbox.identify.held import measure, shifts
    from trackingbox.spec import load_spec

    loaded = load_spec(spec)
    found, _ = measure(loaded)
    assert found is not None
    flat = dataclasses.replace(found, gains=np.array([[1.0, 0.5], [2.0, 1.0]]))
    fixed, note = shifts(loaded, flat)
    assert "singular" in note and "own gain" in note
    assert (fixed["a"][0].at_lower, fixed["b"][0].at_upper) == pytest.approx((1.0, 0.0), abs=0.01)


def test_the_other_loops_noise_reaches_a_band_through_their_interaction(fmu: Path, tmp_path: Path) -> None:
    """Nothing held (``q`` exact at the plant's 0), Y1 measured with 0.002 of noise and Y2 with 0.3: the noise on
    Y2 moves ``b``, which moves Y1, which ``a`` absorbs; ``a``'s own tag's fast error alone gives it a band too
    narrow for that. With the loops' noise model together (part 5 of :mod:`trackingbox.identify.bands`) the band
    holds the truth (seeds 7, 3, 11 of this noise: 95.9, 96.9, 94.1 % of the rows; each loop alone 80.1, 82.4,
    75.2 %); a 95 % band over some 1400 autocorrelated rows, hence the 93 % bound."""
    from trackingbox.commands import track as track_command
    from trackingbox.spec import load_spec

    t = np.arange(0.0, STOP + 1.0, 10.0)
    rng = np.random.default_rng(7)
    y1, y2 = U + A_PLANT + 0.5 * B_PLANT, 0.8 * A_PLANT + B_PLANT  # the plant settled, q = 0
    pd.DataFrame({"time": t, "FI": U, "Y1": y1 + rng.normal(0.0, 0.002, t.size),
                  "Y2": y2 + rng.normal(0.0, 0.3, t.size)}).to_csv(tmp_path / "m.csv", index=False)
    pairs = "".join(f'[[pairs]]\nvariable = "{tag}"\nparameter = "{p}"\ngain = 1.0\ntime_constant = {TAU!r}\n'
                    "lambda = 1.0\n\n" for tag, p in (("Y1", "a"), ("Y2", "b")))
    params = "".join(f'[[parameters]]\nname = "{p}"\nstart = 2.5\nmin = 0.0\nmax = 6.0\n\n' for p in "ab")
    (tmp_path / "spec.toml").write_text(
        f'twin = "{fmu}"\nmeasurements = "{tmp_path / "m.csv"}"\nsample_time = 10.0\n\n'
        '[inputs]\nFI = "u"\n\n[outputs]\nY1 = "y1"\nY2 = "y2"\n\n' + params + "[fixed]\nq = 0.0\n\n"
        "[windows]\ntraining = [0.0, 10000.0]\nvalidation = [10000.0, 20000.0]\n\n" + pairs
        + "[tracking]\nhold_until = 200.0\n", encoding="utf-8")
    parser = argparse.ArgumentParser(prog="trackingbox")
    track_command.register(parser.add_subparsers())
    assert track_command.run(parser.parse_args(["track", str(tmp_path / "spec.toml"), "--out",
                                                str(tmp_path / "out")])) == 0
    df = pd.read_csv(tmp_path / "out" / "tracking.csv")
    band = json.loads((tmp_path / "out" / "result.json").read_text())["bands"]["a"]
    assert band["coupling"] == {"a": pytest.approx(1.0 / DET, rel=0.01), "b": pytest.approx(-0.5 / DET, rel=0.01)}
    assert _coverage(df, "a", A_PLANT) >= 0.93 and _coverage(df, "b", B_PLANT) >= 0.93
    alone = _rebanded(df, load_spec(tmp_path / "spec.toml"), fixed={}, gains=None)
    assert _coverage(alone, "a", A_PLANT) < 0.85
    # not merely wider: the band's median half-width stays within three standard deviations of a's jitter
    settled = df[(df["time"] >= AFTER) & df["parameter_lo:a"].notna()]
    half = float((settled["parameter_hi:a"] - settled["parameter_lo:a"]).median()) / 2.0
    assert half < 3.0 * float(settled["parameter:a"].std())
