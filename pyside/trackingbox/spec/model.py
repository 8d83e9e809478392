"""What a spec is: :class:`Spec` and the records of its tables (the parsed ``spec.toml``)."""
from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from ..errors import SpecError, did_you_mean

log = logging.getLogger(__name__)

ControllerKind = Literal["pi", "sliding"]
#: Parameter-controller kinds a pair may name.
CONTROLLERS: tuple[str, ...] = ("pi", "sliding")
#: ``[data] inputs``: how measured inputs reach the twin between samples (the first is the default).
INPUT_RULES: tuple[str, ...] = ("linear", "hold")
#: ``[data] initial``: where a run without measured history starts (the first is the default).
INITIAL_STATES: tuple[str, ...] = ("model", "steady")
#: Names a ``[windows]`` table may hold.
WINDOW_NAMES: tuple[str, ...] = ("training", "validation")


@dataclass(frozen=True)
class SourceSpec:
    """The twin's Modelica source (for ``gen-trackingbox``).

    Attributes
    ----------
    path : Path
        Absolute path of the package directory or ``.mo`` file.
    model : str
        Full class name of the twin, e.g. ``TrackingBox.Benches.HeatExchanger.Twin``.
    libraries : tuple of Path
        Modelica libraries the source uses (package directories or ``.mo`` files, e.g. the
        MSL's ``Modelica`` directory): ``[source] libraries``. Libraries beside the source and
        on ``MODELICAPATH`` are found without being named.
    """

    path: Path
    model: str
    libraries: tuple[Path, ...] = ()


@dataclass(frozen=True)
class ParameterSpec:
    """A candidate tracking parameter with its start value and bounds.

    ``interval``: the confidence interval of the start value where an estimate gave one
    (``estimate --write`` records it; the tracked parameter's band starts from it), else None.
    """

    name: str
    start: float
    min: float
    max: float
    interval: tuple[float, float] | None = None


@dataclass(frozen=True)
class PairSpec:
    """One parameter controller: tracking variable (a tag) and tracking parameter.

    Attributes
    ----------
    variable : str
        Measurement tag the controller makes the twin follow (a key of ``[outputs]``).
    parameter : str
        FMU parameter it adjusts (one of ``[[parameters]]``).
    gain : float
        Steady-state gain d(variable)/d(parameter) in engineering units.
    time_constant : float
        Time constant of the response in s (from the step test).
    lambda_ : float
        Closed-loop tuning factor (TOML key ``lambda``).
    kp, ti : float or None
        Explicit PI gains; ``None`` means "tune from gain and time constant".
    controller : {"pi", "sliding"}
        Kind of parameter controller.
    """

    variable: str
    parameter: str
    gain: float
    time_constant: float
    lambda_: float
    kp: float | None = None
    ti: float | None = None
    controller: ControllerKind = "pi"


@dataclass(frozen=True)
class StateSpec:
    """State compensation of one measured state (a tank level).

    ``correction`` (a twin input, kg/s) is driven by ``gain * (measured - simulated)``.
    """

    tag: str
    variable: str
    correction: str
    gain: float


@dataclass(frozen=True)
class BalanceSpec:
    """A balance over measured tags (``[[balances]]``): ``sum(factor * tag)`` should vanish.

    ``terms`` maps a measurement column to its signed factor (e.g. a mass balance
    ``{"FI-101" = 1.0, "FI-102" = -1.0}``); ``tolerance`` is the imbalance accepted
    beyond the noise of the terms (units of the terms). ``diagnose`` uses it to tell
    a faulty sensor (the balance does not close) from a process change (it closes).
    """

    name: str
    terms: dict[str, float]
    tolerance: float = 0.0


@dataclass(frozen=True)
class DiagnoseSpec:
    """The spec's ``[diagnose]`` table.

    Attributes
    ----------
    effects : tuple of Path
        Folders of user effect entries (absolute, resolved relative to the spec
        file); ``diagnose`` reads them beside the built-in entries.
    varying : tuple of (str, str)
        Candidate parameters the twin tracks because they change in time (a fouling
        resistance), each with how: ``"rising"``, ``"falling"`` or ``"free"``.
        ``diagnose`` lets them move in its null model as tracking would, so that
        their change is never taken for a missing effect.
    """

    effects: tuple[Path, ...] = ()
    varying: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class StoppageRule:
    """Rows where ``tag < below`` are excluded, plus ``settle`` seconds after each stoppage."""

    tag: str
    below: float
    settle: float = 0.0


