"""gen-trackingbox: Modelica tracking box and tracked model from a spec with pairs.

From a ``spec.toml`` that has ``[source]`` and ``[[pairs]]`` this writes a
Modelica package ``<Twin>Tracking`` with

* ``<Twin>TrackingBox``: a block with one scaled PI parameter controller per
  pair, the continuous equivalent of the velocity-form controller of
  :class:`trackingbox.tracking.controllers.ScaledPI` (error in % of the
  variable's span, output 0-100 % mapped onto the parameter's bounds, clamped
  with back-calculation anti-windup, a ``hold`` input that freezes it);
* ``<Twin>Tracked``: the twin extended with its tracked parameters switched to
  their conditional inputs (``hx(use_kht_in = true)``), the measurements as
  top-level inputs and the box connected between measurements, twin sensors and
  the parameter inputs. The tracked parameters are outputs.

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
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jinja2

from .. import __version__
from ..errors import SpecError, unknown_name
from ..io import write_text_atomic
from . import filters
from .source import (ParameterSite, Rewrite, TwinSource, check_loads, load_twin, parameter_site,
                     refusal_message, rewrite_source, stage_packages)

logger = logging.getLogger(__name__)

__all__ = ["ControllerModel", "GeneratedModel", "GenerateResult", "build_model", "render",
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
    modifier_lines: tuple[str, ...]
    class_order: tuple[str, ...]
    package_info: str
    box_info: str
    tracked_info: str


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
            "controllers": [
                {"tag": c.tag, "parameter": c.parameter, "kp": c.kp, "ti": c.ti, "span": c.span,
                 "direction": int(c.direction), "min": c.p_min, "max": c.p_max, "start": c.p_start}
                for c in self.controllers
            ],
        }


def variable_span(gain: float, p_min: float, p_max: float) -> float:
    """Range of a tracking variable that normalises its error: ``|gain|·(p_max - p_min)``.

    It is the change of the variable when the parameter sweeps its bounds, so
    in the scaled domain the process gain is ±1 (% error per % output).

    >>> variable_span(-0.004, 800.0, 1200.0)
    1.6
    """
    span = abs(gain) * (p_max - p_min)
    if not span > 0.0:
        raise ValueError(f"span must be positive (gain {gain}, bounds [{p_min}, {p_max}])")
    return span


def _span(pair: Any, p_min: float, p_max: float) -> float:
    """The span of a pair's variable; the same rule as the Python runtime (``tracking.runtime``)."""
    return variable_span(pair.gain, p_min, p_max)


def _gains(pair: Any, p_min: float, p_max: float, span: float, sample_time: float) -> tuple[float, float, str]:
    """(kp, ti, how) for a pair: explicit ``kp``/``ti`` in the spec, else SIMC tuning."""
    if pair.kp is not None and pair.ti is not None:
        return abs(float(pair.kp)), float(pair.ti), "from the spec"
    from ..tracking.controllers import Scaling
    from ..tracking.tuning import tune_scaled_pi

    g = tune_scaled_pi(pair.gain, pair.time_constant, Scaling(p_min, p_max, span=span),
                       ts=sample_time, lam=pair.lambda_)
    kp = abs(float(pair.kp)) if pair.kp is not None else g.kp
    ti = float(pair.ti) if pair.ti is not None else g.ti
    return kp, ti, f"SIMC, tau_c = {filters.modelica_real(g.tau_c)} s"


