"""Bands on tracked parameters, the spec's ``interval``, and pairing's candidate check.

Independent expectations: a closed loop simulated here with the runtime's own
controller class (:class:`~trackingbox.tracking.controllers.ScaledPI`, linear
interpolation, as ``track`` runs it) around an exactly discretised first-order
process, driven by white and by correlated measurement noise -- the spread of
its parameter and how often its band holds the (known, constant or ramping)
truth are counted, not taken from the band's own model; and hand-made
sensitivity matrices whose columns are parallel or invisible by construction.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from trackingbox.identify.bands import BandTracker, Fixed, loop_model
from trackingbox.tracking.controllers import ScaledPI
from trackingbox.tracking.tuning import pair_settings

TS = 10.0
GAIN, TAU, LAM = -0.02, 120.0, 3.0          # K per unit of the parameter, s, closed loop 6 min
P_MIN, P_MAX, P_TRUE, P0 = 500.0, 1500.0, 910.0, 1000.0
COLUMNS = ["time", "measured:TI", "tracked:TI", "untracked:TI", "parameter:k", "mode:TI"]


def _spec(interval: tuple[float, float] | None = None, tau: float = TAU) -> SimpleNamespace:
    pair = SimpleNamespace(variable="TI", parameter="k", gain=GAIN, time_constant=tau, lambda_=LAM, kp=None,
                           ti=None, controller="pi")
    par = SimpleNamespace(name="k", start=P0, min=P_MIN, max=P_MAX, interval=interval)
    return SimpleNamespace(sample_time=TS, pairs=[pair], parameter=lambda name: par, path="test")


def _closed_loop(noise: np.ndarray, truth: np.ndarray, hold_rows: int = 30, offset: float = 0.0,
                 tau: float = TAU) -> list[list[object]]:
    """Rows of a tracking run: the runtime's PI controller on an exactly discretised first-order twin
    (*offset*: what the plant's tag reads above the twin's at equal parameters)."""
    spec = _spec(tau=tau)
    settings = pair_settings(spec.pairs[0], P_MIN, P_MAX, ts=TS)
    pi = ScaledPI(settings.scaling, kp=settings.kp, ti=settings.ti, ts=TS, direction=settings.direction, p0=P0,
                  interpolation="linear")
    a = math.exp(-TS / tau)
    x = P0  # the twin settled at its start value
    rows = []
    for k in range(noise.size):
        meas = 300.0 + GAIN * truth[k] + offset + noise[k]
        tracked = 300.0 + GAIN * x
        hold = k < hold_rows
        p = pi.update(meas, tracked, hold=hold)
        rows.append([k * TS, meas, tracked, tracked, p, "hold" if hold else "auto"])
        x = a * x + (1.0 - a) * p
    return rows


def _coverage(rows: list[list[object]], truth: np.ndarray, interval: tuple[float, float] | None = None,
              after: float = 0.0, fixed: dict | None = None, tau: float = TAU) -> tuple[float, np.ndarray]:
    bands = BandTracker(_spec(interval, tau), COLUMNS, fixed=fixed)
    out = np.array([bands.row(r) for r in rows])
    t = np.array([r[0] for r in rows])
    ok = np.isfinite(out[:, 0]) & (t >= after)
    inside = (out[:, 0] <= truth) & (truth <= out[:, 1])
    return float(inside[ok].mean()), out


def test_loop_model_predicts_the_spread_of_the_runtime_controller() -> None:
    """White noise sigma 0.05 K: the parameter's spread about the truth is sqrt(sum h^2) sigma."""
    n = 40000
    rng = np.random.default_rng(4)
    truth = np.full(n, P_TRUE)
    rows = _closed_loop(0.05 * rng.normal(size=n), truth)
    p = np.array([r[4] for r in rows])[2000:]
    s = pair_settings(_spec().pairs[0], P_MIN, P_MAX, ts=TS)
    model = loop_model(GAIN, TAU, s.kp * (P_MAX - P_MIN) / s.scaling.span, s.ti, TS)
    predicted = 0.05 * math.sqrt(float(model.acf[0]))
    assert abs(np.std(p - P_TRUE) / predicted - 1.0) < 0.1
    assert abs(np.mean(p) - P_TRUE) < 3 * predicted / math.sqrt(len(p) / 20)


@pytest.mark.parametrize("kind", ["white", "correlated"])
def test_band_holds_a_constant_truth_about_95_percent_of_the_time(kind: str) -> None:
    n = 30000
    rng = np.random.default_rng(8)
    w = rng.normal(size=n)
    noise = 0.05 * w if kind == "white" else 0.05 * np.convolve(w, np.ones(6) / math.sqrt(6), mode="same")
    truth = np.full(n, P_TRUE)
    share, out = _coverage(_closed_loop(noise, truth), truth, after=3600.0)
    assert 0.90 <= share <= 0.99, share
    assert np.all(out[np.isfinite(out[:, 0])][:, 0] >= P_MIN) and np.all(out[np.isfinite(out[:, 1])][:, 1] <= P_MAX)


