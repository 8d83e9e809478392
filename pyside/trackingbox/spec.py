"""The tracking specification, ``spec.toml``: loading, validation and writing back.

A spec names the twin FMU, the measurement file, which measurement tag drives
which FMU input and which FMU output simulates which tag, the candidate tracking
parameters with their bounds, the training/validation windows and (once
``trackingbox pair`` has run) the pairs of tracking variable and tracking
parameter. The format is described in ``docs/architecture.md``.

:func:`load_spec` collects *every* problem it finds and raises one
:class:`~trackingbox.errors.SpecError` listing them all, each naming the key,
the table and the file.
"""
from __future__ import annotations

import csv
import logging
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

import tomli_w
import tomlkit
from tomlkit.items import AoT, Comment, Table, Whitespace

from .errors import SpecError, did_you_mean, unknown_name
from .io import write_text_atomic

if TYPE_CHECKING:  # pragma: no cover
    from .fmu import FMUInfo

log = logging.getLogger(__name__)

ControllerKind = Literal["pi", "sliding"]
#: Parameter-controller kinds a pair may name.
CONTROLLERS: tuple[str, ...] = ("pi", "sliding")
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
    """

    path: Path
    model: str


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
    """

    effects: tuple[Path, ...] = ()


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


# --------------------------------------------------------------------------- parsing

_TOP_KEYS = ("twin", "measurements", "sample_time", "source", "inputs", "outputs", "parameters",
             "fixed", "windows", "data", "pairs", "states", "tracking",
             "balances", "diagnose", "live", "pairing")
_REQUIRED_TOP = ("twin", "measurements", "sample_time", "outputs")


#: longest problem message (characters); longer ones are shortened in the middle
_MAX_MESSAGE = 400


class _Problems:
    """Collects problems while a spec is checked; raises them together."""

    def __init__(self, where: str) -> None:
        self.where = where
        self.items: list[str] = []

    def add(self, message: str) -> None:
        # a value echoed from the file (a 200 kB string) must not make a 200 kB error line
        if len(message) > _MAX_MESSAGE:
            half = _MAX_MESSAGE // 2
            message = f"{message[:half]} ... {message[-half // 2:]}"
        self.items.append(message)

    def raise_if_any(self) -> None:
        if self.items:
            if len(self.items) == 1:
                raise SpecError(f"{self.where}: {self.items[0]}")
            lines = "\n".join(f"  - {m}" for m in self.items)
            raise SpecError(f"{self.where}: {len(self.items)} problems:\n{lines}")


def _table_label(table: str) -> str:
    return "the top level" if not table else f"[{table}]"


def _check_keys(table: Mapping[str, Any], allowed: Sequence[str], required: Sequence[str],
                label: str, problems: _Problems) -> None:
    for key in table:
        if key not in allowed:
            problems.add(f"unknown key {key!r} in {label}{did_you_mean(key, allowed)}")
    for key in required:
        if key not in table:
            problems.add(f"missing required key {key!r} in {label}")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number(table: Mapping[str, Any], key: str, label: str, problems: _Problems, *,
            default: float | None = None, positive: bool = False,
            nonnegative: bool = False) -> float | None:
    if key not in table:
        return default
    value = table[key]
    if not _is_number(value):
        problems.add(f"{key!r} in {label} must be a number, got {_type_name(value)} {value!r}")
        return default
    try:
        value = float(value)
    except OverflowError:
        problems.add(f"{key!r} in {label} is out of range: an integer of {len(str(value))} digits")
        return default
    if not math.isfinite(value):
        problems.add(f"{key!r} in {label} must be finite, got {value!r}")
        return default
    if positive and value <= 0:
        problems.add(f"{key!r} in {label} must be > 0, got {value!r}")
    if nonnegative and value < 0:
        problems.add(f"{key!r} in {label} must be >= 0, got {value!r}")
    return value


def _string(table: Mapping[str, Any], key: str, label: str, problems: _Problems) -> str | None:
    if key not in table:
        return None
    value = table[key]
    if not isinstance(value, str) or not value:
        problems.add(f"{key!r} in {label} must be a non-empty string, got {_type_name(value)} {value!r}")
        return None
    return value


def _type_name(value: Any) -> str:
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, (int, float)):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, dict):
        return "table"
    if isinstance(value, list):
        return "array"
    return type(value).__name__


def _table(raw: Mapping[str, Any], key: str, problems: _Problems) -> dict[str, Any] | None:
    if key not in raw:
        return None
    value = raw[key]
    if not isinstance(value, dict):
        problems.add(f"{key!r} must be a table ([{key}]), got {_type_name(value)}")
        return None
    return value


def _array_of_tables(raw: Mapping[str, Any], key: str, problems: _Problems) -> list[dict[str, Any]]:
    if key not in raw:
        return []
    value = raw[key]
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        problems.add(f"{key!r} must be an array of tables ([[{key}]]), got {_type_name(value)}")
        return []
    return value


def _string_map(raw: Mapping[str, Any], key: str, problems: _Problems) -> dict[str, str]:
    table = _table(raw, key, problems)
    out: dict[str, str] = {}
    for tag, name in (table or {}).items():
        if not isinstance(name, str) or not name:
            problems.add(f"{tag!r} in [{key}] must name an FMU variable (a string), "
                         f"got {_type_name(name)} {name!r}")
        else:
            out[tag] = name
    return out


def _resolve(base: Path, value: str) -> Path:
    p = Path(value)
    try:
        p = p.expanduser()
    except RuntimeError:  # an unknown ~user: the path then does not exist, which is reported
        pass
    try:
        return p if p.is_absolute() else (base / p).resolve()
    except (OSError, ValueError):
        return base / p


def _csv_header(path: Path) -> list[str] | None:
    """Column names of a CSV file (first line), or ``None`` if it cannot be read as CSV."""
    if path.suffix.lower() != ".csv":
        return None
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            row = next(csv.reader(fh), None)
    except (OSError, UnicodeDecodeError):
        return None
    return [c.strip() for c in row] if row else None


def _long_tags(path: Path, column: int) -> list[str]:
    """The tags of a historian's long export (``tag,time,value``), in order of appearance."""
    tags: dict[str, None] = {}
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = csv.reader(fh)
            next(rows, None)
            for row in rows:
                if len(row) > column:
                    tags.setdefault(row[column].strip(), None)
    except (OSError, UnicodeDecodeError):
        return []
    return list(tags)


