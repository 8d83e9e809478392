"""gen-trackingbox: Modelica tracking box and tracked model from a spec with pairs.

From a ``spec.toml`` that has ``[source]`` and ``[[pairs]]`` this writes a
Modelica package ``<Twin>Tracking`` with

* ``<Twin>TrackingBox``: a block with one library block
  ``TrackingBox.Blocks.ParameterController`` per pair and one
  ``TrackingBox.Blocks.StateCompensation`` per ``[[states]]`` entry, wired
  with ``connect`` and drawn (every instance a ``Placement``, every connect a
  ``Line``). The law lives in those blocks only; the Python runtime's
  :class:`~trackingbox.tracking.controllers.ScaledPI` is their exact
  discretisation, and the settings come from the one rule
  :func:`trackingbox.tracking.tuning.pair_settings`;
* ``<Twin>Tracked``: the twin extended with its tracked parameters switched to
  their conditional inputs (``hx(use_kht_in = true)``), the measurements as
  top-level inputs and the box connected between measurements, twin sensors,
  the parameter inputs and the twin's correction-flow inputs. The tracked
  parameters are outputs. A twin variable that is not a connector (a sensor
  value such as ``ThOut``) reaches the box through an equation.

The tracked model *extends* the twin rather than instantiating it: a connect
equation may only name a connector of a direct component (``hx.kht_in``), and
a conditional connector may only be used in connect equations. Extending keeps
the twin's own inputs and outputs top-level under their own names.

Output is deterministic: same inputs, byte-identical files.
"""
from __future__ import annotations

import importlib.resources
import logging
import os
import re
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import jinja2

from ..compiler import compile_model, library_path
from ..errors import SpecError, unknown_name
from ..io import write_text_atomic
from ..tracking.controllers import MEMORY_FRACTION
from ..tracking.tuning import pair_settings, variable_span
from ..version import __version__
from . import filters
from .source import (
    ParameterSite,
    Rewrite,
    TwinSource,
    check_loads,
    load_twin,
    parameter_site,
    refusal_message,
    rewrite_source,
)
from .variants import class_variant, component_class, is_library_class, library_index, twin_variant

logger = logging.getLogger(__name__)

#: Diagram coordinates: the corners of an extent or the points of a line.
Points = tuple[tuple[float, float], ...]

__all__ = ["ControllerModel", "StateModel", "Layout", "GeneratedModel", "GenerateResult", "build_model", "render",
           "generate", "environment", "variable_span"]


def environment() -> jinja2.Environment:
    """The Jinja environment of the templates in ``trackingbox.codegen``.

    Delimiters are ``<< >>`` and ``<% %>`` so that Modelica's ``{...}`` never
    clashes; undefined values are errors.
    """
    root = importlib.resources.files("trackingbox.codegen")
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(root)),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
        trim_blocks=True,
        lstrip_blocks=True,
        autoescape=False,
        variable_start_string="<<",
        variable_end_string=">>",
        block_start_string="<%",
        block_end_string="%>",
        comment_start_string="<#",
        comment_end_string="#>",
    )
    return filters.register(env)


@dataclass(frozen=True)
class ControllerModel:
    """One parameter controller of the box (one ``[[pairs]]`` entry)."""

    tag: str                 # measurement tag, e.g. "TI-102"
    parameter: str           # tracked parameter, e.g. "hx.kht"
    input: str               # the component's conditional input, e.g. "hx.kht_in"
    twin_variable: str       # twin variable that simulates the tag, e.g. "ThOut"
    out: str                 # identifier of the tracked value, e.g. "hx_kht"
    meas: str                # box/model input with the measurement, e.g. "TI_102_meas"
    sim: str                 # box input with the twin's value, e.g. "TI_102_sim"
    span_name: str           # e.g. "TI_102_span"
    p_min: float
    p_max: float
    p_start: float
    span: float
    kp: float
    ti: float
    direction: float
    gain: float
    time_constant: float
    tuning: str              # how kp/ti were obtained (for the description)
    p_unit: str = ""         # unit of the parameter in the twin ("" if none)
    y_unit: str = ""         # unit of the tracking variable in the twin
    p_description: str = ""  # the parameter's description in the twin
    instance: str = ""       # the ParameterController instance in the box, e.g. "hx_kht_controller"
    hold_in: str = ""        # box/model input that holds this controller alone, e.g. "TI_102_hold"
    layout: Layout | None = None
    #: every conditional input the box drives (a top-level parameter: one per component bound to it)
    inputs: tuple[str, ...] = ()


