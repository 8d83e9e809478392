"""The pairing stage: step tests on the twin, relative gain array, data checks, chosen pairs.

:func:`pair` is what ``trackingbox pair`` and the demo call, and what a notebook
calls::

    from trackingbox import PairSettings, load_spec, pair
    result = pair(load_spec("case1/spec.toml"), PairSettings(freeze=(("holdControllers", 1.0),)))
    result = pair(load_spec("case2/spec.toml"))   # the spec's [pairing] freeze
    result.pairing.pairs            # the chosen (variable, parameter) pairs
    result.to_json()                # the ``pair --json`` document

This module chains :mod:`~trackingbox.analysis.steptest`,
:mod:`~trackingbox.analysis.pairing`, :mod:`~trackingbox.analysis.offsets` and
:mod:`~trackingbox.analysis.sobol`.

The procedure (the options are :class:`PairSettings` fields, named as
the command's): the twin's inputs are held at an operating point (mean of the first
hour of the training window, or --at TIME); the twin runs with its controllers
active until it settles; the --freeze values (else the spec's [pairing]
freeze) are set (e.g. holdControllers=1 freezes every controller,
holdLevelControllers=1 only some, so that a loop left active shows a parameter
error in its controller's output) and it settles again; then each [[parameters]] entry is stepped by +/- --step of
its bound range and the new steady state of every [outputs] tag is recorded.
Tank levels listed in [[states]] are held by proportional state compensation
from the freeze on (they are not tracking variables).
Settled = over --window seconds no output moved more than --tolerance x its
measured range (the 0.5-99.5 % quantile span of its scored samples in the
training window: stoppages and gaps left out); responses are measured against an unstepped reference run, so
a slow residual drift is not taken for a gain. Gains g_ij = dy_i/dp_j, scaled
by measured ranges and parameter bound ranges, give the relative gain array
(after leaving out parameters that cannot be told apart, see --rank-tol); each
tag gets the unused parameter with a positive relative gain closest to 1. The
spec's [pairing] scale gives a tag's scale instead of its measured range (e.g.
its sensor accuracy: with more tags than parameters the RGA, and so which tag a
parameter pairs with, depends on the scaling).

Data checks (off with --no-data-checks): before the assignment the twin runs
untracked over the training window with the measured inputs (parameters at
their starts, [[states]] compensation on, the first [tracking] hold_until
seconds left out) and is compared with the measurements. A tag whose untracked
RMS error is below --noise-ratio x its sensor noise (robust std of first
differences / sqrt 2) has nothing to track and is left out. A pair is allowed
only if the parameter's remaining range toward the measurement moves the tag
by at least --min-reach x its mean offset. The chosen set is then simulated as
first-order loops with the parameters clipped to their bounds; while a pair
would leave more than --max-ratio of its tag's untracked RMS error, the worst
one is forbidden and the assignment redone. Reasons go to the left-out list.
Which gains judge the data checks (--check-gains, default recording): the
data were recorded with the plant's controllers active, so an offset a
parameter has to close shows where the controlled loops put it (e.g. on a
pump's speed when a temperature loop holds its measurement) and with the
closed-loop gain. With a freeze, the step tests are therefore run a second time
at the same operating point with nothing frozen (the twin as the data were
recorded); the RGA keeps the frozen gains (the structure of the pairing, the
source's method), while the reach and predicted-tracking checks use the
recorded-way gains and time constants. Tags no parameter moves with the
freeze (a controller's output: pump speed, heating-medium temperature) are
paired from the RGA of the recorded-way gains over them and the tags the frozen
structure paired, keeping the frozen pairs, and all pairs are predicted
together (:func:`~trackingbox.analysis.pairing.complete_with_recording`; each
pair says which RGA chose it). A pair whose two gains differ in sign
is not chosen, and a pair's written gain is the largest in magnitude of all
the step tests (the tracking loop runs on the twin as recorded). With
--check-gains structure, or without a freeze, the checks use the frozen gains.
With --second-point (default auto) the step tests are repeated at the hour of
the training window whose mean inputs differ most from the first point (means
over the running samples: stoppages, their settle time and input gaps are not
an operating point, :func:`running_inputs`): a pair
whose gain changes sign between the points is not chosen, and each pair is
written with the larger of its two gains (and that point's time constant), so
the loop, tuned for the highest gain seen, stays stable where the gain grows.
:func:`spec_pairs` turns the chosen pairs (gain, 63 % time constant) into
``[[pairs]]`` entries; an existing pair keeps its tuning settings (lambda, kp,
ti, controller; a new pair gets lambda = 1; the relative gain is reported, not
written).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..data import MeasurementView
from ..errors import AnalysisError, SpecError
from ..spec import PairSpec
from .blocks import output_unit, parameter_unit
from .executor import make_executor
from ..identify.hooks import explain, indistinct_candidates, without_candidates
from .offsets import simulate_untracked
from .pairing import DataChecks, Pair, choose_pairs, complete_with_recording
from .rga import parameter_ranges, variable_ranges
from .sobol import agreement, sobol_indices
from .steptest import (
    StepSettings,
    farthest_operating_point,
    make_problem,
    operating_point,
    step_tests,
)

if TYPE_CHECKING:
    from concurrent.futures import Executor

    from ..spec import Spec
    from .pairing import Pairing
    from .sobol import Agreement, SobolResult
    from .steptest import StepTestResult

log = logging.getLogger(__name__)

__all__ = ["PairSettings", "PairingResult", "explain_left_out", "pair", "spec_pairs"]

#: ``progress(stage, done, total)``: stage ``"step runs"``, ``"step runs (2nd point)"``,
#: ``"step runs (as recorded)"`` or ``"Sobol runs"``.
StageProgress = Callable[[str, int, int], None]

Method = Literal["rga", "sobol", "both"]

CheckGains = Literal["recording", "structure"]

#: Fraction of the scored training samples left out at each end of a tag's range (the scale of its
#: gains): the restart transients after a stoppage do not set it.
RANGE_TRIM = 0.005


@dataclass(frozen=True)
class PairSettings:
    """Settings of :func:`pair` (the ``trackingbox pair`` options, same names and defaults).

    Attributes
    ----------
    method
        ``"rga"``: pairs from the relative gain array; ``"sobol"``: from Sobol total
        indices; ``"both"``: RGA pairs plus Sobol indices and their agreement.
    step, two_sided
        Parameter step as a fraction of its bound range; also step down (linearity check).
    freeze
        ``(name, value)`` set after the first settle to freeze the twin's controllers
        (all or some of them: a loop left active shows a parameter error in its
        controller's output); ``None``: the spec's ``[pairing] freeze``.
    at
        Operating point time (s from the first sample); ``None``: mean of the
        first hour of the training window.
    interval, window
        Communication step (default ``sample_time``) and settle window (default 60 intervals), s.
    tolerance, baseline_tolerance, max_time
        Settle rule of the step phase and the phases before it; longest settle (s).
    rank_tol
        Relative singular-value threshold for parameters that cannot be told apart
        (``None``: :func:`~trackingbox.analysis.pairing.choose_pairs`' default).
    second_point
        ``"auto"``, ``"none"`` or a time (s): the second operating point of the step tests.
    data_checks, noise_ratio, min_reach, max_ratio, max_leak, max_jitter
        The untracked-run checks of :class:`~trackingbox.analysis.pairing.DataChecks` (*max_leak*: the
        separation of a paired parameter from the candidates left unpaired; ``None``: the spec's
        ``[pairing] max_leak``, absent: no separation check; *max_jitter*: the noise a pair's loop may
        put into its parameter, a fraction of its bound range; ``None``: the spec's ``[pairing]
        max_jitter``, absent: no such limit).
    check_gains
        Gains the data checks judge with: ``"recording"`` (default): with a freeze,
        from a second step-test set with nothing frozen (the twin run as the
        data were recorded, controllers active); ``"structure"``: the frozen
        step tests' gains (the RGA's).
    closed_loop
        Shortest closed-loop time constant (s) of the predicted loops, and of the new
        pairs' tuning (:class:`~trackingbox.analysis.pairing.DataChecks`); ``None``: the
        spec's ``[pairing] closed_loop`` (absent: the step-response time constants).
    closed_loop_min
        Loop speed per pair: the fastest loop (s) a pair whose prediction fails with
        *closed_loop* may get instead (``DataChecks.closed_loop_min``); ``None``: the spec's
        ``[pairing] closed_loop_min`` (absent: every loop at *closed_loop*); 0: off.
    samples, seed
        Sobol base sample size and seed.
    workers, scheduler
        Local worker processes (``None``: all cores), or a Dask cluster: ``"local"``
        (*workers* processes on 127.0.0.1) or a scheduler address ``tcp://host:8786``
        (:func:`~trackingbox.analysis.executor.make_executor`).
    identify
        With the data checks: leave out candidates whose effect on the tags the data cannot
        tell apart from another's (the twin's output sensitivities over the training window,
        as the data were recorded: :func:`trackingbox.identify.analysis.leave_out`), before the
        assignment, with that reason (``pair --no-identify``: off).
    """

    method: Method = "rga"
    step: float = 0.05
    two_sided: bool = True
    freeze: tuple[tuple[str, float], ...] | None = None
    at: float | None = None
    interval: float | None = None
    window: float | None = None
    tolerance: float = 1e-4
    baseline_tolerance: float = 1e-3
    max_time: float = 86400.0
    rank_tol: float | None = None
    second_point: str | float = "auto"
    data_checks: bool = True
    noise_ratio: float = 5.0
    min_reach: float = 0.5
    max_ratio: float = 0.25
    max_leak: float | None = None
    max_jitter: float | None = None
    check_gains: CheckGains = "recording"
    closed_loop: float | None = None
    closed_loop_min: float | None = None
    samples: int = 32
    seed: int = 0
    workers: int | None = None
    scheduler: str | None = None
    identify: bool = True


@dataclass(frozen=True)
class PairingResult:
    """What :func:`pair` found.

    Attributes
    ----------
    pairing
        The chosen pairs, RGA, scaled gains, data checks (:class:`~trackingbox.analysis.pairing.Pairing`).
    steptest, steptest_second
        Step tests at the operating point and at the second one (``None`` if skipped).
    sobol, agreement
        Sobol indices and their agreement with the RGA (``None`` unless asked for).
    step_settings
        The step-test settings used (interval, window, freeze).
    operating_point
        Twin input -> value the inputs were held at.
    second_point
        ``(time, {input: value})`` of the second operating point, or ``None``.
    warnings
        Pairing warnings and nonlinear step responses.
    """

    pairing: Pairing
    steptest: StepTestResult
    step_settings: StepSettings
    operating_point: dict[str, float]
    warnings: tuple[str, ...] = ()
    steptest_second: StepTestResult | None = None
    second_point: tuple[float, dict[str, float]] | None = None
    sobol: SobolResult | None = None
    agreement: Agreement | None = None
    settings: PairSettings = field(default_factory=PairSettings)
    steptest_recording: StepTestResult | None = None

    @property
    def check_rule(self) -> str:
        """Which gains judged the data checks (reach, predicted tracking), in words."""
        if self.pairing.checks is None:
            return "no data checks"
        frozen = ", ".join(f"{n} = {v:g}" for n, v in self.step_settings.freeze)
        if self.steptest_recording is not None:
            return (f"RGA from the step tests with the controllers frozen ({frozen}); reach and predicted "
                    "tracking judged with the gains of step tests with nothing frozen (the twin run as the "
                    "data were recorded)")
        if frozen:
            return f"RGA, reach and predicted tracking all from the step tests with {frozen}"
        return "RGA, reach and predicted tracking all from the step tests with nothing frozen"

    @property
    def runs(self) -> int:
        """Twin simulations run (step tests at both points and as recorded, Sobol with its base run)."""
        n = self.steptest.runs + (0 if self.steptest_second is None else self.steptest_second.runs)
        n += 0 if self.steptest_recording is None else self.steptest_recording.runs
        return n + (0 if self.sobol is None else self.sobol.runs + 1)

    def to_json(self) -> dict[str, Any]:
        """The ``trackingbox pair --json`` document (NaN as ``null``)."""
        st, pairing, sob, agr = self.steptest, self.pairing, self.sobol, self.agreement
        doc: dict[str, Any] = {
            "pairs": [{"variable": p.variable, "parameter": p.parameter, "lambda": _finite(p.lambda_),
                       "gain": _finite(p.gain), "time_constant": _finite(p.time_constant),
                       "predicted_ratio": _finite(p.predicted_ratio), "at_bound": _finite(p.at_bound),
                       "closed_loop": _finite(p.closed_loop), "rga_from": p.rga_from}
                      for p in pairing.pairs],
            "gain_matrix": _matrix(st.variables, st.parameters, st.gains),
            "rga": _matrix(st.variables, st.parameters, pairing.rga),
            "condition_number": _finite(pairing.condition_number),
            "left_out": [{"name": n, "kind": "parameter" if n in st.parameters else "variable", "reason": r}
                         for n, r in pairing.left_out],
            "warnings": list(self.warnings),
            "asymmetry": _matrix(st.variables, st.parameters, st.asymmetry),
            "time_constants": _matrix(st.variables, st.parameters, st.time_constants),
            "operating_point": dict(self.operating_point),
            "step_time": st.step_time,
            "runs": self.runs,
            "sobol": None,
            "agreement": None,
            "pairs_condition_number": _finite(pairing.pairs_condition_number),
            "data_checks": None if pairing.checks is None else {
                "noise_ratio": pairing.checks.noise_ratio, "min_reach": pairing.checks.min_reach,
                "max_ratio": pairing.checks.max_ratio, "closed_loop": pairing.checks.closed_loop or None,
                "closed_loop_min": pairing.checks.closed_loop_min or None,
                "max_leak": _finite(pairing.checks.max_leak),
                "max_jitter": _finite(pairing.checks.max_jitter)},
            "check_gains": None if pairing.checks is None else {
                "source": "recording" if self.steptest_recording is not None else "structure",
                "rule": self.check_rule,
                "freeze": {n: v for n, v in self.step_settings.freeze},
                "recording_freeze": {} if self.steptest_recording is not None else
                {n: v for n, v in self.step_settings.freeze}},
            "gain_matrix_recording": None if self.steptest_recording is None else
            _matrix(st.variables, st.parameters, self.steptest_recording.gains),
            "offsets": [{"variable": o.variable, "noise": _finite(o.noise), "mean": _finite(o.mean),
                         "rms": _finite(o.rms), "noise_ratio": _finite(o.noise_ratio), "samples": o.samples}
                        for o in pairing.offsets],
            "rejected_pairs": [{"variable": v, "parameter": p, "reason": r} for v, p, r in pairing.rejected],
            "unit_block": None if pairing.block is None else {
                "variables": [st.variables[i] for i in pairing.block.tags],
                "parameters": [st.parameters[j] for j in pairing.block.parameters],
                "rga": [[_finite(x) for x in row] for row in pairing.block.rga.tolist()],
                "rga_number": _finite(pairing.block.number),
                "left_unpaired": [{"parameter": st.parameters[j], "best_lambda": _finite(lam)}
                                  for j, lam in pairing.block.dropped]},
            "second_operating_point": None if self.second_point is None else
            {"time": self.second_point[0], "inputs": dict(self.second_point[1])},
            "gain_matrix_second": None if self.steptest_second is None else
            _matrix(st.variables, st.parameters, self.steptest_second.gains),
        }
        if sob is not None:
            doc["sobol"] = {"first": _matrix(sob.variables, sob.parameters, sob.first),
                            "total": _matrix(sob.variables, sob.parameters, sob.total),
                            "samples": sob.samples, "runs": sob.runs}
        if agr is not None:
            doc["agreement"] = {"index": agr.index, "agree": agr.agree, "compared": agr.compared,
                                "rows": [{"variable": v, "rga": a, "sobol": b, "same": s}
                                         for v, a, b, s in agr.rows]}
        return doc


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _matrix(rows: tuple[str, ...], cols: tuple[str, ...], values: npt.ArrayLike) -> dict[str, Any]:
    return {"variables": list(rows), "parameters": list(cols),
            "values": [[_finite(float(x)) for x in row] for row in np.asarray(values, dtype=float)]}


def _measured(spec: Spec) -> tuple[pd.DataFrame, pd.DataFrame, npt.NDArray[np.bool_], float, float, pd.DataFrame]:
    """The measurements on the spec's grid (:class:`~trackingbox.data.MeasurementView`), the same with the
    output tags NaN where they are not scored (stoppages and their settle time, gaps), the training-window
    mask, the window ``[start, stop)`` (all data when the spec has no training window), and the
    measurements with the inputs NaN where the plant was not running (:func:`running_inputs`)."""
    view = MeasurementView.from_spec(spec, "training" if "training" in spec.windows else "all")
    return (view.to_frame(), view.to_frame(scored=True), view.in_window, float(view.window[0]),
            float(view.window[1]), running_inputs(view, spec))


def running_inputs(view: Any, spec: Spec) -> pd.DataFrame:
    """The view's table with the input tags NaN where the view is stopped (the second operating point's data).

    An operating point is a state the plant runs in: the hours of a flow stoppage (and the
    settle time after it, or an input's communication loss) are not one. Without this the
    second operating point of a case with stoppages is the hour whose mean feed is furthest
    from the first point's, i.e. a stoppage (the evaporator's 3-day case: 0.35 kg/s of a 2 kg/s
    feed), and its gains, measured at a feed the twin never tracks at, veto or re-tune the pairs.

    Examples
    --------
    >>> import types
    >>> from pathlib import Path
    >>> from trackingbox.spec import Spec
    >>> v = types.SimpleNamespace(stopped=np.array([False, True, False]),
    ...     to_frame=lambda: pd.DataFrame({"time": [0.0, 10.0, 20.0], "u": [1.0, 0.1, 1.0], "y": [5.0, 6.0, 7.0]}))
    >>> s = Spec(path=Path("s.toml"), twin=Path("t.fmu"), measurements=Path("m.csv"), sample_time=10.0,
    ...          inputs={"u": "u_in"}, outputs={"y": "y_out"})
    >>> running_inputs(v, s)[["u", "y"]].to_numpy().tolist()
    [[1.0, 5.0], [nan, 6.0], [1.0, 7.0]]
    """
    frame = view.to_frame()
    stopped = np.asarray(view.stopped, dtype=bool)
    if stopped.any():
        for tag in spec.inputs:
            if tag in frame.columns:
                frame.loc[stopped, tag] = np.nan
    return frame


def second_operating_point(choice: str | float, frame: Any, spec: Spec, op: dict[str, float], start: float,
                           stop: float) -> tuple[float, dict[str, float]] | None:
    """The second operating point *choice* asks for (``"auto"``, ``"none"`` or a time in s), or ``None``."""
    text = str(choice).strip().lower()
    if text == "none":
        return None
    if text == "auto":
        return farthest_operating_point(frame, spec.inputs, op, start=start, stop=stop)
    try:
        at = float(text)
    except ValueError:
        raise AnalysisError(f"second operating point {choice!r}: expected auto, none or a time in s") from None
    return at, operating_point(frame, spec.inputs, at=at)


def _counter(progress: StageProgress | None, stage: str) -> Callable[[int, int], None] | None:
    if progress is None:
        return None
    return lambda done, total: progress(stage, done, total)


def pair(spec: Spec, settings: PairSettings | None = None, *,
         progress: StageProgress | None = None, executor: Executor | None = None) -> PairingResult:
    """Choose a tracking parameter for each tracking variable of *spec*.

    Parameters
    ----------
    spec : trackingbox.spec.Spec
        A loaded spec with ``[[parameters]]``; ``[[states]]`` tags are compensated, not paired.
    settings : PairSettings, optional
        Step-test, data-check and assignment settings (defaults: ``PairSettings()``).
    progress : callable, optional
        ``progress(stage, runs_done, runs_total)`` while simulations run.
    executor : concurrent.futures.Executor, optional
        Run the simulations there (e.g. a running Dask cluster's, from
        :func:`~trackingbox.analysis.executor.make_executor`; left running);
        default: one made from ``settings.workers`` and ``settings.scheduler``.

    Returns
    -------
    PairingResult
        Nothing is written: :func:`spec_pairs` gives the ``[[pairs]]`` entries to write.

    Raises
    ------
    SpecError
        The spec has no ``[[parameters]]``.
    AnalysisError, DataError, FMUError
        Unusable settings, data or twin (named).
    """
    s = settings or PairSettings()
    if not spec.parameters:
        raise SpecError(f"{spec.path} has no [[parameters]]: nothing to pair")
    frame, scored, in_window, start, stop, running = _measured(spec)
    op = operating_point(frame, spec.inputs, start=start, duration=3600.0, at=s.at)
    train = scored[in_window]
    state_tags = {st.tag for st in spec.states}
    tags = [t for t in spec.outputs if t not in state_tags]
    if state_tags:
        log.info("state-compensated tags are not tracking variables: %s", ", ".join(sorted(state_tags)))
    # scale of each tag: its span in operation (stoppages left out: a flow or a valve going to zero in
    # a stoppage would otherwise make a flow's range several times what it moves in operation, and
    # shrink its scaled gains against a tag the stoppage hardly moves, such as the product DS)
    spans = (variable_ranges(train[tags].to_numpy(dtype=float), trim=RANGE_TRIM) if len(train)
             else np.full(len(tags), np.nan))
    ranges = {tag: float(r) for tag, r in zip(tags, spans) if math.isfinite(r) and r > 0}
    params = [(p.name, p.start, p.min, p.max) for p in spec.parameters]
    freeze = dict(spec.pairing.freeze if s.freeze is None else s.freeze)
    problem = make_problem(spec.twin, outputs={t: spec.outputs[t] for t in tags}, parameters=params,
                           fixed=spec.fixed, operating=op, ranges=ranges, freeze=freeze,
                           compensation=[(st.variable, st.correction, st.gain) for st in spec.states])
    interval = float(s.interval or spec.sample_time)
    step_settings = StepSettings(step=s.step, two_sided=s.two_sided, freeze=tuple(freeze.items()),
                                 interval=interval, window=float(s.window or 60 * interval),
                                 tolerance=s.tolerance, baseline_tolerance=s.baseline_tolerance,
                                 max_time=s.max_time, steady_start=spec.data.initial == "steady")
    if s.check_gains not in ("recording", "structure"):
        raise AnalysisError(f"check_gains {s.check_gains!r}: expected 'recording' or 'structure'")
    sob = st2 = st_rec = None
    with make_executor(s.scheduler, s.workers) if executor is None else nullcontext(executor) as ex:
        log.info("step tests: %d parameters x %d directions, %d variables", len(params),
                 2 if s.two_sided else 1, len(tags))
        st = step_tests(problem, step_settings, ex, progress=_counter(progress, "step runs"))
        second = second_operating_point(s.second_point, running, spec, op, start, stop)
        if second is not None:
            at2, op2 = second
            log.info("second operating point (t = %g s): %s", at2, op2)
            fixed2 = tuple((k, v) for k, v in problem.fixed if k not in op2) + tuple(op2.items())
            st2 = step_tests(replace(problem, fixed=fixed2), step_settings, ex,
                             progress=_counter(progress, "step runs (2nd point)"))
        if s.data_checks and s.check_gains == "recording" and freeze:
            log.info("step tests with nothing frozen (the twin as the data were recorded) for the data checks")
            st_rec = step_tests(problem, replace(step_settings, freeze=()), ex,
                                progress=_counter(progress, "step runs (as recorded)"))
        if s.method in ("sobol", "both"):
            sob = sobol_indices(problem, step_settings, n=s.samples, seed=s.seed, executor=ex,
                                progress=_counter(progress, "Sobol runs"))
    residuals = checks = None
    if s.data_checks:
        checks = DataChecks(noise_ratio=s.noise_ratio, min_reach=s.min_reach, max_ratio=s.max_ratio,
                            closed_loop=float(_closed_loop(spec, s) or 0.0), max_leak=_max_leak(spec, s),
                            closed_loop_min=_closed_loop_min(spec, s), max_jitter=_max_jitter(spec, s))
        log.info("data checks: untracked twin over the training window [%g, %g) s", start, stop)
        residuals = simulate_untracked(spec, st.variables, start=start, stop=stop)
    scales = dict(spec.pairing.scale)
    # candidates the data cannot tell apart (dynamic sensitivities, trackingbox.identify): out, with the reason
    points = None if progress is None else (lambda stage, done, total: progress(f"identifiability ({stage})",
                                                                                 done, total))
    drop = indistinct_candidates(spec, progress=points) if s.identify and s.data_checks else {}
    st_m, st2_m, rec_m = (without_candidates(x, drop) for x in (st, st2, st_rec))
    pairing = choose_pairs(st_m.gains, st.variables, st.parameters, time_constants=st.time_constants,
                           variable_ranges=[scales.get(v, r) for v, r in zip(st.variables, st.ranges)],
                           parameter_ranges=parameter_ranges([(p.min, p.max) for p in spec.parameters]),
                           residuals=residuals, bounds=[(p.start, p.min, p.max) for p in spec.parameters],
                           checks=checks, other_gains=None if st2_m is None else st2_m.gains,
                           other_time_constants=None if st2 is None else st2.time_constants,
                           check_gains=None if rec_m is None else rec_m.gains,
                           check_time_constants=None if st_rec is None else st_rec.time_constants,
                           units=spec_units(spec, st.variables, st.parameters),
                           **({"rtol": s.rank_tol} if s.rank_tol else {}))
    if st_rec is not None and residuals is not None:
        pairing = complete_with_recording(
            pairing, rec_m.gains, time_constants=st_rec.time_constants,
            variable_ranges=[scales.get(v, r) for v, r in zip(st.variables, st.ranges)],
            parameter_ranges=parameter_ranges([(p.min, p.max) for p in spec.parameters]), residuals=residuals,
            bounds=[(p.start, p.min, p.max) for p in spec.parameters], checks=checks,
            **({"rtol": s.rank_tol} if s.rank_tol else {}))
    agr = agreement(pairing, sob) if sob is not None else None
    if s.method == "sobol" and sob is not None:
        pairing = _sobol_pairs(pairing, sob, st)
    pairing = replace(pairing, left_out=explain(explain_left_out(pairing, step_settings.freeze), drop))
    warnings = list(pairing.warnings)
    warnings += [f"{v}/{p}: +/- step gains differ by {100 * a:.0f} % (nonlinear response)"
                 for v, p, a in st.nonlinear()]
    return PairingResult(pairing=pairing, steptest=st, step_settings=step_settings, operating_point=op,
                         warnings=tuple(warnings), steptest_second=st2, second_point=second, sobol=sob,
                         agreement=agr, settings=s, steptest_recording=st_rec)


def spec_units(spec: Spec, variables: Sequence[str], parameters: Sequence[str]
               ) -> tuple[list[int | None], list[int | None]] | None:
    """The unit index of each tag (its twin output's trailing ``[k]``, for the outputs the spec's
    ``[pairing] units`` lists; all of them for a unit listed without outputs) and of each parameter of
    those units (``effect[k].Rf``), for :func:`~trackingbox.analysis.pairing.choose_pairs`' pairing per
    unit; None when the spec names no units. With several arrays a tag listed for any of them belongs
    to that index's units."""
    if not spec.pairing.units:
        return None
    listed = {t for _, tags in spec.pairing.units for t in tags}
    anything = any(not tags for _, tags in spec.pairing.units)

    def unit(variable: str) -> int | None:
        name = spec.outputs.get(variable, variable)
        k = output_unit(name)
        return k if k is not None and (anything or name[: name.rindex("[")] in listed) else None

    return ([unit(v) for v in variables], [parameter_unit(p, [u for u, _ in spec.pairing.units]) for p in parameters])