def _modifier_lines(sites: Sequence[ParameterSite]) -> tuple[str, ...]:
    """Nested modifiers ``hx(use_kht_in = true)`` merged per component, sorted."""
    tree: dict[str, Any] = {}
    for site in sites:
        node = tree
        for part in site.component.split("."):
            node = node.setdefault(part, {})
        node[f"use_{site.leaf}_in"] = None

    def fmt(name: str, sub: dict[str, Any]) -> str:
        inner = ", ".join(k + " = true" if v is None else fmt(k, v) for k, v in sorted(sub.items()))
        return f"{name}({inner})"

    items = [fmt(k, v) for k, v in sorted(tree.items())]
    return tuple(s + ("," if i < len(items) - 1 else "") for i, s in enumerate(items))


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
        from ..compiler import library_path

        if lib == library_path().resolve():
            return f"{lib.name} (the library shipped with trackingbox)"
    except ImportError:  # pragma: no cover - the compiler is part of the package
        pass
    return _rel(lib, pkg_dir)


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
        span = _span(pair, p_min, p_max)
        kp, ti, how = _gains(pair, p_min, p_max, span, spec.sample_time)
        ident = filters.modelica_name(pair.variable)
        out = filters.modelica_name(pair.parameter)
        names = {"meas": f"{ident}_meas", "sim": f"{ident}_sim", "out": out}
        for kind in ("meas", "out"):
            if names[kind] in taken:
                raise SpecError(f"name {names[kind]!r} for {pair.variable if kind == 'meas' else pair.parameter} "
                                f"clashes with the {taken[names[kind]]} of that name in {src.model}")
            taken[names[kind]] = f"generated {kind}"
        controllers.append(ControllerModel(
            tag=pair.variable, parameter=pair.parameter, input=site.input, twin_variable=twin_var,
            out=out, meas=names["meas"], sim=names["sim"], span_name=f"{ident}_span",
            p_min=p_min, p_max=p_max, p_start=p_start, span=span, kp=kp, ti=ti,
            direction=1.0 if pair.gain > 0 else -1.0, gain=float(pair.gain),
            time_constant=float(pair.time_constant), tuning=how,
            p_unit=_text_attr(src.variables[pair.parameter], "unit"),
            y_unit=_text_attr(src.variables[twin_var], "unit"),
            p_description=_text_attr(src.variables[pair.parameter], "description")))
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
    pairs_html = "".join(
        f"<li><code>{c.parameter}</code> tracks <code>{c.tag}</code> (twin variable "
        f"<code>{c.twin_variable}</code>), bounds [{filters.modelica_real(c.p_min)}, "
        f"{filters.modelica_real(c.p_max)}]</li>" for c in controllers)
    package_info = (f"<html><p>Generated by trackingbox {__version__} for <code>{src.model}</code>. "
                    f"<code>{tracked_class}</code> is the twin with its parameters tracked by "
                    f"<code>{box_class}</code>:</p><ul>{pairs_html}</ul></html>")
    box_info = (
        "<html><p>One PI parameter controller per pair. The error "
        "<code>e = 100 (measured - simulated)/span</code> is in % of the variable's span; the output "
        "<code>u</code> is 0..100 % of the parameter's bounds. The law is the continuous form of the "
        "velocity (incremental) PI <code>u(k) = u(k-1) + d kp (e(k) - e(k-1) + Ts/Ti e(k))</code>: "
        "<code>du/dt = d kp (de/dt + e/Ti)</code>, with <code>de/dt</code> taken as "
        "<code>(e - ef)/Tf</code> (<code>ef</code> lags <code>e</code> by the sample time <code>Tf</code>). "
        "The output is clamped to 0..100 % and pulled back by back-calculation (<code>Tt</code>), so "
        "it never winds up. <code>hold = 1</code> freezes every output (start-up, missing data); "
        "tracking resumes without a bump.</p></html>")
    tracked_info = (
        f"<html><p><code>{src.model}</code> with "
        + ", ".join(f"<code>{c.parameter}</code>" for c in controllers)
        + f" switched to their conditional inputs and driven by <code>{box_class}</code>. Inputs: the "
        "twin's own inputs, the measurements (<code>*_meas</code>) and <code>hold</code>; the box also "
        "holds until <code>holdUntil</code> (the spec's start-up hold). Outputs: the twin's own outputs "
        "and the tracked parameter values. State compensation (<code>[[states]]</code> in the spec) is "
        "not generated: the twin's correction inputs stay inputs.</p></html>")
    return GeneratedModel(
        header="\n".join(header_lines), package=package, box_class=box_class, tracked_class=tracked_class,
        twin_model=src.model, sample_time=float(spec.sample_time), stop_time=float(stop),
        hold_until=float(spec.tracking.hold_until),
        controllers=tuple(controllers), modifier_lines=_modifier_lines(list(sites.values())),
        class_order=("RealInput", "RealOutput", box_class, tracked_class),
        package_info=package_info, box_info=box_info, tracked_info=tracked_info)