@dataclass(frozen=True)
class StateModel:
    """One state compensation of the box (one ``[[states]]`` entry)."""

    tag: str                 # level measurement tag, e.g. "LI-100"
    variable: str            # twin variable of the level, e.g. "LI_100"
    correction: str          # the twin's correction-flow input, e.g. "T100_m_flow_corr"
    meas: str                # box/model input with the measured level, e.g. "LI_100_meas"
    sim: str                 # box input with the twin's level, e.g. "LI_100_sim"
    out: str                 # box output with the correction flow (named after the twin input)
    gain_name: str           # box parameter with the gain, e.g. "T100_m_flow_corr_k"
    instance: str            # the StateCompensation instance, e.g. "T100_m_flow_corr_compensation"
    gain: float
    target: str = ""         # the component's conditional input it drives ("tank.m_flow_corr_in"), or ""
    level_unit: str = ""
    flow_unit: str = ""
    gain_unit: str = ""
    layout: Layout | None = None

    @property
    def exposed(self) -> str:
        """Output of the tracked model that carries a correction for a top-level twin input ("" if wired)."""
        return "" if self.target else f"{self.out}_comp"


@dataclass(frozen=True)
class Layout:
    """Diagram geometry of one row of the box (one pair or state) and its wiring in the tracked model.

    Extents and points are in the box's (``box_*``) or the tracked model's
    (``tracked_*``) diagram coordinates, ready for :func:`filters.modelica_points`.
    """

    meas_extent: Points
    sim_extent: Points
    out_extent: Points
    block_extent: Points
    line_meas: Points
    line_sim: Points
    hold_extent: Points
    line_out: Points
    tracked_meas_extent: Points
    tracked_hold_extent: Points
    tracked_out_extent: Points
    tracked_line_meas: Points
    tracked_line_out: Points
    tracked_line_input: Points


@dataclass(frozen=True)
class GeneratedModel:
    """Everything the templates need; one typed object per generated package."""

    header: str
    package: str
    box_class: str
    tracked_class: str
    twin_model: str
    sample_time: float
    stop_time: float
    hold_until: float
    controllers: tuple[ControllerModel, ...]
    states: tuple[StateModel, ...]
    te: float                  # time constant of the error memories (s)
    box_extent: Points
    hold_extent: Points
    hold_all_extent: Points
    tracked_box_extent: Points
    tracked_hold_extent: Points
    tracked_line_hold: Points
    modifier_lines: tuple[str, ...]
    fill_equations: tuple[str, ...]
    """``effect[1].Rf_in = effect[1].Rf;``: the elements of a switched component array no pair drives."""
    class_order: tuple[str, ...]
    package_info: str
    box_info: str
    tracked_info: str
    #: the class the tracked model extends: the twin, or its variant in the package
    base_model: str = ""


@dataclass(frozen=True)
class GenerateResult:
    """What :func:`generate` wrote."""

    package_dir: Path
    files: tuple[Path, ...]
    package: str
    tracked_model: str         # full name, e.g. "TwinTracking.TwinTracked"
    box_model: str
    library: Path              # the twin's library (patched copy with --rewrite)
    rewrite: Rewrite | None = None
    controllers: tuple[ControllerModel, ...] = field(default=())
    states: tuple[StateModel, ...] = field(default=())
    #: libraries the tracked model compiles with (the twin's package, TrackingBox, the twin's libraries)
    libraries: tuple[Path, ...] = field(default=())
    #: classes generated as variants of library classes and of the twin (names in the package)
    variants: tuple[str, ...] = field(default=())

    def to_json(self) -> dict[str, Any]:
        """The ``trackingbox generate --json`` document (without its ``compile`` entry)."""
        return {
            "package": self.package,
            "package_dir": str(self.package_dir),
            "files": [str(f) for f in self.files],
            "tracked_model": self.tracked_model,
            "box_model": self.box_model,
            "library": str(self.library),
            "patched_source": None if self.rewrite is None else str(self.rewrite.path),
            "variants": list(self.variants),
            "controllers": [
                {"tag": c.tag, "parameter": c.parameter, "kp": c.kp, "ti": c.ti, "span": c.span,
                 "direction": int(c.direction), "min": c.p_min, "max": c.p_max, "start": c.p_start}
                for c in self.controllers
            ],
        }


#: Row pitch of the box's diagram and the scale of the box instance in the tracked model.
_PITCH = 80.0
_SCALE = 0.4

