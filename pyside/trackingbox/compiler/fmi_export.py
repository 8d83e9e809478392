"""Export an :class:`ExplicitModel` as an FMI 3.0 model-exchange FMU.

CasADi's ``DaeBuilder.export_fmu`` writes the C sources and the model
description; we compile them with the machine's C compiler against the FMI 3
headers that fmpy ships, then tidy the model description:

* variables that CasADi must treat as outputs to compute them (every algebraic
  variable is listed in its output category so that the FMU can report it)
  get back their Modelica causality, ``local``;
* CasADi's internal ``__assign__*`` helper variables are dropped;
* units used by variables are declared in ``UnitDefinitions``;
* the model's ``experiment`` annotation becomes ``DefaultExperiment``.

Models with asserts or initial equations get a small runtime (only they: an
FMU of a model without either is exactly what CasADi exports, with the
``fmi3SetTime`` fix). The assert conditions and the initialisation solve are
separate CasADi functions, generated as ``tbx_runtime.c`` (its own translation
unit) and called from patched FMI functions of the wrapper:

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
solver's internal steps.
"""
from __future__ import annotations

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
from .events import MAX_EVENT_ITERATIONS, EventSystem
from .flat_model import ExplicitModel, InitialSystem, ScalarVar

log = logging.getLogger(__name__)


def model_identifier(model: str) -> str:
    """A C identifier for the FMU's binaries: ``Pkg.Sub.Model`` → ``Pkg_Sub_Model``."""
    ident = re.sub(r"[^A-Za-z0-9_]", "_", model)
    if not re.match(r"[A-Za-z_]", ident):
        ident = "m_" + ident
    return ident


def _fmi_headers() -> Path:
    import fmpy

    path = Path(fmpy.__file__).parent / "c-code"
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
    unit = _string_attr(sv.attrs.get("unit"))
    if unit:
        opts["unit"] = unit
    if sv.description:
        opts["description"] = sv.description
    if extra:
        opts.update(extra)
    return opts


def _string_attr(node) -> str | None:
    if node is None:
        return None
    if isinstance(node, str):
        return node
    if isinstance(node, dict):
        lit = node.get("Literal")
        if lit and isinstance(lit.get("value"), dict) and "String" in lit["value"]:
            return str(lit["value"]["String"])
    return None


def build_dae(em: ExplicitModel, translator) -> tuple[ca.DaeBuilder, list[str], dict[str, str]]:
    """Build the DaeBuilder; returns it, the names of exposed locals, and causalities."""
    ident = model_identifier(em.name)
    dae = ca.DaeBuilder(ident)
    dae.add("time", "independent", "continuous", em.time, {})

    def attr(sv: ScalarVar, node, key: str):
        try:
            return translator.numeric(translator._element(sv, node), f"{key} of {sv.name}")
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
    for sv in em.inputs:
        start = 0.0
        if sv.start_node is not None:
            start = attr(sv, sv.start_node, "start") or 0.0
        dae.add(sv.name, "input", "continuous", sv.sym, _opts(sv, attr, {"start": float(start)}))
    for sv in em.states:
        start = 0.0
        if sv.start_node is not None:
            start = translator.numeric(translator._element(sv, sv.start_node), f"start value of state {sv.name}")
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
    if exposed:
        dae.set_all("y", exposed)
    return dae, exposed, causality


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
        extra_sources: list[str] = []
        if em.asserts or em.initial is not None or em.events is not None:
            wrapper = next(tmpdir / name for name in sources if name.endswith("_wrap.c"))
            refs = _value_references((tmpdir / "modelDescription.xml").read_text())
            runtime = _add_runtime(em, wrapper, tmpdir, refs)
            extra_sources.append(runtime)
            files[runtime] = f"sources/{runtime}"
            _add_build_source(tmpdir / "buildDescription.xml", runtime)
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
                                    initial=em.initial, events=em.events)
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


