"""A first-order lag as FMI 2 FMUs with both interfaces from one C source, for the input-rule tests.

``der(x) = k (u - x)``, ``y = x``, ``x(0) = x0``; ``k`` a tunable parameter, ``x0`` a fixed one,
``u`` an input. The co-simulation interface solves each step in closed form: with an input slope
given through ``fmi2SetRealInputDerivatives`` (order 1) the input is the ramp ``u + s (t - t0)``
over the step, without one it is held (FMI 2's default), so one binary is an FMU that interpolates
inputs (``canInterpolateInputs="true"``) or one that does not, as its model description says.
:func:`build_lag_fmus` compiles it with the C compiler against fmpy's FMI headers and writes one
FMU per interface variant; :func:`lag_response` is the closed form the tests compare with.
"""
from __future__ import annotations

import math
import os
import subprocess
import zipfile
from collections.abc import Sequence
from pathlib import Path

import fmpy
import numpy as np
import numpy.typing as npt

__all__ = ["build_lag_fmus", "lag_response", "VARIANTS"]

#: variant -> (interfaces in the model description, canInterpolateInputs)
VARIANTS = {
    "me": (("ModelExchange",), False),
    "cs": (("CoSimulation",), False),
    "cs-interpolating": (("CoSimulation",), True),
}

_C = r"""
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

enum { VR_K, VR_X0, VR_U, VR_X, VR_DER_X, VR_Y, NVR };

typedef struct { double v[NVR]; double slope; double time; } Lag;

static void defaults(Lag *m) {
    memset(m, 0, sizeof(Lag));
    m->v[VR_K] = 0.01; m->v[VR_X0] = 1.0; m->v[VR_U] = 1.0; m->v[VR_X] = 1.0;
}
static void calc(Lag *m) {
    m->v[VR_DER_X] = m->v[VR_K] * (m->v[VR_U] - m->v[VR_X]);
    m->v[VR_Y] = m->v[VR_X];
}

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions* cb, fmi2Boolean visible, fmi2Boolean logging) {
    Lag *m = (Lag*)calloc(1, sizeof(Lag));
    if (m) defaults(m);
    return m;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real t0,
                               fmi2Boolean stopDef, fmi2Real t1) { ((Lag*)c)->time = t0; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Lag *m = (Lag*)c; m->v[VR_X] = m->v[VR_X0]; calc(m); return fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { defaults((Lag*)c); return fmi2OK; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Lag *m = (Lag*)c; size_t i; calc(m);
    for (i = 0; i < n; i++) { if (vr[i] >= NVR) return fmi2Error; value[i] = m->v[vr[i]]; }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Lag *m = (Lag*)c; size_t i;
    for (i = 0; i < n; i++) {
        if (vr[i] != VR_K && vr[i] != VR_X0 && vr[i] != VR_U) return fmi2Error;
        m->v[vr[i]] = value[i];
        if (vr[i] == VR_U) m->slope = 0.0;  /* a new value: no ramp until one is given */
    }
    return fmi2OK;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Lag *m = (Lag*)c; size_t i;
    for (i = 0; i < n; i++) {
        if (vr[i] != VR_U || order[i] != 1) return fmi2Error;
        m->slope = value[i];
    }
    return fmi2OK;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) { return fmi2Error; }
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    /* exact over the step for the input u + slope (tau - t): x' = k (u + s tau - x) */
    Lag *m = (Lag*)c;
    double k = m->v[VR_K], u = m->v[VR_U], s = m->slope, x = m->v[VR_X], e = exp(-k * h);
    m->v[VR_X] = u + s * h - s / k + (x - u + s / k) * e;
    m->v[VR_U] = u + s * h;
    m->time = t + h;
    calc(m);
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status* v) { return fmi2Error; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* v) { return fmi2Error; }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer* v) { return fmi2Error; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* v) { return fmi2Error; }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String* v) { return fmi2Error; }
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
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { ((Lag*)c)->time = t; return fmi2OK; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    ((Lag*)c)->v[VR_X] = x[0]; return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) {
    Lag *m = (Lag*)c; calc(m); dx[0] = m->v[VR_DER_X]; return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) { return fmi2OK; }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) { x[0] = ((Lag*)c)->v[VR_X]; return fmi2OK; }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    x_nominal[0] = 1.0; return fmi2OK;
}
"""