def _half_height(rows: int) -> float:
    """Half the height of the box's coordinate system for *rows* rows (pairs + states)."""
    return _PITCH / 2.0 * rows + 40.0


def _row_layout(i: int, rows: int) -> Layout:
    """Geometry of row *i*: inputs left (a pair's own hold above its measurement), the library block in
    the middle, the output right."""
    h = _half_height(rows)
    yc = h - _PITCH - _PITCH * i
    k = _SCALE
    return Layout(
        meas_extent=((-140, yc + 5), (-100, yc + 25)),
        sim_extent=((-140, yc - 25), (-100, yc - 5)),
        out_extent=((100, yc - 10), (120, yc + 10)),
        block_extent=((-20, yc - 20), (20, yc + 20)),
        line_meas=((-120, yc + 15), (-40, yc + 15), (-40, yc), (-24, yc)),
        line_sim=((-120, yc - 15), (-50, yc - 15), (-50, yc - 34), (0, yc - 34), (0, yc - 24)),
        hold_extent=((-140, yc + 30), (-100, yc + 50)),
        line_out=((22, yc), (110, yc)),
        tracked_meas_extent=((-140, k * (yc + 15) - 10), (-100, k * (yc + 15) + 10)),
        tracked_hold_extent=((-140, k * yc - 15), (-100, k * yc - 5)),
        tracked_out_extent=((100, k * yc - 10), (120, k * yc + 10)),
        tracked_line_meas=((-120, k * (yc + 15)), (-120 * k, k * (yc + 15))),
        tracked_line_out=((110 * k, k * yc), (110, k * yc)),
        tracked_line_input=((110 * k, k * yc), (70, k * yc), (70, k * yc + 20)),
    )


def _BLOCKS_LIBRARY() -> Path:  # noqa: N802 - reads as the constant it is
    """The shipped library whose ``Blocks`` the generated box instantiates."""
    return library_path()


_ELEMENT = re.compile(r"^([A-Za-z_]\w*)\[(\d+)\]$")


def _modifier_lines(sites: Sequence[ParameterSite], variables: Mapping[str, Any] | None = None) -> tuple[str, ...]:
    """Nested modifiers ``hx(use_kht_in = true)`` merged per component, sorted.

    A site in an element of a component array (``effect[2].Rf``) switches the whole array,
    ``effect(each use_Rf_in = true)`` (rumoca 0.10 refuses a conditional component under an array
    of flags, ``use_Rf_in = {false, true}``); :func:`_fill_equations` feeds the elements no pair
    drives from their own parameter. The array's size is counted from the twin's flat *variables*
    (``effect[k].use_Rf_in``).
    """
    tree: dict[str, Any] = {}
    arrays: dict[str, dict[str, set[int]]] = {}  # array path -> flag -> switched elements
    sites = [leaf for s in sites for leaf in s.leaves()]
    for site in sites:
        parts = site.component.split(".")
        m = _ELEMENT.match(parts[-1])
        if m is not None and not any(_ELEMENT.match(p) for p in parts[:-1]):
            path = ".".join([*parts[:-1], m.group(1)])
            arrays.setdefault(path, {}).setdefault(f"use_{site.leaf}_in", set()).add(int(m.group(2)))
            continue
        if any("[" in p for p in parts):
            raise SpecError(f"parameter {site.name!r}: gen-trackingbox switches parameters of elements of "
                            f"top-level component arrays (e.g. 'effect[2].Rf') only, not of nested arrays")
        node = tree
        for part in parts:
            node = node.setdefault(part, {})
        node[f"use_{site.leaf}_in"] = None
    for path, flags in arrays.items():
        node = tree
        for part in path.split("."):
            node = node.setdefault(part, {})
        for flag, switched in flags.items():
            prefix = re.escape(path) + r"\[(\d+)\]\." + re.escape(flag) + "$"
            size = max((int(mm.group(1)) for n in (variables or {}) if (mm := re.match(prefix, n))), default=0)
            if size < max(switched):
                raise SpecError(f"component array {path!r} of the twin has no flag {flag!r} for element "
                                f"{max(switched)}: cannot switch it to a conditional input")
            node[f"each {flag}"] = None

    def fmt(name: str, sub: dict[str, Any]) -> str:
        inner = ", ".join(k + " = true" if v is None else (f"{k} = {v}" if isinstance(v, str) else fmt(k, v))
                          for k, v in sorted(sub.items(), key=lambda kv: kv[0].removeprefix("each ")))
        return f"{name}({inner})"

    items = [fmt(k, v) for k, v in sorted(tree.items())]
    return tuple(s + ("," if i < len(items) - 1 else "") for i, s in enumerate(items))