def _parse(raw: Mapping[str, Any], path: Path, *, check_files: bool) -> Spec:
    problems = _Problems(str(path))
    base = path.parent
    _check_keys(raw, _TOP_KEYS, _REQUIRED_TOP, "the top level", problems)

    # files -----------------------------------------------------------------
    files: dict[str, Path] = {}
    for key in ("twin", "measurements"):
        value = _string(raw, key, "the top level", problems)
        if value is None:
            continue
        resolved = _resolve(base, value)
        files[key] = resolved
        if check_files and not resolved.is_file():
            problems.add(f"{key} file {value!r} does not exist (looked for {resolved})")
    sample_time = _number(raw, "sample_time", "the top level", problems, positive=True)

    source = None
    src = _table(raw, "source", problems)
    if src is not None:
        _check_keys(src, ("path", "model"), ("path", "model"), "[source]", problems)
        spath = _string(src, "path", "[source]", problems)
        smodel = _string(src, "model", "[source]", problems)
        if spath is not None and smodel is not None:
            resolved = _resolve(base, spath)
            if check_files and not resolved.exists():
                problems.add(f"path {spath!r} in [source] does not exist (looked for {resolved})")
            source = SourceSpec(path=resolved, model=smodel)

    inputs = _string_map(raw, "inputs", problems)
    outputs = _string_map(raw, "outputs", problems)
    for tag in set(inputs) & set(outputs):
        problems.add(f"tag {tag!r} is both in [inputs] and [outputs]")

    # parameters ------------------------------------------------------------
    parameters: list[ParameterSpec] = []
    pkeys = ("name", "start", "min", "max")
    for i, table in enumerate(_array_of_tables(raw, "parameters", problems)):
        label = f"[[parameters]] #{i + 1}" + (f" ({table['name']!r})" if isinstance(table.get("name"), str) else "")
        _check_keys(table, (*pkeys, "interval"), pkeys, label, problems)
        name = _string(table, "name", label, problems)
        start = _number(table, "start", label, problems)
        lo = _number(table, "min", label, problems)
        hi = _number(table, "max", label, problems)
        if None in (name, start, lo, hi):
            continue
        assert name is not None and start is not None and lo is not None and hi is not None
        if lo >= hi:
            problems.add(f"lower bound min = {lo!r} is not below upper bound max = {hi!r} in {label}")
        elif not lo <= start <= hi:
            problems.add(f"start = {start!r} is outside its bounds [{lo!r}, {hi!r}] in {label}")
        if any(p.name == name for p in parameters):
            problems.add(f"parameter {name!r} is listed twice in [[parameters]]")
        interval = _parameter_interval(table, start, lo, hi, label, problems)  # trackingbox.identify
        parameters.append(ParameterSpec(name=name, start=start, min=lo, max=hi, interval=interval))
    pnames = [p.name for p in parameters]

    fixed: dict[str, float] = {}
    for name, value in (_table(raw, "fixed", problems) or {}).items():
        if not _is_number(value):
            problems.add(f"{name!r} in [fixed] must be a number, got {_type_name(value)} {value!r}")
            continue
        if name in pnames:
            problems.add(f"{name!r} is both a candidate in [[parameters]] and fixed in [fixed]")
        try:
            number = float(value)
        except OverflowError:
            problems.add(f"{name!r} in [fixed] is out of range: an integer of {len(str(value))} digits")
            continue
        if not math.isfinite(number):
            problems.add(f"{name!r} in [fixed] must be finite, got {number!r}")
            continue
        fixed[name] = number

    # windows ---------------------------------------------------------------
    windows: dict[str, tuple[float, float]] = {}
    wtable = _table(raw, "windows", problems)
    if wtable is not None:
        _check_keys(wtable, WINDOW_NAMES, (), "[windows]", problems)
        for name in WINDOW_NAMES:
            if name not in wtable:
                continue
            value = wtable[name]
            if (not isinstance(value, list) or len(value) != 2
                    or not all(_is_number(v) for v in value)):
                problems.add(f"{name!r} in [windows] must be [start, stop] in seconds, got {value!r}")
                continue
            try:
                lo, hi = float(value[0]), float(value[1])
            except OverflowError:
                problems.add(f"window {name!r} in [windows] has a bound out of range")
                continue
            if not (math.isfinite(lo) and math.isfinite(hi)):
                problems.add(f"window {name!r} in [windows] must have finite bounds, got [{lo!r}, {hi!r}]")
                continue
            if lo >= hi:
                problems.add(f"window {name!r} in [windows] has start {lo!r} >= stop {hi!r}")
                continue
            if lo < 0:
                problems.add(f"window {name!r} in [windows] starts before the first sample ({lo!r} < 0)")
            windows[name] = (lo, hi)
        if len(windows) == 2:
            (a0, a1), (b0, b1) = windows[WINDOW_NAMES[0]], windows[WINDOW_NAMES[1]]
            if a0 < b1 and b0 < a1:
                problems.add(f"windows {WINDOW_NAMES[0]!r} [{a0!r}, {a1!r}] and {WINDOW_NAMES[1]!r} "
                             f"[{b0!r}, {b1!r}] in [windows] overlap: held-out data must not be trained on")

    known_tags = [*inputs, *outputs]

    # data rules ------------------------------------------------------------
    data = DataRules()
    dtable = _table(raw, "data", problems)
    if dtable is not None:
        _check_keys(dtable, ("stoppage", "max_gap", "heartbeat"), (), "[data]", problems)
        stoppage = None
        stable = _table(dtable, "stoppage", problems)
        if stable is not None:
            label = "[data.stoppage]"
            _check_keys(stable, ("tag", "below", "settle"), ("tag", "below"), label, problems)
            tag = _string(stable, "tag", label, problems)
            below = _number(stable, "below", label, problems)
            settle = _number(stable, "settle", label, problems, default=0.0, nonnegative=True)
            if tag is not None and below is not None:
                stoppage = StoppageRule(tag=tag, below=below, settle=settle or 0.0)
        max_gap = _number(dtable, "max_gap", "[data]", problems, positive=True)
        heartbeat: dict[str, float] = {}
        if isinstance(dtable.get("heartbeat"), dict):
            for key in dtable["heartbeat"]:
                value = _number(dtable["heartbeat"], key, "[data.heartbeat]", problems, positive=True)
                if value is not None:
                    heartbeat[str(key)] = value
        elif "heartbeat" in dtable:
            value = _number(dtable, "heartbeat", "[data]", problems, positive=True)
            if value is not None:
                heartbeat["*"] = value
        data = DataRules(stoppage=stoppage, max_gap=max_gap, heartbeat=heartbeat)

    # pairs -----------------------------------------------------------------
    pairs: list[PairSpec] = []
    pair_keys = ("variable", "parameter", "gain", "time_constant", "lambda", "kp", "ti", "controller")
    for i, table in enumerate(_array_of_tables(raw, "pairs", problems)):
        label = f"[[pairs]] #{i + 1}"
        _check_keys(table, pair_keys, ("variable", "parameter", "gain", "time_constant"), label, problems)
        variable = _string(table, "variable", label, problems)
        parameter = _string(table, "parameter", label, problems)
        gain = _number(table, "gain", label, problems)
        tau = _number(table, "time_constant", label, problems, positive=True)
        lam = _number(table, "lambda", label, problems, default=1.0, positive=True)
        kp = _number(table, "kp", label, problems)
        ti = _number(table, "ti", label, problems, positive=True)
        controller = _string(table, "controller", label, problems) or "pi"
        if controller not in CONTROLLERS:
            problems.add(f"unknown controller {controller!r} in {label}{did_you_mean(controller, CONTROLLERS)}"
                         f"; choose one of {', '.join(CONTROLLERS)}")
        if variable is not None and variable not in outputs:
            problems.add(f"unknown tag {variable!r} as variable in {label}: a pair's variable must be "
                         f"a tag of [outputs]{did_you_mean(variable, list(outputs))}")
        if parameter is not None and parameter not in pnames:
            problems.add(f"unknown parameter {parameter!r} in {label}: a pair's parameter must be "
                         f"one of [[parameters]]{did_you_mean(parameter, pnames)}")
        if gain is not None and gain == 0.0:
            problems.add(f"gain in {label} is 0: the parameter has no effect on the variable")
        if None in (variable, parameter, gain, tau, lam):
            continue
        assert variable is not None and parameter is not None
        assert gain is not None and tau is not None and lam is not None
        pairs.append(PairSpec(variable=variable, parameter=parameter, gain=gain, time_constant=tau,
                              lambda_=lam, kp=kp, ti=ti,
                              controller=controller if controller in CONTROLLERS else "pi"))  # type: ignore[arg-type]
    for attr, what in (("variable", "tag"), ("parameter", "parameter")):
        values = [getattr(p, attr) for p in pairs]
        for v in sorted({v for v in values if values.count(v) > 1}):
            problems.add(f"{what} {v!r} appears in more than one [[pairs]] entry")

    # states ----------------------------------------------------------------
    states: list[StateSpec] = []
    skeys = ("tag", "variable", "correction", "gain")
    for i, table in enumerate(_array_of_tables(raw, "states", problems)):
        label = f"[[states]] #{i + 1}"
        _check_keys(table, skeys, skeys, label, problems)
        tag = _string(table, "tag", label, problems)
        variable = _string(table, "variable", label, problems)
        correction = _string(table, "correction", label, problems)
        gain = _number(table, "gain", label, problems, positive=True)
        if None in (tag, variable, correction, gain):
            continue
        assert tag is not None and variable is not None and correction is not None and gain is not None
        states.append(StateSpec(tag=tag, variable=variable, correction=correction, gain=gain))

    if data.stoppage is not None or data.heartbeat:
        known_tags += [st.tag for st in states]
    for tag in data.heartbeat:
        if tag != "*" and tag not in known_tags:
            problems.add(f"unknown tag {tag!r} in [data.heartbeat]{did_you_mean(tag, known_tags)}")
    if data.stoppage is not None:
        if data.stoppage.tag not in known_tags:
            problems.add(f"unknown tag {data.stoppage.tag!r} in [data.stoppage]"
                         f"{did_you_mean(data.stoppage.tag, known_tags)}")

    tracking = TrackingSettings()
    ttable = _table(raw, "tracking", problems)
    if ttable is not None:
        _check_keys(ttable, ("hold_until",), (), "[tracking]", problems)
        hold = _number(ttable, "hold_until", "[tracking]", problems, default=0.0, nonnegative=True)
        tracking = TrackingSettings(hold_until=hold or 0.0)

    balances = _parse_balances(raw, problems)
    diagnose = _parse_diagnose(raw, base, problems, check_files=check_files)
    live = _parse_live(raw, base, problems, [*inputs, *outputs, *(s.tag for s in states)])
    pairing = _parse_pairing(raw, problems)
    for tag, _ in pairing.scale:
        if tag not in outputs:
            problems.add(f"[pairing] scale names tag {tag!r}, which is not an [outputs] tag"
                         f"{did_you_mean(tag, list(outputs))}")

    # tags against the measurement file header --------------------------------
    meas = files.get("measurements")
    if check_files and meas is not None and meas.is_file():
        header = _csv_header(meas)
        if header is not None and sorted(header) == ["tag", "time", "value"]:
            # a historian's long export: the tags are the values of its 'tag' column
            header = ["time", *_long_tags(meas, header.index("tag"))]
        if header is not None:
            tags = [*inputs, *outputs, *(s.tag for s in states), *(t for b in balances for t in b.terms)]
            columns = [c for c in header if c != "time"]
            if "time" not in header:
                problems.add(f"measurements file {meas.name} has no 'time' column")
            for tag in dict.fromkeys(tags):
                if tag not in header:
                    problems.add(f"tag {tag!r} is not a column of {meas.name}{did_you_mean(tag, columns)}")

    problems.raise_if_any()
    assert sample_time is not None
    return Spec(path=path, twin=files["twin"], measurements=files["measurements"],
                sample_time=sample_time, source=source, inputs=inputs, outputs=outputs,
                parameters=tuple(parameters), fixed=fixed, windows=windows, data=data,
                pairs=tuple(pairs), states=tuple(states), tracking=tracking, balances=balances,
                diagnose=diagnose, live=live, pairing=pairing)