def _max_leak(spec: Spec, settings: PairSettings) -> float:
    """The separation limit *settings* or the spec's ``[pairing] max_leak`` ask for (``inf``: no check)."""
    value = settings.max_leak if settings.max_leak is not None else spec.pairing.max_leak
    if value is None:
        return math.inf
    if not (math.isfinite(float(value)) and float(value) >= 0):
        raise AnalysisError(f"max_leak must be a number >= 0, got {value!r}")
    return float(value)


def _max_jitter(spec: Spec, settings: PairSettings) -> float:
    """The loop-noise limit *settings* or the spec's ``[pairing] max_jitter`` ask for (``inf``: none)."""
    value = settings.max_jitter if settings.max_jitter is not None else spec.pairing.max_jitter
    if value is None:
        return math.inf
    if not (math.isfinite(float(value)) and float(value) > 0):
        raise AnalysisError(f"max_jitter must be a number > 0, got {value!r}")
    return float(value)


def _closed_loop(spec: Spec, settings: PairSettings) -> float | None:
    """The closed-loop time constant (s) *settings* or the spec's ``[pairing]`` ask for, or None."""
    value = settings.closed_loop if settings.closed_loop is not None else spec.pairing.closed_loop
    if value is None:
        return None
    if not (math.isfinite(float(value)) and float(value) >= 0):
        raise AnalysisError(f"closed_loop must be a time >= 0 s, got {value!r}")
    return float(value) or None


