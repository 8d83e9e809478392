"""A function input sized by a constant of the enclosing package (``input MassFraction X[nX]`` in
``Modelica.Media.Interfaces.PartialSimpleMedium``) stopped rumoca 0.10.2's function shape proof
("dependent extent is not an exact Integer expression over proven shape axes") for every
Modelica.Fluid source or vessel with such a medium (issue 35). The front end now reads such inputs
as ``X[:]`` (:func:`trackingbox.compiler.rewrite.relax_input_extents`), keeping every byte offset;
what the function computes is unchanged (checked against the closed form)."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model
from trackingbox.compiler.rewrite import relax_input_extents

PACKAGE = b"""package Mix "a package constant sizes a function's inputs"
  constant Integer nX = 3;
  constant Real w[nX] = {1, 2, 3};
  function weighted "sum of w[i] X[i] + k n"
    input Real X[nX] "mass fractions, [nX] in a string";
    input Integer n;
    input Real u[n];
    input Real A[nX, 2];
    output Real y;
  algorithm
    y := w*X + sum(u) + sum(A[:, 2]);
  end weighted;
  model M
    Real X[nX] = {time, 2*time, 1};
    Real y;
  equation
    y = weighted(X, 2, {1, time}, [1, 2; 3, 4; 5, 6]);
  end M;
end Mix;
"""


def test_only_undeclared_names_in_input_sizes_are_relaxed_and_offsets_kept():
    data, lines = relax_input_extents(PACKAGE)
    assert len(data) == len(PACKAGE) and data.count(b"\n") == PACKAGE.count(b"\n")
    assert lines == [5, 8]
    assert b"input Real X[: ]" in data and b"input Real A[: , 2]" in data
    assert b"input Real u[n]" in data  # n is the function's own input
    assert b"[nX] in a string" in data and b"Real X[nX] = " in data  # strings and models untouched


@pytest.mark.compile
def test_a_function_with_inputs_sized_by_a_package_constant_computes_as_written(tmp_path):
    src = tmp_path / "Mix.mo"
    src.write_bytes(PACKAGE)
    res = compile_model(src, "Mix.M", backend="embedded", output=tmp_path / "m.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.25, output=["y"])
    t = out["time"]
    assert np.allclose(out["y"], (t + 4 * t + 3) + (1 + t) + 12, atol=1e-12)


@pytest.mark.compile
def test_a_fluid_boundary_with_a_simple_medium_passes_the_front_end(tmp_path):
    """Before: refused with rumoca's shape-proof message (the medium's density_phX, sized by the
    package constant nX, is reachable from the boundary's density parameter); then by the check of
    packages extended with modified constants, which took PartialSimpleMedium's own ``end`` name
    and PartialMedium as the default of a replaceable package for uses; then at a field of a record
    returned by a function. It now compiles, and the medium's functions, which go through its
    ThermodynamicState record (``density(setState_pTX(p, T, X))``), give the values of the medium's
    definition worked by hand: d = d_const = 995.586, h = cp_const*(T - T0) = 4184*(300 - 273.15)."""
    need_msl("Fluid", "Sources.mo")
    medium = "Modelica.Media.Water.ConstantPropertyLiquidWater"
    src = tmp_path / "B.mo"
    src.write_text(f"model B\n  Modelica.Fluid.Sources.FixedBoundary a(redeclare package Medium = {medium}, "
                   "nPorts = 0, p = 1.1e5, T = 300);\n  inner Modelica.Fluid.System system;\n"
                   f"  Real d = {medium}.density_pTX(a.p, a.T, a.X);\n"
                   f"  Real h = {medium}.specificEnthalpy_pTX(a.p, a.T, a.X);\nend B;\n")
    res = compile_model(src, "B", backend="embedded", output=tmp_path / "b.fmu", libraries=[MSL])
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output=["d", "h"])
    assert np.allclose(out["d"], 995.586, rtol=1e-12)
    assert np.allclose(out["h"], 4184 * (300 - 273.15), rtol=1e-12)