def test_band_follows_a_drifting_truth_with_the_loops_lag() -> None:
    """A truth falling 100 units over the run (fouling): noise alone would leave it outside the band."""
    n = 30000
    rng = np.random.default_rng(9)
    truth = P_TRUE - 100.0 * np.arange(n) / n
    share, _ = _coverage(_closed_loop(0.05 * rng.normal(size=n), truth), truth, after=3600.0)
    assert share >= 0.90, share


def test_band_carries_a_parameter_the_twin_holds_off_within_its_interval() -> None:
    """A second parameter q moves the tag by GQ per unit; the twin holds it at its estimate 50
    (interval 45..55), the plant's is 53.5. Worked by hand: the loop settles where
    GAIN (p - truth) = GQ (53.5 - 50), i.e. 7 units below the truth, four times the noise part;
    q at its interval's ends would put the truth -GQ (45 - 50) / GAIN = -10 and +10 from p."""
    gq, q_hat, q_true, (qa, qb) = 0.04, 50.0, 53.5, (45.0, 55.0)
    n = 20000
    rng = np.random.default_rng(11)
    truth = np.full(n, P_TRUE)
    rows = _closed_loop(0.05 * rng.normal(size=n), truth, offset=gq * (q_true - q_hat))
    p = np.array([r[4] for r in rows])[4000:]
    assert abs(np.mean(p) - (P_TRUE + gq * (q_true - q_hat) / GAIN)) < 0.3  # the runtime loop: 7 below
    without, _ = _coverage(rows, truth, after=3600.0)
    fixed = {"k": [Fixed("q", -gq * (qa - q_hat) / GAIN, -gq * (qb - q_hat) / GAIN)]}
    share, out = _coverage(rows, truth, after=3600.0, fixed=fixed)
    assert without < 0.05, without
    assert share >= 0.95, share
    # the fixed part adds at most its own extent on either side (in quadrature with the others)
    _, plain = _coverage(rows, truth, after=3600.0)
    ok = np.isfinite(out[:, 0])
    assert np.all(out[ok, 1] - plain[ok, 1] <= 10.0 + 1e-9) and np.all(plain[ok, 0] - out[ok, 0] <= 10.0 + 1e-9)
    # the summary says what the band takes as exact, and drops what a fixed part covers
    spec = _spec()
    spec.fixed = {"q": q_hat, "known": 1.0}
    assert BandTracker(spec, COLUMNS).describe()["k"]["taken_as_exact"] == ["known", "q"]
    described = BandTracker(spec, COLUMNS, fixed=fixed).describe()["k"]
    assert described["taken_as_exact"] == ["known"] and described["fixed"] == {"q": [-10.0, 10.0]}
    # only the pair's own parameter gets it: an entry for another parameter changes nothing
    _, other = _coverage(rows, truth, after=3600.0, fixed={"not-k": fixed["k"]})
    assert np.array_equal(other, plain, equal_nan=True)


def test_band_starts_from_the_interval_and_is_empty_before_the_noise_is_known() -> None:
    n = 2000
    rng = np.random.default_rng(2)
    truth = np.full(n, P_TRUE)
    rows = _closed_loop(0.05 * rng.normal(size=n), truth)
    _, wide = _coverage(rows, truth)
    _, narrow = _coverage(rows, truth, interval=(980.0, 1020.0))
    first = int(np.argmax(np.isfinite(wide[:, 0])))
    assert first > 0 and np.all(np.isnan(wide[:first]))  # empty until an hour of fast error has been seen
    # within a loop time constant of the start the start's uncertainty still shows, less with an interval
    assert (narrow[first, 1] - narrow[first, 0]) <= (wide[first, 1] - wide[first, 0])


def test_band_state_round_trip_gives_the_same_rows() -> None:
    n = 1200
    rng = np.random.default_rng(3)
    rows = _closed_loop(0.05 * rng.normal(size=n), np.full(n, P_TRUE))
    expected, got, _, _ = _whole_and_resumed(COLUMNS, rows, 700)
    assert np.array_equal(np.array(got), np.array(expected), equal_nan=True)


def _whole_and_resumed(columns: list[str], rows: list, split: int) -> tuple[list, list, BandTracker, BandTracker]:
    """The band rows of one run through *rows*, and of a run stopped at *split* and resumed from its
    state written as JSON (as a checkpoint holds it); with the two trackers that ended them."""
    whole = BandTracker(_spec(), columns)
    expected = [whole.row(r) for r in rows]
    first = BandTracker(_spec(), columns)
    got = [first.row(r) for r in rows[:split]]
    second = BandTracker(_spec(), columns)
    second.load_state_dict(json.loads(json.dumps(first.state_dict())))
    got += [second.row(r) for r in rows[split:]]
    return expected, got, whole, second