def _patch_set_time(wrapper: Path) -> None:
    text = wrapper.read_text()
    if text.count(_SET_TIME) != 1:
        raise CompileError(
            f"unexpected CasADi FMU wrapper {wrapper.name} (casadi {ca.__version__}): fmi3SetTime not found "
            "as expected; the embedded path is pinned to casadi 3.8.2"
        )
    wrapper.write_text(text.replace(_SET_TIME, _SET_TIME_PATCHED))


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
) -> str:
    root = ET.fromstring(xml)
    root.set("modelName", model)
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


# ---------------------------------------------------------------------------
# runtime: asserts and initial equations
# ---------------------------------------------------------------------------

#: the largest residual of an initial equation accepted after the Newton solve
INIT_TOLERANCE = 1e-6

_TIME_VR = -1  # marks the time in the runtime's tables of value references


def _value_references(xml: str) -> dict[str, int]:
    root = ET.fromstring(xml)
    variables = root.find("ModelVariables")
    refs: dict[str, int] = {}
    for var in (variables if variables is not None else []):
        refs[var.get("name", "")] = int(var.get("valueReference", "0"))
    return refs


def _c_string(text: str) -> str:
    """A C string literal of *text* (UTF-8, every byte outside printable ASCII as an octal escape)."""
    out = []
    for byte in text.encode("utf-8"):
        ch = chr(byte)
        if ch in '"\\':
            out.append("\\" + ch)
        elif 32 <= byte < 127 and ch != "?":
            out.append(ch)
        else:
            out.append(f"\\{byte:03o}")
    return '"' + "".join(out) + '"'


def _c_array(ctype: str, name: str, values: list[str]) -> str:
    body = ", ".join(values) if values else "0"
    return f"static const {ctype} {name}[{max(len(values), 1)}] = {{{body}}};\n"


def _vrs(syms: list[ca.MX], refs: dict[str, int], model: str, what: str) -> list[str]:
    out = []
    for sym in syms:
        name = sym.name()
        if name.startswith("pre(") and name.endswith(")") and name[4:-1] in refs:
            name = name[4:-1]  # pre(v) in a runtime function: v's value when it is called
        if name == "time":
            out.append(str(_TIME_VR))
        elif name in refs:
            out.append(str(refs[name]))
        else:
            raise CompileError(f"{what} of {model} uses {name!r}, which the exported FMU does not have")
    return out


def _work_defines(prefix: str, fn: ca.Function) -> str:
    return (f"#define {prefix}_SZ_ARG {fn.sz_arg()}\n#define {prefix}_SZ_RES {fn.sz_res()}\n"
            f"#define {prefix}_SZ_IW {fn.sz_iw()}\n#define {prefix}_SZ_W {fn.sz_w()}\n")


_CALL = """
static int tbx_call_%(fn)s(const casadi_real** arg, casadi_real** res) {
  casadi_int* iw = (casadi_int*)malloc(sizeof(casadi_int) * (%(P)s_SZ_IW + 1));
  casadi_real* w = (casadi_real*)malloc(sizeof(casadi_real) * (%(P)s_SZ_W + 1));
  int mem, flag = 1;
  if (iw && w) {
    mem = %(fn)s_checkout();
    flag = %(fn)s(arg, res, iw, w, mem);
    %(fn)s_release(mem);
  }
  free(iw);
  free(w);
  return flag;
}
"""

_COMMON = """
/* trackingbox runtime: asserts and initial equations (generated by trackingbox.compiler.fmi_export) */
#include <stdio.h>
#include <stdlib.h>
#include <math.h>
static double tbx_value(casadi_fmi_memory* m, long vr) {
  return vr < 0 ? m->t : m->v[var_offset[vr]];
}
static void tbx_log(casadi_fmi_memory* m, fmi3Status status, const char* category, const char* text) {
  if (m->tbx_logger) m->tbx_logger(m->tbx_env, status, category, text);
}
"""