_LIVE_KEYS = ("nodes", "auth", "security", "mode", "certificate", "private_key", "server_certificate",
              "stale_after", "publish")


def _parse_live(raw: Mapping[str, Any], base: Path, problems: _Problems, tags: Sequence[str]) -> LiveSpec:
    table = _table(raw, "live", problems)
    if table is None:
        return LiveSpec()
    for secret in ("user", "username", "password", "credentials"):
        if secret in table:
            problems.add(f"{secret!r} in [live]: credentials are never kept in the spec; give them in the "
                         "environment (TRACKINGBOX_OPCUA_USER, TRACKINGBOX_OPCUA_PASSWORD) or a file "
                         "(trackingbox track --credentials FILE)")
    _check_keys({k: v for k, v in table.items() if k not in ("user", "username", "password", "credentials")},
                _LIVE_KEYS, (), "[live]", problems)
    nodes: dict[str, str] = {}
    raw_nodes = table.get("nodes", {})
    if not isinstance(raw_nodes, dict):
        problems.add(f"'nodes' in [live] must be a table tag = \"node id\", got {_type_name(raw_nodes)}")
        raw_nodes = {}
    for tag, node in raw_nodes.items():
        if not isinstance(node, str) or not node:
            problems.add(f"{tag!r} in [live.nodes] must be an OPC UA node id (e.g. \"ns=2;s={tag}\"), "
                         f"got {_type_name(node)} {node!r}")
        else:
            nodes[tag] = node
    for tag in nodes:
        if tag not in tags:
            problems.add(f"unknown tag {tag!r} in [live.nodes]{did_you_mean(tag, tags)}")
    auth = _string(table, "auth", "[live]", problems) or "anonymous"
    if auth not in ("anonymous", "user"):
        problems.add(f"'auth' in [live] must be \"anonymous\" or \"user\", got {auth!r}")
    security = _string(table, "security", "[live]", problems)
    if security is not None and security not in ("Basic256Sha256", "None"):
        problems.add(f"'security' in [live] must be \"Basic256Sha256\" or \"None\", got {security!r}")
    mode = _string(table, "mode", "[live]", problems) or "SignAndEncrypt"
    if mode not in ("SignAndEncrypt", "Sign"):
        problems.add(f"'mode' in [live] must be \"SignAndEncrypt\" or \"Sign\", got {mode!r}")
    paths: dict[str, Path | None] = {}
    for key in ("certificate", "private_key", "server_certificate"):
        value = _string(table, key, "[live]", problems)
        paths[key] = _resolve(base, value) if value is not None else None
    if security == "Basic256Sha256" and (paths["certificate"] is None or paths["private_key"] is None):
        problems.add("[live] security = \"Basic256Sha256\" needs 'certificate' and 'private_key' (the client's)")
    stale = _number(table, "stale_after", "[live]", problems, positive=True)
    publish = _string(table, "publish", "[live]", problems)
    if publish is not None and not publish.startswith("opc.tcp://"):
        problems.add(f"'publish' in [live] must be an opc.tcp:// endpoint, got {publish!r}")
    return LiveSpec(nodes=nodes, auth=auth, security=None if security == "None" else security, mode=mode,
                    certificate=paths["certificate"], private_key=paths["private_key"],
                    server_certificate=paths["server_certificate"], stale_after=stale, publish=publish)


