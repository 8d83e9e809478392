"""The effect library of ``diagnose``: entries, targets, patches.

An *effect entry* is a folder holding ``effect.toml`` (what the effect is, where
it applies, its parameters with bounds) and ``patch.mo.jinja`` (the Modelica it
adds to the twin). The built-in entries live in ``trackingbox.codegen.effects``;
a spec adds its own with ``[diagnose] effects = ["folder", ...]`` (see
``docs/diagnose-effects.md``).

A *patch* is the twin extended with one or more effects::

    model TwinDiagnosed "..."
      extends TrackingBox.Benches.HeatProduction.Twin(T200(use_leak = true));
      parameter Real leak_T200_k(unit = "kg/s", min = 0.0, max = 0.05) = 0.004 "...";
      ...
    equation
      ...
    end TwinDiagnosed;

:func:`render_patch` writes its text (deterministic, with a header stating what
was found and the fitted values) and the unified diff against the twin's file,
:func:`compile_patch` builds it on the embedded path and :func:`patched_spec`
writes a spec for the patched twin so that estimation and tracking go on with it.
"""
from __future__ import annotations

import difflib
import functools
import importlib.resources
import logging
import math
import re
import shutil
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

import jinja2

from ..compiler import compile_model, library_path
from ..compiler.source import _class_range, _file_of, read_text, resolve_source, strip_comments
from ..errors import SpecError, did_you_mean
from ..fmu import read_info
from ..generate import filters
from ..generate.filters import modelica_string
from ..io import write_text_atomic
from ..spec import ParameterSpec, SourceSpec, load_spec, write_spec
from ..version import __version__
from . import elements, sizes

log = logging.getLogger(__name__)

__all__ = ["Effect", "EffectParameter", "Finding", "Patch", "PatchParameter", "load_effects", "targets",
           "render_patch", "write_patch", "compile_patch", "patched_spec", "builtin_folder"]

EffectKind = Literal["sensor", "process"]
ScreenKind = Literal["bias", "drift", "levelling-drift", "lag", "coefficient-ramp", "levelling-ramp", "compile"]
KINDS: tuple[str, ...] = ("sensor", "process")
SCREENS: tuple[str, ...] = ("bias", "drift", "levelling-drift", "lag", "coefficient-ramp", "levelling-ramp",
                             "compile")
#: ``unit`` of an effect parameter may name the unit of the tag's variable: ``{unit}`` or ``{unit}/s``.
UNIT_OF_VARIABLE = "{unit}"

_ID = re.compile(r"^[a-z][a-z0-9]*(?:-[a-z0-9]+)*$")
_IDENT = re.compile(r"^[A-Za-z_]\w*$")
_DOTTED = re.compile(r"^[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*$")
_ENTRY_KEYS = ("id", "explanation", "kind", "classes", "hook", "screen", "coefficient", "parameters", "sources",
               "carried")
_PARAMETER_KEYS = ("name", "description", "unit", "start", "min", "max", "ranges", "onset_of", "per", "per_range")


# --------------------------------------------------------------------------- entries

@dataclass(frozen=True)
class EffectParameter:
    """One parameter of an effect.

    Attributes
    ----------
    name : str
        Modelica identifier (the patch declares ``<prefix>_<name>``).
    description : str
    unit : str
        SI unit; ``{unit}`` stands for the unit of the tag's variable (sensor effects).
    start, min, max : float
        Start value and bounds.
    ranges : mapping
        Bounds per unit of the tag's variable (``"K" = [-2.0, 2.0]``), overriding
        ``min``/``max`` for a tag of that unit.
    onset_of : str
        A threshold of the target's variable of this name (``x``): the linearised screen starts the
        parameter at that variable's quartiles too (:func:`trackingbox.diagnose.fit.onset_starts`).
    per, per_range : str or mapping, tuple
        Process entries: (start, min, max) per unit of the target's parameter *per* (``"A"``, or a table
        class = parameter), replacing the absolute ones on those targets (:mod:`.sizes`).
    """

    name: str
    description: str
    unit: str
    start: float
    min: float
    max: float
    ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    onset_of: str = ""
    per: str | Mapping[str, str] = ""
    per_range: tuple[float, float, float] | None = None

    def resolved(self, variable_unit: str = "") -> tuple[str, float, float, float]:
        """(unit, start, min, max) for a target whose variable has unit *variable_unit*."""
        base = variable_unit or "1"
        if self.unit != UNIT_OF_VARIABLE and "/" in base:  # "{unit}/s" of kg/s is (kg/s)/s
            base = f"({base})"
        unit = self.unit.replace(UNIT_OF_VARIABLE, base)
        lo, hi = self.ranges.get(variable_unit, (self.min, self.max))
        start = min(max(self.start, lo), hi)
        return unit, float(start), float(lo), float(hi)


