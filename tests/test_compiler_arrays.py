"""Array algebra in the embedded compile path: Modelica's meaning, or a clean refusal.

Each model is compiled once with the embedded backend and simulated with fmpy;
the expected values are computed here with NumPy/SciPy from the same numbers
(matrix products, powers, a matrix exponential) or by hand (MLS chapter 10
examples), never taken from the compiler.
"""
from __future__ import annotations

from pathlib import Path

import fmpy
from fmpy import read_model_description
import numpy as np
import pytest
import scipy.linalg

from trackingbox.compiler import compile_model
from trackingbox.errors import CompileError, UnsupportedConstructError

pytestmark = pytest.mark.compile

A = np.array([[1.0, 2.0], [3.0, 4.0]])
B = np.array([[5.0, 6.0, 7.0], [8.0, 9.0, 10.0]])
V = np.array([1.0, 2.0])
W = np.array([3.0, -1.0, 2.0])

PRODUCTS = """
model Products
  parameter Real A[2, 2] = [1, 2; 3, 4];
  parameter Real B[2, 3] = {{5, 6, 7}, {8, 9, 10}};
  parameter Real v[2] = {1, 2};
  Real C[2, 3] = A*B "matrix*matrix";
  Real Av[2] = A*v "matrix*vector";
  Real vA[2] = v*A "vector*matrix";
  Real vv = v*v "scalar product";
  Real vAv = v*A*v;
  Real P0[2, 2] = A^0;
  Real P3[2, 2] = A^3;
  Real Em[2, 2] = A .* A;
  Real Ed[2, 3] = B ./ 2;
  Real Ep[2, 2] = A .^ 2;
  Real Eb[2, 2] = 1 .+ A;
  Real Es[2, 2] = A .- 1;
  Real Sc[2, 2] = 2*A - A/4;
  Real N[2, 2] = -A + A*A;
  Real x[2](each start = 1, each fixed = true);
equation
  der(x) = -A*x;
  annotation(experiment(StopTime = 1));
end Products;
"""

PRODUCT_CASES = {
    "C": A @ B,
    "Av": A @ V,
    "vA": V @ A,
    "vv": V @ V,
    "vAv": V @ A @ V,
    "P0": np.eye(2),
    "P3": np.linalg.matrix_power(A, 3),
    "Em": A * A,
    "Ed": B / 2,
    "Ep": A**2,
    "Eb": 1 + A,
    "Es": A - 1,
    "Sc": 2 * A - A / 4,
    "N": -A + A @ A,
}

CONSTRUCTORS = """
model Constructors
  parameter Integer n = 3;
  parameter Real A[2, 2] = [1, 2; 3, 4];
  parameter Real B[2, 3] = {{5, 6, 7}, {8, 9, 10}};
  parameter Real v[2] = {1, 2};
  parameter Real w[3] = {3, -1, 2};
  Real f[2, 3] = fill(time + 2, 2, 3);
  Real z[2] = zeros(2);
  Real o[3] = ones(n);
  Real I[3, 3] = identity(n);
  Real D[3, 3] = diagonal(w);
  Real l[5] = linspace(0, 2, 5);
  Real c1[5] = cat(1, v, w);
  Real c2[2, 5] = cat(2, A, B);
  Real h[2, 5] = [A, B];
  Real m[3, 2] = [A; {{7, 8}}];
  Real T[3, 2] = transpose(B);
  Real O[2, 3] = outerProduct(v, w);
  Real s1 = size(B, 2);
  Real q[4] = {i^2 for i in 1:4};
  Real Q[2, 3] = {{10*i + j for j in 1:3} for i in 1:2};
  Real sA = sum(A);
  Real pw = product(w);
  Real mn = min(w);
  Real mx = max(B);
  Real sw = sum(w[i]*i for i in 1:3);
  Real K[3, 3] = skew(w);
  Real X[3] = cross(w, {1.0, 2.0, 0.5});
  Real row[3] = B[2, :];
  Real col[2] = B[:, 3];
  Real last = w[end];
  Real mid[2] = w[2:3];
  Real pick[2] = B[{2, 1}, 1];
  Real vec[3] = vector({{1}, {2}, {3}});
  Real ab[3] = abs(-w);
  annotation(experiment(StopTime = 1));
end Constructors;
"""

