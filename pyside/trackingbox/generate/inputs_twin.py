"""The twin with its tracked parameters as Real inputs: what the continuous tracking mode integrates.

The tracking loop's continuous mode (``track(..., controllers="continuous")``)
integrates the parameter controllers with the twin in one right-hand side, so
the tracked parameters change *inside* an integrator step. FMI 3 allows a
tunable parameter to be set only in event mode (CVODE would have to stop at
every change); a continuous Real *input* may be set at any time in
continuous-time mode. This module makes that twin the way the tracked model of
:mod:`.generator` does: it extends the twin with each tracked parameter's
component switched to its conditional input (the MSL pattern
``hx(use_kht_in = true)``, :func:`.generator._modifier_lines`) and connects a
top-level ``RealInput`` (``hx_kht_in``) to it. A correction that is a
component parameter gets an input the same way; a correction that is already
a top-level input stays what it is.

:func:`inputs_twin` generates that package, compiles it (embedded backend
unless told otherwise) and caches the FMU by the generated text and the twin's
source files, so a bench or a repeated run compiles it once.
"""
from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..compiler import compile_model
from ..errors import SpecError
from ..io import write_text_atomic
from ..version import __version__
from . import filters
from .generator import _fill_equations, _modifier_lines, environment
from .source import (
    ParameterSite,
    check_loads,
    load_twin,
    parameter_site,
    stage_packages,
)

log = logging.getLogger(__name__)

__all__ = ["InputsTwin", "InputsModel", "inputs_model", "inputs_twin"]


@dataclass(frozen=True)
class InputSite:
    """One generated input: ``name`` drives the component's conditional input ``target``."""

    parameter: str       # e.g. "hx.kht"
    name: str            # top-level input, e.g. "hx_kht_in"
    target: str          # e.g. "hx.kht_in"
    start: float
    unit_attr: str       # 'unit = "W/(m2.K)", ' or ""
    extent: tuple[tuple[float, float], ...]
    line: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class InputsModel:
    """The template's input (``codegen/Inputs.mo.jinja``)."""

    header: str
    package: str
    model_class: str
    twin_model: str
    modifier_lines: tuple[str, ...]
    fill_equations: tuple[str, ...]
    inputs: tuple[InputSite, ...]
    info: str

    @property
    def model(self) -> str:
        return f"{self.package}.{self.model_class}"

    def render(self) -> str:
        return environment().get_template("Inputs.mo.jinja").render(m=self)


@dataclass(frozen=True)
class InputsTwin:
    """A compiled inputs twin: its FMU and, per tracked value, the FMU input that takes it."""

    fmu: Path
    model: str
    inputs: dict[str, str]


def inputs_model(spec: Any) -> tuple[InputsModel, Path]:
    """The inputs twin of *spec* (its ``[source]`` twin and ``[[pairs]]``), and the twin's library.

    Raises
    ------
    SpecError
        No ``[source]``, or a tracked parameter without the conditional-input pattern.
    """
    where = str(spec.path)
    if spec.source is None:
        raise SpecError(f"{where} has no [source] table: the continuous tracking mode compiles the twin with "
                        f"its tracked parameters as inputs from its Modelica source")
    src = load_twin(spec.source.path, spec.source.model)
    sites: dict[str, ParameterSite] = {}
    for pair in spec.pairs:
        sites[pair.parameter] = parameter_site(src, pair.parameter, f"[[pairs]] of {where}")
    for st in spec.states:
        if "." in st.correction:  # a component parameter (a top-level input has no dot)
            sites[st.correction] = parameter_site(src, st.correction, f"[[states]] {st.tag!r} of {where}")
    missing = [s.name for s in sites.values() if not s.has_pattern]
    if missing:
        raise SpecError(f"the continuous tracking mode needs {', '.join(missing)} with a conditional input "
                        f"(use_<name>_in / <name>_in, see `trackingbox generate --rewrite`); run with "
                        f"controllers='discrete' or add the pattern to the twin's source")
    twin_short = src.model.rsplit(".", 1)[-1]
    package = filters.modelica_ident(f"{twin_short}Inputs")
    taken = {n for n in src.variables if "." not in n}
    inputs = []
    for i, name in enumerate(sorted(sites)):
        site = sites[name]
        ident = f"{filters.modelica_name(name)}_in"
        if ident in taken:
            raise SpecError(f"input name {ident!r} for {name} clashes with a variable of {src.model}")
        var = src.variables[name]
        unit = var.get("unit") if isinstance(var.get("unit"), str) else ""
        try:
            start = float(spec.parameter(name).start)
        except (KeyError, ValueError, AttributeError):
            start = 0.0
        y = 80.0 - 40.0 * i
        inputs.append(InputSite(parameter=name, name=ident, target=site.input, start=start,
                                unit_attr=f'unit = "{unit}", ' if unit else "",
                                extent=((-140.0, y - 20.0), (-100.0, y + 20.0)),
                                line=((-120.0, y), (-80.0, y))))
    header = "\n".join([
        f"// Generated by trackingbox {__version__} (the continuous tracking mode's inputs twin). Do not edit.",
        f"// twin:  {src.model}",
        *(f"// input: {x.name} -> {x.target}" for x in inputs),
    ])
    info = (f"<html><p><code>{src.model}</code> with "
            + ", ".join(f"<code>{x.parameter}</code>" for x in inputs)
            + " switched to their conditional inputs and driven by the top-level inputs "
            + ", ".join(f"<code>{x.name}</code>" for x in inputs)
            + ": the tracking loop sets them inside the integrator's right-hand side (continuous mode)."
            "</p></html>")
    model = InputsModel(header=header, package=package, model_class=f"{twin_short}Inputs", twin_model=src.model,
                        modifier_lines=_modifier_lines(list(sites.values()), src.variables),
                        fill_equations=_fill_equations(list(sites.values()), src.variables),
                        inputs=tuple(inputs), info=info)
    return model, src.top


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "trackingbox" / "inputs-twins"