def _closed_loop_min(spec: Spec, settings: PairSettings) -> float:
    """The fastest loop per pair (s) *settings* or the spec's ``[pairing] closed_loop_min`` ask for
    (0: every loop at the closed loop)."""
    value = settings.closed_loop_min if settings.closed_loop_min is not None else spec.pairing.closed_loop_min
    if value is None:
        return 0.0
    if not (math.isfinite(float(value)) and float(value) >= 0):
        raise AnalysisError(f"closed_loop_min must be a time >= 0 s, got {value!r}")
    return float(value)


#: Left-out reasons that say a parameter shows in no tag, or a tag shows no parameter.
_UNSEEN = ("negligible gain", "no candidate parameter moves it", "all gains are zero")


def explain_left_out(pairing: Pairing, freeze: tuple[tuple[str, float], ...]) -> tuple[tuple[str, str], ...]:
    """Every variable and parameter of *pairing* that is not paired, with its reason.

    The reasons of :func:`~trackingbox.analysis.pairing.choose_pairs` are kept; a
    "moves nothing" / "nothing moves it" reason found with controllers frozen by
    *freeze* says so (what a frozen loop would have shown in its controller's
    output, or what a loop left active holds at its setpoint, is not observable
    with that freeze). A name without a reason (none is expected) gets one
    saying so, and is logged.

    Examples
    --------
    >>> from trackingbox.analysis.pairing import choose_pairs
    >>> p = choose_pairs([[1.0, 0.0], [0.0, 0.0]], ["y1", "y2"], ["a", "b"])
    >>> for name, why in explain_left_out(p, (("hold", 1.0),)):
    ...     print(name, "|", why.split(":")[0], "|", "not observable with this freeze" in why)
    b | negligible gain | True
    y2 | no candidate parameter moves it | True
    """
    paired = {p.variable for p in pairing.pairs} | {p.parameter for p in pairing.pairs}
    reasons = dict(pairing.left_out)
    if freeze:
        frozen = ", ".join(f"{n} = {v:g}" for n, v in freeze)
        for name, why in reasons.items():
            if any(key in why for key in _UNSEEN):
                reasons[name] = (f"{why} (not observable with this freeze, {frozen}: a frozen loop no longer "
                                 "shows a parameter error in its controller's output, and a loop left active "
                                 "holds its measurement at the setpoint; another freeze may show it)")
    out = []
    for name in (*pairing.parameters, *pairing.variables):
        if name in paired:
            continue
        if name not in reasons:
            log.warning("%s was left out without a reason", name)
            reasons[name] = "not paired (no reason was recorded)"
        out.append((name, reasons[name]))
    return tuple(out)