@dataclass(frozen=True)
class Effect:
    """One effect entry: what it is, where it applies, its parameters and its Modelica template.

    Attributes
    ----------
    id : str
        Kebab-case identifier, the entry's folder name.
    explanation : str
        One line of physics: what the effect does.
    kind : {"sensor", "process"}
        ``sensor``: the target is a measurement tag; ``process``: a component instance of the twin.
    classes : tuple of str
        Process effects: the component classes it applies to (full names; subclasses match too).
    hook : str or None
        Process effects: the Boolean parameter of the hook the component offers (set true by the patch).
    screen : str
        How ``diagnose`` screens it cheaply (``bias``, ``drift``, ``levelling-drift``, ``lag``,
        ``coefficient-ramp``, ``levelling-ramp``, ``compile``).
    coefficient : str or None
        For ``coefficient-ramp`` and ``levelling-ramp``: the target's parameter that changes with time.
    parameters : tuple of EffectParameter
    template : str
        Text of ``patch.mo.jinja``.
    folder : Path
        Where the entry was read from.
    sources : str
        Where its form and bounds come from (notes, literature), for the reader.
    carried : tuple of str
        States the template declares (``<prefix>_<name>``) that hold the plant's history (a scale grown
        over hours): carried from the run over the history into a later window's run, never settled at
        a steady start (``[data] carry`` of the patched spec, :func:`trackingbox.simulation.windows.carried_states`).
    """

    id: str
    explanation: str
    kind: EffectKind
    classes: tuple[str, ...]
    hook: str | None
    screen: ScreenKind
    coefficient: str | None
    parameters: tuple[EffectParameter, ...]
    template: str
    folder: Path
    sources: str = ""
    carried: tuple[str, ...] = ()

    def parameter(self, name: str) -> EffectParameter:
        """The parameter *name*; SpecError with did-you-mean when unknown."""
        for p in self.parameters:
            if p.name == name:
                return p
        raise SpecError(f"effect {self.id!r} has no parameter {name!r}"
                        f"{did_you_mean(name, [p.name for p in self.parameters])}")


def builtin_folder() -> Path:
    """Folder of the built-in entries (``codegen/effects``)."""
    return Path(str(importlib.resources.files("trackingbox.codegen"))) / "effects"


def _number(table: Mapping[str, Any], key: str, where: str, problems: list[str]) -> float | None:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        problems.append(f"{where}: field {key!r} must be a finite number, got {value!r}")
        return None
    return float(value)


def _read_parameter(table: Any, i: int, where: str, problems: list[str]) -> EffectParameter | None:
    label = f"{where}: [[parameters]] #{i + 1}"
    if not isinstance(table, dict):
        problems.append(f"{label} must be a table")
        return None
    for key in sorted(set(table) - set(_PARAMETER_KEYS)):
        problems.append(f"{label}: unknown field {key!r}{did_you_mean(key, _PARAMETER_KEYS)}")
    name = table.get("name")
    if not isinstance(name, str) or not _IDENT.match(name):
        problems.append(f"{label}: field 'name' must be a Modelica identifier, got {name!r}")
        name = None
    else:
        label = f"{where}: parameter {name!r}"
    description = table.get("description", "")
    unit = table.get("unit")
    if not isinstance(description, str):
        problems.append(f"{label}: field 'description' must be a string")
    if not isinstance(unit, str) or not unit:
        problems.append(f"{label}: field 'unit' must be a unit string (SI, e.g. \"kg/s\"), got {unit!r}")
    values = [_number(table, k, label, problems) for k in ("start", "min", "max")]
    ranges: dict[str, tuple[float, float]] = {}
    raw_ranges = table.get("ranges", {})
    if not isinstance(raw_ranges, dict):
        problems.append(f"{label}: field 'ranges' must be a table unit = [min, max]")
    else:
        for u, pair in raw_ranges.items():
            if (not isinstance(pair, list) or len(pair) != 2
                    or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in pair)
                    or not pair[0] < pair[1]):
                problems.append(f"{label}: field 'ranges' entry {u!r} must be [min, max] with min < max, "
                                f"got {pair!r}")
                continue
            ranges[u] = (float(pair[0]), float(pair[1]))
    onset = table.get("onset_of", "")
    if not isinstance(onset, str) or (onset and not _DOTTED.match(onset)):
        problems.append(f"{label}: field 'onset_of' must name a variable of the target, got {onset!r}")
        onset = ""
    per, per_range = sizes.read_per(table, label, problems)
    if name is None or None in values or not isinstance(unit, str) or not isinstance(description, str):
        return None
    start, lo, hi = values
    assert start is not None and lo is not None and hi is not None
    if not lo < hi:
        problems.append(f"{label}: field 'min' ({lo!r}) must be below field 'max' ({hi!r})")
    elif not lo <= start <= hi:
        problems.append(f"{label}: field 'start' ({start!r}) is outside [min, max] = [{lo!r}, {hi!r}]")
    return EffectParameter(name=name, description=description, unit=unit, start=start, min=lo, max=hi,
                           ranges=ranges, onset_of=onset, per=per, per_range=per_range)