def _fill_equations(sites: Sequence[ParameterSite], variables: Mapping[str, Any]) -> tuple[str, ...]:
    """``effect[1].Rf_in = effect[1].Rf;`` for every element of a component array that
    :func:`_modifier_lines` switches but no site drives: it keeps its own parameter's value."""
    switched: dict[tuple[str, str], set[int]] = {}
    sites = [leaf for s in sites for leaf in s.leaves()]
    for site in sites:
        m = _ELEMENT.match(site.component.split(".")[-1])
        if m is not None:
            base = ".".join([*site.component.split(".")[:-1], m.group(1)])
            switched.setdefault((base, site.leaf), set()).add(int(m.group(2)))
    out = []
    for (base, leaf), ks in sorted(switched.items()):
        pattern = re.compile(re.escape(base) + r"\[(\d+)\]\.use_" + re.escape(leaf) + "_in$")
        size = max((int(mm.group(1)) for n in variables if (mm := pattern.match(n))), default=0)
        out += [f"{base}[{k}].{leaf}_in = {base}[{k}].{leaf};" for k in range(1, size + 1) if k not in ks]
    return tuple(out)


def _text_attr(variable: dict[str, Any], key: str) -> str:
    """A plain string attribute (unit, description) of a flat rumoca variable, or ``""``."""
    value = variable.get(key)
    return value if isinstance(value, str) else ""


def _rel(path: Path, start: Path) -> str:
    return Path(os.path.relpath(path.resolve(), start.resolve())).as_posix()


def _where(library: Path, spec_dir: Path, pkg_dir: Path) -> str:
    """Name the twin's library in the header without machine-specific paths where possible."""
    lib = library.resolve()
    for base, label in ((spec_dir, "beside the spec"), (pkg_dir.parent, "beside the output")):
        try:
            return f"{lib.relative_to(base.resolve()).as_posix()} ({label})"
        except ValueError:
            pass
    try:
        if lib == library_path().resolve():
            return f"{lib.name} (the library shipped with trackingbox)"
    except ImportError:  # pragma: no cover - the compiler is part of the package
        pass
    rel = _rel(lib, pkg_dir)
    return rel if not rel.startswith("../../..") else lib.as_posix()


