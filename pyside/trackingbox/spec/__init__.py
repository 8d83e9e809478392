"""The tracking specification, ``spec.toml``: loading, validation and writing back.

A spec names the twin FMU, the measurement file, which measurement tag drives
which FMU input and which FMU output simulates which tag, the candidate tracking
parameters with their bounds, the training/validation windows and (once
``trackingbox pair`` has run) the pairs of tracking variable and tracking
parameter. The format is described in the README.

Modules: :mod:`.model` (the records), :mod:`.parse` (:func:`load_spec`, which collects
*every* problem and raises one :class:`~trackingbox.errors.SpecError` listing them all),
:mod:`.write` (one writer, :func:`update_spec`, keeps the user's comments and layout).
"""
from __future__ import annotations

from .model import (
    CONTROLLERS,
    WINDOW_NAMES,
    BalanceSpec,
    ControllerKind,
    DataRules,
    DiagnoseSpec,
    LiveSpec,
    PairingSettings,
    PairSpec,
    ParameterSpec,
    SourceSpec,
    Spec,
    StateSpec,
    StoppageRule,
    TrackingSettings,
)
from .parse import (
    check_against_fmu,
    load_spec,
    loads_spec,
)
from .write import (
    dump_spec,
    spec_to_dict,
    update_spec,
    write_pairs,
    write_spec,
    write_starts,
)

__all__ = [
    "ControllerKind",
    "CONTROLLERS",
    "WINDOW_NAMES",
    "SourceSpec",
    "ParameterSpec",
    "PairSpec",
    "StateSpec",
    "BalanceSpec",
    "DiagnoseSpec",
    "StoppageRule",
    "DataRules",
    "TrackingSettings",
    "LiveSpec",
    "PairingSettings",
    "Spec",
    "load_spec",
    "loads_spec",
    "check_against_fmu",
    "spec_to_dict",
    "dump_spec",
    "write_spec",
    "update_spec",
    "write_pairs",
    "write_starts",
]