def read_effect(folder: str | Path) -> Effect:
    """Read the effect entry in *folder* (``effect.toml`` + ``patch.mo.jinja``).

    Raises
    ------
    SpecError
        Listing every problem, each naming the file and the field.
    """
    folder = Path(folder)
    toml_file = folder / "effect.toml"
    template_file = folder / "patch.mo.jinja"
    where = str(toml_file)
    problems: list[str] = []
    if not toml_file.is_file():
        raise SpecError(f"effect entry {folder}: no effect.toml (looked for {toml_file})")
    if not template_file.is_file():
        raise SpecError(f"effect entry {folder}: no patch.mo.jinja (looked for {template_file})")
    try:
        raw = tomllib.loads(toml_file.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{where}: not valid TOML: {exc}") from None
    for key in sorted(set(raw) - set(_ENTRY_KEYS)):
        problems.append(f"{where}: unknown field {key!r}{did_you_mean(key, _ENTRY_KEYS)}")
    eid = raw.get("id")
    if not isinstance(eid, str) or not _ID.match(eid):
        problems.append(f"{where}: field 'id' must be a kebab-case identifier, got {eid!r}")
    elif eid != folder.name:
        problems.append(f"{where}: field 'id' ({eid!r}) must equal the folder name {folder.name!r}")
    explanation = raw.get("explanation")
    if not isinstance(explanation, str) or not explanation.strip():
        problems.append(f"{where}: field 'explanation' must be a one-line physical explanation")
    kind = raw.get("kind")
    if kind not in KINDS:
        problems.append(f"{where}: field 'kind' must be one of {', '.join(KINDS)}, got {kind!r}"
                        f"{did_you_mean(str(kind), KINDS)}")
    screen = raw.get("screen", "compile")
    if screen not in SCREENS:
        problems.append(f"{where}: field 'screen' must be one of {', '.join(SCREENS)}, got {screen!r}"
                        f"{did_you_mean(str(screen), SCREENS)}")
    classes = raw.get("classes", [])
    if not isinstance(classes, list) or not all(isinstance(c, str) and _DOTTED.match(c) for c in classes):
        problems.append(f"{where}: field 'classes' must be a list of full Modelica class names, got {classes!r}")
        classes = []
    if kind == "process" and not classes:
        problems.append(f"{where}: field 'classes' is required for a process effect (the component classes "
                        "it applies to)")
    hook = raw.get("hook")
    if hook is not None and (not isinstance(hook, str) or not _IDENT.match(hook)):
        problems.append(f"{where}: field 'hook' must be the name of a Boolean parameter, got {hook!r}")
    sources = raw.get("sources", "")
    if not isinstance(sources, str):
        problems.append(f"{where}: field 'sources' must be a string (where the form and the bounds come from)")
        sources = ""
    coefficient = raw.get("coefficient")
    if coefficient is not None and (not isinstance(coefficient, str) or not _IDENT.match(coefficient)):
        problems.append(f"{where}: field 'coefficient' must be a parameter name, got {coefficient!r}")
    if not isinstance(carried := raw.get("carried", []), list) or not all(
            isinstance(c, str) and _IDENT.match(c) for c in carried):
        problems.append(f"{where}: field 'carried' must list names of states the template declares, got {carried!r}")
    if screen in ("coefficient-ramp", "levelling-ramp") and coefficient is None:
        problems.append(f"{where}: field 'coefficient' is required with screen = {screen!r}")
    if screen in ("levelling-drift", "levelling-ramp") and len(raw.get("parameters") or []) != 2:
        problems.append(f"{where}: screen = {screen!r} needs exactly two [[parameters]]: the rate at the start, "
                        f"then the levelling coefficient c (1/s; 0 = no levelling)")
    if kind == "sensor" and screen in ("coefficient-ramp", "levelling-ramp"):
        problems.append(f"{where}: field 'screen' = {screen!r} needs a process effect")
    raw_params = raw.get("parameters", [])
    params: list[EffectParameter] = []
    if not isinstance(raw_params, list) or not raw_params:
        problems.append(f"{where}: field 'parameters' must be a non-empty array of tables [[parameters]]")
    else:
        for i, table in enumerate(raw_params):
            p = _read_parameter(table, i, where, problems)
            if p is not None:
                if any(q.name == p.name for q in params):
                    problems.append(f"{where}: parameter {p.name!r} is listed twice")
                params.append(p)
    template = template_file.read_text(encoding="utf-8")
    try:
        _environment().parse(template)
    except jinja2.TemplateSyntaxError as exc:
        problems.append(f"{template_file}:{exc.lineno}: template syntax error: {exc.message}")
    if problems:
        raise SpecError("bad effect entry: " + "; ".join(problems))
    return Effect(id=eid, explanation=explanation.strip(), kind=kind, classes=tuple(classes), hook=hook,
                  screen=screen, coefficient=coefficient, parameters=tuple(params), template=template,
                  folder=folder.resolve(), sources=sources.strip(), carried=tuple(carried))


def load_effects(folders: Iterable[str | Path] = ()) -> dict[str, Effect]:
    """The built-in effect entries plus those in *folders* (each a folder of entry folders).

    A user entry with the id of a built-in one replaces it (logged).

    Raises
    ------
    SpecError
        A folder does not exist, or an entry is malformed (file and field named).
    """
    effects: dict[str, Effect] = {}
    roots = [builtin_folder(), *(Path(f) for f in folders)]
    for root in roots:
        if not root.is_dir():
            raise SpecError(f"effects folder {root} does not exist")
        entries = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith((".", "_")))
        if (root / "effect.toml").is_file():  # the folder is itself one entry
            entries = [root]
        for folder in entries:
            effect = read_effect(folder)
            if effect.id in effects:
                log.info("effect %r from %s replaces the one from %s", effect.id, folder,
                         effects[effect.id].folder)
            effects[effect.id] = effect
    return effects


