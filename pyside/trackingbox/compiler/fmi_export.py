"""Export an :class:`ExplicitModel` as an FMI 3.0 model-exchange FMU.

CasADi's ``DaeBuilder.export_fmu`` writes the C sources and the model
description; we compile them with the machine's C compiler against the FMI 3
headers that fmpy ships, then tidy the model description:

* variables that CasADi must treat as outputs to compute them (every algebraic
  variable is listed in its output category so that the FMU can report it)
  get back their Modelica causality, ``local``;
* CasADi's internal ``__assign__*`` helper variables are dropped;
* units used by variables are declared in ``UnitDefinitions``;
* the adjoint derivative, which CasADi always generates and nothing here calls, is left out of
  the C (:mod:`.c_prune`; ``providesAdjointDerivatives="false"``);
* the model's ``experiment`` annotation becomes ``DefaultExperiment``.

Models with asserts, initial equations, events or algebraic loops get a small runtime (only
they: an FMU of a model without any is exactly what CasADi exports, with the
``fmi3SetTime`` fix); a loop's last solution, Newton's next guess, is kept in local variables
``_tbx_m<j>`` that the runtime writes after each evaluation (:mod:`.loop_solve`). The assert conditions are outputs of the model function
(local variables ``_tbx_a<k>``: 1 where the assert holds, 0 where it fails),
computed by the same evaluation as the equations; the initialisation solve is a
separate CasADi function, generated as ``tbx_runtime.c`` (its own translation
unit, :mod:`.fmi_runtime`). Patched FMI functions of the wrapper read or call them:

* ``fmi3ExitInitializationMode`` solves the initial equations (Newton, from the
  current values of the unknowns as guesses and with the parameters as set)
  and writes the states and ``fixed = false`` parameters; a residual left above
  1e-6 fails the call with a logged message (category ``init``);
* ``fmi3ExitInitializationMode``, ``fmi3EnterContinuousTimeMode`` (after every
  event, e.g. a parameter change) and ``fmi3CompletedIntegratorStep`` check the
  asserts: a failing error-level assert logs ``assert failed at t = T s:
  message`` (category ``assert``, status error) through the FMI logger and the
  call returns ``fmi3Error``; a warning-level assert logs once per violation;
* ``fmi3GetContinuousStateDerivatives`` (the solver's trial points) only notes
  the first failing error-level assert (category ``assert-trial``, status OK),
  so that an importer whose solver then fails can name the assert; a completed
  step clears the note.

Asserts are checked at the points the importer completes a step (for
:class:`trackingbox.fmu.Stepper`: every communication point), not at the
solver's internal steps; a model with asserts declares ``needsCompletedIntegratorStep``,
without which an importer such as fmpy never calls ``fmi3CompletedIntegratorStep``
and runs on past a failed assert.
"""
from __future__ import annotations

import importlib.util
import logging
import os
import re
import shlex
import shutil
import subprocess
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import casadi as ca

from .. import config
from ..errors import CompileError
from .c_prune import drop_adjoint
from .events import EventSystem
from .flat_model import ExplicitModel, InitialSystem, ScalarVar, string_attr
from .fmi_runtime import add_build_source, add_runtime, fmu_asserts, value_references

log = logging.getLogger(__name__)


def model_identifier(model: str) -> str:
    """A C identifier for the FMU's binaries: ``Pkg.Sub.Model`` → ``Pkg_Sub_Model``."""
    ident = re.sub(r"[^A-Za-z0-9_]", "_", model)
    if not re.match(r"[A-Za-z_]", ident):
        ident = "m_" + ident
    return ident


def _fmi_headers() -> Path:
    """FMPy's copy of the FMI 3 C headers, found without importing FMPy (its simulation stack)."""
    found = importlib.util.find_spec("fmpy")
    if found is None or found.origin is None:
        raise CompileError("FMI 3 headers not found: the package fmpy is not installed")
    path = Path(found.origin).parent / "c-code"
    if not (path / "fmi3Functions.h").exists():
        raise CompileError(f"FMI 3 headers not found in {path} (is fmpy installed?)")
    return path