_ASSERTS = """
static int tbx_eval_asserts(casadi_fmi_memory* m, casadi_real* c) {
  casadi_real win[TBX_A_NW + 1];
  const casadi_real* arg[TBX_A_SZ_ARG + 1];
  casadi_real* res[TBX_A_SZ_RES + 1];
  size_t i;
  if (!m->up_to_date) {
    if (evaluate(m)) return 1;
    m->up_to_date = 1;
  }
  for (i = 0; i < TBX_A_NW; ++i) win[i] = tbx_value(m, tbx_a_vr[i]);
  arg[0] = win;
  res[0] = c;
  return tbx_call_tbx_asserts(arg, res);
}
/* At the solver's trial points (derivative calls) a failing error-level assert is only noted
   (category assert-trial, status OK): the step may be rejected. If the solver then fails, the
   importer can report the assert; a completed step clears the note. */
static void tbx_note_asserts(casadi_fmi_memory* m) {
  casadi_real c[TBX_N_ASSERT + 1];
  char text[1400];
  int k;
  if (m->tbx_pending >= 0 || tbx_eval_asserts(m, c)) return;
  for (k = 0; k < TBX_N_ASSERT; ++k) {
    if (tbx_a_error[k] && !(c[k] > 0.5)) {
      m->tbx_pending = k;
      snprintf(text, sizeof text, "assert failed at t = %.17g s: %s", m->t, tbx_a_message[k]);
      tbx_log(m, fmi3OK, "assert-trial", text);
      return;
    }
  }
}
static fmi3Status tbx_check_asserts(casadi_fmi_memory* m) {
  casadi_real c[TBX_N_ASSERT + 1];
  char text[1400];
  int k;
  if (tbx_eval_asserts(m, c)) return fmi3Error;
  m->tbx_pending = -1;
  for (k = 0; k < TBX_N_ASSERT; ++k) {
    if (c[k] > 0.5) {
      m->tbx_warned[k] = 0;
      continue;
    }
    if (tbx_a_error[k]) {
      snprintf(text, sizeof text, "assert failed at t = %.17g s: %s", m->t, tbx_a_message[k]);
      tbx_log(m, fmi3Error, "assert", text);
      return fmi3Error;
    }
    if (!m->tbx_warned[k]) {
      snprintf(text, sizeof text, "assert warning at t = %.17g s: %s", m->t, tbx_a_message[k]);
      tbx_log(m, fmi3Warning, "assert", text);
      m->tbx_warned[k] = 1;
    }
  }
  return fmi3OK;
}
"""

_INIT = """
static fmi3Status tbx_initialize(casadi_fmi_memory* m) {
  casadi_real z0[TBX_I_NZ + 1], wk[TBX_I_NK + 1], z[TBX_I_NZ + 1], r[TBX_I_NZ + 1];
  const casadi_real* arg[TBX_I_SZ_ARG + 1];
  casadi_real* res[TBX_I_SZ_RES + 1];
  char text[1400];
  size_t i, worst = 0;
  for (i = 0; i < TBX_I_NZ; ++i) z0[i] = m->v[var_offset[tbx_i_unknown_vr[i]]];
  for (i = 0; i < TBX_I_NK; ++i) wk[i] = tbx_value(m, tbx_i_known_vr[i]);
  arg[0] = z0;
  arg[1] = wk;
  res[0] = z;
  res[1] = r;
  if (tbx_call_tbx_init(arg, res)) {
    tbx_log(m, fmi3Error, "init", "initialisation failed: the Newton solve of the initial equations failed");
    return fmi3Error;
  }
  for (i = 0; i < TBX_I_NZ; ++i) {
    if (!(fabs(r[i]) <= fabs(r[worst])) || !isfinite(z[i])) worst = i;
  }
  for (i = 0; i < TBX_I_NZ; ++i) {
    if (!(fabs(r[i]) <= TBX_I_TOL) || !isfinite(z[i])) {
      snprintf(text, sizeof text, "initialisation failed at t = %.17g s: the initial equations have no "
               "solution near the start values (residual %g of the %s)", m->t, r[worst], tbx_i_origin[worst]);
      tbx_log(m, fmi3Error, "init", text);
      return fmi3Error;
    }
  }
  for (i = 0; i < TBX_I_NZ; ++i) m->v[var_offset[tbx_i_unknown_vr[i]]] = z[i];
  m->up_to_date = 0;
  return fmi3OK;
}
"""