def _sobol_pairs(pairing: Pairing, sob: SobolResult, st: StepTestResult) -> Pairing:
    """*pairing* with its pairs replaced by the Sobol total-index choice."""
    choice = sob.choice("total")
    idx = {n: k for k, n in enumerate(st.parameters)}
    pairs = []
    for i, v in enumerate(st.variables):
        if v in choice:
            j = idx[choice[v]]
            pairs.append(Pair(v, choice[v], float(pairing.rga[i, j]), float(st.gains[i, j]),
                              float(st.time_constants[i, j])))
    chosen = {p.parameter for p in pairs} | {p.variable for p in pairs}
    left = tuple((n, "not chosen by the Sobol total indices") for n in (*st.variables, *st.parameters)
                 if n not in chosen)
    return replace(pairing, pairs=tuple(pairs), left_out=left)


def spec_pairs(spec: Spec, result: PairingResult) -> list[PairSpec]:
    """``[[pairs]]`` entries for the chosen pairs; an existing identical pair keeps its tuning settings.

    A pair without a measurable time constant gets the step interval (logged as a warning).
    A new pair gets ``lambda = 1``, or, with a closed-loop time constant (the pair's own,
    :attr:`~trackingbox.analysis.pairing.Pair.closed_loop`, chosen with ``closed_loop_min``;
    else the result's settings or the spec's ``[pairing] closed_loop``), the ``lambda`` that
    makes ``lambda x time_constant`` reach it: the loop the prediction judged.
    """
    interval = result.step_settings.interval
    loop = _closed_loop(spec, result.settings)
    old = {(p.variable, p.parameter): p for p in spec.pairs}
    out = []
    for p in result.pairing.pairs:
        measured = math.isfinite(p.time_constant) and p.time_constant > 0
        tau = p.time_constant if measured else interval
        if not measured:
            log.warning("pair %s/%s has no measurable time constant; writing %g s (the step interval)",
                        p.variable, p.parameter, interval)
        prev = old.get((p.variable, p.parameter))
        if prev is not None:
            out.append(replace(prev, gain=float(p.gain), time_constant=float(tau)))
        else:
            own = getattr(p, "closed_loop", math.nan)
            target = float(own) if math.isfinite(own) and own > 0 else (loop or 0.0)
            out.append(PairSpec(variable=p.variable, parameter=p.parameter, gain=float(p.gain),
                                time_constant=float(tau), lambda_=max(1.0, target / float(tau))))
    return out