def test_band_text_matches_the_csv_writer() -> None:
    """The native rows' text gets the same band values as the csv module's rows (byte for byte)."""
    import csv
    import io

    n = 800
    rng = np.random.default_rng(5)
    rows = _closed_loop(0.05 * rng.normal(size=n), np.full(n, P_TRUE))
    buf = io.StringIO()
    writer = csv.writer(buf)
    a = BandTracker(_spec(), COLUMNS)
    writer.writerows([[*r, *a.row(r)] for r in rows])
    plain = io.StringIO()
    csv.writer(plain).writerows(rows)
    numeric = np.array([[*r[:5], 1.0 if r[5] == "hold" else 0.0] for r in rows])
    b = BandTracker(_spec(), COLUMNS)
    assert b.append_text(plain.getvalue(), numeric) == buf.getvalue()


# --------------------------------------------------------------------------- the spec's interval


SPEC = """\
twin = "twin.fmu"
measurements = "data.csv"
sample_time = 10.0
[outputs]
"TI-1" = "T"
[[parameters]]
name = "k"
start = 1.0  # first guess
min = 0.5
max = 2.0
"""


def test_spec_interval_is_read_written_and_dropped_with_a_new_start(tmp_path: Path) -> None:
    from trackingbox.errors import SpecError
    from trackingbox.spec import load_spec, loads_spec, update_spec

    path = tmp_path / "spec.toml"
    path.write_text(SPEC)
    spec = update_spec(path, starts={"k": 1.2}, intervals={"k": (1.1, 1.3)})
    assert spec.parameter("k").interval == (1.1, 1.3)
    assert load_spec(path, check_files=False).parameter("k").interval == (1.1, 1.3)
    assert "# first guess" in path.read_text()
    spec = update_spec(path, starts={"k": 1.25})  # a new start without an interval: the old one goes
    assert spec.parameter("k").interval is None and "interval" not in path.read_text()
    for bad in ("[1.3, 1.4]", "[0.1, 1.1]", "[1.1]", "\"wide\""):
        with pytest.raises(SpecError, match="interval"):
            loads_spec(SPEC + f"interval = {bad}\n", tmp_path / "x.toml", check_files=False)


# --------------------------------------------------------------------------- pairing's check


def test_pairing_leaves_out_a_candidate_parallel_to_a_stronger_one_and_one_nobody_sees() -> None:
    from trackingbox.identify import structure as st
    from trackingbox.identify.analysis import Identifiability, leave_out

    t = np.linspace(0.0, 10.0, 500)
    a = np.sin(t) + 0.3 * t           # strong
    b = 0.5 * a                       # the same effect, weaker: cannot be told from a's
    c = np.cos(3 * t)                 # its own effect
    d = 1e-9 * np.ones_like(t)        # seen by nothing
    S = np.stack([b, a, c, d], axis=1) * 100.0
    names = ("b", "a", "c", "d")
    found = Identifiability(names=names, scaling=("log",) * 4, noise={}, points=(), rank=2,
                            determined={n: True for n in names}, findings=(), correlation=np.eye(4),
                            matrix=S, widths=np.full(4, math.log(4.0)))
    out = leave_out(found)
    assert set(out) == {"b", "d"}
    assert "cannot be told from that of a" in out["b"] and "a has the larger effect" in out["b"]
    assert "do not see it" in out["d"]
    assert st.analyse(S[:, [1, 2]], ["a", "c"], np.full(2, math.log(4.0))).determined.all()


# --------------------------------------------------------------------------- lack of fit


C2 = 0.01  # K per unit of the parameter on a second, untracked tag


def _closed_loop_two_tags(noise: np.ndarray, noise2: np.ndarray, truth: np.ndarray, missing: float | np.ndarray
                          ) -> list[list[object]]:
    """:func:`_closed_loop` with a second output ``TO = 50 + C2·k`` nobody tracks; the plant's TI carries an
    effect of *missing* K the twin lacks (absorbed by the tracked parameter; an array: per row)."""
    missing = np.broadcast_to(np.asarray(missing, dtype=float), noise.shape)
    spec = _spec()
    settings = pair_settings(spec.pairs[0], P_MIN, P_MAX, ts=TS)
    pi = ScaledPI(settings.scaling, kp=settings.kp, ti=settings.ti, ts=TS, direction=settings.direction, p0=P0,
                  interpolation="linear")
    a = math.exp(-TS / TAU)
    x = P0
    rows = []
    for k in range(noise.size):
        meas = 300.0 + GAIN * truth[k] + missing[k] + noise[k]
        tracked = 300.0 + GAIN * x
        hold = k < 30
        p = pi.update(meas, tracked, hold=hold)
        rows.append([k * TS, meas, tracked, tracked, p, "hold" if hold else "auto",
                     50.0 + C2 * truth[k] + noise2[k], 50.0 + C2 * x, 50.0 + C2 * x])
        x = a * x + (1.0 - a) * p
    return rows