# --------------------------------------------------------------------------- targets

_CLASS_KW = r"(?:model|block|class|connector|record)"
_EXTENDS = re.compile(r"\bextends\s+([A-Za-z_][\w.]*)")
_DECL = re.compile(r"(?m)^\s*(?:(?:parameter|constant|input|output|flow|stream|inner|outer|final|replaceable|"
                   r"redeclare|discrete)\s+)*([A-Za-z_][\w.]*)\s+([A-Za-z_]\w*)\s*(?:\[([^\]]*)\]\s*)?(?=[(\"=;]|\bif\b)")
_NOT_TYPES = {"extends", "import", "within", "equation", "algorithm", "protected", "public", "end", "connect",
              "annotation", "if", "for", "when", "else", "elseif", "der", "initial", "model", "block", "class",
              "package", "connector", "record", "function", "type", "partial", "encapsulated"}


class _ClassIndex:
    """Class bodies of a Modelica source and the shipped library, looked up by full name."""

    def __init__(self, source_path: Path) -> None:
        self.sources = [resolve_source(source_path)]
        lib = Path(library_path())
        if lib.resolve() != Path(source_path).resolve():
            self.sources.append(resolve_source(lib))
        self._cache: dict[str, tuple[str, str] | None] = {}

    def body(self, name: str) -> tuple[str, str] | None:
        """(full name, comment-free text of the class) or None when not found."""
        if name in self._cache:
            return self._cache[name]
        found = None
        for src in self.sources:
            file = _file_of(src, name)
            if file is None:
                continue
            code = strip_comments(read_text(file))
            rng = _class_range(code, name)  # the longest suffix: a class nested in a one-file package too
            if rng is not None:
                found = (name, code[rng[0]:rng[1]])
                break
        self._cache[name] = found
        return found

    def resolve(self, type_name: str, scope: str) -> str | None:
        """Full name of *type_name* as seen from class *scope* (Modelica's outward lookup)."""
        parts = scope.split(".")
        for k in range(len(parts) - 1, -1, -1):
            candidate = ".".join([*parts[:k], type_name])
            if self.body(candidate) is not None:
                return candidate
        return type_name if self.body(type_name) is not None else None

    def bases(self, name: str) -> list[str]:
        """*name* and every class it extends, transitively."""
        out, todo = [], [name]
        while todo:
            cur = todo.pop()
            if cur in out:
                continue
            out.append(cur)
            found = self.body(cur)
            if found is None:
                continue
            for m in _EXTENDS.finditer(found[1]):
                full = self.resolve(m.group(1), cur)
                if full is not None:
                    todo.append(full)
        return out

    def components(self, model: str) -> dict[str, str]:
        """Component instance name -> full class name, of *model* and the classes it extends."""
        return {inst: cls for inst, (cls, _) in self.declarations(model).items()}

    def declarations(self, model: str) -> dict[str, tuple[str, str | None]]:
        """Component instance name -> (full class name, its array dimensions as written or None)."""
        comps: dict[str, tuple[str, str | None]] = {}
        for cls in self.bases(model):
            found = self.body(cls)
            if found is None:
                continue
            text = found[1]
            head = text.find("\n")
            section = re.split(r"\n\s*(?:equation|algorithm|initial\s+equation)\b", text[head + 1:])[0]
            for m in _DECL.finditer(section):
                type_name, inst = m.group(1), m.group(2)
                if type_name in _NOT_TYPES or inst in _NOT_TYPES:
                    continue
                full = self.resolve(type_name, cls)
                if full is not None and inst not in comps:
                    dims = m.group(3)
                    comps[inst] = (full, dims.strip() if dims is not None else None)
        return comps