def _opts(sv: ScalarVar, translate_attr, extra: dict | None = None) -> dict:
    opts: dict = {}
    for key in ("min", "max", "nominal"):
        node = sv.attrs.get(key)
        if node is not None:
            val = translate_attr(sv, node, key)
            if val is not None:
                opts[key] = val
    unit = string_attr(sv.attrs.get("unit"))
    if unit:
        opts["unit"] = unit
    if sv.description:
        opts["description"] = sv.description
    if extra:
        opts.update(extra)
    return opts


def build_dae(em: ExplicitModel, translator) -> tuple[ca.DaeBuilder, list[str], dict[str, str]]:
    """Build the DaeBuilder; returns it, the names of exposed locals, and causalities."""
    ident = model_identifier(em.name)
    dae = ca.DaeBuilder(ident)
    dae.add("time", "independent", "continuous", em.time, {})

    def attr(sv: ScalarVar, node, key: str):
        try:
            return translator.numeric(translator._element(sv, node, once=True), f"{key} of {sv.name}")
        except CompileError:
            return None

    for sv in em.parameters:
        dae.add(sv.name, "parameter", "tunable", sv.sym, _opts(sv, attr, {"start": float(sv.value)}))
    ev = em.events
    if ev is not None:
        # held between events: CasADi reads them like parameters; the event iteration writes them
        starts = {name: start for name, _, start in ev.discrete}
        for sv in em.discrete:
            dae.add(sv.name, "parameter", "tunable", sv.sym, _opts(sv, attr, {"start": float(starts[sv.name])}))
        for name, sym, start in ev.internal():
            dae.add(name, "parameter", "tunable", sym, {"start": float(start)})
    for mem in em.loop_memory:  # read like parameters; the runtime writes each loop's last solution
        dae.add(mem.sym.name(), "parameter", "tunable", mem.sym,
                {"start": mem.start, "description": f"last solution of {mem.tear} (loop {mem.loop})"})
    for sv in em.inputs:
        start = 0.0
        if sv.start_node is not None:
            start = attr(sv, sv.start_node, "start") or 0.0
        dae.add(sv.name, "input", "continuous", sv.sym, _opts(sv, attr, {"start": float(start)}))
    for sv in em.states:
        start = 0.0
        if sv.start_node is not None:
            start = translator.numeric(translator._element(sv, sv.start_node, once=True),
                                      f"start value of state {sv.name}")
        causality = "output" if sv.output else "local"
        dae.add(sv.name, causality, "continuous", sv.sym, _opts(sv, attr, {"start": float(start), "initial": "exact"}))
    exposed: list[str] = []
    causality: dict[str, str] = {}
    for sv in em.algebraics + em.calculated:
        c = "output" if sv.output else "local"
        causality[sv.name] = c
        dae.add(sv.name, c, "continuous", sv.sym, _opts(sv, attr))
        exposed.append(sv.name)
    # state derivative placeholders -> DaeBuilder's der(x)
    placeholders = [em.derivative[s.name] for s in em.states]
    ders = [dae.der(s.sym) for s in em.states]
    lhs = [a for a, _ in em.assignments]
    rhs = [b for _, b in em.assignments]
    if placeholders:
        rhs = ca.substitute(rhs, placeholders, ders)
    is_der = {p.name(): d for p, d in zip(placeholders, ders)}
    for target, expr in zip(lhs, rhs):
        if target.name() in is_der:
            dae.eq(is_der[target.name()], expr)
        else:
            dae.eq(target, expr)
    if ev is not None:
        for k, z in enumerate(ev.indicators):
            name = f"_tbx_z{k + 1}"
            sym = ca.MX.sym(name)
            dae.add(name, "local", "continuous", sym, {"description": "event indicator"})
            dae.eq(sym, ca.substitute([z], placeholders, ders)[0] if placeholders else z)
            causality[name] = "local"
            exposed.append(name)
    for k, cond in enumerate(_assert_conditions(em, placeholders, ders)):
        name = f"_tbx_a{k + 1}"
        sym = ca.MX.sym(name)
        dae.add(name, "local", "continuous", sym, {"description": "assert condition (1 holds, 0 fails)"})
        dae.eq(sym, cond)
        causality[name] = "local"
        exposed.append(name)
    if exposed:
        dae.set_all("y", exposed)
    return dae, exposed, causality