def _parse_pairing(raw: Mapping[str, Any], problems: _Problems) -> PairingSettings:
    """``[pairing]``: ``freeze = { NAME = VALUE, ... }``, ``scale = { TAG = VALUE, ... }`` (numbers)."""
    table = _table(raw, "pairing", problems)
    if table is None:
        return PairingSettings()
    _check_keys(table, ("freeze", "scale", "closed_loop", "closed_loop_min", "max_leak", "max_jitter", "units"), (), "[pairing]",
                problems)
    out: dict[str, Any] = {}
    if "units" in table:
        units = table["units"]
        ident = re.compile(r"[A-Za-z_][A-Za-z0-9_.]*")
        if isinstance(units, list):
            units = {u: [] for u in units} if all(isinstance(u, str) for u in units) else None
        if (not isinstance(units, Mapping)
                or not all(isinstance(u, str) and ident.fullmatch(u) and isinstance(tags, list)
                           and all(isinstance(t, str) and ident.fullmatch(t) for t in tags)
                           for u, tags in units.items())):
            problems.add("[pairing] units must be a list of component array names (units = [\"effect\"]) or a table "
                         "of array name = [twin output array names] (units = { effect = [\"PI_steamChest\"] }), got "
                         f"{table['units']!r}")
        else:
            out["units"] = tuple((str(u), tuple(dict.fromkeys(tags))) for u, tags in units.items())
    if "closed_loop" in table:
        out["closed_loop"] = _number(table, "closed_loop", "[pairing]", problems, positive=True)
    if "closed_loop_min" in table:
        out["closed_loop_min"] = _number(table, "closed_loop_min", "[pairing]", problems, positive=True)
        slowest = out.get("closed_loop")
        if out["closed_loop_min"] is not None and (slowest is None or out["closed_loop_min"] > slowest):
            problems.add(f"'closed_loop_min' in [pairing] ({out['closed_loop_min']:g} s) needs a 'closed_loop' "
                         "at least as long (the loop every pair is tried with first)"
                         + (f", got {slowest:g} s" if slowest is not None else ""))
    if "max_leak" in table:
        out["max_leak"] = _number(table, "max_leak", "[pairing]", problems, positive=True)
    if "max_jitter" in table:
        out["max_jitter"] = _number(table, "max_jitter", "[pairing]", problems, positive=True)
    for key, example, positive in (("freeze", "holdControllers = 1", False), ("scale", '"TI-101" = 0.2', True)):
        value = table.get(key, {})
        if not isinstance(value, Mapping):
            problems.add(f"[pairing] {key} must be a table of NAME = VALUE (e.g. {key} = {{ {example} }}), "
                         f"got {_type_name(value)}")
            continue
        items = []
        for name, v in value.items():
            number = _number(value, name, f"[pairing.{key}]", problems, positive=positive)
            if number is not None:
                items.append((str(name), float(number)))
        out[key] = tuple(items)
    return PairingSettings(**out)