def build_model(spec: Any, src: TwinSource, sites: dict[str, ParameterSite], out_dir: Path,
                library_for_header: Path) -> GeneratedModel:
    """Build the typed template input from a loaded spec and the inspected twin."""
    twin_short = src.model.rsplit(".", 1)[-1]
    package = filters.modelica_ident(f"{twin_short}Tracking")
    box_class = f"{twin_short}TrackingBox"
    tracked_class = f"{twin_short}Tracked"
    pkg_dir = out_dir / package
    where = spec.path.name
    controllers: list[ControllerModel] = []
    taken: dict[str, str] = {n: "twin variable" for n in src.variables if "." not in n}
    taken.update({"hold": "hold input", "box": "box instance"})
    for n in ("hold", "box"):
        if n in src.variables:
            raise SpecError(f"the twin {src.model} has a top-level variable {n!r}, which the tracked model needs")
    for pair in sorted(spec.pairs, key=lambda p: (p.parameter, p.variable)):
        if pair.controller != "pi":
            raise SpecError(f"pair {pair.variable} -> {pair.parameter} in {where} uses controller "
                            f"{pair.controller!r}: the generated tracking box has PI controllers only")
        if pair.variable not in spec.outputs:
            raise SpecError(unknown_name("tag", pair.variable, spec.outputs, f"[outputs] of {where} (pair "
                                         f"{pair.variable} -> {pair.parameter})"))
        twin_var = spec.outputs[pair.variable]
        if twin_var not in src.variables:
            raise SpecError(unknown_name("twin variable", twin_var, sorted(src.variables),
                                         f"model {src.model} ([outputs] {pair.variable!r} in {where})"))
        param = spec.parameter(pair.parameter)
        site = sites[pair.parameter]
        p_min, p_max, p_start = float(param.min), float(param.max), float(param.start)
        settings = pair_settings(pair, p_min, p_max, ts=float(spec.sample_time), where=where)
        span, kp, ti, how = settings.scaling.span, settings.kp, settings.ti, settings.tuning
        ident = filters.modelica_name(pair.variable)
        out = filters.tracked_output(pair.parameter)
        names = {"meas": f"{ident}_meas", "sim": f"{ident}_sim", "out": out, "hold": f"{ident}_hold"}
        for kind in ("meas", "hold", "out"):
            if names[kind] in taken:
                raise SpecError(f"name {names[kind]!r} for {pair.parameter if kind == 'out' else pair.variable} "
                                f"clashes with the {taken[names[kind]]} of that name in {src.model}")
            taken[names[kind]] = f"generated {kind}"
        controllers.append(ControllerModel(
            tag=pair.variable, parameter=pair.parameter, input=site.input, inputs=site.inputs, twin_variable=twin_var,
            out=out, meas=names["meas"], sim=names["sim"], span_name=f"{ident}_span",
            p_min=p_min, p_max=p_max, p_start=p_start, span=span, kp=kp, ti=ti,
            direction=float(settings.direction), gain=float(pair.gain),
            time_constant=float(pair.time_constant), tuning=how,
            p_unit=_text_attr(src.variables[pair.parameter], "unit"),
            y_unit=_text_attr(src.variables[twin_var], "unit"),
            p_description=_text_attr(src.variables[pair.parameter], "description"),
            instance=f"{out}_controller", hold_in=names["hold"]))
    states = _state_models(spec, src, sites, taken, where)
    rows = len(controllers) + len(states)
    controllers = [replace(c, layout=_row_layout(i, rows)) for i, c in enumerate(controllers)]
    states = [replace(x, layout=_row_layout(len(controllers) + i, rows)) for i, x in enumerate(states)]
    h = _half_height(rows)
    stop = spec.windows.get("validation", spec.windows.get("training", (0.0, 3600.0)))[1]
    header_lines = [
        f"// Generated by trackingbox {__version__} (trackingbox generate / gen-trackingbox). Do not edit:",
        "// change the spec or the twin and generate again.",
        f"// spec:  {_rel(spec.path, pkg_dir)}",
        f"// twin:  {src.model} in {_where(library_for_header, spec.path.parent, pkg_dir)}",
    ]
    for c in controllers:
        header_lines.append(f"// pair:  {c.tag} -> {c.parameter} (kp = {filters.modelica_real(c.kp)}, "
                            f"Ti = {filters.modelica_real(c.ti)} s, span = {filters.modelica_real(c.span)})")
    for x in states:
        header_lines.append(f"// state: {x.tag} -> {x.correction} (k = {filters.modelica_real(x.gain)}, "
                            f"level {x.variable})")
    pairs_html = "".join(
        f"<li><code>{c.parameter}</code> tracks <code>{c.tag}</code> (twin variable "
        f"<code>{c.twin_variable}</code>), bounds [{filters.modelica_real(c.p_min)}, "
        f"{filters.modelica_real(c.p_max)}]</li>" for c in controllers)
    states_html = "".join(
        f"<li><code>{x.correction}</code> keeps <code>{x.variable}</code> on <code>{x.tag}</code></li>"
        for x in states)
    package_info = (f"<html><p>Generated by trackingbox {__version__} for <code>{src.model}</code>. "
                    f"<code>{tracked_class}</code> is the twin with its parameters tracked by "
                    f"<code>{box_class}</code>:</p><ul>{pairs_html}{states_html}</ul></html>")
    box_info = (
        "<html><p>One <code>TrackingBox.Blocks.ParameterController</code> per pair (error in % of the "
        "variable's span, output 0..100 % of the parameter's bounds, direction from the sign of the "
        "pair's gain, clamp with anti-windup) and one <code>TrackingBox.Blocks.StateCompensation</code> "
        "per state (correction = k (measured - simulated level)). The law and its hold are documented "
        "in those blocks; the Python runtime implements the same law. <code>hold = 1</code>, and any "
        "time before <code>holdUntil</code> (the start-up hold), freezes every parameter controller: "
        "nothing integrates and tracking resumes without a bump; a pair's own "
        "<code>&lt;tag&gt;_hold = 1</code> (its measurement missing) freezes that controller alone, as the "
        "Python runtime holds only the loop whose tag is missing. State compensation keeps running "
        "through holds, as in the Python runtime.</p></html>")
    tracked_info = (
        f"<html><p><code>{src.model}</code> with "
        + ", ".join(f"<code>{c.parameter}</code>" for c in controllers)
        + f" switched to their conditional inputs and driven by <code>{box_class}</code>"
        + "".join(f", <code>{x.correction}</code> driven by the box's state compensation" for x in states
                  if x.target)
        + "".join(f". <code>{x.correction}</code> is a top-level input of the twin, which a model that "
                  f"extends the twin cannot drive: the box's correction is the output <code>{x.exposed}</code>; "
                  f"feed it to <code>{x.correction}</code> each sample, as the Python runtime does"
                  for x in states if not x.target)
        + ". Inputs: the twin's own inputs, the measurements (<code>*_meas</code>), <code>hold</code> (every "
        "controller) and per pair <code>*_hold</code> (that controller alone: its measurement missing); "
        "the box also holds until <code>holdUntil</code> (the spec's start-up hold). Outputs: the twin's "
        "own outputs and the tracked parameter values. Twin variables that are not connectors (the "
        "simulated sensors) reach the box through equations; everything else is connected.</p></html>")
    k = _SCALE
    return GeneratedModel(
        header="\n".join(header_lines), package=package, box_class=box_class, tracked_class=tracked_class,
        twin_model=src.model, sample_time=float(spec.sample_time), stop_time=float(stop),
        hold_until=float(spec.tracking.hold_until),
        controllers=tuple(controllers), states=tuple(states),
        te=MEMORY_FRACTION * float(spec.sample_time),
        box_extent=((-100, -h), (100, h)),
        hold_extent=((-140, h - 30), (-100, h - 10)),
        hold_all_extent=((-80, h - 30), (-60, h - 10)),
        tracked_box_extent=((-100 * k, -h * k), (100 * k, h * k)),
        tracked_hold_extent=((-140, k * (h - 20) - 10), (-100, k * (h - 20) + 10)),
        tracked_line_hold=((-120, k * (h - 20)), (-120 * k, k * (h - 20))),
        modifier_lines=_modifier_lines(list(sites.values()), src.variables),
        fill_equations=_fill_equations(list(sites.values()), src.variables),
        class_order=("RealInput", "RealOutput", box_class, tracked_class),
        package_info=package_info, box_info=box_info, tracked_info=tracked_info)