def _model_description(interfaces: Sequence[str], interpolates: bool) -> str:
    parts = []
    if "ModelExchange" in interfaces:
        parts.append('  <ModelExchange modelIdentifier="Lag"/>')
    if "CoSimulation" in interfaces:
        parts.append('  <CoSimulation modelIdentifier="Lag" canHandleVariableCommunicationStepSize="true" '
                     f'canInterpolateInputs="{"true" if interpolates else "false"}"/>')
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Lag" guid="{{5d1c7d6e-2b64-4c0e-9a55-3a0f6a0c1a01}}"
  numberOfEventIndicators="0" generationTool="trackingbox (testing.lag_fmu)">
{chr(10).join(parts)}
  <ModelVariables>
    <ScalarVariable name="k" valueReference="0" causality="parameter" variability="tunable" description="rate (1/s)">
      <Real start="0.01" min="0.0001" max="1"/>
    </ScalarVariable>
    <ScalarVariable name="x0" valueReference="1" causality="parameter" variability="fixed">
      <Real start="1"/>
    </ScalarVariable>
    <ScalarVariable name="u" valueReference="2" causality="input" variability="continuous">
      <Real start="1"/>
    </ScalarVariable>
    <ScalarVariable name="x" valueReference="3" causality="local" variability="continuous" initial="calculated">
      <Real/>
    </ScalarVariable>
    <ScalarVariable name="der(x)" valueReference="4" causality="local" variability="continuous" initial="calculated">
      <Real derivative="4"/>
    </ScalarVariable>
    <ScalarVariable name="y" valueReference="5" causality="output" variability="continuous" initial="calculated">
      <Real/>
    </ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="6"/></Outputs>
    <Derivatives><Unknown index="5"/></Derivatives>
    <InitialUnknowns><Unknown index="4"/><Unknown index="5"/><Unknown index="6"/></InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


def build_lag_fmus(dest: Path, variants: Sequence[str] = tuple(VARIANTS)) -> dict[str, Path]:
    """Compile the lag once under *dest* and write ``Lag-<variant>.fmu`` for each of *variants*."""
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    src = dest / "Lag.c"
    src.write_text(_C, encoding="utf-8")
    so = dest / "Lag.so"
    include = os.path.join(os.path.dirname(fmpy.__file__), "c-code")
    cc = os.environ.get("CC", "gcc")
    done = subprocess.run([cc, "-shared", "-fPIC", "-O1", "-I", include, str(src), "-o", str(so), "-lm"],
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"compiling the lag FMU failed:\n{done.stderr[-2000:]}")
    out = {}
    for variant in variants:
        interfaces, interpolates = VARIANTS[variant]
        fmu = dest / f"Lag-{variant}.fmu"
        with zipfile.ZipFile(fmu, "w") as zf:
            zf.writestr("modelDescription.xml", _model_description(interfaces, interpolates))
            zf.write(so, "binaries/linux64/Lag.so")
        out[variant] = fmu
    return out


def lag_response(t: npt.ArrayLike, u: npt.ArrayLike, k: float, x0: float, rule: str) -> npt.NDArray[np.float64]:
    """The lag's output at the sample times *t* for input samples *u*, in closed form.

    *rule* ``"linear"``: the input is the straight line between samples; ``"hold"``: it stays
    at each sample's value until the next sample.
    """
    t = np.asarray(t, dtype=float)
    u = np.asarray(u, dtype=float)
    x = np.empty_like(t)
    x[0] = x0
    for i in range(1, t.size):
        h = t[i] - t[i - 1]
        s = (u[i] - u[i - 1]) / h if rule == "linear" else 0.0
        e = math.exp(-k * h)
        x[i] = u[i - 1] + s * h - s / k + (x[i - 1] - u[i - 1] + s / k) * e
    return x