def _parse_diagnose(raw: Mapping[str, Any], base: Path, problems: _Problems, *,
                    check_files: bool) -> DiagnoseSpec:
    """``[diagnose]``: ``effects``, a list of folders (relative to the spec file) of user effect entries."""
    table = _table(raw, "diagnose", problems)
    if table is None:
        return DiagnoseSpec()
    _check_keys(table, ("effects",), (), "[diagnose]", problems)
    value = table.get("effects", [])
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        problems.add(f"effects in [diagnose] must be a list of folder paths (strings), got {value!r}")
        return DiagnoseSpec()
    folders: list[Path] = []
    for item in value:
        resolved = _resolve(base, item)
        if check_files and not resolved.is_dir():
            problems.add(f"effects folder {item!r} in [diagnose] does not exist (looked for {resolved})")
        folders.append(resolved)
    return DiagnoseSpec(effects=tuple(folders))


def _parse_balances(raw: Mapping[str, Any], problems: _Problems) -> tuple[BalanceSpec, ...]:
    """``[[balances]]``: name, terms (tag -> nonzero factor, at least two), optional tolerance >= 0."""
    out: list[BalanceSpec] = []
    keys = ("name", "terms", "tolerance")
    names: list[str] = []
    for i, table in enumerate(_array_of_tables(raw, "balances", problems)):
        label = f"[[balances]] #{i + 1}"
        _check_keys(table, keys, ("name", "terms"), label, problems)
        name = _string(table, "name", label, problems)
        tolerance = _number(table, "tolerance", label, problems, default=0.0, nonnegative=True)
        terms = table.get("terms")
        if "terms" in table and not isinstance(terms, dict):
            problems.add(f"'terms' in {label} must be a table of tag = factor, got {_type_name(terms)}")
            continue
        parsed: dict[str, float] = {}
        for tag, factor in (terms or {}).items():
            if not _is_number(factor) or float(factor) == 0.0:
                problems.add(f"factor of tag {tag!r} in {label} terms must be a nonzero number, got {factor!r}")
            else:
                parsed[str(tag)] = float(factor)
        if terms is not None and len(terms) < 2:
            problems.add(f"{label} terms need at least two tags, got {len(terms)}")
        if name is not None and name in names:
            problems.add(f"{label}: balance name {name!r} is used twice")
        if name is None or len(parsed) < 2 or len(parsed) != len(terms or {}):
            continue
        names.append(name)
        out.append(BalanceSpec(name=name, terms=parsed, tolerance=tolerance or 0.0))
    return tuple(out)


def load_spec(path: str | os.PathLike[str], *, check_files: bool = True) -> Spec:
    """Load and validate a ``spec.toml``.

    Parameters
    ----------
    path : path-like
        The spec file.
    check_files : bool
        Also check that the twin, measurement and source files exist and that
        every tag is a column of the measurement file.

    Returns
    -------
    Spec

    Raises
    ------
    SpecError
        Listing every problem found (unknown/missing keys, wrong types, bad bounds
        and windows, missing files, pairs naming unknown tags or parameters).
    """
    from .errors import TrackingError
    from .io import user_path

    try:
        path = user_path(path, "spec file").resolve()
    except TrackingError as exc:
        raise SpecError(str(exc)) from None
    except (OSError, RuntimeError) as exc:
        raise SpecError(f"spec file {_short(str(path))}: cannot be resolved ({exc})") from None
    if path.is_dir():
        raise SpecError(f"spec file {_short(str(path))} is a directory, not a spec.toml")
    try:
        if path.exists() and not path.is_file():
            raise SpecError(f"spec file {_short(str(path))} is not a regular file")
        size = path.stat().st_size
        if size > _MAX_SPEC_BYTES:
            raise SpecError(f"spec file {_short(str(path))} is {size} bytes; a spec is at most "
                            f"{_MAX_SPEC_BYTES} bytes")
        data = path.read_bytes()
    except FileNotFoundError:
        raise SpecError(f"spec file {_short(str(path))} does not exist") from None
    except OSError as exc:
        raise SpecError(f"cannot read spec file {_short(str(path))}: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise SpecError(f"{path}: line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                        f"{exc.start}); save the spec as UTF-8") from None
    return loads_spec(text.removeprefix("\ufeff"), path, check_files=check_files)


#: largest spec file read (bytes): a spec is a few kB
_MAX_SPEC_BYTES = 10 << 20


def _short(text: str, limit: int = 160) -> str:
    return text if len(text) <= limit else f"{text[:limit // 2]}...{text[-(limit // 2):]}"


def loads_spec(text: str, path: str | os.PathLike[str], *, check_files: bool = True) -> Spec:
    """Parse spec text as if it were the file *path* (relative paths resolve against it)."""
    path = Path(path).expanduser().resolve()
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: not valid TOML: {_short(str(exc), 300)}") from None
    except RecursionError:
        raise SpecError(f"{path}: not valid TOML: arrays or tables nested too deeply") from None
    except ValueError as exc:  # e.g. an integer beyond Python's digit limit
        raise SpecError(f"{path}: not valid TOML: {_short(str(exc), 300)}") from None
    spec = _parse(raw, path, check_files=check_files)
    log.debug("loaded spec %s: %d inputs, %d outputs, %d parameters, %d pairs",
              path, len(spec.inputs), len(spec.outputs), len(spec.parameters), len(spec.pairs))
    return spec


# --------------------------------------------------------------------------- FMU check