@dataclass(frozen=True)
class DataRules:
    """Optional rules applied to the measurements."""

    stoppage: StoppageRule | None = None
    max_gap: float | None = None
    #: Exception-reported tags: tag -> the historian's heartbeat (s), the longest interval between
    #: archived values of a tag whose value did not move (``[data] heartbeat = s`` for every tag or
    #: ``[data.heartbeat]`` per tag; ``"*"`` there is every tag not listed). See ``data.MeasurementView``.
    heartbeat: Mapping[str, float] = field(default_factory=dict)
    #: How measured inputs reach the twin between their samples, the same in every stage and on both FMI
    #: interfaces: ``"linear"`` (interpolated) or ``"hold"`` (the last sample held until the next).
    inputs: str = "linear"
    #: Where a run without measured history starts (a window at the first sample, tracking, validation):
    #: ``"model"`` (the FMU's own initial state) or ``"steady"`` (its steady state with the inputs there).
    initial: str = "model"
    #: Slow states of the twin carried through the measured history (``[data] carry``, the diagnosis's
    #: effect states such as a scale): :attr:`trackingbox.simulation.windows.Problem.carry`.
    carry: tuple[str, ...] = ()

    def heartbeat_of(self, tag: str) -> float | None:
        """The heartbeat (s) of *tag*, or None when the tag is not exception-reported."""
        value = self.heartbeat.get(tag, self.heartbeat.get("*"))
        return None if value is None else float(value)


@dataclass(frozen=True)
class TrackingSettings:
    """Optional tracking overrides."""

    hold_until: float = 0.0


@dataclass(frozen=True)
class LiveSpec:
    """The online mode (``[live]``): where each tag is on the OPC UA server and how to connect.

    Credentials are never in the spec: a user name and password come from the
    environment (``TRACKINGBOX_OPCUA_USER``, ``TRACKINGBOX_OPCUA_PASSWORD``) or
    a credentials file (see :mod:`trackingbox.online`).
    """

    nodes: dict[str, str] = field(default_factory=dict)   # tag -> node id; default "ns=2;s=<tag>"
    auth: str = "anonymous"                               # "anonymous" | "user"
    security: str | None = None                           # "Basic256Sha256" or None
    mode: str = "SignAndEncrypt"                          # "SignAndEncrypt" | "Sign"
    certificate: Path | None = None                       # the client's certificate (DER or PEM)
    private_key: Path | None = None                       # its private key (PEM)
    server_certificate: Path | None = None                # the server's certificate to trust
    stale_after: float | None = None                      # s; default 3 x sample_time
    publish: str | None = None                            # endpoint of the results server

    def node(self, tag: str) -> str:
        """The node id of *tag* (``ns=2;s=<tag>`` unless ``[live.nodes]`` says otherwise)."""
        return self.nodes.get(tag, f"ns=2;s={tag}")


