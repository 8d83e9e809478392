"""Where a run without measured history starts: the twin's initial states by name.

Every stage starts a run at the data's first sample (or after an input gap) from the FMU's own
initial state, or, with the spec's ``[data] initial = "steady"``, from its steady state there
(:meth:`~trackingbox.fmu.steppers.ModelExchangeStepper.settle`). The stages that run the twin
itself settle its own stepper; :func:`twin_initial_states` gives the twin's starting states by
name for a run of another FMU that contains the twin (the tracked model that extends it, in
validation), and :func:`apply_states` writes them there.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from .models import open_model

if TYPE_CHECKING:
    from ..spec import Spec


def twin_initial_states(spec: Spec, *, start_time: float, inputs: pd.DataFrame | None,
                        parameters: Mapping[str, float], tolerance: float = 1e-6) -> dict[str, float]:
    """The twin's continuous states at *start_time* as the spec's ``[data] initial`` starts them, by name."""
    model = open_model(spec.twin, tolerance=tolerance)
    try:
        run = model.stepper(start_time=start_time, parameters=dict(parameters), inputs=inputs,
                            input_rule=spec.data.inputs)
        if spec.data.initial == "steady":
            run.settle()
        x = run.get_continuous_states()
        names = run.state_names
        run.finish()
    finally:
        model.close()
    return {name: float(v) for name, v in zip(names, x)}


def apply_states(stepper: Any, states: Mapping[str, float]) -> list[str]:
    """Overwrite the continuous states of *stepper* that *states* names; returns the names written.

    The others keep their values (e.g. a tracking box's own controller states).
    """
    names = stepper.state_names
    x = np.asarray(stepper.get_continuous_states(), dtype=float)
    written = []
    for i, name in enumerate(names):
        if name in states:
            x[i] = float(states[name])
            written.append(name)
    if written:
        stepper.set_continuous_states(x)
    return written