def _state_models(spec: Any, src: TwinSource, sites: dict[str, ParameterSite], taken: dict[str, str],
                  where: str) -> list[StateModel]:
    """One :class:`StateModel` per ``[[states]]`` entry (sorted by correction); *taken* gets their names."""
    states: list[StateModel] = []
    for st in sorted(spec.states, key=lambda x: x.correction):
        label = f"[[states]] {st.tag!r} in {where}"
        if st.variable not in src.variables:
            raise SpecError(unknown_name("twin level variable", st.variable, sorted(src.variables),
                                         f"model {src.model} ({label})"))
        if st.correction in src.top_inputs:
            # A top-level input of the twin cannot be driven from a model that extends the
            # twin: the embedded path keeps it an FMU input whatever binds it. The box's
            # correction is then an output of the tracked model, to be fed to that input.
            target, flow_var = "", src.variables[st.correction]
        elif st.correction in sites:
            target, flow_var = sites[st.correction].input, src.variables[st.correction]
        else:  # pragma: no cover - generate() collects a site for every non-input correction
            raise SpecError(f"{label}: correction {st.correction!r} is neither a top-level input of "
                            f"{src.model} nor a component parameter with a conditional input")
        ident = filters.modelica_name(st.tag)
        corr = filters.modelica_name(st.correction)
        names = {"meas": f"{ident}_meas", "out": f"{corr}_comp"}
        for kind, name in names.items():
            if kind == "out" and target:
                continue
            if name in taken:
                raise SpecError(f"name {name!r} for {label} clashes with the {taken[name]} of that name in "
                                f"{src.model}")
            taken[name] = f"generated {kind}"
        level_unit = _text_attr(src.variables[st.variable], "unit")
        flow_unit = _text_attr(flow_var, "unit")
        states.append(StateModel(
            tag=st.tag, variable=st.variable, correction=st.correction, meas=names["meas"], sim=f"{ident}_sim",
            out=corr, gain_name=f"{corr}_k", instance=f"{corr}_compensation", gain=float(st.gain),
            target=target, level_unit=level_unit, flow_unit=flow_unit,
            gain_unit=filters.unit_quotient(flow_unit, level_unit)))
    return states


def render(model: GeneratedModel) -> dict[str, str]:
    """Render the package files: file name -> text."""
    env = environment()
    return {
        "package.mo": env.get_template("package.mo.jinja").render(m=model),
        "package.order": env.get_template("package.order.jinja").render(m=model),
        f"{model.box_class}.mo": env.get_template("TrackingBox.mo.jinja").render(m=model),
        f"{model.tracked_class}.mo": env.get_template("Tracked.mo.jinja").render(m=model),
    }