def targets(effect: Effect, spec: Any, *, _index: _ClassIndex | None = None) -> list[str]:
    """Where *effect* may act in *spec*'s twin.

    Sensor effects: the tags of ``[outputs]`` (spec order). Process effects: the
    component instances of the twin (``[source]``, through ``extends``) whose
    class is one of ``effect.classes`` or extends one, sorted by name.

    Raises
    ------
    SpecError
        A process effect on a spec without ``[source]``.
    """
    if effect.kind == "sensor":
        return list(spec.outputs)
    if spec.source is None:
        raise SpecError(f"effect {effect.id!r} acts on components of the twin's Modelica source, but "
                        f"{spec.path} has no [source] table")
    index = _index or _ClassIndex(spec.source.path)
    if index.body(spec.source.model) is None:
        raise SpecError(f"model {spec.source.model!r} in [source] of {spec.path} is not found in "
                        f"{spec.source.path}")
    wanted = set(effect.classes)
    declared = index.declarations(spec.source.model)
    found = [inst for inst, (cls, _) in declared.items() if wanted & set(index.bases(cls))]
    # an array of components (a train's effects): the whole array, and each element on its own
    elements = [f"{inst}[{k}]" for inst in found if declared[inst][1] is not None
                for k in range(1, _array_size(spec, inst, declared[inst][1]) + 1)]
    return sorted(found + elements)


_ELEMENT = re.compile(r"^([A-Za-z_]\w*)\[(\d+)\]$")


def _array_size(spec: Any, inst: str, dims: str) -> int:
    """Number of elements of the component array *inst* declared ``[dims]``: the literal, else the largest
    index of ``inst[k].`` among the twin FMU's variables (0 when neither tells: no element targets)."""
    if dims.strip().isdigit():
        return int(dims)
    try:
        names = _fmu_names(str(Path(spec.twin).resolve()), Path(spec.twin).stat().st_mtime_ns)
    except Exception as exc:  # noqa: BLE001 - without the FMU the whole array stays a target
        log.warning("cannot read the size of %s[%s] from the twin FMU %s: %s", inst, dims, spec.twin, exc)
        return 0
    pat = re.compile(rf"^{re.escape(inst)}\[(\d+)\]\.")
    return max((int(m.group(1)) for name in names if (m := pat.match(name))), default=0)


@functools.lru_cache(maxsize=8)
def _fmu_names(path: str, mtime_ns: int) -> tuple[str, ...]:
    """Variable names of the FMU at *path* (read once per file version)."""
    return tuple(v.name for v in read_info(path).variables)


# --------------------------------------------------------------------------- patches

@dataclass(frozen=True)
class Finding:
    """An effect on a target with its parameter values (fitted, or the starts)."""

    effect: str
    target: str
    values: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class PatchParameter:
    """A tunable parameter a patch adds: full name, unit, start (the value written), bounds."""

    name: str
    unit: str
    start: float
    min: float
    max: float
    description: str
    effect: str
    target: str


@dataclass(frozen=True)
class Patch:
    """A rendered patch: the twin extended with the findings' effects.

    Attributes
    ----------
    model : str
        Full class name of the patched twin (``TwinDiagnosed``).
    twin : str
        Full class name of the twin it extends.
    source : str
        Text of ``<model>.mo``.
    diff : str
        Unified diff that adds ``<model>.mo`` (the twin's own file is unchanged: the patch extends it).
    outputs : dict
        Tag -> new output variable, for sensor effects.
    parameters : tuple of PatchParameter
    findings : tuple of Finding
    library : Path
        The twin's Modelica source (package directory or file).
    """

    model: str
    twin: str
    source: str
    diff: str
    outputs: dict[str, str]
    parameters: tuple[PatchParameter, ...]
    findings: tuple[Finding, ...]
    library: Path
    carry: tuple[str, ...] = ()   # the effects' carried states, full names (Effect.carried)

    @property
    def file_name(self) -> str:
        return f"{self.model.rsplit('.', 1)[-1]}.mo"

    def to_json(self) -> dict[str, Any]:
        return {"model": self.model, "twin": self.twin, "source": self.source, "diff": self.diff,
                "outputs": dict(self.outputs),
                "parameters": [{"name": p.name, "unit": p.unit, "start": p.start, "min": p.min, "max": p.max,
                                "effect": p.effect, "target": p.target} for p in self.parameters]}


