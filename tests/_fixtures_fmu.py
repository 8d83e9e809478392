"""Small FMUs for the FMU-layer tests, built once per test process.

All three implement the same first-order lag, hand-solvable:

    dx/dt = k (u - x),  x(0) = x0,  y = x
    => x(t) = u + (x0 - u) exp(-k t)   for constant u and k.

* :func:`me3_fmu`: FMI 3.0 model exchange, exported by CasADi's DaeBuilder (what
  the embedded compiler produces).
* :func:`me2_fmu`: FMI 2.0 model exchange, a hand-written C model compiled with
  gcc. It has an extra parameter ``p`` (default 0): dx/dt = k (u - x) + p x^2,
  which with k = 0, p = 1 blows up at t = 1/x0 (for solver-failure tests).
* :func:`cs2_fmu`: FMI 2.0 co-simulation, built with pythonfmu; exact update per
  communication step (inputs held over a step). Extra output ``z = sqrt(y)``,
  NaN when y < 0 (for non-finite-value tests).
* :func:`cs3_fmu`: FMI 3.0 co-simulation, FMPy's FMI 3 C template (``fmpy.template``)
  with the exact per-step update filled in, compiled with gcc.
"""
from __future__ import annotations

import atexit
import functools
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import zipfile
from pathlib import Path

import fmpy

from _fixtures_casadi import build_casadi_fmu

_ROOT = Path(tempfile.mkdtemp(prefix="tb-test-fmus-"))
atexit.register(shutil.rmtree, _ROOT, True)


def _dir(name: str) -> Path:
    d = _ROOT / name
    d.mkdir(parents=True, exist_ok=True)
    return d


@functools.lru_cache(maxsize=None)
def me3_fmu() -> Path:
    """FMI 3.0 ME FMU 'firstorder': k (tunable, 2, [0.5, 5]), u (input, 1), x (state, 0.5), y (output)."""
    return build_casadi_fmu(_dir("me3"), "firstorder", variables=[
        ("k", ("parameter", "tunable"), {"start": 2.0, "min": 0.5, "max": 5.0, "description": "rate constant"}),
        ("u", ("input",), {"start": 1.0}),
        ("x", ("local", "continuous"), {"start": 0.5, "initial": "exact"}),
        ("y", ("output",), {}),
    ], equations=[("der(x)", "k * (u - x)"), ("y", "x")])


_CS_SOURCE = '''
import math
from pythonfmu import Fmi2Slave, Fmi2Causality, Fmi2Variability, Real


class FirstOrderCS(Fmi2Slave):
    description = "dx/dt = k (u - x), exact update per communication step"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.k = 2.0
        self.x0 = 0.5
        self.u = 1.0
        self.y = 0.5
        self.z = math.sqrt(0.5)
        self.register_variable(Real("k", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("x0", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))
        self.register_variable(Real("z", causality=Fmi2Causality.output))

    def exit_initialization_mode(self):
        self.y = self.x0
        self.z = math.sqrt(self.y) if self.y >= 0 else float("nan")

    def do_step(self, current_time, step_size):
        self.y = self.u + (self.y - self.u) * math.exp(-self.k * step_size)
        self.z = math.sqrt(self.y) if self.y >= 0 else float("nan")
        return True
'''


@functools.lru_cache(maxsize=None)
def cs2_fmu() -> Path:
    """FMI 2.0 CS FMU 'FirstOrderCS' (pythonfmu): k (tunable), x0 (fixed), u (input), y, z (outputs)."""
    d = _dir("cs2")
    script = d / "FirstOrderCS.py"
    script.write_text(_CS_SOURCE)
    subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(d),
                    "--no-external-tool"], check=True, capture_output=True, text=True)
    return d / "FirstOrderCS.fmu"