_EVENTS = """
static int tbx_event_step(casadi_fmi_memory* m, int quiet, casadi_real* out) {
  casadi_real win[TBX_E_NW + 1];
  casadi_real q = quiet ? 1 : 0;
  const casadi_real* arg[TBX_E_SZ_ARG + 1];
  casadi_real* res[TBX_E_SZ_RES + 1];
  size_t i;
  if (!m->up_to_date) {
    if (evaluate(m)) return 1;
    m->up_to_date = 1;
  }
  for (i = 0; i < TBX_E_NW; ++i) win[i] = tbx_value(m, tbx_e_vr[i]);
  arg[0] = win;
  arg[1] = &q;
  res[0] = out;
  return tbx_call_tbx_event(arg, res);
}
/* The event iteration (trackingbox.compiler.events): repeat the step until no held value changes;
   re-initialised states are written too. Then the next sample() instant, if any. */
static fmi3Status tbx_event_iteration(casadi_fmi_memory* m, int quiet, int* states_changed) {
  casadi_real out[TBX_E_NOUT + 1];
  char text[300];
  int it, changed;
  size_t k, j;
  for (it = 0; it < TBX_E_MAXIT; ++it) {
    if (tbx_event_step(m, quiet, out)) {
      snprintf(text, sizeof text, "event iteration at t = %.17g s: the model could not be evaluated", m->t);
      tbx_log(m, fmi3Error, "event", text);
      return fmi3Error;
    }
    changed = 0;
    for (k = 0; k < TBX_E_NU; ++k) {
      casadi_real* v = &m->v[var_offset[tbx_e_upd_vr[k]]];
      if (*v != out[k]) {
        *v = out[k];
        changed = 1;
      }
    }
    for (k = 0; k < TBX_E_NR; ++k) {
      casadi_real* v = &m->v[var_offset[tbx_e_reinit_vr[k]]];
      if (*v != out[TBX_E_NU + k]) {
        *v = out[TBX_E_NU + k];
        changed = 1;
        *states_changed = 1;
      }
    }
    m->up_to_date = 0;
    if (!changed) {
      m->tbx_next_defined = 0;
      for (j = 0; j < TBX_E_NS; ++j) {
        casadi_real start = out[TBX_E_NU + TBX_E_NR + j];
        casadi_real interval = out[TBX_E_NU + TBX_E_NR + TBX_E_NS + j];
        casadi_real eps = 1e-9 * fmax(1.0, fabs(m->t)), n, tn;
        if (!(interval > 0)) continue;
        n = ceil((m->t - start) / interval);
        if (n < 0) n = 0;
        tn = start + n * interval;
        if (tn <= m->t + eps) tn = start + (n + 1) * interval;
        if (!m->tbx_next_defined || tn < m->tbx_next) {
          m->tbx_next = tn;
          m->tbx_next_defined = 1;
        }
      }
      return fmi3OK;
    }
  }
  snprintf(text, sizeof text, "event iteration at t = %.17g s did not converge after %d steps", m->t, TBX_E_MAXIT);
  tbx_log(m, fmi3Error, "event", text);
  return fmi3Error;
}
static int tbx_samples_on(casadi_fmi_memory* m) {
  size_t j;
  for (j = 0; j < TBX_E_NS; ++j) {
    if (m->v[var_offset[tbx_e_sample_vr[j]]] != 0) return 1;
  }
  return 0;
}
/* Initialisation with events: initial() is true; the initial equations and the event iteration are
   repeated until the held values no longer change (the continuous part depends on them). */
static fmi3Status tbx_initialize_events(casadi_fmi_memory* m) {
  casadi_real held[TBX_E_NU + 1];
  int round, changed = 0;
  size_t k;
  m->v[var_offset[TBX_E_INIT_VR]] = 1;
  m->up_to_date = 0;
  for (round = 0; round < 20; ++round) {
#ifdef TBX_I_NZ
    if (tbx_initialize(m) != fmi3OK) return fmi3Error;
#endif
    for (k = 0; k < TBX_E_NU; ++k) held[k] = m->v[var_offset[tbx_e_upd_vr[k]]];
    if (tbx_event_iteration(m, 0, &changed) != fmi3OK) return fmi3Error;
#ifndef TBX_I_NZ
    break;
#endif
    changed = 0;
    for (k = 0; k < TBX_E_NU; ++k) {
      if (held[k] != m->v[var_offset[tbx_e_upd_vr[k]]]) changed = 1;
    }
    if (!changed) break;
  }
  m->v[var_offset[TBX_E_INIT_VR]] = 0;
  m->up_to_date = 0;
  return fmi3OK;
}
"""