def _assert_conditions(em: ExplicitModel, placeholders: list[ca.MX], ders: list[ca.MX]) -> list[ca.MX]:
    """The asserts' conditions (:func:`.fmi_runtime.fmu_asserts`: one per message and level) as outputs
    of the model function (``_tbx_a<k>``), so that one evaluation computes them with the equations,
    sharing what they share (a traced function's call gives both its values and its asserts), instead
    of a second function in the runtime evaluating them again. ``pre(v)`` of a *v* the FMU does not
    hold is *v*'s value (as the runtime's tables of value references read it)."""
    if not em.asserts:
        return []
    held = {sv.sym.name() for sv in (*em.parameters, *em.inputs, *em.states, *em.algebraics, *em.calculated)}
    held.update(sv.sym.name() for sv in em.discrete)
    by_name = {sv.sym.name(): sv.sym for sv in (*em.parameters, *em.inputs, *em.states, *em.algebraics,
                                                  *em.calculated, *em.discrete)}
    if em.events is not None:
        held.update(name for name, _, _ in em.events.internal())
    held.update(mem.sym.name() for mem in em.loop_memory)
    conds = [a.condition for a in fmu_asserts(em)]
    if placeholders:
        conds = ca.substitute(conds, placeholders, ders)
    held.update(d.name() for d in ders)
    held.add(em.time.name())
    olds, news = [], []
    for sym in ca.symvar(ca.vertcat(*conds)):
        name = sym.name()
        if name in held:
            continue
        if name.startswith("pre(") and name.endswith(")") and name[4:-1] in by_name:
            olds.append(sym)
            news.append(by_name[name[4:-1]])
        else:
            raise CompileError(f"an assert of {em.name} uses {name!r}, which the exported FMU does not have")
    return ca.substitute(conds, olds, news) if olds else list(conds)


#: Generated C above this many bytes is compiled with ``-O0`` instead of ``-O1``: gcc's ``-O1``
#: grows faster than linearly with the size of CasADi's few huge functions (the model, its forward
#: and adjoint derivatives). Measured on the 7-effect evaporator train's twin (3.7 MB of C, loaded
#: machine): gcc -O1 42 s CPU, -O0 5.6 s, one simulated day 1.9 s CPU at -O1 and 2.2 s at -O0 with
#: identical results. The single-effect benches stay well below it.
LARGE_SOURCE_BYTES = 2_000_000


def optimization_flag(source_bytes: int, environ: dict[str, str] | None = None) -> str:
    """gcc's optimisation flag for *source_bytes* of generated C.

    ``TRACKINGBOX_CC_OPT`` (e.g. ``-O2``) overrides the choice.

    >>> optimization_flag(500_000, {}), optimization_flag(3_700_000, {})
    ('-O1', '-O0')
    >>> optimization_flag(3_700_000, {"TRACKINGBOX_CC_OPT": "-O2"})
    '-O2'
    """
    chosen = config.get("cc_opt", environ)  # checked there: a gcc optimisation flag or empty
    if chosen:
        return chosen
    return "-O0" if source_bytes > LARGE_SOURCE_BYTES else "-O1"