def _environment() -> jinja2.Environment:
    env = jinja2.Environment(
        undefined=jinja2.StrictUndefined, keep_trailing_newline=True, trim_blocks=True, lstrip_blocks=True,
        autoescape=False, variable_start_string="<<", variable_end_string=">>", block_start_string="<%",
        block_end_string="%>", comment_start_string="<#", comment_end_string="#>")
    return filters.register(env)


def _camel(effect_id: str) -> str:
    head, *rest = effect_id.split("-")
    return head + "".join(w[:1].upper() + w[1:] for w in rest)


def prefix_for(effect_id: str, target: str) -> str:
    """The identifier prefix of a finding: ``leak_T200``, ``sensorBias_TI_102``."""
    return f"{_camel(effect_id)}_{re.sub(r'[^A-Za-z0-9_]', '_', target)}"


def _variable_units(spec: Any) -> dict[str, str]:
    """Twin variable -> unit, from the twin FMU (empty when it cannot be read)."""
    try:
        info = read_info(spec.twin)
    except Exception as exc:  # noqa: BLE001 - units only refine the bounds
        log.warning("cannot read units from the twin FMU %s: %s", spec.twin, exc)
        return {}
    return {v.name: (v.unit or "") for v in info.variables}


_SECTIONS = ("public", "protected", "initial equation", "equation")


def _split_rendered(text: str, where: str) -> dict[str, list[str]]:
    """Public declarations, protected declarations, initial equations and equations of a rendered template.

    The template separates them with lines ``protected``, ``initial equation`` and
    ``equation`` (in that order, each optional).
    """
    parts: dict[str, list[str]] = {k: [] for k in _SECTIONS}
    order = list(_SECTIONS)
    current = "public"
    for line in text.splitlines():
        word = " ".join(line.split())
        if word in order[1:]:
            if order.index(word) <= order.index(current):
                raise SpecError(f"{where}: the rendered patch has {word!r} out of order or twice "
                                "(declarations, then 'protected', 'initial equation', 'equation')")
            current = word
            continue
        if word:
            parts[current].append(line.rstrip())
    return parts


def _parameter(spec: Any, effect: Effect, p: EffectParameter, f: Finding, variable_unit: str, bases: list[str],
               sized: list[str], prefix: str, where: str) -> tuple[dict[str, Any], PatchParameter]:
    """Parameter *p* of *effect* on the finding's target: its template values and its patch parameter, the
    bounds per unit of the target's size (``per``, read for the components *sized*) where the entry says."""
    unit, start, lo, hi = p.resolved(variable_unit)
    var = sizes.per_variable(p.per, bases) if effect.kind != "sensor" else ""
    if p.per_range is not None and var:
        start, lo, hi = sizes.scaled(effect.id, p.name, f.target, var, spec.twin, sized, p.per_range)
    value = float(f.values.get(p.name, start))
    if not math.isfinite(value) or not lo <= value <= hi:
        raise SpecError(f"{where}: value {value!r} of {p.name!r} is outside its bounds [{lo!r}, {hi!r}]")
    full = f"{prefix}_{p.name}"
    return ({"name": full, "value": value, "unit": unit, "min": lo, "max": hi, "description": p.description},
            PatchParameter(name=full, unit=unit, start=value, min=lo, max=hi, description=p.description,
                           effect=effect.id, target=f.target))