@pytest.mark.parametrize("kind", ["white", "correlated"])
def test_lack_of_fit_is_quiet_when_the_twin_is_right_and_flags_a_missing_effect(kind: str) -> None:
    """Twin right: the untracked tag's error is its noise (white, or correlated over a minute) and the
    loop's jitter: the flag is raised in under 1 % of the rows. A missing effect of 0.4 K on the tracked
    tag (20 units of the parameter, several band half-widths): the band misses the truth, and the untracked
    tag, off by C2 · 20 = 0.2 K against its 0.05 K noise, raises the flag in nearly every row."""
    n = 20000
    rng = np.random.default_rng(12)
    w = rng.normal(size=n)
    n2 = 0.05 * (w if kind == "white" else np.convolve(w, np.ones(6) / math.sqrt(6), mode="same"))
    truth = np.full(n, P_TRUE)
    columns = [*COLUMNS, "measured:TO", "tracked:TO", "untracked:TO"]
    after = 4 * 3600.0
    t = np.arange(n) * TS
    for missing in (0.0, 0.4):
        rows = _closed_loop_two_tags(0.05 * rng.normal(size=n), n2, truth, missing)
        bands = BandTracker(_spec(), columns)
        assert bands.columns == ["parameter_lo:k", "parameter_hi:k", "lack_of_fit"] and bands.fit_tags == ["TO"]
        out = np.array([bands.row(r) for r in rows])
        sel = (t >= after) & np.isfinite(out[:, 0])
        assert np.all(np.isfinite(out[sel, 2]))
        flagged = float(np.mean(out[sel, 2] >= 1.0))
        inside = float(np.mean(((out[:, 0] <= truth) & (truth <= out[:, 1]))[sel]))
        summary = bands.describe()["lack_of_fit"]
        if missing == 0.0:
            assert flagged < 0.01 and inside >= 0.9, (flagged, inside)
        else:
            assert inside < 0.5 and flagged > 0.95, (flagged, inside)
            assert summary["flagged_by"] == {"TO": summary["rows_flagged"]}


def test_lack_of_fit_state_round_trip_gives_the_same_rows() -> None:
    n = 2000
    rng = np.random.default_rng(13)
    rows = _closed_loop_two_tags(0.05 * rng.normal(size=n), 0.05 * rng.normal(size=n), np.full(n, P_TRUE), 0.4)
    columns = [*COLUMNS, "measured:TO", "tracked:TO", "untracked:TO"]
    expected, got, whole, second = _whole_and_resumed(columns, rows, 1500)
    assert np.array_equal(np.array(got), np.array(expected), equal_nan=True)
    assert second.describe()["lack_of_fit"] == whole.describe()["lack_of_fit"]


def test_a_checkpoint_from_before_the_lack_of_fit_column_is_refused() -> None:
    """Its CSV has no lack_of_fit column: resuming would append rows one column longer than its header."""
    from trackingbox.errors import CheckpointError

    columns = [*COLUMNS, "measured:TO", "tracked:TO", "untracked:TO"]
    old = BandTracker(_spec(), columns).state_dict()
    del old["fit"], old["fit_rows"], old["fit_worst"]
    with pytest.raises(CheckpointError, match="lack_of_fit"):
        BandTracker(_spec(), columns).load_state_dict(old)
    BandTracker(_spec(), COLUMNS).load_state_dict(old)  # no untracked tag: no such column, resumes



@pytest.mark.parametrize("loops", [1, 2])
def test_slow_part_weights_match_a_monte_carlo_of_the_loops(loops: int) -> None:
    """Tag errors whose covariance at lag l is C (1 - |l|/N) (moving means over N samples of white noise,
    correlated across the tags) driven through PI loops simulated here by hand (first-order tags, every tag
    following both parameters through G): the parameters' variance is sum_kq C[k, q] w[j, k, q]."""
    from trackingbox.identify.bands import batch_weights, loops_impulse

    ts, batch = 10.0, 40
    if loops == 1:
        g = np.array([[-0.02]])
        spec = [(-0.02, 120.0, 1.0 / (0.02 * 3.0), 120.0)]
    else:
        g = np.array([[-0.02, 0.01], [0.004, 0.05]])
        spec = [(-0.02, 120.0, 1.0 / (0.02 * 3.0), 120.0), (0.05, 300.0, 1.0 / (0.05 * 2.0), 300.0)]
    m = len(spec)
    w = batch_weights(loops_impulse(g, spec, ts), batch)
    rng = np.random.default_rng(31)
    n = 300000
    mix = np.array([[1.0, 0.0], [0.6, 0.8]])[:m, :m]  # tag 2 shares 0.6 of tag 1's white source
    white = rng.normal(size=(n + batch, m)) @ mix.T
    noise = (np.cumsum(white, axis=0)[batch:] - np.cumsum(white, axis=0)[:-batch]) / batch
    cov = mix @ mix.T / batch
    sign = np.array([1.0 if lp[0] > 0 else -1.0 for lp in spec])
    a = np.array([math.exp(-ts / lp[1]) for lp in spec])
    kc = np.array([lp[2] for lp in spec])
    ti = np.array([lp[3] for lp in spec])
    z, p, e_prev = np.zeros(m), np.zeros(m), np.zeros(m)
    out = np.empty((n, m))
    for k in range(n):
        e = noise[k] - z
        p = p + sign * kc * ((e - e_prev) + ts * (e + e_prev) / (2.0 * ti))
        e_prev = e
        out[k] = p
        z = a * z + (1.0 - a) * (g @ p)
    measured = out[5000:].var(axis=0)
    expected = np.einsum("kq,jkq->j", cov, w)
    assert np.all(np.abs(measured / expected - 1.0) < 0.1), (measured, expected)