CONSTRUCTOR_CASES = {
    "f": np.full((2, 3), 2.0),  # at t = 0
    "z": np.zeros(2),
    "o": np.ones(3),
    "I": np.eye(3),
    "D": np.diag(W),
    "l": np.array([0.0, 0.5, 1.0, 1.5, 2.0]),
    "c1": np.concatenate([V, W]),
    "c2": np.hstack([A, B]),
    "h": np.hstack([A, B]),
    "m": np.vstack([A, [[7.0, 8.0]]]),
    "T": B.T,
    "O": np.outer(V, W),
    "s1": 3.0,
    "q": np.array([1.0, 4.0, 9.0, 16.0]),
    "Q": np.array([[11.0, 12.0, 13.0], [21.0, 22.0, 23.0]]),
    "sA": 10.0,
    "pw": -6.0,
    "mn": -1.0,
    "mx": 10.0,
    "sw": 3.0 * 1 - 1.0 * 2 + 2.0 * 3,
    "K": np.array([[0.0, -2.0, -1.0], [2.0, 0.0, -3.0], [1.0, 3.0, 0.0]]),
    "X": np.cross(W, [1.0, 2.0, 0.5]),
    "row": B[1, :],
    "col": B[:, 2],
    "last": 2.0,
    "mid": W[1:],
    "pick": B[[1, 0], 0],
    "vec": np.array([1.0, 2.0, 3.0]),
    "ab": np.abs(W),
}

FUNCTIONS = """
model Functions
  function quad "x' M x"
    input Real M[:, :];
    input Real x[size(M, 1)];
    output Real y;
  algorithm
    y := x*M*x;
  end quad;
  function ramp "rows {a*i, -a*i}, then R[1, 2] = 100"
    input Real a;
    input Integer n;
    output Real R[n, 2];
  algorithm
    R := zeros(n, 2);
    for i in 1:n loop
      R[i, :] := {a*i, -a*i};
    end for;
    R[1, 2] := 100;
  end ramp;
  parameter Real A[2, 2] = [1, 2; 3, 4];
  parameter Real v[2] = {1, 2};
  Real q = quad(A, v);
  Real R[3, 2] = ramp(time + 1, 3);
  Real dq = div(0.5 - 2*time, 0.4) "towards zero";
  Real rq = rem(0.5 - 2*time, 0.4);
  Real mq = mod(0.5 - 2*time, 0.4);
  annotation(experiment(StopTime = 1));
end Functions;
"""


CALLS = """
model Calls
  type Phase = enumeration(solid, liquid, gas);
  function stats "sum, weighted sum and sum of squares of a vector"
    input Real a[:];
    input Real w = 2;
    output Real s;
    output Real ws;
    output Real sq;
  algorithm
    s := 0;
    ws := 0;
    sq := 0;
    for i in 1:size(a, 1) loop
      s := s + a[i];
      ws := ws + w*i*a[i];
      sq := sq + a[i]^2;
    end for;
  end stats;
  parameter Real v[3] = {1, 2, 4};
  parameter Real byPhase[Phase] = {10, 20, 30};
  Real s;
  Real ws;
  Real sq;
  Real t;
  Real g = byPhase[Phase.gas] + time;
equation
  (s, ws, sq) = stats(v*(1 + time));
  (t, , ) = stats(a = {3, 4}, w = 5);
  annotation(experiment(StopTime = 1));
end Calls;
"""


def _compile(tmp_path_factory: pytest.TempPathFactory, name: str, text: str) -> Path:
    root = tmp_path_factory.mktemp(name)
    src = root / f"{name}.mo"
    src.write_text(text)
    return compile_model(src, name, backend="embedded", output=root / f"{name}.fmu").fmu