def export_fmu(
    em: ExplicitModel,
    translator,
    output: Path,
    *,
    experiment: dict[str, float] | None = None,
    description: str | None = None,
    optimize: str | None = None,
    fixed_parameters: bool = False,
) -> str:
    """Write the FMU to *output* atomically; return the build log.

    *optimize* is gcc's optimisation flag; ``None`` chooses by the size of the generated C
    (:func:`optimization_flag`). *fixed_parameters*: declare the model's parameters with FMI
    variability ``fixed`` (settable before initialisation only), as other tools export them.
    """
    logs: list[str] = []
    dae, exposed, causality = build_dae(em, translator)
    ident = model_identifier(em.name)
    with tempfile.TemporaryDirectory(prefix="tbx-fmu-") as tmp:
        cwd = os.getcwd()
        os.chdir(tmp)
        try:
            files = dae.export_fmu({"no_warning": True, "with_serialization": False})
        except RuntimeError as exc:
            raise CompileError(f"CasADi could not export {em.name}: {exc}") from None
        finally:
            os.chdir(cwd)
        tmpdir = Path(tmp)
        sources = [name for name in files if name.endswith(".c")]
        for name in sources:
            if name.endswith("_wrap.c"):
                _patch_set_time(tmpdir / name)
        adjoint = not _drop_adjoint(tmpdir / f"{ident}.c", ident)
        extra_sources: list[str] = []
        if em.asserts or em.initial is not None or em.events is not None or em.loop_memory:
            wrapper = next(tmpdir / name for name in sources if name.endswith("_wrap.c"))
            refs = value_references((tmpdir / "modelDescription.xml").read_text())
            runtime = add_runtime(em, wrapper, tmpdir, refs)
            extra_sources.append(runtime)
            files[runtime] = f"sources/{runtime}"
            add_build_source(tmpdir / "buildDescription.xml", runtime)
        unity = tmpdir / f"{ident}_unity.c"
        unity.write_text("".join(f'#include "{name}"\n' for name in sorted(sources)))
        libdir = tmpdir / "binaries" / "x86_64-linux"
        libdir.mkdir(parents=True)
        lib = libdir / f"{ident}.so"
        if optimize is None:
            size = sum((tmpdir / name).stat().st_size for name in (*sources, *extra_sources))
            optimize = optimization_flag(size)
            log.debug("%d bytes of generated C: gcc %s", size, optimize)
        cc = os.environ.get("CC", "gcc")
        if shutil.which(cc) is None:
            raise CompileError(f"no C compiler: {cc!r} not found on PATH (set CC or install gcc)")
        cmd = [cc, optimize, "-shared", "-fPIC", "-I", str(_fmi_headers()), "-I", str(tmpdir),
               "-o", str(lib), str(unity), *[str(tmpdir / name) for name in extra_sources], "-lm"]
        log.debug("compiling FMU binary: %s", shlex.join(cmd))
        proc = subprocess.run(cmd, capture_output=True, text=True)
        logs.append("$ " + shlex.join(cmd) + "\n" + proc.stdout + proc.stderr)
        if proc.returncode != 0:
            raise CompileError(f"C compilation of {em.name} failed:\n{proc.stderr[-4000:]}")
        md_path = tmpdir / "modelDescription.xml"
        md_path.write_text(
            _tidy_model_description(md_path.read_text(), set(exposed), causality, em.name, experiment, description,
                                    initial=em.initial, events=em.events, asserts=bool(em.asserts),
                                    adjoint=adjoint, memory={mem.sym.name() for mem in em.loop_memory})
        )
        if fixed_parameters:
            md_path.write_text(declare_fixed(md_path.read_text(), {sv.name for sv in em.parameters}))
        output.parent.mkdir(parents=True, exist_ok=True)
        fd, part = tempfile.mkstemp(prefix=f".{output.name}.", suffix=".part", dir=output.parent)
        os.close(fd)
        try:
            with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
                zf.write(md_path, "modelDescription.xml")
                zf.write(lib, f"binaries/x86_64-linux/{ident}.so")
                for local, arc in sorted(files.items()):
                    if arc.startswith("sources/"):
                        zf.write(tmpdir / local, arc)
            os.replace(part, output)
        finally:
            if os.path.exists(part):
                os.unlink(part)
    return "\n".join(logs)


#: CasADi 3.8's generated ``fmi3SetTime`` stores the time but keeps the cached
#: evaluation, so a model without states (where no state update follows) would
#: report the values of its first evaluation at every later time. The patch
#: invalidates the cache when the time changes.
_SET_TIME = "  // Initialize time\n  m->t = time;\n"
_SET_TIME_PATCHED = "  // Initialize time (trackingbox: a new time invalidates the cached evaluation)\n" \
                    "  if (m->t != time) m->up_to_date = 0;\n  m->t = time;\n"