_UPDATE_DISCRETE = """FMI3_Export fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance,
    fmi3Boolean* discreteStatesNeedUpdate,
    fmi3Boolean* terminateSimulation,
    fmi3Boolean* nominalsOfContinuousStatesChanged,
    fmi3Boolean* valuesOfContinuousStatesChanged,
    fmi3Boolean* nextEventTimeDefined,
    fmi3Float64* nextEventTime) {
  // trackingbox runtime: the event iteration (trackingbox.compiler.events)
  casadi_fmi_memory* m = (casadi_fmi_memory*)instance;
  int states_changed = 0;
  fmi3Status status = tbx_event_iteration(m, 0, &states_changed);
  *discreteStatesNeedUpdate = fmi3False;
  *terminateSimulation = fmi3False;
  *nominalsOfContinuousStatesChanged = fmi3False;
  *valuesOfContinuousStatesChanged = (states_changed || m->continuous_states_changed) ? fmi3True : fmi3False;
  *nextEventTimeDefined = m->tbx_next_defined ? fmi3True : fmi3False;
  if (m->tbx_next_defined) *nextEventTime = m->tbx_next;
  m->continuous_states_changed = 0;
  return status;
}
"""

_EVENT_INDICATORS = """FMI3_Export fmi3Status fmi3GetEventIndicators(fmi3Instance instance,
    fmi3Float64 eventIndicators[],
    size_t nEventIndicators) {
  // trackingbox runtime: the indicators of the frozen relations (trackingbox.compiler.events)
  (void)nEventIndicators;
  if (TBX_NZ == 0) return fmi3OK;
  return fmi3GetFloat64(instance, tbx_z_vr, TBX_NZ, eventIndicators, TBX_NZ);
}
"""


def _runtime_functions(em: ExplicitModel) -> tuple[list[ca.Function], list[ca.MX], list[ca.MX]]:
    """CasADi functions ``tbx_asserts(w) -> c`` and ``tbx_init(z0, wk) -> (z, r)``; their input symbols."""
    functions: list[ca.Function] = []
    assert_syms: list[ca.MX] = []
    if em.asserts:
        conds = [a.condition for a in em.asserts]
        seen: dict[str, ca.MX] = {}
        for c in conds:
            for sym in ca.symvar(c):
                seen.setdefault(sym.name(), sym)
        assert_syms = [seen[n] for n in sorted(seen)]
        w = ca.MX.sym("w", len(assert_syms))
        body = ca.vertcat(*conds)
        if assert_syms:
            body = ca.substitute([body], assert_syms, [w[i] for i in range(len(assert_syms))])[0]
        functions.append(ca.Function("tbx_asserts", [w], [body]))
    known_syms: list[ca.MX] = []
    if em.initial is not None:
        init = em.initial
        known_syms = list(init.knowns)
        nz, nk = len(init.unknowns), len(known_syms)
        z = ca.MX.sym("z", nz)
        wk = ca.MX.sym("wk", nk)
        g = ca.substitute([ca.vertcat(*init.residual)], init.unknowns + known_syms,
                          [z[i] for i in range(nz)] + [wk[i] for i in range(nk)])[0]
        residual = ca.Function("tbx_init_residual", [z, wk], [g])
        z0 = ca.MX.sym("z0", nz)
        if init.solution:  # block by block (FlatTranslator._initial_system)
            zsol = ca.substitute([ca.vertcat(*init.solution)], init.guesses + known_syms,
                                 [z0[i] for i in range(nz)] + [wk[i] for i in range(nk)])[0]
        else:
            newton = ca.rootfinder("tbx_init_newton", "fast_newton", {"x": z, "p": wk, "g": g},
                                   {"abstol": 1e-12, "max_iter": 100})
            zsol = newton(z0, wk)
        functions.append(ca.Function("tbx_init", [z0, wk], [zsol, residual(zsol, wk)]))
    return functions, assert_syms, known_syms


