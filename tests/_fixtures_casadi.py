"""One builder for the small CasADi-made FMUs of the tests, without ``os.chdir``.

CasADi's ``DaeBuilder.export_fmu``, ``compile_fmu`` and ``pack_fmu`` write into
the *current directory* and have no option to write elsewhere. Changing the
directory of the test process (``os.chdir``) is global state shared by every
thread and every test, so the build runs in a child Python process started
with ``cwd=directory`` instead. The model is handed over as data: variables as
the arguments of ``DaeBuilder.add`` and equations as Python expressions over the
variable names (``der(x)`` for a derivative), evaluated in the child with the
named constants in scope.

Example (the first-order lag ``dx/dt = k (u - x)``, ``y = x``)::

    build_casadi_fmu(directory, "lag",
                     variables=[("k", ("parameter", "tunable"), {"start": 2.0}),
                                ("u", ("input",), {"start": 1.0}),
                                ("x", ("local", "continuous"), {"start": 0.5, "initial": "exact"}),
                                ("y", ("output",), {})],
                     equations=[("der(x)", "k * (u - x)"), ("y", "x")])
"""
from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

#: Run in the child, in the target directory: build, compile, pack; print the FMU's file name.
_BUILD = r"""
import json, os, sys
import casadi, fmpy

model = json.loads(sys.argv[1])
dae = casadi.DaeBuilder(model["name"])
scope = dict(model["constants"])
scope["der"] = dae.der
for name, args, attributes in model["variables"]:
    scope[name] = dae.add(name, *args, attributes)
for lhs, rhs in model["equations"]:
    dae.eq(eval(lhs, {}, scope), eval(rhs, {}, scope))
files = dae.export_fmu({"no_warning": True})
files = dae.compile_fmu(files, {"include_dirs": [os.path.join(os.path.dirname(fmpy.__file__), "c-code")]})
print(dae.pack_fmu(files, {}))
"""


def build_casadi_fmu(directory: Path, name: str, *,
                     variables: Sequence[tuple[str, Sequence[str], Mapping[str, Any]]],
                     equations: Sequence[tuple[str, str]],
                     constants: Mapping[str, float] | None = None) -> Path:
    """Build an FMI 3.0 model-exchange FMU with CasADi's DaeBuilder in *directory*.

    Parameters
    ----------
    directory : Path
        Where the sources, the binary and the FMU are written (created if needed).
    name : str
        Model name (also the FMU's file name stem).
    variables : sequence of (name, args, attributes)
        In declaration order: ``dae.add(name, *args, attributes)``.
    equations : sequence of (lhs, rhs)
        Python expressions over the variable names and *constants*: ``dae.eq(lhs, rhs)``.
    constants : mapping, optional
        Names usable in the expressions (e.g. ``{"TAU": 100.0}``).

    Returns
    -------
    Path
        Absolute path of the FMU.
    """
    directory = Path(directory).resolve()
    directory.mkdir(parents=True, exist_ok=True)
    model = {"name": name, "variables": [[n, list(a), dict(attrs)] for n, a, attrs in variables],
             "equations": [list(e) for e in equations], "constants": dict(constants or {})}
    done = subprocess.run([sys.executable, "-c", _BUILD, json.dumps(model)], cwd=directory,
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"building the CasADi test FMU {name!r} in {directory} failed:\n{done.stderr}")
    return directory / done.stdout.strip().splitlines()[-1]


def rewrite_model_description(fmu: Path, change: Any) -> Path:
    """Replace *fmu*'s ``modelDescription.xml`` by ``change(text)`` (the other entries copied as they are)."""
    import zipfile

    fmu = Path(fmu)
    part = fmu.with_suffix(".part")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = change(data.decode("utf-8")).encode("utf-8")
            dst.writestr(item, data)
    part.replace(fmu)
    return fmu