def check_against_fmu(spec: Spec, info: FMUInfo | None = None) -> None:
    """Check that the spec's FMU names exist in the twin FMU (with did-you-mean).

    Parameters
    ----------
    spec : Spec
    info : FMUInfo, optional
        The twin's model description; read from ``spec.twin`` if not given.

    Raises
    ------
    SpecError
        Listing every input, output, parameter, fixed value or state variable the
        FMU does not have (or has with the wrong causality), and candidate bounds
        outside the bounds the FMU declares.
    """
    if info is None:
        from .fmu import read_info  # lazy: fmu pulls in fmpy

        info = read_info(spec.twin)
    variables = {v.name: v for v in info.variables}
    names = list(variables)
    by_causality: dict[str, list[str]] = {}
    for v in info.variables:
        by_causality.setdefault(v.causality, []).append(v.name)
    twin = Path(spec.twin).name
    problems = _Problems(str(spec.path))

    def need(name: str, causalities: Iterable[str] | None, what: str, where: str) -> None:
        allowed = tuple(causalities) if causalities is not None else None
        pool = names if allowed is None else [n for c in allowed for n in by_causality.get(c, [])]
        v = variables.get(name)
        if v is None:
            problems.add(f"{where} names {what} {name!r}, which {twin} does not have{did_you_mean(name, pool)}")
        elif allowed is not None and v.causality not in allowed:
            problems.add(f"{where} names {what} {name!r}, but in {twin} it has causality "
                         f"{v.causality!r}, not {' or '.join(repr(c) for c in allowed)}"
                         f"{did_you_mean(name, pool)}")

    for tag, name in spec.inputs.items():
        need(name, ("input",), "input", f"[inputs] {tag!r}")
    for tag, name in spec.outputs.items():
        need(name, None, "variable", f"[outputs] {tag!r}")
    for p in spec.parameters:
        need(p.name, ("parameter",), "parameter", "[[parameters]]")
        v = variables.get(p.name)
        if v is not None and v.causality == "parameter":
            if v.min is not None and p.min < float(v.min):
                problems.add(f"min = {p.min!r} of parameter {p.name!r} is below the min = {v.min!r} "
                             f"{twin} declares")
            if v.max is not None and p.max > float(v.max):
                problems.add(f"max = {p.max!r} of parameter {p.name!r} is above the max = {v.max!r} "
                             f"{twin} declares")
    for p in spec.parameters:
        v = variables.get(p.name)
        if v is not None and v.causality == "parameter":
            if v.min is not None and p.start < float(v.min) or v.max is not None and p.start > float(v.max):
                problems.add(f"start = {p.start!r} of parameter {p.name!r} is outside [{v.min!r}, {v.max!r}] "
                             f"that {twin} declares")
    for name, value in spec.fixed.items():
        need(name, ("parameter",), "parameter", "[fixed]")
        v = variables.get(name)
        if v is not None and v.causality == "parameter":
            if v.min is not None and value < float(v.min):
                problems.add(f"[fixed] {name} = {value!r} is below the min = {v.min!r} {twin} declares")
            if v.max is not None and value > float(v.max):
                problems.add(f"[fixed] {name} = {value!r} is above the max = {v.max!r} {twin} declares")
    for s in spec.states:
        need(s.variable, None, "variable", f"[[states]] {s.tag!r}")
        need(s.correction, ("input",), "input", f"[[states]] {s.tag!r} correction")
    for name, _ in spec.pairing.freeze:
        need(name, ("input", "parameter"), "freeze input or parameter", "[pairing] freeze")
    problems.raise_if_any()


# --------------------------------------------------------------------------- writing

def _rel(path: Path, base: Path, *, outside: bool = True) -> str:
    """*path* relative to *base*; if *outside* is false, absolute unless it lies under *base*."""
    try:
        rel = Path(os.path.relpath(path, base))
    except ValueError:  # different drive on Windows
        return path.as_posix()
    if not outside and rel.parts[:1] == ("..",):
        return path.as_posix()
    return rel.as_posix()


def _pair_dict(p: PairSpec) -> dict[str, Any]:
    d: dict[str, Any] = {"variable": p.variable, "parameter": p.parameter, "gain": float(p.gain),
                         "time_constant": float(p.time_constant), "lambda": float(p.lambda_)}
    if p.kp is not None:
        d["kp"] = float(p.kp)
    if p.ti is not None:
        d["ti"] = float(p.ti)
    if p.controller != "pi":
        d["controller"] = p.controller
    return d


def spec_to_dict(spec: Spec) -> dict[str, Any]:
    """The TOML document of *spec* as a dict (paths relative to the spec file)."""
    base = spec.path.parent
    doc: dict[str, Any] = {
        "twin": _rel(spec.twin, base),
        "measurements": _rel(spec.measurements, base),
        "sample_time": float(spec.sample_time),
    }
    if spec.source is not None:
        # a library outside the case directory is named absolutely: it does not move with the case
        doc["source"] = {"path": _rel(spec.source.path, base, outside=False), "model": spec.source.model}
    doc["inputs"] = dict(spec.inputs)
    doc["outputs"] = dict(spec.outputs)
    if spec.parameters:
        doc["parameters"] = [{"name": p.name, "start": float(p.start), "min": float(p.min),
                              "max": float(p.max), **({"interval": [float(v) for v in p.interval]}
                                                      if p.interval is not None else {})}
                             for p in spec.parameters]
    if spec.fixed:
        doc["fixed"] = {k: float(v) for k, v in spec.fixed.items()}
    if spec.windows:
        doc["windows"] = {k: [float(a), float(b)] for k, (a, b) in spec.windows.items()}
    if spec.data.stoppage is not None or spec.data.max_gap is not None or spec.data.heartbeat:
        data: dict[str, Any] = {}
        if spec.data.stoppage is not None:
            st = spec.data.stoppage
            data["stoppage"] = {"tag": st.tag, "below": float(st.below)}
            if st.settle:
                data["stoppage"]["settle"] = float(st.settle)
        if spec.data.max_gap is not None:
            data["max_gap"] = float(spec.data.max_gap)
        if set(spec.data.heartbeat) == {"*"}:
            data["heartbeat"] = float(spec.data.heartbeat["*"])
        elif spec.data.heartbeat:
            data["heartbeat"] = {k: float(v) for k, v in spec.data.heartbeat.items()}
        doc["data"] = data
    if spec.pairs:
        doc["pairs"] = [_pair_dict(p) for p in spec.pairs]
    if spec.states:
        doc["states"] = [{"tag": s.tag, "variable": s.variable, "correction": s.correction,
                          "gain": float(s.gain)} for s in spec.states]
    if spec.tracking != TrackingSettings():
        doc["tracking"] = {"hold_until": float(spec.tracking.hold_until)}
    if spec.pairing != PairingSettings():
        doc["pairing"] = {key: {k: float(v) for k, v in getattr(spec.pairing, key)}
                          for key in ("freeze", "scale") if getattr(spec.pairing, key)}
        if spec.pairing.closed_loop is not None:
            doc["pairing"]["closed_loop"] = float(spec.pairing.closed_loop)
        if spec.pairing.closed_loop_min is not None:
            doc["pairing"]["closed_loop_min"] = float(spec.pairing.closed_loop_min)
        if spec.pairing.max_leak is not None:
            doc["pairing"]["max_leak"] = float(spec.pairing.max_leak)
        if spec.pairing.max_jitter is not None:
            doc["pairing"]["max_jitter"] = float(spec.pairing.max_jitter)
        if spec.pairing.units:
            doc["pairing"]["units"] = {u: list(tags) for u, tags in spec.pairing.units}
    if spec.diagnose.effects:
        doc["diagnose"] = {"effects": [_rel(f, base, outside=False) for f in spec.diagnose.effects]}
    if spec.balances:
        doc["balances"] = [{"name": b.name, "terms": dict(b.terms),
                            **({"tolerance": float(b.tolerance)} if b.tolerance else {})} for b in spec.balances]
    return doc


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.match(key) else _toml_value(key)