@dataclass(frozen=True)
class PairingSettings:
    """``[pairing]``: how ``pair`` step-tests this twin.

    Attributes
    ----------
    freeze : tuple of (str, float)
        Twin inputs or tunable parameters set after the first settle of the step
        tests to freeze some of its controllers (``freeze = { holdLevelControllers = 1 }``);
        ``pair --freeze`` replaces them.
    scale : tuple of (str, float)
        Output tag -> the scale of its gains in the relative gain array, in the tag's
        units, instead of its measured range (``scale = { "PI-6121" = 200.0 }``): the
        size of a deviation that matters, such as the sensor's accuracy. Scaled by
        accuracy, a parameter pairs with the tag that shows it most clearly above
        the noise; scaled by range, with the tag whose operating swing it explains
        most, which favours tags the inputs hardly move.
    closed_loop : float or None
        Closed-loop time constant (s) the parameter controllers will be tuned for at
        least (``closed_loop = 10800.0``): ``pair`` predicts each loop's tracking with
        it (an error faster than the loop stays, noise and the historian's holds
        included) and writes a new pair's ``lambda`` so that ``lambda x time_constant``
        reaches it. ``None``: the step tests' time constants (lambda = 1).
    closed_loop_min : float or None
        Loop speed per pair (``closed_loop_min = 1800.0``, with *closed_loop*): a pair whose
        tracking ``pair`` predicts to fail with a loop of *closed_loop* is predicted again with
        its own loop faster, in steps of sqrt 2 down to this, before it is refused; each pair is
        written with the slowest loop that passes (its ``lambda``), the others keep
        *closed_loop* (:class:`trackingbox.analysis.pairing.DataChecks`). ``None``: every loop
        at *closed_loop*.
    max_leak : float or None
        Separation check of ``pair`` (``max_leak = 0.5``; see
        :func:`trackingbox.analysis.pairing.leakage`): a pair is refused when a candidate
        left unpaired moves its parameter by more than this many of its bound range per
        bound range of that candidate, at the loops' steady state. ``None``: no check.
    max_jitter : float or None
        Loop noise limit of ``pair`` (``max_jitter = 0.025``; see
        :func:`trackingbox.analysis.offsets.loop_jitter`): a pair's loop is made no faster than
        the one whose tag noise, as the data show it, moves its parameter by this standard
        deviation in fractions of its bound range. ``None``: no limit.
    units : tuple of (str, tuple of str)
        Pairing per unit (see :mod:`trackingbox.analysis.blocks`): component array -> the twin
        outputs (array names) its parameters may pair with, ``units = { effect = ["PI_steamChest",
        "TI_body"] }`` (or ``units = ["effect"]``: any output of the unit). A parameter of unit ``k``
        of these arrays (``effect[3].Rf``) pairs only with a tag of the same unit (a listed twin output
        ending in ``[3]``), the tags chosen so that the square relative gain array of the unit
        parameters is closest to the identity. Empty: the whole matrix's relative gains for every
        parameter.
    """

    freeze: tuple[tuple[str, float], ...] = ()
    scale: tuple[tuple[str, float], ...] = ()
    closed_loop: float | None = None
    max_leak: float | None = None
    closed_loop_min: float | None = None
    units: tuple[tuple[str, tuple[str, ...]], ...] = ()
    max_jitter: float | None = None


@dataclass(frozen=True)
class Spec:
    """A loaded and validated tracking specification.

    Paths are absolute, resolved relative to the spec file.
    """

    path: Path
    twin: Path
    measurements: Path
    sample_time: float
    source: SourceSpec | None = None
    inputs: dict[str, str] = field(default_factory=dict)
    outputs: dict[str, str] = field(default_factory=dict)
    parameters: tuple[ParameterSpec, ...] = ()
    fixed: dict[str, float] = field(default_factory=dict)
    #: ``[fixed_intervals]``: the confidence interval of a ``[fixed]`` value where an estimate gave one
    #: (the value the twin holds is off by up to it: the tracked parameters' bands carry that, see
    #: :mod:`trackingbox.identify.held`)
    fixed_intervals: dict[str, tuple[float, float]] = field(default_factory=dict)
    windows: dict[str, tuple[float, float]] = field(default_factory=dict)
    data: DataRules = field(default_factory=DataRules)
    pairs: tuple[PairSpec, ...] = ()
    states: tuple[StateSpec, ...] = ()
    tracking: TrackingSettings = field(default_factory=TrackingSettings)
    balances: tuple[BalanceSpec, ...] = ()
    diagnose: DiagnoseSpec = field(default_factory=DiagnoseSpec)
    live: LiveSpec = field(default_factory=LiveSpec)
    pairing: PairingSettings = field(default_factory=PairingSettings)

    def parameter(self, name: str) -> ParameterSpec:
        """Return the candidate parameter *name*; :class:`SpecError` with did-you-mean if absent."""
        for p in self.parameters:
            if p.name == name:
                return p
        names = [p.name for p in self.parameters]
        raise SpecError(f"unknown parameter {name!r} in [[parameters]] of {self.path}"
                        f"{did_you_mean(name, names)}")

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the candidate parameters, in file order."""
        return tuple(p.name for p in self.parameters)

    @property
    def tags(self) -> tuple[str, ...]:
        """Every measurement tag the spec uses (inputs, outputs, states), first occurrence order."""
        seen: dict[str, None] = {}
        for tag in [*self.inputs, *self.outputs, *(s.tag for s in self.states)]:
            seen.setdefault(tag, None)
        return tuple(seen)