_ME2_C = r'''
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

enum { VR_K, VR_X0, VR_P, VR_U, VR_X, VR_DER_X, VR_Y, NVR };

typedef struct {
    double v[NVR];
    double time;
    int initialized;
} Model;

static void defaults(Model *m) {
    memset(m, 0, sizeof(Model));
    m->v[VR_K] = 2.0; m->v[VR_X0] = 0.5; m->v[VR_P] = 0.0; m->v[VR_U] = 1.0; m->v[VR_X] = 0.5;
}

static void calc(Model *m) {
    m->v[VR_DER_X] = m->v[VR_K] * (m->v[VR_U] - m->v[VR_X]) + m->v[VR_P] * m->v[VR_X] * m->v[VR_X];
    m->v[VR_Y] = m->v[VR_X];
}

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions* cb, fmi2Boolean visible, fmi2Boolean logging) {
    Model *m;
    if (type != fmi2ModelExchange) return NULL;
    m = (Model*)calloc(1, sizeof(Model));
    if (m) defaults(m);
    return m;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real t0,
                               fmi2Boolean stopDef, fmi2Real t1) { ((Model*)c)->time = t0; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Model *m = (Model*)c;
    m->v[VR_X] = m->v[VR_X0];
    m->initialized = 1;
    calc(m);
    return fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { defaults((Model*)c); return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Model *m = (Model*)c; size_t i;
    calc(m);
    for (i = 0; i < n; i++) { if (vr[i] >= NVR) return fmi2Error; value[i] = m->v[vr[i]]; }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Model *m = (Model*)c; size_t i;
    for (i = 0; i < n; i++) {
        if (vr[i] != VR_K && vr[i] != VR_X0 && vr[i] != VR_P && vr[i] != VR_U) return fmi2Error;
        m->v[vr[i]] = value[i];
    }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* s) { return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* s) { return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t* n) { return fmi2Error; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { return fmi2Error; }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate* s) { return fmi2Error; }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]) { return fmi2Error; }

fmi2Status fmi2EnterEventMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo* e) {
    e->newDiscreteStatesNeeded = fmi2False; e->terminateSimulation = fmi2False;
    e->nominalsOfContinuousStatesChanged = fmi2False; e->valuesOfContinuousStatesChanged = fmi2False;
    e->nextEventTimeDefined = fmi2False; e->nextEventTime = 0.0;
    return fmi2OK;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSet, fmi2Boolean* enter, fmi2Boolean* term) {
    *enter = fmi2False; *term = fmi2False; return fmi2OK;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { ((Model*)c)->time = t; return fmi2OK; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    ((Model*)c)->v[VR_X] = x[0]; return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) {
    Model *m = (Model*)c; calc(m); dx[0] = m->v[VR_DER_X]; return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) { return fmi2OK; }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    x[0] = ((Model*)c)->v[VR_X]; return fmi2OK;
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    x_nominal[0] = 1.0; return fmi2OK;
}
'''

_ME2_XML = '''<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="FirstOrderME2" guid="{8c4e810f-3df3-4a00-8276-176fa3c9f000}"
  numberOfEventIndicators="0" generationTool="trackingbox tests">
  <ModelExchange modelIdentifier="FirstOrderME2"/>
  <UnitDefinitions>
    <Unit name="1/s"><BaseUnit s="-1"/></Unit>
    <Unit name="K"><BaseUnit K="1"/></Unit>
  </UnitDefinitions>
  <TypeDefinitions>
    <SimpleType name="Rate"><Real unit="1/s" min="0" max="10"/></SimpleType>
    <SimpleType name="Temperature"><Real unit="K" nominal="300"/></SimpleType>
  </TypeDefinitions>
  <DefaultExperiment startTime="0" stopTime="3" stepSize="0.1"/>
  <ModelVariables>
    <ScalarVariable name="k" valueReference="0" causality="parameter" variability="tunable" description="rate constant">
      <Real declaredType="Rate" start="2"/>
    </ScalarVariable>
    <ScalarVariable name="x0" valueReference="1" causality="parameter" variability="fixed">
      <Real start="0.5"/>
    </ScalarVariable>
    <ScalarVariable name="p" valueReference="2" causality="parameter" variability="tunable">
      <Real start="0"/>
    </ScalarVariable>
    <ScalarVariable name="u" valueReference="3" causality="input">
      <Real declaredType="Temperature" start="1"/>
    </ScalarVariable>
    <ScalarVariable name="x" valueReference="4" causality="local" variability="continuous" initial="calculated">
      <Real declaredType="Temperature"/>
    </ScalarVariable>
    <ScalarVariable name="der(x)" valueReference="5" causality="local" variability="continuous" initial="calculated">
      <Real derivative="5"/>
    </ScalarVariable>
    <ScalarVariable name="y" valueReference="6" causality="output" variability="continuous" initial="calculated">
      <Real/>
    </ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="7"/></Outputs>
    <Derivatives><Unknown index="6"/></Derivatives>
    <InitialUnknowns><Unknown index="5"/><Unknown index="6"/><Unknown index="7"/></InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
'''