def _toml_value(value: Any) -> str:
    """One TOML value on one line (strings, finite numbers, booleans, flat arrays, inline tables)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return tomli_w.dumps({"v": value})[len("v = "):].rstrip("\n")
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {value!r} to TOML")


def _emit(doc: Mapping[str, Any], header: str = "") -> str:
    """TOML text in the layout of docs/architecture.md: scalars, then tables, then arrays of tables."""
    lines: list[str] = [f"# {h}" if h else "#" for h in header.splitlines()] if header else []
    for key, value in doc.items():
        if not isinstance(value, (dict, list)) or (isinstance(value, list) and not
                                                   any(isinstance(v, dict) for v in value)):
            lines.append(f"{_toml_key(key)} = {_toml_value(value)}")
    for key, value in doc.items():
        if isinstance(value, dict):
            lines += ["", f"[{_toml_key(key)}]"]
            lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()]
        elif isinstance(value, list) and any(isinstance(v, dict) for v in value):
            for item in value:
                lines += ["", f"[[{_toml_key(key)}]]"]
                lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


def dump_spec(spec: Spec, *, header: str = "") -> str:
    """Return the TOML text of *spec* (paths relative to ``spec.path``); it loads back equal.

    Parameters
    ----------
    spec : Spec
    header : str
        Optional comment lines put at the top of the file.
    """
    return _emit(spec_to_dict(spec), header)


def write_spec(spec: Spec, path: str | os.PathLike[str] | None = None, *, header: str = "") -> Path:
    """Write *spec* atomically to *path* (default ``spec.path``); relative paths follow the new file."""
    target = Path(path).expanduser().resolve() if path is not None else spec.path
    spec = replace(spec, path=target)
    write_text_atomic(target, dump_spec(spec, header=header))
    return target


def _trailing_trivia(table: tomlkit.items.Table) -> list[tomlkit.items.Item]:
    """Comments and blank lines at the end of *table*'s body (they precede the next header).

    TOML has no notion of a comment "belonging" to the table after it, so tomlkit
    keeps ``# about [tracking]`` in the body of the table before ``[tracking]``.
    When that table is replaced, these lines are carried over.
    """
    body = table.value.body
    n = len(body)
    while n and body[n - 1][0] is None and isinstance(body[n - 1][1], (Comment, Whitespace)):
        n -= 1
    trivia = [item for _, item in body[n:]]
    del body[n:]
    return trivia


def _previous_table(doc: tomlkit.TOMLDocument, key: str) -> tomlkit.items.Table | None:
    """The table (or last table of an array of tables) just before *key* at the top level."""
    previous = None
    for k, item in doc.body:
        if k is not None and k.key == key:
            return previous
        if isinstance(item, Table):
            previous = item
        elif isinstance(item, AoT) and len(item):
            previous = item[-1]
        elif k is not None:
            previous = None
    return None


def _set_pairs(doc: tomlkit.TOMLDocument, pairs: tuple[PairSpec, ...]) -> None:
    """Replace the document's ``[[pairs]]`` by *pairs*, keeping the comments around them."""
    tables = []
    for pair in pairs:
        table = tomlkit.table()
        for k, v in _pair_dict(pair).items():
            table[k] = v
        tables.append(table)
    old = doc.get("pairs")
    if isinstance(old, AoT) and len(old):
        trivia = _trailing_trivia(old[-1])
        if tables:  # replace in place: the pairs stay where the user put them
            # a comment on the first header (``[[pairs]]  # chosen by pair``) stays on it
            tables[0].trivia.comment_ws = old[0].trivia.comment_ws
            tables[0].trivia.comment = old[0].trivia.comment
            while len(old):
                del old[0]
            for i, table in enumerate(tables):
                if i:  # a blank line between tables, as the user's file has
                    old[-1].add(tomlkit.nl())
                old.append(table)
            host: tomlkit.items.Table | None = old[-1]
        else:
            host = _previous_table(doc, "pairs")
            del doc["pairs"]
        if host is not None:
            body = host.value.body
            if body and body[-1][0] is None and isinstance(body[-1][1], Whitespace):
                while trivia and isinstance(trivia[0], Whitespace):  # no double blank line
                    trivia.pop(0)
            for item in trivia:
                host.value.append(None, item)
        elif any(isinstance(item, Comment) for item in trivia):
            log.warning("comments after the last [[pairs]] table have no table to stay with; dropped")
        return
    if old is not None:  # e.g. an inline ``pairs = [...]``: the tables go to the end
        del doc["pairs"]
    if tables:
        aot = tomlkit.aot()
        for table in tables:
            aot.append(table)
        doc.append("pairs", aot)


def _set_starts(doc: tomlkit.TOMLDocument, starts: Mapping[str, float]) -> None:
    """Set ``start`` of the named ``[[parameters]]`` entries (tables or inline tables)."""
    for table in doc.get("parameters", ()):
        name = table.get("name")
        if isinstance(name, str) and str(name) in starts:
            table["start"] = float(starts[str(name)])