def _event_function(em: ExplicitModel, quiet: ca.MX) -> tuple[ca.Function, list[ca.MX], int]:
    """``tbx_event(w, quiet) -> out``: one step of the event iteration (.events). *w* are the values
    of the symbols it reads (as the FMU holds them: pre(v) is v's value), *out* the new values of
    ``events.updates`` in order, then of the re-initialised states, then each sample's start and
    interval. Returns the function, its input symbols and the number of updates."""
    ev = em.events
    olds: list[ca.MX] = []
    news: list[ca.MX] = []
    for lhs, expr in ev.updates:
        value = ca.substitute([expr], olds, news)[0] if olds else expr
        olds.append(lhs)
        news.append(value)
    reinit = [ca.substitute([e], olds, news)[0] if olds else e for _, e in ev.reinits]
    timing = [x for smp in ev.samples for x in (smp.start,)] + [x for smp in ev.samples for x in (smp.interval,)]
    outs = news + reinit + timing
    body = ca.vertcat(*outs) if outs else ca.MX(0, 1)
    seen: dict[str, ca.MX] = {}
    for sym in ca.symvar(body):
        if sym.name() != quiet.name():
            seen.setdefault(sym.name(), sym)
    syms = [seen[n] for n in sorted(seen)]
    w = ca.MX.sym("w", len(syms))
    q = ca.MX.sym("q")
    args = syms + [s for s in ca.symvar(body) if s.name() == quiet.name()]
    vals = [w[i] for i in range(len(syms))] + [q] * (len(args) - len(syms))
    body = ca.substitute([body], args, vals)[0] if args else body
    return ca.Function("tbx_event", [w, q], [body]), syms, len(news)


