"""``Modelica.Math.Random`` and the ``Modelica.Blocks.Noise`` blocks on the embedded path
(:mod:`trackingbox.compiler.random_ext`, :mod:`trackingbox.compiler.random_source`).

Independent references:

* the published algorithms (S. Vigna, xorshift64*, xorshift128+, xorshift1024*), written here on
  Python integers, with the MSL's two adaptations its C source documents: xorshift64* keeps the
  multiplied word as its next state, xorshift128+ keeps the sum as its second word; the Real drawn
  is the word read as a signed 64-bit integer times 2^-64 plus 0.5;
* the MSL's own C source (``Resources/C-Sources/ModelicaRandom.c`` and ``ModelicaStrings.c``),
  compiled here with the system's C compiler and called through ctypes, where one is installed;
* the MSL's noise example ``Modelica.Blocks.Examples.Noise.UniformNoise``, whose states and outputs
  at the first draws must be the references' exactly; and the uniform and normal noise blocks'
  draws, whose mean and variance must lie within the bounds scipy.stats gives for their
  distributions.
"""
from __future__ import annotations

import ctypes
import random
import shutil
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy import stats

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import random_ext
from trackingbox.compiler.random_source import noise_draw_as_algorithm

M = (1 << 64) - 1


# -- the published algorithms, on Python integers --------------------------------------------------

def ref_xorshift64star(x: int) -> tuple[int, int]:
    """Vigna's xorshift64*: (next state, 64-bit output)."""
    x ^= x >> 12
    x ^= (x << 25) & M
    x ^= x >> 27
    return x, (x * 2685821657736338717) & M


def ref_xorshift128plus(s: list[int]) -> tuple[list[int], int]:
    """Vigna's xorshift128+ (2014): (next state, 64-bit output)."""
    s1, s0 = s
    s1 ^= (s1 << 23) & M
    second = s1 ^ s0 ^ (s1 >> 17) ^ (s0 >> 26)
    return [s0, second], (second + s0) & M


def ref_xorshift1024star(s: list[int], p: int) -> tuple[list[int], int, int]:
    """Vigna's xorshift1024* (2014): (next state, next index, 64-bit output)."""
    s = list(s)
    s0 = s[p]
    p = (p + 1) & 15
    s1 = s[p]
    s1 ^= (s1 << 31) & M
    s1 ^= s1 >> 11
    s0 ^= s0 >> 30
    s[p] = s0 ^ s1
    return s, p, (s[p] * 1181783497276652981) & M


def to_real(word: int) -> float:
    return float(word - (1 << 64) if word >> 63 else word) * 2.0 ** -64 + 0.5


def halves(word: int) -> list[int]:
    return [int(np.int32(np.uint32(word & 0xFFFFFFFF))), int(np.int32(np.uint32(word >> 32)))]


def word(lo: int, hi: int) -> int:
    return (lo & 0xFFFFFFFF) | ((hi & 0xFFFFFFFF) << 32)


def msl_random64(state: list[int]) -> tuple[float, list[int]]:
    """Xorshift64star.random as the MSL adapts it: the output word is the next state."""
    _, out = ref_xorshift64star(word(*state))
    return to_real(out), halves(out)


def msl_random128(state: list[int]) -> tuple[float, list[int]]:
    """Xorshift128plus.random as the MSL adapts it: the output word is the next second word."""
    (first, _), out = ref_xorshift128plus([word(state[0], state[1]), word(state[2], state[3])])
    return to_real(out), halves(first) + halves(out)