def _parameter_interval(table: Mapping[str, Any], start: float, lo: float, hi: float, label: str,
                        problems: _Problems) -> tuple[float, float] | None:
    """``interval = [a, b]`` of a ``[[parameters]]`` entry: two numbers, ``min <= a <= start <= b <= max``."""
    if "interval" not in table:
        return None
    value = table["interval"]
    if not (isinstance(value, list) and len(value) == 2 and all(_is_number(v) for v in value)):
        problems.add(f"'interval' in {label} must be [lower, upper] (two numbers), got {value!r}")
        return None
    a, b = float(value[0]), float(value[1])
    if not (math.isfinite(a) and math.isfinite(b) and lo <= a <= start <= b <= hi):
        problems.add(f"interval = [{a!r}, {b!r}] in {label} must hold its start {start!r} and lie within "
                     f"its bounds [{lo!r}, {hi!r}]")
        return None
    return (a, b)


def _set_intervals(doc: tomlkit.TOMLDocument, starts: Mapping[str, float],
                   intervals: Mapping[str, tuple[float, float]]) -> None:
    """The ``interval`` of each parameter whose start is written: the new one, or none (it was the old start's)."""
    for table in doc.get("parameters", ()):
        name = table.get("name")
        if not isinstance(name, str) or str(name) not in starts:
            continue
        if str(name) in intervals:
            a, b = intervals[str(name)]
            table["interval"] = [float(a), float(b)]
        elif "interval" in table:
            del table["interval"]


def _check_starts(old: Spec, starts: Mapping[str, float]) -> None:
    names = list(old.parameter_names)
    problems = _Problems(str(old.path))
    for name, value in starts.items():
        if name not in names:
            problems.add(unknown_name("parameter", name, names, "[[parameters]]"))
            continue
        p = old.parameter(name)
        if not (math.isfinite(float(value)) and p.min <= float(value) <= p.max):
            problems.add(f"start {float(value)!r} of {name!r} is outside its bounds "
                         f"[{p.min!r}, {p.max!r}] in [[parameters]]")
    problems.raise_if_any()


def update_spec(path: str | os.PathLike[str], *, pairs: Iterable[PairSpec] | None = None,
                starts: Mapping[str, float] | None = None,
                intervals: Mapping[str, tuple[float, float]] | None = None) -> Spec:
    """Write pairs and/or parameter start values into the spec file *path*, atomically.

    The file is edited as a TOML document (tomlkit), so everything the call does
    not change -- comments, blank lines, key order, spacing, inline tables -- is
    kept byte for byte. The new text is loaded back and checked (it must be a
    valid spec equal to the old one with exactly these changes) before it
    replaces the file; on any problem the file is left untouched.

    Parameters
    ----------
    path : path-like
        The spec file.
    pairs : iterable of PairSpec, optional
        The new ``[[pairs]]`` (they replace all existing ones; empty removes
        them). ``None`` leaves the pairs alone.
    starts : mapping of str to float, optional
        New ``start`` values of named ``[[parameters]]``.
    intervals : mapping of str to (float, float), optional
        The confidence intervals of those starts (``interval = [a, b]``); a start written
        without one loses the interval it had (it belonged to the old start).

    Returns
    -------
    Spec
        The spec as written.

    Raises
    ------
    SpecError
        The file is not a valid spec, a start names an unknown parameter or lies
        outside its bounds, or a pair names an unknown tag or parameter.

    Examples
    --------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / "spec.toml").write_text(
    ...     'twin = "twin.fmu"  # the twin\\n'
    ...     'measurements = "data.csv"\\nsample_time = 10.0\\n'
    ...     '[outputs]\\n"TI-1" = "T"\\n'
    ...     '[[parameters]]\\nname = "k"\\nstart = 1.0  # first guess\\nmin = 0.0\\nmax = 2.0\\n')
    >>> spec = update_spec(folder / "spec.toml", starts={"k": 1.25})
    >>> spec.parameter("k").start
    1.25
    >>> print((folder / "spec.toml").read_text().splitlines()[-3])
    start = 1.25  # first guess
    """
    path = Path(path).expanduser().resolve()
    old = load_spec(path, check_files=False)
    new_pairs = tuple(pairs) if pairs is not None else old.pairs
    new_starts = dict(starts or {})
    _check_starts(old, new_starts)
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise SpecError(f"cannot read spec file {path}: {exc}") from None
    doc = tomlkit.parse(text)
    if pairs is not None:
        _set_pairs(doc, new_pairs)
    new_intervals = {k: (float(v[0]), float(v[1])) for k, v in dict(intervals or {}).items() if k in new_starts}
    if new_starts:
        _set_starts(doc, new_starts)
        _set_intervals(doc, new_starts, new_intervals)
    new_text = tomlkit.dumps(doc)
    new = loads_spec(new_text, path, check_files=False)
    wanted = replace(old, pairs=new_pairs, parameters=tuple(
        replace(p, start=float(new_starts[p.name]), interval=new_intervals.get(p.name))
        if p.name in new_starts else p for p in old.parameters))
    if new != wanted:
        raise SpecError(f"{path}: writing back {len(new_pairs)} pairs and {len(new_starts)} start "
                        f"values did not give the expected spec; the file is left unchanged")
    write_text_atomic(path, new_text)
    log.info("updated %s: %s", path, ", ".join(
        [*([f"{len(new_pairs)} pairs"] if pairs is not None else []),
         *([f"start of {', '.join(new_starts)}"] if new_starts else [])]) or "nothing")
    return new


def write_pairs(path: str | os.PathLike[str], pairs: Iterable[PairSpec]) -> Spec:
    """Replace the ``[[pairs]]`` of the spec file *path* by *pairs*, atomically.

    A thin call of :func:`update_spec`: everything else in the file, comments
    included, is kept, and the new file is validated before it replaces the old one.

    Returns
    -------
    Spec
        The spec as written.
    """
    return update_spec(path, pairs=pairs)


def write_starts(path: str | os.PathLike[str], values: Mapping[str, float],
                 intervals: Mapping[str, tuple[float, float]] | None = None) -> Spec:
    """Write *values* as the ``start`` of the spec file's ``[[parameters]]``, atomically.

    A thin call of :func:`update_spec`: only the ``start`` values of the named
    parameters change; comments and layout are kept.

    Returns
    -------
    Spec
        The spec as written.

    Raises
    ------
    SpecError
        A name in *values* is not one of the spec's parameters, or a value is
        outside its bounds.
    """
    return update_spec(path, starts=values, intervals=intervals)