def _add_runtime(em: ExplicitModel, wrapper: Path, tmpdir: Path, refs: dict[str, int]) -> str:
    """Generate ``tbx_runtime.c`` and patch the wrapper to call it; return the new source's name."""
    functions, assert_syms, known_syms = _runtime_functions(em)
    ev = em.events
    if ev is not None:
        quiet = ca.MX.sym("_tbx_quiet")
        event_fn, event_syms, n_updates = _event_function(em, quiet)
        functions.append(event_fn)
    name = "tbx_runtime.c"
    gen = ca.CodeGenerator(name, {"with_header": False})
    for fn in functions:
        gen.add(fn)
    gen.generate(str(tmpdir) + os.sep)
    by_name = {fn.name(): fn for fn in functions}

    n_assert = len(em.asserts)
    glue = [_COMMON]
    if em.asserts:
        fn = by_name["tbx_asserts"]
        glue.append(f"#define TBX_N_ASSERT {n_assert}\n#define TBX_A_NW {len(assert_syms)}\n")
        glue.append(_work_defines("TBX_A", fn))
        glue.append("int tbx_asserts(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, "
                    "int mem);\nint tbx_asserts_checkout(void);\nvoid tbx_asserts_release(int mem);\n")
        glue.append(_c_array("long", "tbx_a_vr", _vrs(assert_syms, refs, em.name, "an assert")))
        glue.append(_c_array("char*", "tbx_a_message", [_c_string(a.message) for a in em.asserts]))
        glue.append(_c_array("int", "tbx_a_error", ["1" if a.level == "error" else "0" for a in em.asserts]))
        glue.append(_CALL % {"fn": "tbx_asserts", "P": "TBX_A"})
        glue.append(_ASSERTS)
    if em.initial is not None:
        init = em.initial
        fn = by_name["tbx_init"]
        glue.append(f"#define TBX_I_NZ {len(init.unknowns)}\n#define TBX_I_NK {len(known_syms)}\n"
                    f"#define TBX_I_TOL {INIT_TOLERANCE!r}\n")
        glue.append(_work_defines("TBX_I", fn))
        glue.append("int tbx_init(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, "
                    "int mem);\nint tbx_init_checkout(void);\nvoid tbx_init_release(int mem);\n")
        glue.append(_c_array("long", "tbx_i_unknown_vr", _vrs(init.unknowns, refs, em.name, "the initial equations")))
        glue.append(_c_array("long", "tbx_i_known_vr", _vrs(known_syms, refs, em.name, "the initial equations")))
        glue.append(_c_array("char*", "tbx_i_origin", [_c_string(o) for o in init.origins]))
        glue.append(_CALL % {"fn": "tbx_init", "P": "TBX_I"})
        glue.append(_INIT)

    n_z = len(ev.indicators) if ev is not None else 0
    if ev is not None:
        fn = by_name["tbx_event"]
        n_out = fn.size1_out(0)
        glue.append(f"#define TBX_E_NW {len(event_syms)}\n#define TBX_E_NU {n_updates}\n"
                    f"#define TBX_E_NR {len(ev.reinits)}\n#define TBX_E_NS {len(ev.samples)}\n"
                    f"#define TBX_E_NOUT {max(n_out, 1)}\n#define TBX_E_MAXIT {MAX_EVENT_ITERATIONS}\n"
                    f"#define TBX_E_INIT_VR {refs[ev.initial.name()]}\n#define TBX_NZ {n_z}\n")
        glue.append(_work_defines("TBX_E", fn))
        glue.append("int tbx_event(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, "
                    "int mem);\nint tbx_event_checkout(void);\nvoid tbx_event_release(int mem);\n")
        glue.append(_c_array("long", "tbx_e_vr", _vrs(event_syms, refs, em.name, "the event iteration")))
        glue.append(_c_array("long", "tbx_e_upd_vr", _vrs([lhs for lhs, _ in ev.updates], refs, em.name,
                                                          "the event iteration")))
        glue.append(_c_array("long", "tbx_e_reinit_vr", _vrs([x for x, _ in ev.reinits], refs, em.name, "reinit")))
        glue.append(_c_array("long", "tbx_e_sample_vr", _vrs([smp.sym for smp in ev.samples], refs, em.name,
                                                             "sample()")))
        glue.append(_c_array("fmi3ValueReference", "tbx_z_vr",
                             [str(refs[f"_tbx_z{k + 1}"]) for k in range(n_z)]))
        glue.append(_CALL % {"fn": "tbx_event", "P": "TBX_E"})
        glue.append(_EVENTS)

    exit_body = ["  casadi_fmi_memory* m = (casadi_fmi_memory*)instance;\n"]
    if ev is not None:
        exit_body.append("  if (tbx_initialize_events(m) != fmi3OK) return fmi3Error;\n")
    elif em.initial is not None:
        exit_body.append("  if (tbx_initialize(m) != fmi3OK) return fmi3Error;\n")
    exit_body.append("  return tbx_check_asserts(m);\n" if em.asserts else "  (void)m;\n  return fmi3OK;\n")
    check = "  return tbx_check_asserts((casadi_fmi_memory*)instance);\n" if em.asserts else \
            "  (void)instance;\n  return fmi3OK;\n"
    enter_ct = check
    if ev is not None and ev.samples:  # a sample() instant is over: its conditions fall (no when fires)
        enter_ct = ("  casadi_fmi_memory* m = (casadi_fmi_memory*)instance;\n  int changed = 0;\n"
                    "  if (tbx_samples_on(m) && tbx_event_iteration(m, 1, &changed) != fmi3OK) return fmi3Error;\n"
                    + ("  return tbx_check_asserts(m);\n" if em.asserts else "  return fmi3OK;\n"))

    text = wrapper.read_text()
    patches = [
        ("  const char* instance_name;\n",
         "  const char* instance_name;\n  // trackingbox runtime: FMI logger and assert warning flags\n"
         "  fmi3LogMessageCallback tbx_logger;\n  fmi3InstanceEnvironment tbx_env;\n"
         f"  int tbx_warned[{max(n_assert, 1)}];\n  int tbx_pending;\n"
         "  double tbx_next;\n  int tbx_next_defined;\n"),
        ("    m->instance_name = instanceName;\n",
         "    m->instance_name = instanceName;\n    m->tbx_logger = logMessage;\n"
         "    m->tbx_env = instanceEnvironment;\n"),
        ("  // Zero index is negative: No event\n",
         f"  for (i = 0; i < {max(n_assert, 1)}; ++i) m->tbx_warned[i] = 0;\n  m->tbx_pending = -1;\n"
         "  m->tbx_next = 0;\n  m->tbx_next_defined = 0;\n"
         "  // Zero index is negative: No event\n"),
        ("FMI3_Export fmi3Status fmi3Reset(fmi3Instance instance) {\n",
         "".join(glue) + "FMI3_Export fmi3Status fmi3Reset(fmi3Instance instance) {\n"),
        ("FMI3_Export fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {\n  // Unused variables\n"
         "  (void)instance;  // unused\n  // Always successful return\n  return fmi3OK;\n}\n",
         "FMI3_Export fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {\n"
         + "".join(exit_body) + "}\n"),
        ("FMI3_Export fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {\n  // Unused variables\n"
         "  (void)instance;  // unused\n  // Always successful return\n  return fmi3OK;\n}\n",
         "FMI3_Export fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {\n" + enter_ct + "}\n"),
        ("  // We should not need this as there are no internal iterations\n  return fmi3OK;\n",
         "  (void)noSetFMUStatePriorToCurrentPoint;\n  if (enterEventMode) *enterEventMode = fmi3False;\n"
         "  if (terminateSimulation) *terminateSimulation = fmi3False;\n" + check),
    ]
    if em.asserts:
        patches.append((
            "  return fmi3GetFloat64(instance, xdot_vr, N_X, derivatives, N_X);\n",
            "  fmi3Status status = fmi3GetFloat64(instance, xdot_vr, N_X, derivatives, N_X);\n"
            "  if (status == fmi3OK) tbx_note_asserts((casadi_fmi_memory*)instance);\n  return status;\n"))
    if ev is not None:
        patches.append(("  if (nEventIndicators) *nEventIndicators = N_ZERO;\n",
                        "  if (nEventIndicators) *nEventIndicators = TBX_NZ;\n"))
        for func, replacement in (("fmi3GetEventIndicators", _EVENT_INDICATORS),
                                  ("fmi3UpdateDiscreteStates", _UPDATE_DISCRETE)):
            found = re.search(rf"FMI3_Export fmi3Status {func}\(.*?\n}}\n", text, re.S)
            if found is None:
                raise CompileError(f"unexpected CasADi FMU wrapper {wrapper.name} (casadi {ca.__version__}): {func} "
                                   "not found; the embedded path is pinned to casadi 3.8.2")
            text = text[:found.start()] + replacement + text[found.end():]
    for old, new in patches:
        if text.count(old) != 1:
            raise CompileError(
                f"unexpected CasADi FMU wrapper {wrapper.name} (casadi {ca.__version__}): "
                f"{old.strip().splitlines()[0]!r} not found once; the embedded path is pinned to casadi 3.8.2")
        text = text.replace(old, new)
    wrapper.write_text(text)
    return name


def _add_build_source(build_description: Path, source: str) -> None:
    if not build_description.exists():
        return
    root = ET.fromstring(build_description.read_text())
    for file_set in root.iter("SourceFileSet"):
        ET.SubElement(file_set, "SourceFile", {"name": source})
    ET.indent(root, space="    ")
    build_description.write_text('<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n")