def render_patch(spec: Any, findings: Sequence[Finding], name: str | None = None, *,
                 effects: Mapping[str, Effect] | None = None) -> Patch:
    """Render ``<Twin>Diagnosed``: the twin of *spec* extended with *findings*.

    Parameters
    ----------
    spec : Spec
        With ``[source]`` (the twin's Modelica class).
    findings : sequence of Finding
        Effects with targets and values; missing values take the parameter's start.
    name : str, optional
        Class name of the patched twin (default ``<Twin>Diagnosed``).
    effects : mapping, optional
        The effect entries (default: :func:`load_effects` with the spec's ``[diagnose] effects``).

    Returns
    -------
    Patch

    Raises
    ------
    SpecError
        No ``[source]``, an unknown effect, parameter or target, a value outside its bounds.
    """
    if spec.source is None:
        raise SpecError(f"a patch extends the twin's Modelica class, but {spec.path} has no [source] table")
    if not findings:
        raise SpecError("render_patch needs at least one finding")
    effects = effects if effects is not None else load_effects(getattr(getattr(spec, "diagnose", None), "effects", ()))
    twin = spec.source.model
    model = name or f"{twin.rsplit('.', 1)[-1]}Diagnosed"
    if not _IDENT.match(model):
        raise SpecError(f"patched model name {model!r} is not a Modelica identifier")
    ordered = sorted(findings, key=lambda f: (f.effect, f.target))
    units: dict[str, str] | None = None
    index: _ClassIndex | None = None
    modifiers: dict[str, list[str]] = {}
    declarations: list[str] = []
    hidden: list[str] = []
    initial: list[str] = []
    equations: list[str] = []
    outputs: dict[str, str] = {}
    parameters: list[PatchParameter] = []
    header: list[str] = []
    env = _environment()
    seen: set[tuple[str, str]] = set()
    for f in ordered:
        if f.effect not in effects:
            raise SpecError(f"unknown effect {f.effect!r}{did_you_mean(f.effect, list(effects))}; "
                            f"known: {', '.join(sorted(effects))}")
        if (f.effect, f.target) in seen:
            raise SpecError(f"effect {f.effect!r} on {f.target!r} is listed twice")
        seen.add((f.effect, f.target))
        effect = effects[f.effect]
        where = f"effect {effect.id!r} on {f.target!r}"
        for key in f.values:
            effect.parameter(key)
        context: dict[str, Any] = {"target": f.target, "prefix": prefix_for(effect.id, f.target)}
        variable_unit = ""
        element = None
        if effect.kind == "sensor":
            if f.target not in spec.outputs:
                raise SpecError(f"{where}: {f.target!r} is not a tag of [outputs] in {spec.path}"
                                f"{did_you_mean(f.target, list(spec.outputs))}")
            if units is None:
                units = _variable_units(spec)
            variable = spec.outputs[f.target]
            variable_unit = units.get(variable, "")
            context["variable"] = variable
            context["output"] = f"{context['prefix']}_y"
            context["unit"] = variable_unit
            outputs[f.target] = context["output"]
        else:
            if index is None:
                index = _ClassIndex(spec.source.path)
            known = targets(effect, spec, _index=index)
            if f.target not in known:
                raise SpecError(f"{where}: {f.target!r} is not a component of {twin} that the effect applies to "
                                f"(classes {', '.join(effect.classes)}){did_you_mean(f.target, known)}")
            element = _ELEMENT.match(f.target)
            array_name = element.group(1) if element else f.target
            cls, dims = index.declarations(twin)[array_name]
            if effect.hook:
                # an array of components (a train's effects): the hook on every element
                hook = f"{'each ' if dims else ''}{effect.hook} = true"
                if hook in modifiers.get(array_name, []):
                    raise SpecError(f"{where}: another effect of the patch already uses the hook {effect.hook!r} "
                                    f"of {array_name!r}; one patch can drive a hook once")
                modifiers.setdefault(array_name, []).append(hook)
            context["cls"] = cls
            context["bases"] = index.bases(cls)
            context["array"] = dims is not None and element is None
            context["dims"] = (dims or "") if element is None else ""
        element_fill: tuple[list[str], list[str]] = ([], [])
        if effect.kind != "sensor" and element is not None and effect.hook and dims is not None:
            element_fill = elements.element_fill(_array_size(spec, array_name, dims), index, cls, effect.hook,
                                                 array_name, dims, int(element.group(2)),
                                         context["prefix"], where)
        params: dict[str, dict[str, Any]] = {}
        sized = [f.target]
        if effect.kind != "sensor" and dims is not None and element is None:  # a whole array: every element
            sized = [f"{array_name}[{k}]" for k in range(1, _array_size(spec, array_name, dims) + 1)] or sized
        for p in effect.parameters:
            params[p.name], patch_parameter = _parameter(spec, effect, p, f, variable_unit,
                                                         context.get("bases", []), sized, context["prefix"], where)
            parameters.append(patch_parameter)
        context["params"] = params
        try:
            rendered = env.from_string(effect.template).render(**context)
        except jinja2.TemplateError as exc:
            raise SpecError(f"{effect.folder / 'patch.mo.jinja'}: rendering for {f.target!r} failed: {exc}") from None
        parts = _split_rendered(rendered, str(effect.folder / "patch.mo.jinja"))
        declarations += [f"  // {effect.id} on {f.target}: {effect.explanation}", *parts["public"]]
        hidden += parts["protected"] + element_fill[0]
        initial += parts["initial equation"]
        equations += [f"  // {effect.id} on {f.target}", *parts["equation"], *element_fill[1]] if parts["equation"] else []
        values = ", ".join(f"{p['name']} = {p['value']:.6g} {p['unit']}".rstrip() for p in params.values())
        header.append(f"//   {effect.id} on {f.target}: {values}")

    mods = ", ".join(f"{t}({', '.join(sorted(set(m)))})" for t, m in sorted(modifiers.items()))
    extends = f"  extends {twin}({mods});" if mods else f"  extends {twin};"
    summary = "; ".join(f"{f.effect} on {f.target}" for f in ordered)
    lines = [
        f"// Generated by trackingbox diagnose (trackingbox {__version__}) from {Path(spec.path).name}.",
        f"// {twin} extended with the effect(s) diagnosis found, with the fitted values:",
        *header,
        "// Review it like hand-written Modelica; regenerate rather than edit.",
        f"model {model} {modelica_string(f'{twin} with {summary}')}",
        extends,
        *declarations,
    ]
    if hidden:
        lines += ["protected", *hidden]
    if initial:
        lines += ["initial equation", *initial]
    if equations:
        lines += ["equation", *equations]
    info = "".join(f"<li>{f.effect} on <code>{f.target}</code>: {effects[f.effect].explanation}</li>"
                   for f in ordered)
    info = modelica_string(f"<html><p>Diagnosed effects:</p><ul>{info}</ul></html>")
    lines += [f"  annotation (Documentation(info = {info}));",
              f"end {model};", ""]
    source = "\n".join(lines)
    diff = _diff(source, model)
    return Patch(model=model, twin=twin, source=source, diff=diff, outputs=outputs, parameters=tuple(parameters),
                 findings=tuple(ordered), library=Path(spec.source.path),
                 carry=tuple(f"{prefix_for(f.effect, f.target)}_{name}" for f in ordered
                             for name in effects[f.effect].carried))