# fmi3SetFloat64 (and fmi3SetContinuousStates, which calls it): only a value that differs, bit for bit,
# from the one held invalidates the cached evaluation. fmpy's CVODE sets the states twice at each output
# point to the same values (its root function's call at the output point, then the step's end), and each
# set made the next read evaluate the model again: two evaluations per output point where one gives all
_SET_FLOAT64 = ("  // Not evaluated\n  m->up_to_date = 0;\n  // Position in values vector\n  val_ind = 0;\n",
                "    for (j = 0; j < var_sz; ++j) m->v[var_off + j] = values[val_ind++];\n")
_SET_FLOAT64_PATCHED = (
    "  // Position in values vector\n  val_ind = 0;\n",
    "    for (j = 0; j < var_sz; ++j, ++val_ind) {\n"
    "      // trackingbox: a value that changes (bit for bit) invalidates the cached evaluation\n"
    "      if (memcmp(&m->v[var_off + j], &values[val_ind], sizeof(fmi3Float64)) != 0) m->up_to_date = 0;\n"
    "      m->v[var_off + j] = values[val_ind];\n"
    "    }\n")


def _drop_adjoint(source: Path, ident: str) -> bool:
    """Leave the adjoint derivative out of CasADi's C *source* (:func:`.c_prune.drop_adjoint`);
    whether it was there."""
    if not source.exists():
        return False
    text, dropped = drop_adjoint(source.read_text(), ident)
    if dropped:
        before = source.stat().st_size
        source.write_text(text)
        log.debug("adjoint derivative left out of %s: %d -> %d bytes", source.name, before, len(text))
    return dropped


def _patch_set_time(wrapper: Path) -> None:
    """fmi3SetTime and fmi3SetFloat64 of CasADi's wrapper invalidate the cached evaluation only where
    the time or a value changes (see _SET_TIME_PATCHED, _SET_FLOAT64_PATCHED)."""
    text = wrapper.read_text()
    patches = [(_SET_TIME, _SET_TIME_PATCHED, "fmi3SetTime")]
    patches += [(a, b, "fmi3SetFloat64") for a, b in zip(_SET_FLOAT64, _SET_FLOAT64_PATCHED)]
    for old, new, where in patches:
        if text.count(old) != 1:
            raise CompileError(
                f"unexpected CasADi FMU wrapper {wrapper.name} (casadi {ca.__version__}): {where} not found "
                "as expected; the embedded path is pinned to casadi 3.8.2"
            )
        text = text.replace(old, new)
    wrapper.write_text("#include <string.h>\n" + text)