def test_batch_weights_of_a_short_response_and_by_their_definition() -> None:
    from trackingbox.identify.bands import batch_weights

    rng = np.random.default_rng(5)
    h, n = rng.normal(size=(30, 2, 2)), 7
    brute = np.zeros((2, 2, 2))
    for lag in range(-n + 1, n):
        for t in range(30):
            if 0 <= t + lag < 30:
                brute += (1 - abs(lag) / n) * np.einsum("jk,jq->jkq", h[t], h[t + lag])
    assert np.allclose(batch_weights(h, n), brute, rtol=1e-12, atol=1e-12)


def _ar1(n: int, rho: float, sd: float, rng: np.random.Generator) -> np.ndarray:
    """A stationary AR(1) series of standard deviation *sd* and lag-one correlation *rho*."""
    w = rng.normal(size=n) * sd * math.sqrt(1.0 - rho * rho)
    out = np.empty(n)
    out[0] = rng.normal() * sd
    for k in range(1, n):
        out[k] = rho * out[k - 1] + w[k]
    return out



SLOW_TAU = 1200.0  # the same loop ten times slower: lag about an hour, beyond the fast error's 30 min window


@pytest.mark.parametrize("correlation", [0.0, 1800.0])
def test_slow_part_on_white_noise_and_on_an_analyser_error_wandering_at_the_loops_time_scale(
        correlation: float, monkeypatch: pytest.MonkeyPatch) -> None:
    """The runtime's loop with a lag of about an hour, counted here. White noise (0.05 K): its batch means are
    what its fast level predicts, and the band is the noise part alone, z sigma sqrt(sum h^2) worked from the
    loop's impulse response, within 5 %. Plus an AR(1) analyser error of the same size with a 30 min
    correlation time (slower than the fast error's window, as fast as the loop): the band without the slow part
    holds the constant truth in about 71 % of the rows (seed 21), with it in more than 80 %, and it is wider by
    less than the realised spread asks (half-width / z at most the parameter's spread about the truth)."""
    from trackingbox.identify import bands as bands_module

    n = 60000
    rng = np.random.default_rng(21)
    noise = 0.05 * rng.normal(size=n)
    if correlation:
        noise = noise + _ar1(n, math.exp(-TS / correlation), 0.05, rng)
    truth = np.full(n, P_TRUE)
    rows = _closed_loop(noise, truth, tau=SLOW_TAU)
    after = 24 * 3600.0
    share, out = _coverage(rows, truth, after=after, tau=SLOW_TAU)
    late = np.array([r[0] for r in rows]) >= after
    half = float(np.median((out[late, 1] - out[late, 0]) / 2.0))
    z = 1.959963984540054
    if not correlation:
        s = pair_settings(_spec(tau=SLOW_TAU).pairs[0], P_MIN, P_MAX, ts=TS)
        model = loop_model(GAIN, SLOW_TAU, s.kp * (P_MAX - P_MIN) / s.scaling.span, s.ti, TS)
        expected = z * 0.05 * math.sqrt(float(model.acf[0]))
        assert abs(half / expected - 1.0) < 0.05, (half, expected)
        return
    spread = float(np.sqrt(np.mean((np.array([r[4] for r in rows])[late] - P_TRUE) ** 2)))
    monkeypatch.setattr(bands_module, "SLOW_MIN", 10 ** 9)  # the slow part never given
    without, narrow = _coverage(rows, truth, after=after, tau=SLOW_TAU)
    assert without < 0.75 and share > 0.80, (without, share)
    assert float(np.median((narrow[late, 1] - narrow[late, 0]) / 2.0)) < half <= z * spread


