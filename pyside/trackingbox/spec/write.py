"""Writing a spec: a whole one (:func:`write_spec`, :func:`dump_spec`), or the pairs and start values into
the user's file as a TOML document, comments and layout kept (:func:`update_spec`).
"""
from __future__ import annotations

import logging
import math
import os
import re
from collections.abc import Iterable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import tomli_w
import tomlkit
from tomlkit.items import AoT, Comment, Table, Whitespace

from ..errors import SpecError, unknown_name
from ..io import write_text_atomic
from .model import PairingSettings, PairSpec, Spec, TrackingSettings
from .parse import Problems, load_spec, loads_spec

log = logging.getLogger(__name__)

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
        if spec.source.libraries:
            doc["source"]["libraries"] = [_rel(p, base, outside=False) for p in spec.source.libraries]
    doc["inputs"] = dict(spec.inputs)
    doc["outputs"] = dict(spec.outputs)
    if spec.parameters:
        doc["parameters"] = [{"name": p.name, "start": float(p.start), "min": float(p.min),
                              "max": float(p.max), **({"interval": [float(v) for v in p.interval]}
                                                      if p.interval is not None else {})}
                             for p in spec.parameters]
    if spec.fixed:
        doc["fixed"] = {k: float(v) for k, v in spec.fixed.items()}
    if spec.fixed_intervals:
        doc["fixed_intervals"] = {k: [float(a), float(b)] for k, (a, b) in spec.fixed_intervals.items()}
    if spec.windows:
        doc["windows"] = {k: [float(a), float(b)] for k, (a, b) in spec.windows.items()}
    if (spec.data.stoppage is not None or spec.data.max_gap is not None or spec.data.heartbeat
            or spec.data.inputs != "linear" or spec.data.initial != "model" or spec.data.carry):
        data: dict[str, Any] = {}
        if spec.data.carry:
            data["carry"] = list(spec.data.carry)
        if spec.data.inputs != "linear":
            data["inputs"] = spec.data.inputs
        if spec.data.initial != "model":
            data["initial"] = spec.data.initial
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
    if spec.diagnose.effects or spec.diagnose.varying:
        doc["diagnose"] = {}
        if spec.diagnose.effects:
            doc["diagnose"]["effects"] = [_rel(f, base, outside=False) for f in spec.diagnose.effects]
        if spec.diagnose.varying:
            doc["diagnose"]["varying"] = dict(spec.diagnose.varying)
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
    problems = Problems(str(old.path))
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
        if p.name in new_starts else p
        for p in old.parameters))
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