def declare_fixed(xml: str, names: set[str]) -> str:
    """The model description *xml* with the tunable parameters among *names* declared ``fixed``.

    >>> x = '<m><ModelVariables><Float64 name="k" causality="parameter" variability="tunable"/></ModelVariables></m>'
    >>> 'variability="fixed"' in declare_fixed(x, {"k"})
    True
    """
    root = ET.fromstring(xml)
    for var in root.iter():
        if var.get("name") in names and var.get("causality") == "parameter" and var.get("variability") == "tunable":
            var.set("variability", "fixed")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _tidy_model_description(
    xml: str,
    exposed: set[str],
    causality: dict[str, str],
    model: str,
    experiment: dict[str, float] | None,
    description: str | None,
    initial: InitialSystem | None = None,
    events: EventSystem | None = None,
    asserts: bool = False,
    adjoint: bool = True,
    memory: set[str] | frozenset[str] = frozenset(),
) -> str:
    root = ET.fromstring(xml)
    root.set("modelName", model)
    me = root.find("ModelExchange")
    if not adjoint and me is not None:
        me.set("providesAdjointDerivatives", "false")  # left out of the C (.c_prune)
    if (asserts or memory) and me is not None:
        # the asserts are checked, and the loops' last solutions kept (.fmi_runtime), in
        # fmi3CompletedIntegratorStep: an importer calls it only when asked (FMI 3.0
        # needsCompletedIntegratorStep, default false; fmpy follows it)
        me.set("needsCompletedIntegratorStep", "true")
    if description:
        root.set("description", description)
    root.set("generationTool", "trackingbox (embedded: rumoca + CasADi)")
    variables = root.find("ModelVariables")
    structure = root.find("ModelStructure")
    if variables is None or structure is None:
        raise CompileError("CasADi wrote a model description without ModelVariables/ModelStructure")
    demoted: set[str] = set()
    units: set[str] = set()
    for var in list(variables):
        name = var.get("name", "")
        if name.startswith("__assign__"):
            variables.remove(var)
            continue
        if name in exposed and causality.get(name) == "local" and var.get("causality") == "output":
            del var.attrib["causality"]
            demoted.add(var.get("valueReference", ""))
        if initial is not None and name in initial.computed_parameters:
            # fixed = false: computed by the initial equations, not set by the user
            var.set("causality", "calculatedParameter")
            var.set("variability", "fixed")
            var.set("initial", "calculated")
            var.attrib.pop("start", None)
        elif initial is not None and name in initial.free_states:
            var.set("initial", "approx")  # the start value is a guess for the initial equations
        if name in memory:  # a loop's last solution (.loop_solve): the runtime's, not the user's
            var.set("causality", "local")
            var.set("variability", "discrete")
            var.set("initial", "exact")
        if var.get("unit"):
            units.add(var.get("unit", ""))
    for elem in list(structure):
        if elem.tag in ("Output", "InitialUnknown") and elem.get("valueReference") in demoted:
            structure.remove(elem)
    if events is not None:
        held = {name for name, _, _ in events.discrete} | {name for name, _, _ in events.internal()}
        indicators = [f"_tbx_z{k + 1}" for k in range(len(events.indicators))]
        by_name = {var.get("name", ""): var for var in variables}
        for name in held:
            var = by_name.get(name)
            if var is not None:  # a discrete variable: set by the event iteration, not by the user
                var.set("causality", "local")
                var.set("variability", "discrete")
                var.set("initial", "exact")
        for name in indicators:
            var = by_name.get(name)
            if var is not None:
                ET.SubElement(structure, "EventIndicator", {"valueReference": var.get("valueReference", "")})
    if initial is not None:
        # the initial equations make the free states and fixed = false parameters initial unknowns;
        # every initial unknown may then depend on every known (no dependencies attribute)
        computed = set(initial.free_states) | set(initial.computed_parameters)
        new_vrs = sorted(int(var.get("valueReference", "0")) for var in variables if var.get("name") in computed)
        listed = set()
        for elem in structure:
            if elem.tag == "InitialUnknown":
                elem.attrib.pop("dependencies", None)
                elem.attrib.pop("dependenciesKind", None)
                listed.add(int(elem.get("valueReference", "0")))
        kinds = [c.tag for c in structure]
        at = max((i + 1 for i, k in enumerate(kinds) if k in ("Output", "ContinuousStateDerivative",
                                                               "ClockedState", "InitialUnknown")), default=0)
        for vr in new_vrs:
            if vr not in listed:
                structure.insert(at, ET.Element("InitialUnknown", {"valueReference": str(vr)}))
                at += 1
    children = list(root)
    insert_at = next((i for i, c in enumerate(children) if c.tag == "ModelVariables"), len(children))
    if experiment:
        exp = ET.Element("DefaultExperiment")
        for key in ("StartTime", "StopTime", "Tolerance", "StepSize"):
            src_key = "Interval" if key == "StepSize" else key
            if src_key in experiment:
                exp.set(
                    {"StartTime": "startTime", "StopTime": "stopTime", "Tolerance": "tolerance", "StepSize": "stepSize"}[key],
                    repr(float(experiment[src_key])),
                )
        root.insert(insert_at, exp)
    if units:
        unit_defs = ET.Element("UnitDefinitions")
        for unit in sorted(units):
            ET.SubElement(unit_defs, "Unit", {"name": unit})
        me_index = next((i for i, c in enumerate(list(root)) if c.tag in ("ModelExchange", "CoSimulation")), -1)
        root.insert(me_index + 1, unit_defs)
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
