"""The tracking loop: step the twin beside the plant data and adjust its parameters.

:func:`track` runs the twin FMU through the measurement period on the spec's
``sample_time`` grid. At each sample ``t_k`` it

1. reads the twin's simulated sensors (and, in lockstep, those of an
   *untracked* twin: same FMU, same inputs, same state compensation, parameters
   frozen at their start values);
2. updates one parameter controller per ``[[pairs]]`` entry (setpoint = the
   measured tag, process value = the mapped twin variable, output = the
   parameter) and one :class:`~.controllers.StateCompensator` per
   ``[[states]]`` entry;
3. writes one CSV row (so the output is on disk as it is produced and memory
   stays flat);
4. sets the new parameter values and correction flows and integrates both
   twins to ``t_{k+1}``: with ``substeps`` the tracked twin in parts of the
   sample, the parameter controllers advancing after each part (see
   :func:`track`). A small change is carried by the tracked twin's
   integrator (no re-initialisation; ``carry`` in :func:`track`).

The controllers hold (output frozen, no integration) during the start-up hold
``t < tracking.hold_until``, while their measured tag or simulated variable is
missing (NaN, long gaps masked by ``data.max_gap``), during a flow stoppage
(``data.stoppage``: ``tag < below``, plus ``settle`` seconds after it) and for
``recovery_hold`` seconds after a solver failure. State compensation keeps
running through start-up hold and stoppages (it protects the twin's tanks)
and holds only while its own level measurement is missing.

The loop is a :class:`TrackingLoop` whose parts (the parameter controllers,
the state compensation, the tracked and untracked twins, the output stream)
each save and restore their own state (``state_dict()`` /
``load_state_dict()``). A checkpoint (JSON, every ``checkpoint_every`` steps
and at the end) is the loop's state: the row index and the parts' states
(controller and compensator states, the applied values and, for
model-exchange FMUs, the continuous states of both twins, the CSV length and
the summaries). ``resume=True`` truncates the CSV to the checkpoint and
continues. For co-simulation FMUs, whose states are not accessible, the twins
are rebuilt by *replaying* the recorded parameter and correction trajectory
from the CSV. Every checkpoint is also a restart point of an uninterrupted
run, so a run resumed from a checkpoint writes the same bytes.

The data (grid, per-tag samples with the gap rule, stoppage mask, the twin's
input table and the samples scored per tag) come from the spec's
:class:`~trackingbox.data.MeasurementView`, as in estimation and validation.

A :class:`~trackingbox.errors.SimulationError` during a step is logged, the
twin is re-initialised from its last good state (the continuous states after
the previous step, or a replay) and the step retried with the controllers on
hold; if it fails again the twin is cold-started at that time (fresh
initialisation). Rows already written are never lost.

The streamed CSV cannot be written atomically; its valid length is the one
recorded in the last checkpoint, and the summary files (``checkpoint.json``,
``result.json``) are written atomically.
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import pandas as pd

from ..data import MeasurementView
from .controllers import Interpolation
from .loop import TrackingLoop
from .parts import CARRY_FRACTION, substeps_for, within_sample_gains
from .plan import ControllerMode, Window
from .result import (
    CHECKPOINT_NAME,
    CSV_NAME,
    RESULT_NAME,
    ParameterResult,
    TrackingEvent,
    TrackingResult,
    VariableResult,
)

if TYPE_CHECKING:
    from ..spec import Spec

log = logging.getLogger(__name__)

#: The entry point, and the names a caller of the tracking stage uses, in one place.
__all__ = [
    "TrackingResult", "VariableResult", "ParameterResult", "TrackingEvent", "TrackingLoop", "track",
    "CSV_NAME", "CHECKPOINT_NAME", "RESULT_NAME", "CARRY_FRACTION", "ControllerMode", "Window",
    "within_sample_gains", "substeps_for",
]


def track(
    spec: Spec,
    *,
    out_dir: str | Path,
    resume: bool = False,
    progress: Callable[[int, int], None] | None = None,
    max_steps: int | None = None,
    window: Window = "all",
    untracked: bool | pd.DataFrame = True,
    checkpoint_every: int = 200,
    recovery_hold: float | None = None,
    tolerance: float = 1e-6,
    view: MeasurementView | None = None,
    interpolation: Interpolation = "linear",
    substeps: int | Literal["auto"] = "auto",
    carry: float = CARRY_FRACTION,
    controllers: ControllerMode = "discrete",
    inputs_twin: Any = None,
    window_rows: int | None = None,
) -> TrackingResult:
    """Run the tracking simulator over the spec's measurements.

    Parameters
    ----------
    spec : trackingbox.spec.Spec
        A loaded spec with ``[[pairs]]``.
    out_dir : path
        Where ``tracking.csv``, ``checkpoint.json`` and ``result.json`` go.
    resume : bool
        Continue from ``checkpoint.json`` in *out_dir* (fresh start if there is none).
    progress : callable, optional
        ``progress(rows_done, rows_total)`` after each row.
    max_steps : int, optional
        Stop after this many rows in this call (checkpointed; resume to continue).
    window : {"all", "training", "validation"}
        Window the NRMSE figures are taken over (always after the start-up hold).
        The twin runs from the first sample to the end of this window.
    untracked : bool or pandas.DataFrame
        Run the untracked twin in lockstep (True), skip it (False) or use a
        given simulation (``time`` + the twin variable names of the outputs).
    checkpoint_every : int
        Rows between checkpoints.
    recovery_hold : float, optional
        Seconds the controllers stay on hold after a solver failure; default
        ``10·sample_time``.
    tolerance : float
        Relative solver tolerance of the twins.
    view : trackingbox.data.MeasurementView, optional
        The measurements to track, when the caller has built them already
        (``MeasurementView.from_spec(spec, window, skip=spec.tracking.hold_until)``);
        default: built here from the spec.
    interpolation : {"linear", "zoh"}
        How the controllers see the error between samples (see
        :class:`~trackingbox.tracking.controllers.ScaledPI`). ``"linear"``
        (default): the error goes linearly from one sample to the next, as in
        the compiled box (interpolated measurement, continuous twin output);
        the parameter of row ``k`` is the controller's value at ``t_k``, held
        over ``[t_k, t_k+1]``. ``"zoh"``: the error held over the sample; the
        parameter of row ``k`` is the value at ``t_k+1``, applied from ``t_k``.
    substeps : int or "auto"
        ``"linear"`` only: integrate the PI controllers with the tracked twin
        over this many equal parts of each sample. After each part but the
        last the controllers read the twin, take the measurement interpolated
        between the two samples, advance and give the twin their new values,
        so a pair whose variable answers its parameter within a sample closes
        its loop within the sample, as in the compiled box (where the loop is
        continuous). Hold flags, state compensation, the CSV rows and the
        untracked twin stay per sample. ``"auto"`` (default): one part when
        every pair's within-sample loop gain (:func:`within_sample_gains`,
        measured on the twin before the run) is at most
        :data:`SUBSTEP_GAIN`, else ``ceil(sqrt(g / SUBSTEP_GAIN))`` for the
        largest, at most :data:`MAX_SUBSTEPS`. Needs a model-exchange twin
        (``"auto"`` chooses 1 for a co-simulation one). A checkpoint records
        the count; resuming with another is refused.
    carry : float
        Model exchange: the tracked twin's integrator (CVODE) is carried
        across a change of its parameters and correction flows instead of
        being re-initialised, when every change is at most this fraction of
        the parameter's bound range (a correction: of its compensator's gain
        times its level's measured range). CVODE then stops exactly at each
        sample and sub-step (its stop time), and the change becomes a jump of
        the derivatives that its error test absorbs. Larger changes, the
        start, entering or leaving a hold, a recovery and a checkpoint's
        restart point re-initialise it. ``0``: re-initialise at every change
        (the restart path). Default :data:`CARRY_FRACTION`.
    controllers : {"discrete", "continuous"}
        ``"discrete"`` (default): the controllers are the exact
        discretisations of the box's laws (:class:`ScaledPI`,
        :class:`StateCompensator`), updated at every sample (and sub-step);
        the twin's integrator stops at each. ``"continuous"``: the box's laws
        themselves, as continuous states integrated by CVODE together with
        the twin's states in the native right-hand side (``tbn_closed_rows``,
        see :class:`ClosedRows`), the measurement interpolated linearly
        between samples as the compiled box sees it; CVODE returns at every
        sample (its stop time: the data's kinks) and is re-initialised only
        where a hold starts or ends or a tag goes missing or comes back, and
        at a checkpoint. It runs on the *inputs twin*
        (:func:`~trackingbox.generate.inputs_twin.inputs_twin`: the twin
        compiled with its tracked parameters switched to their conditional
        inputs), which it builds from the spec's ``[source]`` unless
        *inputs_twin* is given; it needs the native stepper, PI pairs and
        ``interpolation="linear"``; *substeps* and *carry* do not apply.
        Rows that need Python (a tag going missing or coming back, a solver
        failure) run on the discrete path.
    inputs_twin : trackingbox.generate.inputs_twin.InputsTwin, optional
        The compiled inputs twin for ``controllers="continuous"``.
    window_rows : int, optional
        Without *view*: the measurements are read once into a temporary file
        in *out_dir* and the run holds this many grid rows of them at a time
        (:class:`~trackingbox.stream.WindowedMeasurements`; default
        :data:`~trackingbox.stream.WINDOW_ROWS`), the twins' input tables
        too, so its memory does not grow with its length; the rows are the
        same as from the whole view. ``0``: the whole view. Data the windows
        cannot give exactly (a historian's long export, heartbeat tags, a tag
        bridging every gap) and a given *untracked* table take the whole view.

    Returns
    -------
    TrackingResult

    Raises
    ------
    SpecError, DataError
        Unusable spec or data (named).
    SimulationError
        The twin failed at the same time even after a cold restart (the rows
        up to that time stay in the CSV).
    """
    loop = TrackingLoop(spec, out_dir=out_dir, window=window, untracked=untracked,
                        checkpoint_every=checkpoint_every, recovery_hold=recovery_hold, tolerance=tolerance,
                        view=view, interpolation=interpolation, substeps=substeps, carry=carry,
                        controllers=controllers, inputs_twin=inputs_twin, window_rows=window_rows)
    try:
        loop.begin(resume=resume)
        loop.run(max_steps=max_steps, progress=progress)
    finally:
        loop.close()
    return loop.result()