def test_slow_part_is_not_given_to_a_loop_faster_than_the_fast_errors_window() -> None:
    """A 6 min loop: its own time scale lies inside the fast error's 30 min window, which the noise part
    already measures; the slow part adds nothing however the batch means look."""
    n = 6000
    rng = np.random.default_rng(23)
    rows = _closed_loop(0.05 * rng.normal(size=n) + _ar1(n, math.exp(-TS / 1800.0), 0.05, rng), np.full(n, P_TRUE))
    bands = BandTracker(_spec(), COLUMNS)
    for r in rows:
        bands.row(r)
    assert bands.slow["batches"] >= 3 and bands.batch * TS < 1800.0
    parts = [bands._update(bands.pairs[0], bands.states[0], 0.0, 0.0, float(rows[-1][4]), False)]
    assert bands._slow_var(parts) is None


def test_a_checkpoint_from_before_the_slow_part_is_refused() -> None:
    from trackingbox.errors import CheckpointError

    old = BandTracker(_spec(), COLUMNS).state_dict()
    del old["slow"]
    with pytest.raises(CheckpointError, match="slow part"):
        BandTracker(_spec(), COLUMNS).load_state_dict(old)


def test_lag_part_rate_is_exact_on_a_ramp_through_holds_and_a_short_history() -> None:
    """The lag part's rate (part 3) from two exponential means with their rows' mean times: a tracked value
    that is an exact ramp (frozen while the loop holds, the clock running on) gives exactly its slope from the
    second auto row on, long before the means' day-long memory has filled."""
    rate = -2.5e-3  # parameter units per s
    bands = BandTracker(_spec(tau=SLOW_TAU), COLUMNS)
    slopes = []
    for k in range(400):
        hold = 100 <= k < 160
        p = P0 + rate * TS * k
        bands.row([k * TS, 300.0, 300.0, 300.0, p if not hold else P0 + rate * TS * 99, "hold" if hold else "auto"])
        slopes.append(bands.states[0].slope)
    assert np.allclose(np.array(slopes[1:100] + slopes[161:]), rate, rtol=1e-9, atol=0.0)