def _library_digest(library: Path) -> str:
    h = hashlib.sha256()
    files = sorted(library.rglob("*")) if library.is_dir() else [library]
    for f in files:
        if f.is_file() and f.suffix in (".mo", ".order"):
            h.update(str(f.relative_to(library.parent)).encode())
            h.update(f.read_bytes())
    return h.hexdigest()


def _names(spec: Any) -> list[str]:
    """The values the inputs twin takes as inputs: the pairs' parameters and the corrections that are
    component parameters (a dotted name; a top-level input of the twin stays what it is)."""
    names = {pair.parameter for pair in spec.pairs}
    names |= {st.correction for st in spec.states if "." in st.correction}
    return sorted(names)


def inputs_twin(spec: Any, *, backend: str = "embedded", cache: Path | None = None) -> InputsTwin:
    """Generate and compile *spec*'s inputs twin, or take it from the cache.

    The cache key is the twin's source files, its model, the values switched to
    inputs with their start values, this version and *backend*: what the
    generated text is made from, so a hit needs no Modelica front end.

    Returns
    -------
    InputsTwin
        The FMU, its model name and ``{tracked value: FMU input}``.
    """
    if spec.source is None:
        inputs_model(spec)  # raises: no [source]
    names = _names(spec)
    starts = []
    for n in names:
        try:
            starts.append(repr(float(spec.parameter(n).start)))
        except (KeyError, ValueError, AttributeError):
            starts.append("-")
    library = Path(spec.source.path)
    parts = [__version__, backend, spec.source.model, _library_digest(library), *names, *starts]
    key = hashlib.sha256("\n".join(parts).encode()).hexdigest()[:16]
    cache = cache or _cache_dir()
    short = spec.source.model.rsplit(".", 1)[-1]
    fmu = cache / f"{short}Inputs-{key}.fmu"
    model_name = f"{filters.modelica_ident(short + 'Inputs')}.{short}Inputs"
    if fmu.exists():
        return InputsTwin(fmu, model_name, {n: f"{filters.modelica_name(n)}_in" for n in names})
    model, top = inputs_model(spec)
    cache.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="trackingbox-inputs-") as tmp:
        gen = Path(tmp) / "gen" / model.package
        gen.mkdir(parents=True)
        write_text_atomic(gen / "package.mo", model.render())
        pkg = stage_packages(Path(tmp) / "stage", top, gen)
        check_loads(pkg, model.model, pkg.parent)
        log.info("compiling the inputs twin %s (%s backend)", model.model, backend)
        compile_model(pkg, model.model, backend=backend, output=fmu, libraries=[Path(tmp) / "stage" / top.name])
    return InputsTwin(fmu, model.model, {x.parameter: x.name for x in model.inputs})
