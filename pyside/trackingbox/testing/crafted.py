"""FMI 2 co-simulation FMUs with tiny, deliberately misbehaving binaries.

The tests and the fuzz script (``scripts/fuzz``) need FMUs whose native code
crashes, hangs, exits or runs slowly in a named FMI function, to check that the
canary, the supervisor and the watchdog turn each into one clear error line.
Each FMU is a C library built here with the machine's C compiler (``$CC`` or
``gcc``, Linux only) from one source, its misbehaviour chosen by three macros:

``WHERE``
    1 on load (a constructor), 2 ``fmi2Instantiate``, 3 ``fmi2SetupExperiment`` and
    ``fmi2EnterInitializationMode``, 4 ``fmi2ExitInitializationMode``,
    5 every ``fmi2GetReal``, 6 every ``fmi2DoStep``, 7 ``fmi2FreeInstance``,
    8 the ``NTH`` and later ``fmi2GetReal``, 9 the ``NTH`` ``fmi2DoStep`` only
    (0: nowhere, a well-behaved binary).
``WHAT``
    1 segfault, 2 ``abort()``, 3 ``_exit(0)``, 4 hang (never returns), 5 ``exit(3)``,
    6 ``SIGBUS``, 7 sleep 30 ms and return, 8 sleep 2 s and return.
``NTH``
    the call count used by ``WHERE`` 8 and 9.

Otherwise the binary is trivial: every ``fmi2GetReal`` returns 1.0, every setter
succeeds, and the FMU state functions report an error. The model description
declares an input ``u``, a tunable parameter ``k`` (start 1, range 0..10) and an
output ``y``.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Misbehaviour", "C_SOURCE", "MODEL_DESCRIPTION", "available", "build", "package"]

C_SOURCE = r"""
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#ifndef WHERE
#define WHERE 0
#endif
#ifndef WHAT
#define WHAT 0
#endif
#ifndef NTH
#define NTH 0
#endif
static void misbehave(void) {
    volatile int *p = 0;
    switch (WHAT) {
    case 1: *p = 1; break;
    case 2: abort(); break;
    case 3: _exit(0); break;
    case 4: for (;;) pause(); break;
    case 5: exit(3); break;
    case 6: raise(SIGBUS); break;
    case 7: usleep(30000); break;
    case 8: sleep(2); break;
    }
}
#define AT(w) do { if (WHERE == (w)) misbehave(); } while (0)
__attribute__((constructor)) static void on_load(void) { AT(1); }
typedef void *C;
static int dummy, reads, steps;
const char *fmi2GetTypesPlatform(void) { return "default"; }
const char *fmi2GetVersion(void) { return "2.0"; }
int fmi2SetDebugLogging(C c, int a, size_t n, const char *const *x) { return 0; }
C fmi2Instantiate(const char *n, int t, const char *g, const char *r, const void *f, int v, int l) { AT(2); return &dummy; }
void fmi2FreeInstance(C c) { AT(7); }
int fmi2SetupExperiment(C c, int a, double tol, double t0, int b, double t1) { AT(3); return 0; }
int fmi2EnterInitializationMode(C c) { AT(3); return 0; }
int fmi2ExitInitializationMode(C c) { AT(4); return 0; }
int fmi2Terminate(C c) { return 0; }
int fmi2Reset(C c) { return 0; }
int fmi2GetReal(C c, const unsigned *vr, size_t n, double *v) {
    AT(5);
    if (WHERE == 8 && ++reads >= NTH) misbehave();
    for (size_t i = 0; i < n; i++) v[i] = 1.0;
    return 0;
}
int fmi2GetInteger(C c, const unsigned *vr, size_t n, int *v) { memset(v, 0, n * sizeof *v); return 0; }
int fmi2GetBoolean(C c, const unsigned *vr, size_t n, int *v) { memset(v, 0, n * sizeof *v); return 0; }
int fmi2GetString(C c, const unsigned *vr, size_t n, const char **v) { for (size_t i = 0; i < n; i++) v[i] = ""; return 0; }
int fmi2SetReal(C c, const unsigned *vr, size_t n, const double *v) { return 0; }
int fmi2SetInteger(C c, const unsigned *vr, size_t n, const int *v) { return 0; }
int fmi2SetBoolean(C c, const unsigned *vr, size_t n, const int *v) { return 0; }
int fmi2SetString(C c, const unsigned *vr, size_t n, const char *const *v) { return 0; }
int fmi2GetFMUstate(C c, void **s) { return 3; }
int fmi2SetFMUstate(C c, void *s) { return 3; }
int fmi2FreeFMUstate(C c, void **s) { return 3; }
int fmi2SerializedFMUstateSize(C c, void *s, size_t *n) { return 3; }
int fmi2SerializeFMUstate(C c, void *s, char *b, size_t n) { return 3; }
int fmi2DeSerializeFMUstate(C c, const char *b, size_t n, void **s) { return 3; }
int fmi2GetDirectionalDerivative(C c, const unsigned *a, size_t na, const unsigned *b, size_t nb, const double *x, double *y) { return 3; }
int fmi2SetRealInputDerivatives(C c, const unsigned *vr, size_t n, const int *o, const double *v) { return 0; }
int fmi2GetRealOutputDerivatives(C c, const unsigned *vr, size_t n, const int *o, double *v) { return 0; }
int fmi2DoStep(C c, double t, double h, int nsp) {
    AT(6);
    if (WHERE == 9 && ++steps == NTH) misbehave();
    return 0;
}
int fmi2CancelStep(C c) { return 0; }
int fmi2GetStatus(C c, int s, int *v) { return 3; }
int fmi2GetRealStatus(C c, int s, double *v) { return 3; }
int fmi2GetIntegerStatus(C c, int s, int *v) { return 3; }
int fmi2GetBooleanStatus(C c, int s, int *v) { return 3; }
int fmi2GetStringStatus(C c, int s, const char **v) { return 3; }
"""

MODEL_DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{{crafted-{name}}}" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{name}" canHandleVariableCommunicationStepSize="true"/>
  <DefaultExperiment startTime="0" stopTime="10" stepSize="1"/>
  <ModelVariables>
    <ScalarVariable name="u" valueReference="0" causality="input" variability="continuous"><Real start="1"/></ScalarVariable>
    <ScalarVariable name="k" valueReference="1" causality="parameter" variability="tunable"><Real start="1" min="0" max="10"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="2" causality="output" variability="continuous"><Real/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="3"/></Outputs></ModelStructure>
</fmiModelDescription>
"""