def _names(var: str, shape: tuple[int, ...]) -> list[str]:
    if not shape:
        return [var]
    return [var + "[" + ",".join(str(i + 1) for i in idx) + "]" for idx in np.ndindex(shape)]


def _simulate(fmu: Path, outputs: list[str], **kw) -> np.ndarray:
    return fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.25, output=outputs,
                             relative_tolerance=1e-8, **kw)


@pytest.fixture(scope="module")
def products(tmp_path_factory: pytest.TempPathFactory) -> np.ndarray:
    fmu = _compile(tmp_path_factory, "Products", PRODUCTS)
    names = [n for var, exp in PRODUCT_CASES.items() for n in _names(var, np.shape(exp))]
    return _simulate(fmu, names + ["x[1]", "x[2]"]), fmu


@pytest.fixture(scope="module")
def constructors(tmp_path_factory: pytest.TempPathFactory) -> np.ndarray:
    fmu = _compile(tmp_path_factory, "Constructors", CONSTRUCTORS)
    names = [n for var, exp in CONSTRUCTOR_CASES.items() for n in _names(var, np.shape(exp))]
    return _simulate(fmu, names)


def _values(out: np.ndarray, var: str, shape: tuple[int, ...], row: int = 0) -> np.ndarray:
    return np.array([out[n][row] for n in _names(var, shape)]).reshape(shape)


@pytest.mark.parametrize("var", list(PRODUCT_CASES))
def test_products_and_powers_have_their_modelica_meaning(products, var):
    out, _ = products
    expected = PRODUCT_CASES[var]
    assert np.allclose(_values(out, var, np.shape(expected)), expected), var


def test_matrix_state_equation_follows_the_matrix_exponential(products):
    out, _ = products
    x = np.column_stack([out["x[1]"], out["x[2]"]])
    expected = np.array([scipy.linalg.expm(-A * t) @ np.ones(2) for t in out["time"]])
    assert np.allclose(x, expected, atol=1e-6)


def test_products_follow_a_tunable_parameter(products):
    """The product is built symbolically: changing A in the FMU changes C = A*B."""
    _, fmu = products
    A2 = np.array([[0.5, -1.0], [2.0, 0.0]])
    starts = {f"A[{i + 1},{j + 1}]": float(A2[i, j]) for i in range(2) for j in range(2)}
    out = _simulate(fmu, _names("C", (2, 3)) + _names("P3", (2, 2)), start_values=starts)
    assert np.allclose(_values(out, "C", (2, 3)), A2 @ B)
    assert np.allclose(_values(out, "P3", (2, 2)), np.linalg.matrix_power(A2, 3))


@pytest.mark.parametrize("var", list(CONSTRUCTOR_CASES))
def test_constructors_reductions_and_slices(constructors, var):
    expected = CONSTRUCTOR_CASES[var]
    assert np.allclose(_values(constructors, var, np.shape(expected)), expected), var


def test_fill_of_a_time_varying_value_follows_time(constructors):
    assert np.allclose(constructors["f[2,3]"], constructors["time"] + 2.0)


def test_array_functions_are_inlined_with_array_semantics(tmp_path_factory):
    fmu = _compile(tmp_path_factory, "Functions", FUNCTIONS)
    out = _simulate(fmu, ["q", "dq", "rq", "mq"] + _names("R", (3, 2)))
    assert np.allclose(out["q"], V @ A @ V)  # 27
    a = out["time"] + 1.0
    R = np.stack([_values(out, "R", (3, 2), k) for k in range(len(a))])
    expected = np.stack([np.column_stack([ak * np.arange(1, 4), -ak * np.arange(1, 4)]) for ak in a])
    expected[:, 0, 1] = 100.0
    assert np.allclose(R, expected)
    x = 0.5 - 2 * out["time"]  # from 0.5 down to -1.5: both signs
    assert np.allclose(out["dq"], np.trunc(x / 0.4))
    assert np.allclose(out["rq"], np.fmod(x, 0.4))
    assert np.allclose(out["mq"], x - np.floor(x / 0.4) * 0.4)