def generate(spec: Any, out_dir: str | Path, *, rewrite: bool = False,
             libraries: Sequence[str | Path] = ()) -> GenerateResult:
    """Generate the ``<Twin>Tracking`` package for *spec* into *out_dir*.

    Parameters
    ----------
    spec : trackingbox.spec.Spec
        A loaded spec with ``[source]`` and ``[[pairs]]``.
    out_dir : path
        Directory that receives ``<Twin>Tracking/`` (and ``patched/`` with *rewrite*).
    rewrite : bool
        If a tracked parameter's component lacks the conditional-input pattern
        and its class is the twin's own, write a patched copy of the twin's source
        (under ``out_dir/patched``) instead of refusing. A component whose class
        lives in a library (the MSL, ``[source] libraries``, *libraries*) gets a
        variant of that class in the generated package instead
        (:mod:`trackingbox.generate.variants`), whatever *rewrite* says.
    libraries : paths
        Further Modelica libraries the twin uses (``--library``), beside
        ``[source] libraries``; those beside the source and on ``MODELICAPATH``
        are found without.

    Raises
    ------
    SpecError
        Missing ``[source]`` or ``[[pairs]]``, unknown names, or a component
        without the conditional-input pattern (the message says what to add).
    CompileError
        If the twin or the generated package does not load with rumoca.
    """
    out_dir = Path(out_dir)
    where = str(spec.path)
    if not spec.pairs:
        raise SpecError(f"{where} has no [[pairs]]: run `trackingbox pair {where}` first")
    if spec.source is None:
        raise SpecError(f"{where} has no [source] table: gen-trackingbox needs the twin's Modelica source "
                        f"(path = package directory or .mo file, model = full class name)")
    libs = tuple(dict.fromkeys([*spec.source.libraries, *(Path(p) for p in libraries)]))
    src = load_twin(spec.source.path, spec.source.model, libs)
    known = set(spec.parameter_names)
    sites: dict[str, ParameterSite] = {}
    for pair in spec.pairs:
        if pair.parameter not in known:
            raise SpecError(unknown_name("parameter", pair.parameter, sorted(known), f"[[pairs]] of {where}"))
        sites[pair.parameter] = parameter_site(src, pair.parameter, f"[[pairs]] of {where}")
    for st in spec.states:
        if st.correction not in src.top_inputs:
            sites[st.correction] = parameter_site(src, st.correction, f"[[states]] {st.tag!r} of {where}")
    index = library_index(src.path, src.libraries)
    in_library = _library_sites(src, index, sites, libs)
    missing = [leaf for s in sites.values() for leaf in s.leaves()
               if not leaf.has_pattern and leaf.name not in in_library]
    rw: Rewrite | None = None
    library = src.top
    if missing:
        if not rewrite:
            raise SpecError("\n".join(refusal_message(src, s) for s in missing))
        rw = rewrite_source(src, missing, out_dir / "patched")
        logger.info("wrote a patched copy of the twin's source to %s", rw.path)
        src_new = load_twin(rw.path, spec.source.model, libs)
        for name in sites:
            sites[name] = parameter_site(src_new, name, f"[[pairs]]/[[states]] of {where}")
        src = src_new
        library = src_new.top
        index = library_index(src.path, src.libraries)
        in_library = _library_sites(src, index, sites, libs)
        for leaf in (x for s in sites.values() for x in s.leaves()):
            if not leaf.has_pattern and leaf.name not in in_library:
                raise SpecError(f"rewriting the source did not give {leaf.name!r} a conditional input")
    model = build_model(spec, src, sites, out_dir, library)
    variants: dict[str, str] = {}
    if in_library:
        model, variants = _with_variants(model, src, index, in_library)
    texts = render(model)
    for name, text in variants.items():
        texts[f"{name}.mo"] = text
    # the twin's own package (or its patched copy) and the shipped library the box instantiates, and the
    # libraries the twin uses
    compile_libs = tuple(dict.fromkeys([*([library] if library.is_dir() or library.suffix == ".mo" else []),
                                        _BLOCKS_LIBRARY(), *src.libraries]))
    # Never write what does not load: check in a staging tree first.
    with tempfile.TemporaryDirectory(prefix="trackingbox-gen-") as tmp:
        staged_gen = Path(tmp) / "gen" / model.package
        staged_gen.mkdir(parents=True)
        for name, text in texts.items():
            (staged_gen / name).write_text(text, encoding="utf-8")
        check_loads(staged_gen, f"{model.package}.{model.tracked_class}", staged_gen.parent, compile_libs)
    pkg_dir = out_dir / model.package
    pkg_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name in sorted(texts):
        write_text_atomic(pkg_dir / name, texts[name])
        written.append(pkg_dir / name)
    logger.info("wrote %s", pkg_dir)
    return GenerateResult(package_dir=pkg_dir, files=tuple(written), package=model.package,
                          tracked_model=f"{model.package}.{model.tracked_class}",
                          box_model=f"{model.package}.{model.box_class}", library=library,
                          rewrite=rw, controllers=model.controllers, states=model.states,
                          libraries=compile_libs, variants=tuple(sorted(variants)))


