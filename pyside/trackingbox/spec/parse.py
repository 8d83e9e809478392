"""Loading a spec: :func:`load_spec` collects *every* problem it finds and raises one
:class:`~trackingbox.errors.SpecError` listing them all, each naming the key, the table and the
file; :func:`check_against_fmu` checks the names against the twin FMU.
"""
from __future__ import annotations

import csv
import errno
import logging
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]


from ..errors import SpecError, TrackingError, did_you_mean
from ..fmu import read_info
from ..io import user_path

if TYPE_CHECKING:  # pragma: no cover
    from ..fmu import FMUInfo


from .model import (
    CONTROLLERS,
    INITIAL_STATES,
    INPUT_RULES,
    WINDOW_NAMES,
    BalanceSpec,
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

log = logging.getLogger(__name__)

# --------------------------------------------------------------------------- parsing

VARYING_KINDS = ("rising", "falling", "free")
_TOP_KEYS = ("twin", "measurements", "sample_time", "source", "inputs", "outputs", "parameters",
             "fixed", "fixed_intervals", "windows", "data", "pairs", "states", "tracking",
             "balances", "diagnose", "live", "pairing")
_REQUIRED_TOP = ("twin", "measurements", "sample_time", "outputs")


#: longest problem message (characters); longer ones are shortened in the middle
_MAX_MESSAGE = 400


class Problems:
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
                label: str, problems: Problems) -> None:
    for key in table:
        if key not in allowed:
            problems.add(f"unknown key {key!r} in {label}{did_you_mean(key, allowed)}")
    for key in required:
        if key not in table:
            problems.add(f"missing required key {key!r} in {label}")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number(table: Mapping[str, Any], key: str, label: str, problems: Problems, *,
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


def _string(table: Mapping[str, Any], key: str, label: str, problems: Problems) -> str | None:
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


def _table(raw: Mapping[str, Any], key: str, problems: Problems) -> dict[str, Any] | None:
    if key not in raw:
        return None
    value = raw[key]
    if not isinstance(value, dict):
        problems.add(f"{key!r} must be a table ([{key}]), got {_type_name(value)}")
        return None
    return value


def _array_of_tables(raw: Mapping[str, Any], key: str, problems: Problems) -> list[dict[str, Any]]:
    if key not in raw:
        return []
    value = raw[key]
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        problems.add(f"{key!r} must be an array of tables ([[{key}]]), got {_type_name(value)}")
        return []
    return value


def _string_map(raw: Mapping[str, Any], key: str, problems: Problems) -> dict[str, str]:
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
    except (OSError, ValueError, RuntimeError):  # RuntimeError: a symlink loop (Python < 3.13), then reported
        return base / p


def _absent(path: Path) -> str:
    """Why *path* cannot be used as a file or folder: it does not exist, or it is a loop of symbolic links."""
    try:
        path.resolve(strict=True)
    except RuntimeError:  # Python < 3.13
        return "is a loop of symbolic links"
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "is a loop of symbolic links"
    return "does not exist"


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
    problems = Problems(str(path))
    base = path.parent
    _check_keys(raw, _TOP_KEYS, _REQUIRED_TOP, "the top level", problems)
    files, sample_time, source = _parse_files(raw, base, problems, check_files=check_files)
    inputs = _string_map(raw, "inputs", problems)
    outputs = _string_map(raw, "outputs", problems)
    for tag in set(inputs) & set(outputs):
        problems.add(f"tag {tag!r} is both in [inputs] and [outputs]")

    parameters, fixed = _parse_parameters(raw, problems)
    fixed_intervals = _parse_fixed_intervals(raw, fixed, problems)
    pnames = [p.name for p in parameters]
    windows = _parse_windows(raw, problems)
    known_tags = [*inputs, *outputs]
    data = _parse_data(raw, problems)
    pairs = _parse_pairs(raw, problems, outputs, pnames)
    states = _parse_states(raw, problems)
    _check_data_tags(data, known_tags, states, problems)
    tracking = _parse_tracking(raw, problems)
    balances = _parse_balances(raw, problems)
    diagnose = _parse_diagnose(raw, base, problems, check_files=check_files, parameters=pnames)
    live = _parse_live(raw, base, problems, [*inputs, *outputs, *(s.tag for s in states)])
    pairing = _parse_pairing(raw, problems)
    for tag, _ in pairing.scale:
        if tag not in outputs:
            problems.add(f"[pairing] scale names tag {tag!r}, which is not an [outputs] tag"
                         f"{did_you_mean(tag, list(outputs))}")
    if check_files:
        _check_header(files.get("measurements"), [*inputs, *outputs, *(s.tag for s in states),
                                                  *(t for b in balances for t in b.terms)], problems)
    problems.raise_if_any()
    assert sample_time is not None
    return Spec(path=path, twin=files["twin"], measurements=files["measurements"],
                sample_time=sample_time, source=source, inputs=inputs, outputs=outputs,
                parameters=tuple(parameters), fixed=fixed, fixed_intervals=fixed_intervals, windows=windows, data=data,
                pairs=tuple(pairs), states=tuple(states), tracking=tracking, balances=balances,
                diagnose=diagnose, live=live, pairing=pairing)


def _parse_files(raw: Mapping[str, Any], base: Path, problems: Problems, *, check_files: bool
                 ) -> tuple[dict[str, Path], float | None, SourceSpec | None]:
    """``twin``, ``measurements`` (resolved against the spec's folder), ``sample_time`` and ``[source]``."""
    # files -----------------------------------------------------------------
    files: dict[str, Path] = {}
    for key in ("twin", "measurements"):
        value = _string(raw, key, "the top level", problems)
        if value is None:
            continue
        resolved = _resolve(base, value)
        files[key] = resolved
        if check_files and not resolved.is_file():
            problems.add(f"{key} file {value!r} {_absent(resolved)} (looked for {resolved})")
    sample_time = _number(raw, "sample_time", "the top level", problems, positive=True)

    source = None
    src = _table(raw, "source", problems)
    if src is not None:
        _check_keys(src, ("path", "model", "libraries"), ("path", "model"), "[source]", problems)
        spath = _string(src, "path", "[source]", problems)
        smodel = _string(src, "model", "[source]", problems)
        libraries: list[Path] = []
        raw_libs = src.get("libraries", [])
        if not isinstance(raw_libs, list) or not all(isinstance(x, str) and x for x in raw_libs):
            problems.add(f"libraries in [source] must be a list of paths (Modelica package directories or .mo "
                         f"files), got {raw_libs!r}")
            raw_libs = []
        for lib in raw_libs:
            resolved_lib = _resolve(base, lib)
            libraries.append(resolved_lib)
            if check_files and not resolved_lib.exists():
                problems.add(f"library {lib!r} in [source] libraries {_absent(resolved_lib)} "
                             f"(looked for {resolved_lib})")
        if spath is not None and smodel is not None:
            resolved = _resolve(base, spath)
            if check_files and not resolved.exists():
                problems.add(f"path {spath!r} in [source] {_absent(resolved)} (looked for {resolved})")
            source = SourceSpec(path=resolved, model=smodel, libraries=tuple(libraries))

    return files, sample_time, source


def _parse_parameters(raw: Mapping[str, Any], problems: Problems) -> tuple[list[ParameterSpec], dict[str, float]]:
    """``[[parameters]]`` (name, start, min, max) and ``[fixed]``."""
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

    return parameters, fixed


def _parameter_interval(table: Mapping[str, Any], start: float, lo: float, hi: float, label: str,
                        problems: Problems) -> tuple[float, float] | None:
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


def _parse_fixed_intervals(raw: Mapping[str, Any], fixed: Mapping[str, float],
                           problems: Problems) -> dict[str, tuple[float, float]]:
    """``[fixed_intervals]``: ``name = [a, b]``, the confidence interval of a ``[fixed]`` value (``a <= it <= b``)."""
    out: dict[str, tuple[float, float]] = {}
    for name, value in (_table(raw, "fixed_intervals", problems) or {}).items():
        if name not in fixed:
            problems.add(f"{name!r} in [fixed_intervals] is not in [fixed]{did_you_mean(name, list(fixed))}")
        elif not (isinstance(value, list) and len(value) == 2 and all(_is_number(v) and abs(v) < 1e308 for v in value)
                  and value[0] <= fixed[name] <= value[1]):  # finite (a huge integer would overflow a float)
            problems.add(f"[fixed_intervals] {name} = {value!r} must be [lower, upper] (two finite numbers) "
                         f"holding its [fixed] value {fixed[name]!r}")
        else:
            out[name] = (float(value[0]), float(value[1]))
    return out


def _parse_windows(raw: Mapping[str, Any], problems: Problems) -> dict[str, tuple[float, float]]:
    """``[windows]``: training and validation ``[start, stop]`` s, not overlapping."""
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

    return windows


def _parse_data(raw: Mapping[str, Any], problems: Problems) -> DataRules:
    """``[data]``: the stoppage rule, the longest gap, the heartbeats."""
    data = DataRules()
    dtable = _table(raw, "data", problems)
    if dtable is not None:
        _check_keys(dtable, ("stoppage", "max_gap", "heartbeat", "inputs", "initial", "carry"), (), "[data]",
                    problems)
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
        choices = {"inputs": INPUT_RULES, "initial": INITIAL_STATES}
        chosen = {}
        for key, allowed in choices.items():
            value = _string(dtable, key, "[data]", problems) if key in dtable else allowed[0]
            if value is not None and value not in allowed:
                problems.add(f"[data] {key} = {value!r} is not one of {', '.join(repr(a) for a in allowed)}"
                             f"{did_you_mean(value, allowed)}")
                value = None
            chosen[key] = value or allowed[0]
        if not isinstance(carry := dtable.get("carry", []), list) or not all(isinstance(c, str) for c in carry):
            problems.add(f"[data] carry must be a list of the twin's state names, got {carry!r}")
        data = DataRules(stoppage=stoppage, max_gap=max_gap, heartbeat=heartbeat,
                         carry=tuple(carry) if isinstance(carry, list) else (), **chosen)
    return data


def _parse_pairs(raw: Mapping[str, Any], problems: Problems, outputs: Mapping[str, str],
                 pnames: Sequence[str]) -> list[PairSpec]:
    """``[[pairs]]``: each an [outputs] tag and a [[parameters]] name, once each."""
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

    return pairs


def _parse_states(raw: Mapping[str, Any], problems: Problems) -> list[StateSpec]:
    """``[[states]]``: the compensated levels."""
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

    return states


def _check_data_tags(data: DataRules, known_tags: list[str], states: Sequence[StateSpec],
                     problems: Problems) -> None:
    """The tags ``[data]`` names are tags of the spec."""
    if data.stoppage is not None or data.heartbeat:
        known_tags += [st.tag for st in states]
    for tag in data.heartbeat:
        if tag != "*" and tag not in known_tags:
            problems.add(f"unknown tag {tag!r} in [data.heartbeat]{did_you_mean(tag, known_tags)}")
    if data.stoppage is not None:
        if data.stoppage.tag not in known_tags:
            problems.add(f"unknown tag {data.stoppage.tag!r} in [data.stoppage]"
                         f"{did_you_mean(data.stoppage.tag, known_tags)}")


def _parse_tracking(raw: Mapping[str, Any], problems: Problems) -> TrackingSettings:
    """``[tracking]``: the start-up hold."""
    tracking = TrackingSettings()
    ttable = _table(raw, "tracking", problems)
    if ttable is not None:
        _check_keys(ttable, ("hold_until",), (), "[tracking]", problems)
        hold = _number(ttable, "hold_until", "[tracking]", problems, default=0.0, nonnegative=True)
        tracking = TrackingSettings(hold_until=hold or 0.0)

    return tracking


def _check_header(meas: Path | None, tags: Sequence[str], problems: Problems) -> None:
    """Every tag the spec names is a column of the measurement file (or a tag of its long export)."""
    if meas is not None and meas.is_file():
        header = _csv_header(meas)
        if header is not None and sorted(header) == ["tag", "time", "value"]:
            # a historian's long export: the tags are the values of its 'tag' column
            header = ["time", *_long_tags(meas, header.index("tag"))]
        if header is not None:
            columns = [c for c in header if c != "time"]
            if "time" not in header:
                problems.add(f"measurements file {meas.name} has no 'time' column")
            for tag in dict.fromkeys(tags):
                if tag not in header:
                    problems.add(f"tag {tag!r} is not a column of {meas.name}{did_you_mean(tag, columns)}")


_LIVE_KEYS = ("nodes", "auth", "security", "mode", "certificate", "private_key", "server_certificate",
              "stale_after", "publish")


def _parse_live(raw: Mapping[str, Any], base: Path, problems: Problems, tags: Sequence[str]) -> LiveSpec:
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


def _parse_pairing(raw: Mapping[str, Any], problems: Problems) -> PairingSettings:
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


def _parse_diagnose(raw: Mapping[str, Any], base: Path, problems: Problems, *,
                    check_files: bool, parameters: Sequence[str] = ()) -> DiagnoseSpec:
    """``[diagnose]``: ``effects``, a list of folders (relative to the spec file) of user effect entries;
    ``varying``, candidate parameter -> ``"rising"`` | ``"falling"`` | ``"free"`` (tracked in time)."""
    table = _table(raw, "diagnose", problems)
    if table is None:
        return DiagnoseSpec()
    _check_keys(table, ("effects", "varying"), (), "[diagnose]", problems)
    varying: list[tuple[str, str]] = []
    how = table.get("varying", {})
    if not isinstance(how, dict):
        problems.add(f"varying in [diagnose] must be a table parameter = \"rising\" | \"falling\" | \"free\", "
                     f"got {how!r}")
    else:
        for name, kind in how.items():
            if kind not in VARYING_KINDS:
                problems.add(f"varying {name!r} in [diagnose] must be one of {', '.join(VARYING_KINDS)}, got {kind!r}"
                             f"{did_you_mean(str(kind), VARYING_KINDS)}")
            elif name not in parameters:
                problems.add(f"varying {name!r} in [diagnose] is not a [[parameters]] entry"
                             f"{did_you_mean(name, list(parameters))}")
            else:
                varying.append((str(name), str(kind)))
    value = table.get("effects", [])
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        problems.add(f"effects in [diagnose] must be a list of folder paths (strings), got {value!r}")
        return DiagnoseSpec(varying=tuple(varying))
    folders: list[Path] = []
    for item in value:
        resolved = _resolve(base, item)
        if check_files and not resolved.is_dir():
            problems.add(f"effects folder {item!r} in [diagnose] {_absent(resolved)} (looked for {resolved})")
        folders.append(resolved)
    return DiagnoseSpec(effects=tuple(folders), varying=tuple(varying))


def _parse_balances(raw: Mapping[str, Any], problems: Problems) -> tuple[BalanceSpec, ...]:
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
        info = read_info(spec.twin)
    variables = {v.name: v for v in info.variables}
    names = list(variables)
    by_causality: dict[str, list[str]] = {}
    for v in info.variables:
        by_causality.setdefault(v.causality, []).append(v.name)
    twin = Path(spec.twin).name
    problems = Problems(str(spec.path))

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