def test_multiple_outputs_named_arguments_and_enumeration_indices(tmp_path_factory):
    fmu = _compile(tmp_path_factory, "Calls", CALLS)
    out = _simulate(fmu, ["s", "ws", "sq", "t", "g"])
    k = 1 + out["time"]
    assert np.allclose(out["s"], 7 * k)  # 1 + 2 + 4
    assert np.allclose(out["ws"], 2 * (1 * 1 + 2 * 2 + 3 * 4) * k)  # w = 2 by default
    assert np.allclose(out["sq"], 21 * k**2)  # 1 + 4 + 16
    assert np.allclose(out["t"], 7.0)  # the first output only
    assert np.allclose(out["g"], 30 + out["time"])  # Phase.gas is the third element


LINEAR_SYSTEM = """
model LinearSystem "A*y = b with zero entries in the parameter matrix A"
  parameter Real A[3, 3] = [4, 1, 0; 1, 3, 1; 0, 1, 2];
  Real b[3] = {1, 2, 3}*(1 + time);
  Real y[3];
equation
  A*y = b;
  annotation(experiment(StopTime = 1));
end LinearSystem;
"""


def test_matrix_equation_solves_the_linear_system(tmp_path_factory):
    fmu = _compile(tmp_path_factory, "LinearSystem", LINEAR_SYSTEM)
    out = _simulate(fmu, _names("y", (3,)))
    M = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]])
    for k, t in enumerate(out["time"]):
        assert np.allclose(_values(out, "y", (3,), k), np.linalg.solve(M, np.array([1.0, 2.0, 3.0]) * (1 + t)))


# ----------------------------------------------------------------- refusals
REFUSALS = [
    ("parameter Real p = sqrt(-1); Real y = p*time;", CompileError, "sqrt(-1)"),
    ("parameter Real p = acos(2); Real y = p*time;", CompileError, "acos(2)"),
    ("constant Real c = log(0); Real y = c*time;", CompileError, "log(0)"),
    ("Real y = asin(-3) + time;", CompileError, "asin(-3)"),
    ("Real y = 1/0 + time;", CompileError, "division by zero"),
    ("Real y = (-8)^(1/3) + time;", CompileError, "negative base"),
    ("parameter Real M[2, 2] = [1, 2; 3, 4]; Real Y[2, 2] = M^(-1);", CompileError, "Integer >= 0"),
    ("Real y[6] = {10*i + j for i in 1:2, j in 1:3};", UnsupportedConstructError, "several iterators"),
    ("Real y = min({time for i in 1:0});", CompileError, "empty array"),
]


@pytest.mark.parametrize("decl,error,needle", REFUSALS, ids=[r[2] for r in REFUSALS])
def test_invalid_constants_and_unsupported_arrays_are_refused_at_their_line(tmp_path, decl, error, needle):
    src = tmp_path / "Bad.mo"
    src.write_text(f"model Bad\n  Real x(start = 0, fixed = true);\n  {decl}\nequation\n  der(x) = 1;\nend Bad;\n")
    with pytest.raises(error) as info:
        compile_model(src, "Bad", backend="embedded", output=tmp_path / "bad.fmu")
    message = str(info.value)
    assert needle in message
    assert f"{src}:3" in message  # the file and the line of the declaration
    assert not (tmp_path / "bad.fmu").exists()