def _diff(source: str, model: str) -> str:
    """The change to review, as a unified diff: the new file ``<model>.mo`` beside the unchanged twin.

    The patch extends the twin rather than editing it, so the twin's own file
    does not change; the diff adds the patched class.
    """
    return "".join(difflib.unified_diff([], source.splitlines(keepends=True), fromfile="/dev/null",
                                        tofile=f"b/{model}.mo"))


def write_patch(patch: Patch, out_dir: str | Path) -> Path:
    """Write ``<model>.mo`` and ``<model>.diff`` into *out_dir* (atomically); return the ``.mo`` path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    target = out / patch.file_name
    write_text_atomic(target, patch.source)
    write_text_atomic(out / f"{patch.model}.diff", patch.diff)
    return target


def compile_patch(patch: Patch, out_dir: str | Path, *, output: str | Path | None = None,
                  libraries: tuple[Path, ...] | list[Path] = ()) -> Any:
    """Compile the patched twin on the embedded path (the twin's library and TrackingBox beside it).

    *libraries*: further libraries the twin uses (the spec's ``[source] libraries``), named as they are.

    Returns
    -------
    trackingbox.compiler.CompileResult
        The FMU is ``<out_dir>/<model>.fmu`` unless *output* says otherwise.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fmu = Path(output) if output is not None else out / f"{patch.model}.fmu"
    extra = libraries
    with tempfile.TemporaryDirectory(prefix="trackingbox-patch-") as tmp:
        stage = Path(tmp)
        libraries = []
        for lib in dict.fromkeys([Path(patch.library).resolve(), Path(library_path()).resolve()]):
            target = stage / lib.name
            if target.exists():
                continue
            if lib.is_dir():
                shutil.copytree(lib, target)
            else:
                shutil.copy2(lib, target)
            libraries.append(target)
        file = stage / patch.file_name
        file.write_text(patch.source, encoding="utf-8")
        return compile_model(file, patch.model, backend="embedded", output=fmu,
                             libraries=[*libraries, *(Path(p) for p in extra)])


def patched_spec(spec: Any, patch: Patch, out_dir: str | Path, fmu: str | Path) -> Path:
    """Write ``<out_dir>/spec.toml`` for the patched twin and return its path.

    Same measurements, inputs, windows and data rules; ``twin`` is *fmu*,
    ``[source]`` the patched class; sensor tags re-mapped to the patch's new
    outputs; the patch's parameters appended to ``[[parameters]]`` (start = the
    value in the patch) so ``estimate`` fits them with the spec's candidates.
    Existing pairs are kept.
    """
    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    mo = write_patch(patch, out)
    outputs = {tag: patch.outputs.get(tag, var) for tag, var in spec.outputs.items()}
    names = set(spec.parameter_names)
    extra = tuple(ParameterSpec(p.name, p.start, p.min, p.max) for p in patch.parameters if p.name not in names)
    new = replace(spec, path=out / "spec.toml", twin=Path(fmu).resolve(), outputs=outputs,
                  source=SourceSpec(path=mo, model=patch.model),
                  parameters=tuple(spec.parameters) + extra,
                  data=replace(spec.data, carry=tuple(dict.fromkeys((*spec.data.carry, *patch.carry)))))
    findings = "; ".join(f"{f.effect} on {f.target}" for f in patch.findings)
    target = write_spec(new, out / "spec.toml",
                        header=f"spec for {patch.model} ({findings}), written by trackingbox diagnose\n"
                               f"from {spec.path}")
    load_spec(target)
    return target