@dataclass(frozen=True)
class Misbehaviour:
    """Where the binary misbehaves, how, and on which call (see the module docstring)."""

    where: int = 0
    what: int = 0
    nth: int = 0


def _compiler() -> str:
    return os.environ.get("CC", "gcc")


def available() -> bool:
    """True where crafted binaries can be built: Linux with a C compiler on ``PATH``."""
    return sys.platform.startswith("linux") and shutil.which(_compiler()) is not None


def package(fmu: Path, name: str, library: bytes) -> Path:
    """Write *fmu* (atomically) with the crafted model description and *library* as its Linux binary."""
    part = fmu.with_name(fmu.name + ".part")
    with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("modelDescription.xml", MODEL_DESCRIPTION.format(name=name))
        z.writestr(f"binaries/linux64/{name}.so", library)
    part.replace(fmu)
    return fmu


def build(out: Path, crafted: Mapping[str, Misbehaviour]) -> dict[str, Path]:
    """Build one FMU per entry of *crafted* in *out*; existing FMUs are reused.

    Each entry's shared library is kept beside its FMU as ``NAME.so`` (the fuzz
    script derives truncated binaries from it). Raises
    :class:`subprocess.CalledProcessError` if the compiler fails.
    """
    out.mkdir(parents=True, exist_ok=True)
    src = out / "crafted.c"
    if not src.exists() or src.read_text() != C_SOURCE:
        src.write_text(C_SOURCE)
    made: dict[str, Path] = {}
    for name, m in crafted.items():
        fmu = out / f"{name}.fmu"
        so = out / f"{name}.so"
        if not (fmu.exists() and so.exists()):
            subprocess.run([_compiler(), "-shared", "-fPIC", "-O0", f"-DWHERE={m.where}", f"-DWHAT={m.what}",
                            f"-DNTH={m.nth}", "-o", str(so), str(src)], check=True)
            package(fmu, name, so.read_bytes())
        made[name] = fmu
    return made