def _library_sites(src: TwinSource, index: Any, sites: Mapping[str, ParameterSite],
                   read_only: tuple[Path, ...] = ()) -> dict[str, tuple[str, str]]:
    """Sites without the pattern whose component's class is a library's: name -> (component, class).

    Only components declared by the twin's own class qualify (their class is switched in a variant of
    the twin); others take the refusal or ``--rewrite`` path.
    """
    out: dict[str, tuple[str, str]] = {}
    for site in (leaf for s in sites.values() for leaf in s.leaves()):
        if site.has_pattern or "." in site.component or "[" in site.component or not site.component:
            continue
        found = component_class(index, src.model, site.component)
        if found is None:
            continue
        cls, declared_by = found
        if declared_by == src.model and is_library_class(index, cls, src.top, read_only):
            out[site.name] = (site.component, cls)
    return out


def _with_variants(model: GeneratedModel, src: TwinSource, index: Any,
                   in_library: Mapping[str, tuple[str, str]]) -> tuple[GeneratedModel, dict[str, str]]:
    """The model extending a variant of the twin whose library components are variants with the pattern."""
    package = model.package
    connector = "Modelica.Blocks.Interfaces.RealInput"
    taken = {model.box_class, model.tracked_class, "RealInput", "RealOutput"}
    twin_name = _unique(src.model.rsplit(".", 1)[-1], taken)
    by_class: dict[str, list[str]] = {}
    components: dict[str, str] = {}
    for name, (component, cls) in sorted(in_library.items()):
        leaf = name.rsplit(".", 1)[1]
        if leaf not in by_class.setdefault(cls, []):
            by_class[cls].append(leaf)
        components[component] = cls
    texts: dict[str, str] = {}
    names: dict[str, str] = {}
    for cls, leaves in sorted(by_class.items()):
        short = _unique(cls.rsplit(".", 1)[-1], taken)
        names[cls] = short
        texts[short] = class_variant(index, cls, short, tuple(leaves), connector, package).text
    switched = {component: f"{package}.{names[cls]}" for component, cls in components.items()}
    texts[twin_name] = twin_variant(index, src.model, twin_name, switched, package).text
    order = (*model.class_order[:2], *sorted(texts), *model.class_order[2:])
    described = ", ".join(f"{c} ({cls})" for c, cls in sorted(components.items()))
    info = model.tracked_info.replace(
        "<html><p>", f"<html><p>Extends <code>{package}.{twin_name}</code>, the twin with {described} switched to "
                     "the variants generated beside it (the library is not edited). ", 1)
    return replace(model, base_model=f"{package}.{twin_name}", class_order=order, tracked_info=info), texts


def _unique(name: str, taken: set[str]) -> str:
    """*name*, or *name* with a number, not in *taken* (which gets it)."""
    candidate, k = name, 2
    while candidate in taken:
        candidate, k = f"{name}{k}", k + 1
    taken.add(candidate)
    return candidate


def compile_generated(result: GenerateResult, *, backend: str = "auto", output: Path | None = None) -> Any:
    """Compile the tracked model with :func:`trackingbox.compiler.compile_model`.

    The generated package is the source; the twin's library (the patched copy
    after ``--rewrite``), the shipped ``TrackingBox`` library (whose ``Blocks``
    the box instantiates) and the libraries the twin uses are further libraries.

    Returns
    -------
    trackingbox.compiler.CompileResult
    """
    output = output or result.package_dir.parent / f"{result.tracked_model.rsplit('.', 1)[1]}.fmu"
    libraries = result.libraries or (result.library, _BLOCKS_LIBRARY())
    return compile_model(result.package_dir, result.tracked_model, backend=backend, output=output,
                         libraries=list(dict.fromkeys(Path(p) for p in libraries)))