def render(model: GeneratedModel) -> dict[str, str]:
    """Render the package files: file name -> text."""
    env = environment()
    return {
        "package.mo": env.get_template("package.mo.jinja").render(m=model),
        "package.order": env.get_template("package.order.jinja").render(m=model),
        f"{model.box_class}.mo": env.get_template("TrackingBox.mo.jinja").render(m=model),
        f"{model.tracked_class}.mo": env.get_template("Tracked.mo.jinja").render(m=model),
    }


def generate(spec: Any, out_dir: str | Path, *, rewrite: bool = False) -> GenerateResult:
    """Generate the ``<Twin>Tracking`` package for *spec* into *out_dir*.

    Parameters
    ----------
    spec : trackingbox.spec.Spec
        A loaded spec with ``[source]`` and ``[[pairs]]``.
    out_dir : path
        Directory that receives ``<Twin>Tracking/`` (and ``patched/`` with *rewrite*).
    rewrite : bool
        If a tracked parameter's component lacks the conditional-input pattern,
        write a patched copy of the twin's source (under ``out_dir/patched``)
        instead of refusing.

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
    src = load_twin(spec.source.path, spec.source.model)
    known = set(spec.parameter_names)
    sites: dict[str, ParameterSite] = {}
    for pair in spec.pairs:
        if pair.parameter not in known:
            raise SpecError(unknown_name("parameter", pair.parameter, sorted(known), f"[[pairs]] of {where}"))
        sites[pair.parameter] = parameter_site(src, pair.parameter, f"[[pairs]] of {where}")
    missing = [s for s in sites.values() if not s.has_pattern]
    rw: Rewrite | None = None
    library = src.top
    if missing:
        if not rewrite:
            raise SpecError("\n".join(refusal_message(src, s) for s in missing))
        rw = rewrite_source(src, missing, out_dir / "patched")
        logger.info("wrote a patched copy of the twin's source to %s", rw.path)
        src_new = load_twin(rw.path, spec.source.model)
        for name in sites:
            sites[name] = parameter_site(src_new, name, f"[[pairs]] of {where}")
            if not sites[name].has_pattern:
                raise SpecError(f"rewriting the source did not give {name!r} a conditional input")
        src = src_new
        library = src_new.top
    model = build_model(spec, src, sites, out_dir, library)
    texts = render(model)
    # Never write what does not load: check in a staging tree first.
    with tempfile.TemporaryDirectory(prefix="trackingbox-gen-") as tmp:
        staged_gen = Path(tmp) / "gen" / model.package
        staged_gen.mkdir(parents=True)
        for name, text in texts.items():
            (staged_gen / name).write_text(text, encoding="utf-8")
        pkg = stage_packages(Path(tmp) / "stage", library, staged_gen)
        check_loads(pkg, f"{model.package}.{model.tracked_class}", pkg.parent)
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
                          rewrite=rw, controllers=model.controllers)


def compile_generated(result: GenerateResult, *, backend: str = "auto", output: Path | None = None) -> Any:
    """Compile the tracked model with :func:`trackingbox.compiler.compile_model`.

    The twin's library (the patched copy after ``--rewrite``) is passed as a
    further library, the generated package as the source.

    Returns
    -------
    trackingbox.compiler.CompileResult
    """
    from ..compiler import compile_model

    output = output or result.package_dir.parent / f"{result.tracked_model.rsplit('.', 1)[1]}.fmu"
    return compile_model(result.package_dir, result.tracked_model, backend=backend, output=output,
                         libraries=[result.library])