def msl_initial_state(local: int, glob: int, n: int) -> list[int]:
    """Utilities.initialStateWithXorshift64star (the MSL's Modelica algorithm)."""
    aux = [126247697, glob] if local == 0 and glob == 0 else [local, glob]
    for _ in range(10):
        _, aux = msl_random64(aux)
    state = list(aux[: min(n, 2)])
    for _ in range(3, 2 * (n // 2) + 1, 2):
        _, aux = msl_random64(state[-2:])
        state += aux
    if n >= 3 and n % 2:
        _, aux = msl_random64(state[-2:])
        state.append(aux[0])
    return state


def random_states(n: int, seed: int) -> list[list[int]]:
    rng = random.Random(seed)
    edges = [0, 1, -1, 2 ** 31 - 1, -(2 ** 31)]
    out = [[e] * n for e in edges]
    out += [[rng.randint(-(2 ** 31), 2 ** 31 - 1) for _ in range(n)] for _ in range(40)]
    return out


# -- the routines against the references -----------------------------------------------------------

def _symbolic(routine, n: int):
    """The routine on a symbolic state, as a CasADi function of the state's values."""
    x = ca.MX.sym("x", n)
    written = routine([np.array([x[i] for i in range(n)], dtype=object)])
    outs = [ca.vertcat(*[ca.MX(v) if not isinstance(v, ca.MX) else v for v in written[1]]), ca.MX(written[2])]
    return ca.Function("f", [x], outs)


@pytest.mark.parametrize("n, routine, reference", [
    (2, random_ext.xorshift64star, msl_random64),
    (4, random_ext.xorshift128plus, msl_random128),
])
def test_generators_are_bit_exact_on_constants_and_on_symbolic_states(n, routine, reference):
    fn = _symbolic(routine, n)
    for state in random_states(n, 7 + n):
        r, new = reference(state)
        written = routine([np.array(state, dtype=object)])
        assert [int(v) for v in written[1]] == new and written[2] == r
        sym_state, sym_r = fn(state)
        assert [int(v) for v in np.array(sym_state).ravel()] == new
        assert float(sym_r) == r  # the same double, not merely close


def test_xorshift1024star_on_constants_and_refused_on_a_variable_state():
    for state in random_states(32, 3):
        words = [word(state[2 * i], state[2 * i + 1]) for i in range(16)]
        for p in (0, 7, 15, 16 + 5):
            s, q, out = ref_xorshift1024star(words, p & 15)
            written = random_ext.xorshift1024star([np.array(state + [p], dtype=object)])
            assert [int(v) for v in written[1]] == [h for w in s for h in halves(w)] + [q]
            assert written[2] == to_real(out)
    with pytest.raises(random_ext.NotGiven, match="depends on variables"):
        random_ext.xorshift1024star([np.array([ca.MX.sym("s")] * 33, dtype=object)])


def _compile_c(tmp_path: Path, name: str, sources: list[str]) -> ctypes.CDLL:
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler installed to build the MSL's own ModelicaRandom.c as a reference")
    csrc = need_msl("Resources", "C-Sources", "ModelicaRandom.c").parent
    shim = tmp_path / "shim.c"
    shim.write_text(
        "#include <stdlib.h>\n"
        "void ModelicaError(const char* s) { (void)s; abort(); }\n"
        "void ModelicaFormatError(const char* s, ...) { (void)s; abort(); }\n"
        "char* ModelicaAllocateString(size_t n) { return (char*)malloc(n + 1); }\n"
        "void ModelicaInternal_getTime(int* a, int* b, int* c, int* d, int* e, int* f, int* g)"
        " { *a = *b = *c = *d = *e = *f = *g = 0; }\n"
        "int ModelicaInternal_getpid(void) { return 0; }\n")
    lib = tmp_path / f"lib{name}.so"
    subprocess.run([cc, "-shared", "-fPIC", "-O1", f"-I{csrc}", "-o", str(lib),
                    *[str(csrc / s) for s in sources], str(shim)], check=True, capture_output=True)
    return ctypes.CDLL(str(lib))


def test_generators_and_hash_agree_with_the_msl_c_source(tmp_path):
    lib = _compile_c(tmp_path, "random", ["ModelicaRandom.c"])
    for n, cfun, routine in ((2, lib.ModelicaRandom_xorshift64star, random_ext.xorshift64star),
                             (4, lib.ModelicaRandom_xorshift128plus, random_ext.xorshift128plus),
                             (33, lib.ModelicaRandom_xorshift1024star, random_ext.xorshift1024star)):
        for state in random_states(n, 11):
            if n == 33:
                state[32] = abs(state[32]) % 16
            inp, out, y = (ctypes.c_int * n)(*state), (ctypes.c_int * n)(), ctypes.c_double()
            cfun(inp, out, ctypes.byref(y))
            written = routine([np.array(state, dtype=object)])
            assert [int(v) for v in written[1]] == list(out) and written[2] == y.value
    strings = _compile_c(tmp_path, "strings", ["ModelicaStrings.c"])
    strings.ModelicaStrings_hashString.restype = ctypes.c_int
    for text in ("", "a", "UniformNoise.uniformNoise1", "AutomaticSeed.automaticSeed3", "ä b.c[2]"):
        expected = strings.ModelicaStrings_hashString(text.encode("utf-8"))
        assert random_ext.hash_string([text]) == {-1: expected}


def test_noise_draw_rewrite_keeps_lines_and_length():
    path = need_msl("Blocks", "Interfaces.mo")
    data = path.read_bytes()
    new, lines = noise_draw_as_algorithm(data)
    assert len(lines) == 1 and len(new) == len(data) and new.count(b"\n") == data.count(b"\n")
    assert b"(r_raw, state) := generator.random(pre(state)); end when; equation" in new


# -- the MSL's example and the distributions -------------------------------------------------------

def _at_draws(res, name: str, times: np.ndarray) -> np.ndarray:
    """The value of *name* just after each time in *times* (the last output row at that time)."""
    t = res["time"]
    return np.array([res[name][np.nonzero(np.isclose(t, ti, atol=1e-9))[0][-1]] for ti in times])


def test_uniform_noise_example_draws_the_msl_sequence(tmp_path):
    import fmpy

    from trackingbox.compiler import compile_model

    need_msl("Blocks", "package.mo")
    fmu = tmp_path / "UniformNoise.fmu"
    compile_model(MSL, "Modelica.Blocks.Examples.Noise.UniformNoise", backend="embedded", output=fmu)
    period, draws = 0.02, 12
    names = [f"uniformNoise{k}.{v}" for k in (1, 2) for v in ("y", "state[1]", "state[2]", "state[3]", "state[4]")]
    res = fmpy.simulate_fmu(str(fmu), stop_time=period * draws, output_interval=period / 2, output=names)
    times = period * np.arange(draws)
    global_seed = 67867967  # GlobalSeed's fixedSeed
    for k, local in ((1, random_ext.hash_string(["UniformNoise.uniformNoise1"])[-1]), (2, 10)):
        state = msl_initial_state(local, global_seed, 4)
        ys, states = [], []
        for _ in range(draws):  # a draw at every sample from t = 0 on: r from the state before it
            r, state = msl_random128(state)
            ys.append(r * (3 - (-1)) + (-1))
            states.append(list(state))
        got_y = _at_draws(res, f"uniformNoise{k}.y", times)
        got_s = np.stack([_at_draws(res, f"uniformNoise{k}.state[{j}]", times) for j in range(1, 5)], axis=1)
        assert got_s.astype(np.int64).tolist() == states
        np.testing.assert_array_equal(got_y, np.array(ys))


DRAWS = """
model Draws
  inner Modelica.Blocks.Noise.GlobalSeed globalSeed(fixedSeed = 4711);
  Modelica.Blocks.Noise.UniformNoise uniform(samplePeriod = 0.001, y_min = 0, y_max = 6,
    useAutomaticLocalSeed = false, fixedLocalSeed = 5);
  Modelica.Blocks.Noise.NormalNoise normal(samplePeriod = 0.001, mu = 3, sigma = 0.5);
  Modelica.Blocks.Noise.TruncatedNormalNoise truncated(samplePeriod = 0.001, y_min = -1, y_max = 3);
end Draws;
"""


def test_noise_blocks_draw_their_distributions(tmp_path):
    """2000 draws of each block (TruncatedNormalNoise by default: mean (y_max + y_min)/2, sigma
    (y_max - y_min)/6, cut at y_min and y_max): the Kolmogorov-Smirnov test against scipy.stats'
    distribution, and the mean and variance within scipy's 99.9 % bounds for that many draws."""
    import fmpy

    from trackingbox.compiler import compile_model

    need_msl("Blocks", "Noise.mo")
    src = tmp_path / "Draws.mo"
    src.write_text(DRAWS)
    fmu = tmp_path / "Draws.fmu"
    compile_model(src, "Draws", backend="embedded", output=fmu, libraries=[MSL])
    n = 2000
    res = fmpy.simulate_fmu(str(fmu), stop_time=0.001 * (n - 1), output_interval=0.0005,
                            output=["uniform.y", "normal.y", "truncated.y"])
    times = 0.001 * np.arange(n)
    for name, dist in (("uniform.y", stats.uniform(loc=0, scale=6)), ("normal.y", stats.norm(loc=3, scale=0.5)),
                       ("truncated.y", stats.truncnorm(-3, 3, loc=1, scale=4 / 6))):
        y = _at_draws(res, name, times)
        assert len(np.unique(y)) == n, f"{name}: repeated draws"
        assert stats.kstest(y, dist.cdf).pvalue > 1e-3, name
        mean_bound = stats.norm.ppf(0.9995) * dist.std() / np.sqrt(n)
        assert abs(y.mean() - dist.mean()) < mean_bound, name
        chi = stats.chi2(n - 1)  # exact for the normal draws; wider than needed for the other two
        assert chi.ppf(0.0005) < (n - 1) * y.var(ddof=1) / dist.var() < chi.ppf(0.9995), name


AUTOMATIC = """
model Automatic
  inner Modelica.Blocks.Noise.GlobalSeed globalSeed(useAutomaticSeed = true);
  Modelica.Blocks.Noise.UniformNoise noise(samplePeriod = 0.1);
end Automatic;
"""


def _line(path: Path, text: str) -> int:
    data = path.read_text(encoding="utf-8")
    return data.count("\n", 0, data.index(text)) + 1


def test_wall_clock_seed_and_impure_generator_are_refused_naming_the_function(tmp_path):
    from trackingbox.compiler import compile_model
    from trackingbox.errors import UnsupportedConstructError

    random_mo = need_msl("Math", "Random.mo")
    src = tmp_path / "Automatic.mo"
    src.write_text(AUTOMATIC)
    with pytest.raises(UnsupportedConstructError) as info:
        compile_model(src, "Automatic", backend="embedded", output=tmp_path / "a.fmu", libraries=[MSL])
    line = _line(random_mo, "impure function automaticGlobalSeed")
    assert "automaticGlobalSeed" in str(info.value) and f"Random.mo:{line}" in str(info.value)
    with pytest.raises(UnsupportedConstructError) as info:
        compile_model(MSL, "Modelica.Blocks.Examples.Noise.ImpureGenerator", backend="embedded",
                      output=tmp_path / "i.fmu")
    line = _line(random_mo, "impure function impureRandom\n")
    assert "ModelicaRandom_impureRandom_xorshift1024star" in str(info.value) and f"Random.mo:{line}" in str(info.value)


@pytest.mark.parametrize("example, dist", [
    ("UniformNoiseProperties", stats.uniform(loc=0, scale=6)),
    ("NormalNoiseProperties", stats.norm(loc=3, scale=1)),
])
def test_msl_noise_property_examples_meet_their_theoretical_mean_and_deviation(tmp_path, example, dist):
    """The MSL's examples over their experiment (20 s, a draw each 1 ms): the running mean and
    standard deviation they compute from the noise (``meanError``, ``sigmaError``: estimate minus
    theory) end within 4.5 standard errors of the estimators for 20000 draws of the distribution
    (the estimators' spreads from scipy.stats' moments)."""
    import fmpy

    from trackingbox.compiler import compile_model

    need_msl("Blocks", "package.mo")
    fmu = tmp_path / f"{example}.fmu"
    compile_model(MSL, f"Modelica.Blocks.Examples.Noise.{example}", backend="embedded", output=fmu)
    res = fmpy.simulate_fmu(str(fmu), stop_time=20.0, output_interval=0.004, relative_tolerance=1e-9,
                            output=["meanError_y", "sigmaError_y", "noise.y"])
    n = 20000
    sigma = dist.std()
    mu4 = dist.moment(4) - 4 * dist.mean() * dist.moment(3) + 6 * dist.mean() ** 2 * dist.moment(2) - 3 * dist.mean() ** 4
    sd_var = np.sqrt((mu4 - sigma ** 4) / n)  # the sample variance's standard error
    assert abs(res["meanError_y"][-1]) < 4.5 * sigma / np.sqrt(n)
    assert abs(res["sigmaError_y"][-1]) < 4.5 * sd_var / (2 * sigma)
    assert len(np.unique(res["noise.y"])) > 4000  # the draws differ (5000 outputs, 20000 draws)