@functools.lru_cache(maxsize=None)
def me2_fmu() -> Path:
    """FMI 2.0 ME FMU 'FirstOrderME2' (hand-written C): k, x0, p, u, x, y; units on type definitions."""
    d = _dir("me2")
    src = d / "FirstOrderME2.c"
    src.write_text(textwrap.dedent(_ME2_C))
    so = d / "FirstOrderME2.so"
    include = os.path.join(os.path.dirname(fmpy.__file__), "c-code")
    subprocess.run(["gcc", "-shared", "-fPIC", "-O1", "-I", include, str(src), "-o", str(so)],
                   check=True, capture_output=True, text=True)
    fmu = d / "FirstOrderME2.fmu"
    with zipfile.ZipFile(fmu, "w") as zf:
        zf.writestr("modelDescription.xml", _ME2_XML)
        zf.write(so, "binaries/linux64/FirstOrderME2.so")
    return fmu


def _replace_c_function(src: str, name: str, body: str) -> str:
    """Replace the body of C function *name* (``fmi3Status name(...) { ... }``) in *src*."""
    start = src.index(f"fmi3Status {name}(")
    brace = src.index("{", start)
    end = src.index("\n}\n", brace) + 3
    return src[:brace] + "{\n" + body + "\n}\n" + src[end:]


@functools.lru_cache(maxsize=None)
def cs3_fmu() -> Path:
    """FMI 3.0 CS FMU 'FirstOrderCS3': FMPy's FMI 3 C template with the lag's exact step filled in.

    Variables: k (tunable, 2), x0 (fixed, 0.5), u (input, 1), y (output); default
    experiment 0..1 s, step 0.1 s.
    """
    import uuid

    from fmpy.model_description import CoSimulation, DefaultExperiment, ModelDescription, ModelVariable, Unknown
    from fmpy.template import create_fmu

    d = _dir("cs3")
    md = ModelDescription(fmiVersion="3.0", modelName="FirstOrderCS3", instantiationToken=str(uuid.uuid4()),
                          description="first-order lag", generationTool="trackingbox tests",
                          generationDateAndTime="2026-01-01T00:00:00Z")
    md.coSimulation = CoSimulation(modelIdentifier="FirstOrderCS3")
    md.defaultExperiment = DefaultExperiment(startTime="0", stopTime="1", stepSize="0.1")
    # the template numbers value references in declaration order, starting at 0
    for vr, (name, causality, variability, start) in enumerate([
        ("time", "independent", "continuous", None),
        ("k", "parameter", "tunable", "2"),
        ("x0", "parameter", "fixed", "0.5"),
        ("u", "input", "continuous", "1"),
        ("y", "output", "continuous", None),
    ]):
        v = ModelVariable(name=name, valueReference=vr, type="Float64", causality=causality,
                          variability=variability, start=start)
        md.modelVariables.append(v)
    y = md.modelVariables[-1]
    md.outputs.append(Unknown(variable=y))
    md.initialUnknowns.append(Unknown(variable=y))
    template = d / "template.fmu"
    create_fmu(md, template)
    with zipfile.ZipFile(template) as zf:
        xml = zf.read("modelDescription.xml")
        src = zf.read("sources/model.c").decode()
    src = _replace_c_function(src, "fmi3ExitInitializationMode",
                              "    Model* model = (Model*)instance;\n    model->y = model->x0;\n    return fmi3OK;")
    src = _replace_c_function(src, "fmi3DoStep", """    Model* model = (Model*)instance;
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    model->y = model->u + (model->y - model->u) * exp(-model->k * communicationStepSize);
    model->time = currentCommunicationPoint + communicationStepSize;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = model->time;
    return fmi3OK;""")
    c_file = d / "model.c"
    c_file.write_text("#include <math.h>\n" + src)
    so = d / "FirstOrderCS3.so"
    include = os.path.join(os.path.dirname(fmpy.__file__), "c-code")
    subprocess.run(["gcc", "-shared", "-fPIC", "-O1", "-I", include, str(c_file), "-o", str(so), "-lm"],
                   check=True, capture_output=True, text=True)
    fmu = d / "FirstOrderCS3.fmu"
    with zipfile.ZipFile(fmu, "w") as zf:
        zf.writestr("modelDescription.xml", xml)
        zf.write(so, "binaries/x86_64-linux/FirstOrderCS3.so")
    return fmu