# --------------------------------------------- modifications the front end loses
MODIFIERS = """
package Mods
  model Inner
    parameter Real a = 1;
    parameter Real b = 2*a;
  end Inner;
  model Outer
    Inner i(a = 10);
  end Outer;
  model W1
    Outer o1(i(b = 7));
    Outer o2;
  end W1;
  model LostNested "extends W1(o1(i(a = 70))) must keep o1.i.b = 7"
    extends W1(o1(i(a = 70)));
  end LostNested;
  model Base
    parameter Real k = 1;
  end Base;
  model Holder
    replaceable model M = Base;
    M m;
  end Holder;
  model LostRedeclare "through extends, k = kk must reach m.k (a literal is read through a short class; in a component's modification see test_compiler_redeclare_components)"
    parameter Real kk = 5; extends Holder(redeclare model M = Base(k = kk));
  end LostRedeclare;
  package Medium
    constant Real cp = 4180;
  end Medium;
  package Medium2
    extends Medium(cp = 1000);
  end Medium2;
  model MixedMedia "Medium.cp must stay 4180"
    Real c1 = Medium.cp*(1 + time);
    Real c2 = Medium2.cp*(1 + time);
  end MixedMedia;
  model Kept "modifications rumoca keeps: merged through extends and components"
    Inner c(b = 7);
    W1 w(o1(i(a = 4)));
    Outer2 o;
    Real y = (c.a + c.b + w.o1.i.a + w.o1.i.b + w.o2.i.a + w.o2.i.b + o.i.a + o.i.b)*(1 + time);
  end Kept;
  model Outer2
    extends Outer(i(a = 20));
  end Outer2;
  model LostValueWithBounds "rumoca drops a = 30 and the bounds: i.a would stay 10"
    extends Outer(i(a(min = 0, max = 100) = 30));
  end LostValueWithBounds;
  model LostValueShort = Inner(a(start = 2) = 5) "rumoca drops a = 5: a would stay 1";
  model LostValueDeclaration "rumoca drops o.i.a = 40: it would stay 10"
    Outer o(i(a(max = 50) = 40));
  end LostValueDeclaration;
  model KeptValueWithBounds "a declaration's own elements keep value and bounds"
    Inner c(a(min = 0, max = 100) = 30);
    Real y = c.b*(1 + time);
  end KeptValueWithBounds;
end Mods;
"""

LOST = [
    ("LostNested", "o1.i", "package.mo:15"),
    ("LostRedeclare", "class redeclaration with a modification", "package.mo:25"),
    ("MixedMedia", "package Medium2 extends Medium", "package.mo:31"),
    ("LostValueWithBounds", "the modification of i.a in 'extends Outer(...)'", "package.mo:47"),
    ("LostValueShort", "the modification of a in 'LostValueShort = Inner(...)'", "package.mo:49"),
    ("LostValueDeclaration", "the modification of i.a in the declaration of o", "package.mo:51"),
]