def test_lag_part_rate_follows_the_truth_not_the_wander_an_own_tag_error_gives_the_parameter(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The runtime's loop with a lag of about an hour tracking a truth that falls 100 units over the run, its tag
    read with an AR(1) error of 6 h correlation time (sd 0.05 K): the loop turns it into a wander of the
    parameter (sd about 2.5 units) whose slope over the loop's own lag is comparable with the truth's. Counted
    against the truth's known rate after a day: the lag part's rate over a day has a median within 10 % of it
    and is under half of it in under 2 % of the rows; taken over the loop's lag time (the rate before), it is
    under half of it in more than a fifth of the rows (33 % here; 25-37 % on seeds 31-33), where the band's
    lag part drops the truth's motion (what the evaporator's outletValve.KvMax missed, through the fouling's)."""
    from trackingbox.identify import bands as bands_module

    n = 60000
    rng = np.random.default_rng(32)
    rate = -100.0 / (n * TS)
    truth = P_TRUE + rate * TS * np.arange(n)
    noise = 0.05 * rng.normal(size=n) + _ar1(n, math.exp(-TS / 21600.0), 0.05, rng)
    rows = _closed_loop(noise, truth, tau=SLOW_TAU)
    late = np.array([r[0] for r in rows]) >= 24 * 3600.0

    def rates() -> np.ndarray:
        bands = BandTracker(_spec(tau=SLOW_TAU), COLUMNS)
        out = []
        for r in rows:
            bands.row(r)
            out.append(bands.states[0].slope)
        return np.array(out)[late] / rate

    day = rates()
    assert abs(float(np.median(day)) - 1.0) < 0.10 and float(np.mean(day < 0.5)) < 0.02, \
        (float(np.median(day)), float(np.mean(day < 0.5)))
    monkeypatch.setattr(bands_module, "RATE_MEMORY", 0.0)  # the memory falls back to the loop's lag time
    short = rates()
    assert float(np.mean(short < 0.5)) > 0.20, float(np.mean(short < 0.5))


def test_a_checkpoint_from_before_the_day_long_rate_is_refused() -> None:
    from trackingbox.errors import CheckpointError

    old = BandTracker(_spec(), COLUMNS).state_dict()
    for s in old["pairs"]:
        del s["rate"]
    with pytest.raises(CheckpointError, match="day-long rate"):
        BandTracker(_spec(), COLUMNS).load_state_dict(old)


# --------------------------------------------------------------------------- model error (identify.misfit)


def test_closed_gains_and_implied_values_on_a_linear_twin_worked_by_hand() -> None:
    """Two loops on a linear twin, ``G_tt = [[2, 1], [1, 4]]``, one untracked tag ``u = θ1 + 2 θ2``. The plant
    reads 1.4 more than the twin at the truth on pair 1's tag only. The loops settle at ``θ - θ* = G⁻¹ [1.4, 0]
    = [4·1.4, -1.4] / 7 = [0.8, -0.2]``, and tag u is left with ``-(0.8 - 0.4) = -0.4``. With pair 2's loop
    keeping its tag, moving θ1 by 1 moves θ2 by -1/4 and u by 1 - 2/4 = 0.5: u implies θ1 - 0.8, the truth."""
    from trackingbox.identify.misfit import closed_gains, follows, implied_sides

    g = closed_gains(np.array([[2.0, 1.0], [1.0, 4.0]]), np.array([[1.0, 2.0]]))
    assert g == pytest.approx(np.array([[0.5, 2.0 - 1.0 / 2.0]]))
    sides = implied_sides([-0.4], [True], g, [10.0, 10.0])
    assert sides[0] == pytest.approx((0.8, 0.0))            # θ1*: 0.8 below the tracked value
    # for θ2 u reads -0.4 / 1.5 (0.267 below) where the truth is 0.2 above: a tag reads a pair's truth only when
    # the error sits on that pair's own tag (identify.misfit)
    assert sides[1] == pytest.approx((0.4 / 1.5, 0.0))
    # θ1's reading carried: θ2 follows θ1 by -1/4 while pair 2 keeps its tag, so u's reading of θ1 (0.8 below) puts
    # θ2's truth 0.2 above its tracked value, where it is; θ2's reading (0.267 below) carried to θ1 by -1/2 is 0.133
    # above, and θ1's own side below stays 0.8
    v = follows(np.array([[2.0, 1.0], [1.0, 4.0]]))
    assert v == pytest.approx(np.array([[1.0, -0.5], [-0.25, 1.0]]))
    carried = implied_sides([-0.4], [True], g, [10.0, 10.0], carry=v)
    assert carried[0] == pytest.approx((0.8, 0.4 / 1.5 / 2.0))
    assert carried[1] == pytest.approx((0.4 / 1.5, 0.2))
    # a carried value beyond the other pair's range is left out (θ2's range 0.1: θ1's reading puts it 0.2 off)
    assert implied_sides([-0.4], [True], g, [10.0, 0.1], carry=v)[1] == (0.0, 0.0)
    # the identity carries nothing: each pair its own readings, as without it
    assert implied_sides([-0.4], [True], g, [10.0, 10.0], carry=np.eye(2)) == sides
    assert implied_sides([-0.4], [False], g, [10.0, 10.0]) == [(0.0, 0.0), (0.0, 0.0)]  # not flagged: nothing
    assert implied_sides([-0.4], [True], g, [0.5, 0.5])[0] == (0.0, 0.0)   # beyond the bounds' range: not θ1's
    # two tags disagreeing in sign widen both sides, each by its own reading
    assert implied_sides([-0.4, 0.3], [True, True], np.array([[0.5], [0.1]]), [10.0]) == \
        [pytest.approx((0.8, 3.0))]
    with pytest.raises(ValueError, match="one column per pair"):
        closed_gains(np.eye(2), np.ones((1, 3)))


def test_model_error_part_widens_the_band_by_what_the_untracked_tag_implies() -> None:
    """The lack-of-fit case: the plant's TI carries 0.4 K the twin lacks, so the loop settles 0.4 / GAIN = -20
    units from the truth; TO = 50 + C2·k reads C2·20 = 0.2 K above the twin, which implies the truth 20 above
    the tracked value. With TO's gain, the band holds the truth in most rows after 4 h (it did in under half
    without); with the twin right (no missing effect) the band is as before in at least 95 % of the rows."""
    n = 20000
    rng = np.random.default_rng(14)
    truth = np.full(n, P_TRUE)
    columns = [*COLUMNS, "measured:TO", "tracked:TO", "untracked:TO"]
    t = np.arange(n) * TS
    for missing in (0.0, 0.4):
        rows = _closed_loop_two_tags(0.05 * rng.normal(size=n), 0.05 * rng.normal(size=n), truth, missing)
        base = BandTracker(_spec(), columns)
        wide = BandTracker(_spec(), columns, misfit={"TO": [C2]})
        a = np.array([base.row(r) for r in rows])
        b = np.array([wide.row(r) for r in rows])
        sel = (t >= 4 * 3600.0) & np.isfinite(a[:, 0])
        inside = ((b[:, 0] <= truth) & (truth <= b[:, 1]))[sel]
        same = np.isclose(a[sel, 0], b[sel, 0]) & np.isclose(a[sel, 1], b[sel, 1])
        widened = wide.describe()["k"]["model_error"]
        assert widened["closed_gains"] == {"TO": C2}
        if missing == 0.0:  # a 2 h mean beyond chance now and then (the test's false alarms): a little wider
            assert float(np.mean(same)) >= 0.95, float(np.mean(same))
            # (the trend reading's false alarms add a few rows: the median width within 0.01 %)
            assert float(np.median(b[sel, 1] - b[sel, 0])) == pytest.approx(float(np.median(a[sel, 1] - a[sel, 0])),
                                                                             rel=1e-4)
        else:
            assert float(np.mean(inside)) >= 0.9, float(np.mean(inside))
            # the upper side moved by about 20 (and the mean's own margin, 1.96 · 0.0013 / C2), the lower not at all
            assert np.median((b[sel, 1] - a[sel, 1])) == pytest.approx(20.0, rel=0.1)
            assert np.array_equal(a[sel, 0], b[sel, 0])
            assert widened["rows_widened"] > 0.95 * sel.sum()


def test_trend_weights_are_exact_on_a_ramp_and_their_noise_matches_two_exponential_means() -> None:
    """Against the two means computed row by row here: their line read at the newest row equals a ramp's newest
    value (no lag, at any fill), and its variance on white noise (a Monte Carlo of 4000 histories) is the
    weights' ``v``; once full, ``a = 2`` (``2 m_W/2 - m_W``), the noise about 1.9 times the mean's."""
    from trackingbox.identify.misfit import trend_weights

    ls, ll = math.exp(-1.0 / 36.0), math.exp(-1.0 / 72.0)

    def means(e: np.ndarray, lam: float) -> np.ndarray:  # over the last axis, filled from zero, as BandTracker
        m = w = 0.0
        for x in np.moveaxis(e, -1, 0):
            m, w = lam * m + (1.0 - lam) * x, lam * w + (1.0 - lam)
        return m / w

    for n in (2, 30, 72, 400):
        a, v = trend_weights(ls, ll, n)
        ramp = 3.0 + 0.25 * np.arange(n)
        assert a * means(ramp, ls) + (1.0 - a) * means(ramp, ll) == pytest.approx(ramp[-1], abs=1e-9)
        noise = np.random.default_rng(n).normal(size=(4000, n))
        now = a * means(noise, ls) + (1.0 - a) * means(noise, ll)
        assert float(np.var(now)) == pytest.approx(v, rel=0.1)
    a, v = trend_weights(ls, ll, 5000)
    assert a == pytest.approx(2.0, rel=0.01)  # ages 71.5 and 35.5 rows: 71.5 / 36
    assert math.sqrt(v / ((1.0 - ll) / (1.0 + ll))) == pytest.approx(1.9, rel=0.03)
    assert all(math.isnan(x) for x in trend_weights(ls, ll, 1))


def test_model_error_part_follows_a_growing_error_with_its_trend(monkeypatch: pytest.MonkeyPatch) -> None:
    """The plant's TI drifts 0.05 K/h from 4 h on (a sensor drift the twin lacks): the loop follows it, 2.5 units of
    the parameter per hour from the truth, and TO reads the offset C2 times. Its 2 h mean lags about 2 h (5 units,
    the band's half-width about 1.75): with the trend the band holds the truth in most rows from 8 h on; with the
    trend reading switched off (its weights NaN) in under half of them."""
    from trackingbox.identify import misfit

    n = 9000
    t = np.arange(n) * TS
    truth = np.full(n, P_TRUE)
    missing = 0.05 * np.clip(t - 4 * 3600.0, 0.0, None) / 3600.0
    rng = np.random.default_rng(21)
    rows = _closed_loop_two_tags(0.05 * rng.normal(size=n), 0.05 * rng.normal(size=n), truth, missing)
    columns = [*COLUMNS, "measured:TO", "tracked:TO", "untracked:TO"]
    sel = t >= 8 * 3600.0

    def inside() -> float:
        bands = BandTracker(_spec(), columns, misfit={"TO": [C2]})
        out = np.array([bands.row(r) for r in rows])
        return float(np.mean(((out[:, 0] <= truth) & (truth <= out[:, 1]))[sel]))

    with_trend = inside()
    monkeypatch.setattr(misfit, "trend_weights", lambda *args: (math.nan, math.nan))
    without = inside()
    assert with_trend >= 0.9 and without < 0.5, (with_trend, without)



def test_a_checkpoint_from_before_the_trend_reading_is_refused() -> None:
    """An untracked tag's state with rows seen and no half-memory mean was written before the trend: resuming it
    would put a fresh short mean beside a long one filled for hours (the reading assumes both over the same rows)."""
    from trackingbox.errors import CheckpointError

    columns = [*COLUMNS, "measured:TO", "tracked:TO", "untracked:TO"]
    rng = np.random.default_rng(3)
    rows = _closed_loop_two_tags(0.05 * rng.normal(size=50), 0.05 * rng.normal(size=50), np.full(50, P_TRUE), 0.0)
    bands = BandTracker(_spec(), columns, misfit={"TO": [C2]})
    for r in rows:
        bands.row(r)
    state = bands.state_dict()
    BandTracker(_spec(), columns, misfit={"TO": [C2]}).load_state_dict(state)  # its own: accepted
    for s in state["fit"]:
        s["rate"] = [0.0] * len(s["rate"])
    with pytest.raises(CheckpointError, match="trend"):
        BandTracker(_spec(), columns, misfit={"TO": [C2]}).load_state_dict(state)
