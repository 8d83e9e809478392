"""Functions of ``Modelica.Math.Random`` (MSL 4.0.0) that rumoca 0.10.2 cannot take, read with
bodies it can that compute the same (:data:`LIBRARY_BODIES`, keyword arguments of
``rewrite.LibraryBody``, which ``rewrite.py`` adds to its own). The generators' external C routines
get their meaning from :mod:`.random_ext`; :func:`noise_draw_as_algorithm` has rumoca read the noise
blocks' draw.
"""
from __future__ import annotations

import re

from .source_scan import _code_mask

_NOISE_WHEN = re.compile(
    rb"\bequation\s+when\s+generateNoise\s+and\s+sample\s*\(\s*startTime\s*,\s*samplePeriod\s*\)\s+then\s*"
    rb"\(\s*r_raw\s*,\s*state\s*\)\s*=\s*generator\s*\.\s*random\s*\(\s*pre\s*\(\s*state\s*\)\s*\)\s*;"
    rb"\s*end\s+when\s*;")
_NOISE_ALGORITHM = (b"algorithm when generateNoise and sample(startTime, samplePeriod) then "
                    b"(r_raw, state) := generator.random(pre(state)); end when; equation")


def noise_draw_as_algorithm(data: bytes) -> tuple[bytes, list[int]]:
    """*data* with ``Modelica.Blocks.Interfaces.PartialNoise``'s draw, the when-equation
    ``(r_raw, state) = generator.random(pre(state))`` that opens its equation section, read as the
    same when-statement in an algorithm section (rumoca 0.10.2 refuses a call with several outputs
    in a when-equation, "multi-output event calls require a checked function-action owner", and
    takes it in a when-statement); the equations after it stay in an equation section. The meaning
    is the same: the statement assigns r_raw and state at the draws and holds them otherwise, as the
    when-equation does. The text keeps its lines and length (the comment between ``equation`` and
    ``when`` makes room); and the lines changed."""
    if b"generateNoise" not in data:
        return data, []
    code, _, _ = _code_mask(data)
    out = bytearray(data)
    lines = []
    for m in _NOISE_WHEN.finditer(code):
        old = data[m.start():m.end()]
        new = _NOISE_ALGORITHM + b"\n" * old.count(b"\n")
        if len(new) > len(old):
            continue
        out[m.start():m.end()] = new + b" " * (len(old) - len(new))
        lines.append(data.count(b"\n", 0, m.start()) + 1)
    return bytes(out), lines


# Modelica.Math.Random.Utilities.initializeImpureRandom: every Modelica.Blocks.Noise.GlobalSeed
# computes ``id_impure = initializeImpureRandom(seed)`` in an initial equation. The function returns
# its constant ``localSeed`` (715827883) and, on the way, copies an xorshift1024* state into the C
# library's hidden memory with the impure ``setInternalState``, which rumoca refuses twice (an
# impure call from a pure function, MLS 12.3; a call statement without a result). Only
# ``impureRandom`` reads that hidden memory, and the embedded path refuses every call of it (its
# routine is not in random_ext.ROUTINES: the hidden state would have to be carried across events),
# so nothing compiled here can observe the copy: the body below returns the same id without it.
_INITIALIZE_IMPURE = dict(
    name="Modelica.Math.Random.Utilities.initializeImpureRandom",
    header=b"function initializeImpureRandom",
    digest="4e6ba97ca6753e9867b8c5e2145bf0dd8e8361b155cef2650bef010478f00868",
    start=b"algorithm",
    body=b"""algorithm
      id := localSeed;
""",
    why="a call of the impure setInternalState, whose hidden state only the refused impureRandom reads",
    until=b"annotation (Documentation",
)

# Modelica.Math.Random.Generators.Xorshift128plus.initialState and Xorshift1024star.initialState
# (MSL 4.0.0, the same tokens): ``initialStateWithXorshift64star(localSeed, globalSeed, size(state,
# 1))`` reads the size of the output being defined, which rumoca 0.10.2 refuses in ToDae ("missing
# function value definition"); that size is the package's constant nState, written instead.
_GENERATOR_INITIAL_STATE = dict(
    name="Modelica.Math.Random.Generators.<generator>.initialState",
    header=b"function initialState",
    digest="a3c70338236f2e26a90af3b8ec40141d5a19606d604b4e0a4c8ba9fc4b39d8c3",
    start=b"algorithm",
    body=b"""algorithm
        state := Utilities.initialStateWithXorshift64star(
                localSeed, globalSeed, nState);
""",
    why="the size of the output being defined read in its own definition",
)

# (Keyword arguments of rewrite.LibraryBody, which rewrite.py builds.) The last:
# Modelica.Math.Random.Utilities.initialStateWithXorshift64star (MSL 4.0.0): rumoca 0.10.2 refuses
# its slices of the state vector ``state[i:i+1] := aux`` and ``random(state[i-2:i-1])`` whose
# bounds follow the loop variable ("dependent extent is not an exact Integer expression over
# proven shape axes"). The body below assigns and passes the same two elements one by one: the same
# states, in the same order.
LIBRARY_BODIES = (
    _INITIALIZE_IMPURE,
    _GENERATOR_INITIAL_STATE,  # Xorshift128plus's
    _GENERATOR_INITIAL_STATE,  # Xorshift1024star's (the first is replaced by then)
    dict(
        name="Modelica.Math.Random.Utilities.initialStateWithXorshift64star",
        header=b"function initialStateWithXorshift64star",
        digest="b5469558778ed59580e7318426211094f1dc05104dc045373a7b33d0a4ca16ef",
        start=b"protected",
        body=b"""protected
      Real r;
      Integer aux[2];
      Integer nStateEven;
    algorithm
      aux := Xorshift64star.initialState(localSeed, globalSeed);
      if nState >= 2 then
        state[1] := aux[1];
        state[2] := aux[2];
      else
        state[1] := aux[1];
      end if;
      nStateEven := 2*div(nState, 2);
      for i in 3:2:nStateEven loop
        (r, aux) := Xorshift64star.random({state[i - 2], state[i - 1]});
        state[i] := aux[1];
        state[i + 1] := aux[2];
      end for;
      if nState >= 3 and nState <> nStateEven then
        (r, aux) := Xorshift64star.random({state[nState - 2], state[nState - 1]});
        state[nState] := aux[1];
      end if;
""",
        why="slices of the state vector whose bounds follow a loop variable",
    ),
)