@pytest.fixture(scope="module")
def mods_package(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("mods") / "Mods"
    root.mkdir()
    (root / "package.mo").write_text(MODIFIERS)
    return root


@pytest.mark.parametrize("model,needle,where", LOST, ids=[m[0] for m in LOST])
def test_modifications_the_front_end_would_lose_are_refused(mods_package, tmp_path, model, needle, where):
    with pytest.raises(UnsupportedConstructError) as info:
        compile_model(mods_package, f"Mods.{model}", backend="embedded", output=tmp_path / "m.fmu")
    assert needle in str(info.value) and where in str(info.value)
    assert not (tmp_path / "m.fmu").exists()


def test_modifications_the_front_end_keeps_still_compile(mods_package, tmp_path):
    res = compile_model(mods_package, "Mods.Kept", backend="embedded", output=tmp_path / "k.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["y"])
    # c: a = 1, b = 7; w.o1.i: a = 4, b = 7; w.o2.i: a = 10, b = 20; o.i: a = 20, b = 40
    assert np.allclose(out["y"], (1 + 7 + 4 + 7 + 10 + 20 + 20 + 40) * (1 + out["time"]))


# ------------------------------------------------- array helpers without a compile
def test_array_module_examples_hold():
    import doctest

    from trackingbox.compiler import arrays

    assert doctest.testmod(arrays).failed == 0


def _obj(values) -> np.ndarray:
    return np.array(values, dtype=object)


@pytest.mark.parametrize("call,needle", [
    (lambda a: a.matmul(_obj([[1, 2], [3, 4]]), _obj([1, 2, 3])), "matrix*vector product of sizes [2, 2] and [3]"),
    (lambda a: a.matmul(_obj([1, 2]), _obj([1, 2, 3])), "scalar product of vectors"),
    (lambda a: a.power(_obj([[1, 2, 3], [4, 5, 6]]), 2), "only a square matrix"),
    (lambda a: a.power(_obj([[1, 2], [3, 4]]), 1.5), "constant Integer >= 0"),
    (lambda a: a.divide(1.0, _obj([1, 2])), "use ./"),
    (lambda a: a.map2(lambda x, y: x + y, _obj([1, 2]), 1.0, "addition '+'", broadcast=False), "element-wise"),
    (lambda a: a.cat(1, [_obj([[1, 2]]), _obj([[1, 2, 3]])]), "cat() along dimension 1"),
    (lambda a: a.linspace(0.0, 1.0, 1), "at least 2"),
    (lambda a: a.cross(_obj([1, 2]), _obj([1, 2, 3])), "vector of size 3"),
    (lambda a: a.to_scalar(_obj([1, 2])), "every size must be 1"),
    (lambda a: a.subscript(_obj([1, 2, 3]), [4], "'v'"), "index 4 out of range 1..3"),
], ids=["mat-vec", "vec-vec", "non-square", "fraction", "scalar/array", "broadcast", "cat", "linspace",
        "cross", "scalar", "index"])
def test_array_sizes_that_do_not_fit_are_errors(call, needle):
    from trackingbox.compiler import arrays

    with pytest.raises(arrays.ArrayError) as info:
        call(arrays)
    assert needle in str(info.value)
    assert isinstance(info.value, CompileError)


def test_vector_subscripts_pick_rows_and_columns_like_modelica():
    from trackingbox.compiler import arrays

    M = _obj([[1, 2, 3], [4, 5, 6]])
    # M[{2, 1}, {3, 1}] is the 2x2 matrix of rows 2, 1 and columns 3, 1 (not NumPy's paired indexing)
    picked = arrays.subscript(M, [_obj([2, 1]), _obj([3, 1])], "'M'")
    assert picked.tolist() == [[6, 4], [3, 1]]
    assert arrays.subscript(M, [None, 2], "'M'").tolist() == [2, 5]


def test_a_value_with_bounds_in_a_declaration_is_kept(mods_package, tmp_path):
    """``Inner c(a(min = 0, max = 100) = 30)``: rumoca keeps both here (only nested or extends
    modifications lose them), so it is not refused: b = 2a = 60."""
    res = compile_model(mods_package, "Mods.KeptValueWithBounds", backend="embedded", output=tmp_path / "k.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["y"])
    assert np.allclose(out["y"], 60 * (1 + out["time"]))
    a = next(v for v in read_model_description(str(res.fmu)).modelVariables if v.name == "c.a")
    assert (float(a.min), float(a.max)) == (0.0, 100.0)


def test_modification_parser_reads_nesting_values_and_skips_redeclarations():
    from trackingbox.compiler.modifiers import parse_modification

    text = "(each k = f(1, 2), o1(i(a = 70), b.c = {1, 2}), redeclare model M = Base(k = 5), final x)"
    mods, end = parse_modification(text, 0)
    assert end == len(text)
    assert [m.name for m in mods] == ["k", "o1", "x"]
    assert mods[0].has_value and not mods[0].subs
    o1 = mods[1]
    assert [s.name for s in o1.subs] == ["i", "b"]
    assert o1.subs[0].subs[0].name == "a" and o1.subs[0].subs[0].has_value
    assert o1.subs[1].subs[0].name == "c"  # b.c = ... is b(c = ...)
