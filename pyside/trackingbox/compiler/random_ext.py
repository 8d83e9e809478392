"""The external C routines of ``Modelica.Math.Random`` (and ``Strings.hashString``), given their
meaning on the embedded path, bit for bit.

The MSL's generators (``Modelica.Math.Random.Generators``: xorshift64*, xorshift128+,
xorshift1024*, S. Vigna 2014) keep their state in a Modelica ``Integer`` vector: each 64-bit word is
two 32-bit Integers, the low half first (the C union of ``int32_t[2]`` and ``uint64_t`` on a
little-endian machine). A call returns the new state and a Real in [0, 1] (the MSL documents
0 < r <= 1): the new 64-bit word read as a signed 64-bit integer, times 2^-64, plus 0.5. The word is,
as the MSL's C source adapts Vigna's published generators: for xorshift64* the state after its
multiplication (kept as the next state, where the published generator keeps the state before it);
for xorshift128+ the sum that the published generator returns (kept as the second word, where the
published one keeps the sum's first term); for xorshift1024* the new word times
1181783497276652981, as published.

Where every argument is a constant at translation the routine runs here on Python integers. Where
the state is a variable (the noise blocks draw ``(r_raw, state) = random(pre(state))`` at sample
events) the same arithmetic is built as a CasADi expression on the Integers' values (doubles, exact
below 2^53): a word is split into its 64 bits (``fmod`` by 2, exact), ``xor`` of two bits is
``a + b - 2ab``, shifts move bits, and sums and products modulo 2^64 are taken on 16-bit limbs with
their carries (every partial sum stays below 2^36). The result is the C routine's, bit for bit, for
every state; ``tests/test_compiler_random.py`` checks it against the published algorithms (with those
adaptations) and against the MSL's C source compiled there.

``impureRandom`` and ``automaticGlobalSeed`` are refused (the first would need the hidden
xorshift1024* state across events, the second the wall clock and process id at the FMU's start).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np

from .arrays import is_num


class NotGiven(Exception):
    """The routine cannot give its meaning to these arguments (the message says why)."""


M64 = (1 << 64) - 1
MUL64STAR = 2685821657736338717
MUL1024STAR = 1181783497276652981


# -- exact integers -------------------------------------------------------------------------------

def _u32(x: int) -> int:
    return int(x) & 0xFFFFFFFF


def _s32(u: int) -> int:
    u &= 0xFFFFFFFF
    return u - (1 << 32) if u >= 1 << 31 else u


def _word(lo: int, hi: int) -> int:
    return _u32(lo) | (_u32(hi) << 32)


def _halves(w: int) -> tuple[int, int]:
    return _s32(w), _s32(w >> 32)


def _real(w: int) -> float:
    """The C ``(int64_t)w * 2^-64 + 0.5`` (one rounding in the conversion, one in the sum)."""
    signed = w - (1 << 64) if w >= 1 << 63 else w
    return float(signed) * 2.0 ** -64 + 0.5


def _step64(words: list[int]) -> tuple[list[int], int]:
    x = words[0]
    x ^= x >> 12
    x = (x ^ (x << 25)) & M64
    x ^= x >> 27
    x = (x * MUL64STAR) & M64
    return [x], x


def _step128(words: list[int]) -> tuple[list[int], int]:
    s1, s0 = words
    s1 = (s1 ^ (s1 << 23)) & M64
    new = ((s1 ^ s0 ^ (s1 >> 17) ^ (s0 >> 26)) + s0) & M64
    return [s0, new], new


def _step1024(words: list[int], p: int) -> tuple[list[int], int, int]:
    s = list(words)
    p &= 15
    s0 = s[p]
    p = (p + 1) & 15
    s1 = s[p]
    s1 = (s1 ^ (s1 << 31)) & M64
    s1 ^= s1 >> 11
    s0 ^= s0 >> 30
    s[p] = s0 ^ s1
    return s, p, (s[p] * MUL1024STAR) & M64


# -- the same on CasADi expressions of the Integers' values ---------------------------------------

Bits = list  # 64 expressions (or numbers), each 0 or 1, least significant first


def _fmod2(x: Any) -> Any:
    return ca.fmod(x, 2) if isinstance(x, ca.MX) else float(x) % 2


def _bits_of_u(u: Any, n: int) -> Bits:
    """The *n* low bits of the non-negative integer value *u*."""
    out = []
    for _ in range(n):
        b = _fmod2(u)
        out.append(b)
        u = (u - b) / 2
    return out


def _bits_of_halves(lo: Any, hi: Any) -> Bits:
    def unsigned(x: Any) -> Any:
        return ca.if_else(x < 0, x + 2.0 ** 32, x) if isinstance(x, ca.MX) else float(_u32(int(x)))
    return _bits_of_u(unsigned(lo), 32) + _bits_of_u(unsigned(hi), 32)


def _xor(a: Any, b: Any) -> Any:
    return a + b - 2 * a * b


def _shl(bits: Bits, k: int) -> Bits:
    return [0.0] * k + bits[: 64 - k]


def _shr(bits: Bits, k: int) -> Bits:
    return bits[k:] + [0.0] * k


def _xor_bits(a: Bits, b: Bits) -> Bits:
    return [x if isinstance(y, float) and y == 0.0 else _xor(x, y) for x, y in zip(a, b)]


def _limbs(bits: Bits) -> list[Any]:
    """The four 16-bit limbs of a word given by its bits."""
    out = []
    for i in range(4):
        v: Any = 0.0
        for k in range(16):
            v = v + bits[16 * i + k] * float(1 << k)
        out.append(v)
    return out


def _carry(t: Any) -> tuple[Any, Any]:
    r = ca.fmod(t, 65536.0) if isinstance(t, ca.MX) else float(t) % 65536.0
    return r, (t - r) / 65536.0


def _mul_const(limbs: list[Any], c: int) -> list[Any]:
    """The limbs of the product of a word (by limbs) and the constant *c*, modulo 2^64."""
    cl = [float((c >> (16 * i)) & 0xFFFF) for i in range(4)]
    out, carry = [], 0.0
    for i in range(4):
        t = carry
        for j in range(i + 1):
            t = t + limbs[j] * cl[i - j]
        r, carry = _carry(t)
        out.append(r)
    return out


def _add(a: list[Any], b: list[Any]) -> list[Any]:
    out, carry = [], 0.0
    for x, y in zip(a, b):
        r, carry = _carry(x + y + carry)
        out.append(r)
    return out


def _limb_bits(limbs: list[Any]) -> Bits:
    return [b for limb in limbs for b in _bits_of_u(limb, 16)]


def _limb_halves(limbs: list[Any]) -> tuple[Any, Any]:
    def signed(u: Any) -> Any:
        return ca.if_else(u >= 2.0 ** 31, u - 2.0 ** 32, u) if isinstance(u, ca.MX) else _s32(int(u))
    return signed(limbs[0] + limbs[1] * 65536.0), signed(limbs[2] + limbs[3] * 65536.0)


def _limb_real(limbs: list[Any]) -> Any:
    lo = limbs[0] + limbs[1] * 65536.0
    hi = limbs[2] + limbs[3] * 65536.0
    hi_signed = ca.if_else(hi >= 2.0 ** 31, hi - 2.0 ** 32, hi) if isinstance(hi, ca.MX) else hi
    return (hi_signed * 2.0 ** 32 + lo) * 2.0 ** -64 + 0.5


def _sym_step64(bits: Bits) -> list[Any]:
    x = _xor_bits(bits, _shr(bits, 12))
    x = _xor_bits(x, _shl(x, 25))
    x = _xor_bits(x, _shr(x, 27))
    return _mul_const(_limbs(x), MUL64STAR)


def _sym_step128(s1: Bits, s0: Bits) -> list[Any]:
    s1 = _xor_bits(s1, _shl(s1, 23))
    mixed = _xor_bits(_xor_bits(_xor_bits(s1, s0), _shr(s1, 17)), _shr(s0, 26))
    return _add(_limbs(mixed), _limbs(s0))


# -- the routines ----------------------------------------------------------------------------------

def _vector(value: Any, n: int, what: str) -> list[Any]:
    a = np.asarray(value, dtype=object).ravel()
    if a.size < n:
        raise NotGiven(f"{what} has {a.size} elements, not at least {n}")
    return list(a[:n])


def _constant_ints(values: list[Any]) -> list[int] | None:
    if all(is_num(v) for v in values):
        if any(float(v) != int(v) for v in values):
            raise NotGiven("a state element is not an integer")
        return [int(v) for v in values]
    return None


def _mx(values: list[Any]) -> list[Any]:
    return [v if isinstance(v, ca.MX) else ca.MX(float(v)) for v in values]


def xorshift64star(args: list[Any]) -> dict[int, Any]:
    """``ModelicaRandom_xorshift64star(stateIn[2], stateOut[2], result)``."""
    state = _vector(args[0], 2, "stateIn")
    ints = _constant_ints(state)
    if ints is not None:
        words, out = _step64([_word(*ints)])
        return {1: np.array(list(_halves(words[0])), dtype=object), 2: _real(out)}
    limbs = _sym_step64(_bits_of_halves(*_mx(state)))
    return {1: np.array(list(_limb_halves(limbs)), dtype=object), 2: _limb_real(limbs)}


def xorshift128plus(args: list[Any]) -> dict[int, Any]:
    """``ModelicaRandom_xorshift128plus(stateIn[4], stateOut[4], result)``."""
    state = _vector(args[0], 4, "stateIn")
    ints = _constant_ints(state)
    if ints is not None:
        words, out = _step128([_word(ints[0], ints[1]), _word(ints[2], ints[3])])
        return {1: np.array([*_halves(words[0]), *_halves(words[1])], dtype=object), 2: _real(out)}
    st = _mx(state)
    limbs = _sym_step128(_bits_of_halves(st[0], st[1]), _bits_of_halves(st[2], st[3]))
    return {1: np.array([st[2], st[3], *_limb_halves(limbs)], dtype=object), 2: _limb_real(limbs)}


def xorshift1024star(args: list[Any]) -> dict[int, Any]:
    """``ModelicaRandom_xorshift1024star(stateIn[33], stateOut[33], result)``: 16 words and the
    index of the current one (taken modulo 16)."""
    state = _vector(args[0], 33, "stateIn")
    ints = _constant_ints(state)
    if ints is None:
        raise NotGiven("its state depends on variables (only a state known at translation is drawn from)")
    words, p, out = _step1024([_word(ints[2 * i], ints[2 * i + 1]) for i in range(16)], ints[32])
    halves = [h for w in words for h in _halves(w)]
    return {1: np.array(halves + [p], dtype=object), 2: _real(out)}


def hash_string(args: list[Any]) -> dict[int, Any]:
    """``ModelicaStrings_hashString(string)``: the AP hash (Arash Partow) of the string's bytes that
    the MSL's C source computes, as a signed 32-bit Integer (the value ``-1`` key is the return)."""
    text = args[0]
    if not isinstance(text, str):
        raise NotGiven("its string is not known at translation")
    h = 0xAAAAAAAA
    for i, byte in enumerate(text.encode("utf-8")):
        if i % 2 == 0:
            h ^= ((h << 7) ^ (byte * (h >> 3))) & 0xFFFFFFFF
        else:
            h ^= ~((h << 11) + (byte ^ (h >> 5))) & 0xFFFFFFFF
    return {-1: _s32(h)}


ROUTINES: dict[str, Callable[[list[Any]], dict[int, Any]]] = {
    "ModelicaRandom_xorshift64star": xorshift64star,
    "ModelicaRandom_xorshift128plus": xorshift128plus,
    "ModelicaRandom_xorshift1024star": xorshift1024star,
    "ModelicaStrings_hashString": hash_string,
}
"""C routine name -> its meaning on the arguments' values (argument position -> value written; -1 is
the routine's return value). Routines not here (``ModelicaRandom_impureRandom_xorshift1024star``,
``ModelicaRandom_automaticGlobalSeed``) are refused by the translator naming the function."""
