"""Source rewrites that steer the rumoca front end around its known bugs.

rumoca 0.10.2 silently drops the right-hand side of an equation whose left-hand
side is a bare ``der(...)`` inside a for-equation, for some iterations: in

.. code-block:: modelica

    for i in 1:3 loop
      der(x[i]) = a[i] - x[i];
    end for;

the flat model holds ``der(x[3]) = 0.0`` (from the third iteration on in a loop
over one index, from the fourth in ``for i in 1:3, j in 1:2``). Nothing warns.
The same equation with its left-hand side in parentheses, ``(der(x[i])) = ...``,
is flattened correctly, so the embedded backend hands rumoca a copy of the
source in which every such equation inside a for-equation is written that way
(:func:`protect_der_equations`). :func:`.flat_text.check_lost_der_equations`
refuses the model should an equation still come back with the bug's signature.

The copy keeps every byte offset where it can, and every line always: the
opening parenthesis takes the place of a blank before ``der`` and the closing one
the place of a blank after the call; where there is no blank the parenthesis is
inserted and a blank of a later run of blanks on the following text is removed to
compensate. So rumoca's positions (line, column, byte spans) in the copy are
those of the user's file, and messages about the copy can name the original.
"""
from __future__ import annotations

import bisect
import functools
import hashlib
import logging
import re
from dataclasses import dataclass
from pathlib import Path

from .external_locals import external_locals_as_inputs
from .if_asserts import call_equations, if_asserts_outside
from .constant_not import constant_not_as_if
from .der_fields import component_array_der
from .redeclare_short import short_class_redeclarations
from .while_source import while_loops_as_for
from .source import BOM
from .source_scan import _FUNCTION, _blank_comments, _code_mask, _matching_paren, _statement_end
from .random_source import LIBRARY_BODIES as _RANDOM_BODIES, noise_draw_as_algorithm
from .filter_bodies import LIBRARY_BODIES as _FILTER_BODIES
from .streams_error import streams_error_as_assert

log = logging.getLogger(__name__)

_TOKEN = re.compile(rb"[A-Za-z_][A-Za-z_0-9]*|\d+(?:\.\d*)?(?:[eE][-+]?\d+)?|\S")
_DER_CALL = re.compile(rb"\bder\s*\(")
_EQUALS = re.compile(rb"\s*=(?!=)")  # '=' of an equation, not '=='
_BLANK_RUN = re.compile(rb"[ \t]{2,}")
_STATEMENT_START = {b";", b"loop", b"then", b"else", b"equation"}
_SECTION_END = {b"algorithm", b"public", b"protected", b"external"}
_BLOCK_END = {b"for", b"if", b"when", b"while"}


@dataclass(frozen=True)
class Rewrite:
    """What :func:`protect_der_equations` did to one text.

    Attributes
    ----------
    data:
        The rewritten text (bytes, same encoding as given).
    lines:
        The 1-based lines of the equations put in parentheses.
    offsets_kept:
        Whether every byte after each edit stands at its original offset
        (always true of lines; false only where no blank could compensate).
    """

    data: bytes
    lines: tuple[int, ...]
    offsets_kept: bool


def _der_equations(code: bytes) -> list[tuple[int, int]]:
    """(start of ``der``, offset of its closing parenthesis) of every equation inside a
    for-equation of an equation section whose left-hand side is a bare ``der(...)``."""
    found: list[tuple[int, int]] = []
    tokens = [(m.group(0), m.start()) for m in _TOKEN.finditer(code)]
    in_equations = False
    loops = 0
    prev = b";"
    k = 0
    while k < len(tokens):
        tok, start = tokens[k]
        nxt = tokens[k + 1][0] if k + 1 < len(tokens) else b""
        if tok == b"equation":
            in_equations, loops = True, 0
        elif tok in _SECTION_END:
            in_equations, loops = False, 0
        elif tok == b"end":
            if nxt in _BLOCK_END:
                if nxt == b"for" and loops:
                    loops -= 1
                prev, k = nxt, k + 2
                continue
            in_equations, loops = False, 0  # end of a class
        elif in_equations and prev in _STATEMENT_START:
            if tok == b"for":
                loops += 1
            elif tok == b"der" and loops and nxt == b"(":
                close = _matching_paren(code, tokens[k + 1][1])
                if close is not None:
                    after = _EQUALS.match(code, close + 1)
                    if after is not None:
                        found.append((start, close))
        prev = tok
        k += 1
    return found


def protect_der_equations(data: bytes) -> Rewrite:
    """Write every ``der(...) = ...`` equation inside a for-equation as ``(der(...)) = ...``.

    Only equations in equation sections, whose left-hand side is exactly one call of
    ``der`` followed by ``=`` (not ``==`` or ``:=``), are changed; comments, strings
    and quoted identifiers are never touched. Line numbers never change, and byte
    offsets only where no blank was at hand to compensate (see the module docstring).

    Parameters
    ----------
    data:
        The text of a ``.mo`` file (without byte-order mark).

    Returns
    -------
    Rewrite
        The new text and the lines changed.

    Examples
    --------
    >>> src = b"equation\\n  for i in 1:3 loop\\n    der(x[i]) = -x[i];\\n  end for;\\n"
    >>> protect_der_equations(src).data.decode().splitlines()[2]
    '   (der(x[i]))= -x[i];'
    """
    if b"loop" not in data or not _DER_CALL.search(data):  # the common case, cheaply
        return Rewrite(data, (), True)
    code, nc_starts, nc_ends = _code_mask(data)
    sites = _der_equations(code)
    if not sites:
        return Rewrite(data, (), True)

    def in_code(pos: int) -> bool:
        k = bisect.bisect_right(nc_starts, pos) - 1
        return k < 0 or pos >= nc_ends[k]

    replace: dict[int, bytes] = {}  # offset -> byte put in place of a blank
    insert: dict[int, bytes] = {}  # offset -> bytes inserted before it
    drop: set[int] = set()  # blanks removed to compensate an insertion
    kept = True

    def compensate(after: int) -> bool:
        """Remove one blank of a later run of at least two blanks (in code)."""
        pos = after
        while True:
            hit = _BLANK_RUN.search(data, pos)
            if hit is None:
                return False
            for q in range(hit.start(), hit.end() - 1):  # always leave one blank of the run
                if q not in drop and q not in replace and in_code(q):
                    drop.add(q)
                    return True
            pos = hit.end()

    def place(offset: int, blank_at: int, char: bytes) -> None:
        nonlocal kept
        if 0 <= blank_at < len(data) and data[blank_at : blank_at + 1] in (b" ", b"\t") \
                and blank_at not in replace and blank_at not in drop and in_code(blank_at):
            replace[blank_at] = char
            return
        insert[offset] = insert.get(offset, b"") + char
        if not compensate(offset):
            kept = False

    for start, close in sites:
        place(start, start - 1, b"(")
        place(close + 1, close + 1, b")")
    out = bytearray()
    for pos in range(len(data) + 1):
        if pos in insert:
            out += insert[pos]
        if pos == len(data):
            break
        if pos in drop:
            continue
        out += replace.get(pos, data[pos : pos + 1])
    lines = tuple(sorted({data.count(b"\n", 0, start) + 1 for start, _ in sites}))
    return Rewrite(bytes(out), lines, kept)


@dataclass(frozen=True)
class LibraryBody:
    """A library function whose algorithm rumoca 0.10.2 cannot take, and a body it can that computes
    the same (:func:`replace_library_bodies`).

    Attributes
    ----------
    name:
        The function's full name (for messages).
    header:
        The code that opens the function's declaration (``function name``): every place it stands in
        a file's code (comments and strings left out) is tried.
    digest:
        SHA-256 of the code tokens (comments and blanks left out) from *header* up to the function's
        first ``annotation``: only that exact text is replaced.
    start:
        The keyword from which the text is replaced (up to the ``annotation``).
    body:
        What rumoca reads instead, from *start* on.
    why:
        What rumoca does with the original.
    until:
        The code before which the replaced text ends (and the digest's): the function's first
        ``annotation`` unless given (a function without an annotation names its own ``end``).
    """

    name: str
    header: bytes
    digest: str
    start: bytes
    body: bytes
    why: str
    until: bytes = b"annotation"


LIBRARY_BODIES = (
    # Modelica.Math.Vectors.interpolate (MSL 4.0.0): the search for the interval runs in while
    # loops, which rumoca refuses when xi varies ("a statement without a checked DAE owner"), and
    # iNew is assigned on one branch only ("missing function value definition" in ToDae). For the
    # abscissae the function requires (non-decreasing), the MSL's search ends at the largest k in
    # 1..nx-1 with x[k] <= xi, or at 1 where there is none, whatever iLast is: forward from iLast it
    # stops before the first x[k] > xi, backward at the first x[k] <= xi. The loop below takes that
    # same k and the MSL's interpolation (and extrapolation) on it, with the MSL's assert on the
    # segment; abscissae that decrease somewhere (outside the function's contract, where the MSL's
    # result would depend on iLast) stop the run with the MSL's message instead of giving a value.
    LibraryBody(
        name="Modelica.Math.Vectors.interpolate",
        header=b"function interpolate",
        digest="46e06a8d4630ecf8c93c8de7acf7a4b91d1a73fd7886cd6ddd644e3e5099fcb9",
        start=b"protected",
        body=b"""protected
    Integer nx = size(x, 1);
  algorithm
    assert(nx > 0, "The table vectors must have at least 1 entry.");
    yi := y[1];
    iNew := 1;
    for k in 1:nx - 1 loop
      assert(x[k + 1] >= x[k], "Abscissa table vector values must be increasing");
      if k == 1 or xi >= x[k] then
        assert(x[k + 1] > x[k], "Abscissa table vector values must be increasing");
        yi := y[k] + (y[k + 1] - y[k])*(xi - x[k])/(x[k + 1] - x[k]);
        iNew := k;
      end if;
    end for;
""",
        why="while loops and an output assigned on one branch",
    ),
    # Modelica.Math.Matrices.isEqual (MSL 4.0.0): two nested while loops that stop at the first
    # pair of elements farther apart than eps, which rumoca refuses. The result does not depend on
    # where the search stops: true where the sizes agree and no pair is farther apart than eps, so
    # two for loops over every pair give it (the loops' bounds take the smaller size so that the
    # indices stay inside M2 where the sizes differ and the result is already false).
    LibraryBody(
        name="Modelica.Math.Matrices.isEqual",
        header=b"function isEqual",
        digest="0dff0c4aa972219ab581435487b0748b0d07da4ee299ebe0528be09153e66aee",
        start=b"protected",
        body=b"""protected
    Integer nrow = size(M1, 1);
    Integer ncol = size(M1, 2);
  algorithm
    result := size(M2, 1) == nrow and size(M2, 2) == ncol;
    for i in 1:min(nrow, size(M2, 1)) loop
      for j in 1:min(ncol, size(M2, 2)) loop
        if abs(M1[i, j] - M2[i, j]) > eps then
          result := false;
        end if;
      end for;
    end for;
""",
        why="while loops",
    ),
    # Modelica.Math.BooleanVectors.firstTrueIndex (MSL 4.0.0): a for loop that returns at the first
    # true element, which rumoca refuses ("a non-guarded nested return requires a checked
    # control-flow owner"; MathInteger.MultiSwitch, MathBoolean.MultiSwitch and Math.MultiSwitch call
    # it). Setting the index only while it is still 0 gives the same first index, 0 if none is true.
    LibraryBody(
        name="Modelica.Math.BooleanVectors.firstTrueIndex",
        header=b"function firstTrueIndex",
        digest="8e1398c57cca82bdb07a17248eee4c29713ffd456d40d37cdb97b65336dbc952",
        start=b"algorithm",
        body=b"""algorithm
   index := 0;
   for i in 1:size(b, 1) loop
      if b[i] and index == 0 then
         index := i;
      end if;
   end for;
""",
        why="a return inside a for loop",
    ),
    # Modelica.Math.Polynomials.fitting (MSL 4.0.0): the Vandermonde matrix is built column by
    # column from its last one, which rumoca refuses ("reads elements of `V` that do not all have
    # a definition"). Declaring V filled with ones gives the same last column, and the loop then
    # fills the others from it with the same products.
    LibraryBody(
        name="Modelica.Math.Polynomials.fitting",
        header=b"function fitting",
        digest="e164c70ab823a3cf3549c4808142bca51ae45a93408b967d80fbb4770d08dc22",
        start=b"protected",
        body=b"""protected
        Real V[size(u, 1), n + 1] = fill(1.0, size(u, 1), n + 1);
      algorithm
        for j in n:-1:1 loop
          V[:, j] := {u[i] * V[i, j + 1] for i in 1:size(u,1)};
        end for;
        p :=Modelica.Math.Matrices.leastSquares(V, y);
""",
        why="a matrix built column by column without a binding",
    ),
    # Modelica.Blocks.Sources.TimeTable.getInterpolationCoefficients (MSL 4.0.0): a while loop moves
    # the grid index `next` up from `last` while the row's time has been reached, which the embedded
    # backend cannot translate (its condition varies with time). The loop's condition depends only
    # on `next`, so once false it stays false, and it is true at most nrow - last < nrow times: a for
    # loop over nrow passes that moves `next` up where the condition holds ends on the same index.
    LibraryBody(
        name="Modelica.Blocks.Sources.TimeTable.getInterpolationCoefficients",
        header=b"function getInterpolationCoefficients",
        digest="58da4f4104e2ae794c4dfc9e4731e245fe22ae33fb95c13682d145e89a91f431",
        start=b"algorithm",
        until=b"end getInterpolationCoefficients",
        body=b"""algorithm
      next := last;
      nextEventScaled := timeScaled - TimeEps*abs(timeScaled);
      tp := timeScaled + TimeEps*abs(timeScaled);
      if tp < startTimeScaled then
        nextEventScaled := startTimeScaled;
        a := 0;
        b := offset;
      elseif nrow < 2 then
        a := 0;
        b := offset + table[1, columns];
      else
        tp := tp - shiftTimeScaled;
        for k in 1:nrow loop
          if next < nrow and tp >= table[next, 1] then next := next + 1; end if;
        end for;
        if next < nrow then
          nextEventScaled := shiftTimeScaled + table[next, 1];
        end if;
        if next == 1 then
          next := 2;
        end if;
        next0 := next - 1;
        dt := table[next, 1] - table[next0, 1];
        if dt <= TimeEps*abs(table[next, 1]) then
          a := 0;
          b := offset + table[next, columns];
        else
          a := (table[next, columns] - table[next0, columns])/dt;
          b := offset + table[next0, columns] - a*table[next0, 1];
        end if;
      end if;
      b := b - a*shiftTimeScaled;
""",
        why="a while loop on a condition that varies with time",
    ),
    *(LibraryBody(**body) for body in _RANDOM_BODIES),  # (random_source)
    *(LibraryBody(**body) for body in _FILTER_BODIES),  # (filter_bodies)
)


def _code_digest(code: bytes) -> str:
    """SHA-256 of the tokens of comment-free *code*, one blank between them."""
    return hashlib.sha256(b" ".join(m.group(0) for m in _TOKEN.finditer(code))).hexdigest()


def replace_library_bodies(data: bytes) -> tuple[bytes, list[tuple[str, int]]]:
    """*data* with the algorithm of each :data:`LIBRARY_BODIES` function found in it, exactly as the
    library writes it, replaced by the body rumoca can take; and (function, line) of each replaced.

    The replacement takes the same lines and bytes (padded with blanks and empty lines), so every
    position after it, and every line, stays where it is in the user's file. A function whose text
    differs in any token (another library version, an edit) is left alone.
    """
    done: list[tuple[str, int]] = []
    for lib in LIBRARY_BODIES:
        if lib.header not in data:  # the common case, cheaply
            continue
        code, _, _ = _code_mask(data)
        for hit in re.finditer(rb"\b" + re.escape(lib.header) + rb"\b", code):
            at = hit.start()
            end = code.find(lib.until, at)
            start = code.find(lib.start, at, end) if end >= 0 else -1
            if start >= 0 and _code_digest(code[at:end]) == lib.digest:
                break
        else:
            continue
        old = data[start:end]
        lines = old.count(b"\n")
        new = lib.body + b"\n" * max(0, lines - lib.body.count(b"\n"))
        if new.count(b"\n") != lines or len(new) > len(old):
            raise AssertionError(f"the body replacing {lib.name} is longer than the library's")
        new += b" " * (len(old) - len(new))  # the indentation of the annotation's line
        data = data[:start] + new + data[end:]
        done.append((lib.name, data.count(b"\n", 0, start) + 1))
    return data, done


@functools.lru_cache(maxsize=4096)
def _frontend_bytes_cached(file: Path, mtime_ns: int, size: int, tuple_names: frozenset[bytes] = frozenset(),
                           asserting: frozenset[bytes] = frozenset()) -> bytes | None:
    data = file.read_bytes()
    bom = data.startswith(BOM)
    body = data[3:] if bom else data
    changed = bom
    body, replaced = replace_library_bodies(body)
    for name, line in replaced:
        log.debug("%s:%d: %s read by rumoca with an equivalent body (%s)", file, line, name,
                  next(lib.why for lib in LIBRARY_BODIES if lib.name == name))
        changed = True
    for rewrite, what in ((external_locals_as_inputs, "protected locals of external Fortran functions read as inputs"),
                          (streams_error_as_assert, "Modelica.Utilities.Streams.error read as an assert"),
                          (noise_draw_as_algorithm, "PartialNoise's draw read as a when-statement (random_source)"),
                          (if_asserts_outside, "asserts in if-equations read outside them with their guard"),
                          (short_class_redeclarations, "class redeclarations with a literal modification read "
                                                       "through a short class"),
                          (while_loops_as_for, "while statements read as bounded for loops (.while_source)"),
                          (component_array_der, "der of a field of an array of components read element by "
                                                "element (.der_fields)"),
                          (constant_not_as_if, "not in Boolean constants read as if-expressions (.constant_not)")):
        body, lines = rewrite(body)
        if lines:
            log.debug("%s: %s at lines %s", file, what, ", ".join(map(str, lines)))
            changed = True
    for line, name in call_equations(body):  # (.if_asserts) after Streams.error is read as an assert
        log.warning("%s:%d: call equation %s(...) is dropped by rumoca 0.10.2 with any assert in the function: "
                    "not checked in the FMU", file, line, name)
    firsts, lines = first_output_functions(body, tuple_names)
    if firsts != body:
        if lines:
            log.debug("%s: functions with several outputs read with their first one (a __tuple copy "
                      "for the calls taking all) at lines %s", file, ", ".join(map(str, lines)))
        body, changed = firsts, True
    computed, lines = computed_parameter_bindings(body, asserting)
    if lines:
        log.debug("%s: parameters bound to a call of a function that asserts computed at initialisation "
                  "(fixed = false) at lines %s", file, ", ".join(map(str, lines)))
        body, changed = computed, True
    relaxed, lines = relax_input_extents(body)
    if lines:
        log.debug("%s: function inputs sized by a package constant read as [:] at lines %s", file,
                  ", ".join(map(str, lines)))
        body, changed = relaxed, True
    rewrite = protect_der_equations(body)
    if rewrite.lines:
        log.debug("%s: der(...) equations in for-loops put in parentheses for rumoca at lines %s%s",
                  file, ", ".join(map(str, rewrite.lines)),
                  "" if rewrite.offsets_kept else " (byte offsets after them shifted)")
        return rewrite.data
    return body if changed else None


def frontend_bytes(file: Path, tuple_names: frozenset[bytes] = frozenset(),
                   asserting: frozenset[bytes] = frozenset()) -> bytes | None:
    """What rumoca should read for *file* if not the file itself: its text without a
    byte-order mark, with :func:`replace_library_bodies`, :func:`first_output_functions` (calls
    taking several outputs renamed for the functions in *tuple_names*, see
    :func:`tuple_function_names`), :func:`computed_parameter_bindings` for the functions in
    *asserting* (none unless a first try failed, see :func:`asserting_function_names`) and
    :func:`relax_input_extents` and :func:`protect_der_equations` applied; None if none changes
    it."""
    try:
        st = file.stat()
        return _frontend_bytes_cached(file, st.st_mtime_ns, st.st_size, tuple_names, asserting)
    except OSError:
        return None


# --- functions with several outputs -------------------------------------------------------------
#
# rumoca 0.10.2 evaluates a call of a function with several outputs as the array of all its
# outputs where it evaluates a binding (a parameter's): ``parameter Real p = f(a)`` with ``f``
# returning ``(y, k)`` makes ``p`` an array, and ``if p > 2 ...`` fails with "type mismatch:
# expected comparable, got Array". In Modelica such a call in an expression is its first output
# (MLS 12.4.3). So every function that declares several outputs itself is read with its first
# output only, the others moved to its protected section (computed as before, not returned), and a
# copy under the name ``<name>__tuple`` keeps every output for the calls that take them all,
# ``(a, b) := f(...)`` / ``(a, b) = f(...)``, which are renamed to call it. The copy stands on the
# line of the function's ``end``, so every line of the file stays where it is.

TUPLE_SUFFIX = b"__tuple"
_SKIP_BEFORE = {b"partial", b"replaceable", b"redeclare"}


@dataclass(frozen=True)
class _Function:
    name: bytes
    start: int  # of 'function'
    end: int  # after the ';' of 'end name;'
    outputs: tuple[tuple[int, int], ...]  # spans of the output declarations, 'output' to ';'
    single: bool  # whether it is read with its first output only


def _previous_word(code: bytes, at: int) -> bytes:
    """The identifier just before *at* in comment-free *code* (blanks and blanked comments between)."""
    end = len(code[:at].rstrip())
    m = re.search(rb"[A-Za-z_]\w*$", code[max(0, end - 200):end])
    return m.group(0) if m else b""


def _functions(code: bytes) -> list[_Function]:
    """The function definitions of comment-free *code* that declare two or more outputs themselves."""
    found: list[_Function] = []
    for m in _FUNCTION.finditer(code):
        name = m.group(1)
        if name == b"extends" or _previous_word(code, m.start()) in _SKIP_BEFORE | {b"end"}:
            continue
        after = re.match(rb"\s*=", code[m.end():m.end() + 200])
        if after:  # a short class definition
            continue
        end = re.compile(rb"\bend\s+" + re.escape(name) + rb"\s*;").search(code, m.end())
        if end is None:
            continue
        body = code[m.end():end.start()]
        if _FUNCTION.search(body):  # nested functions: not this rewrite's business
            continue
        outputs = []
        for o in re.finditer(rb"\boutput\b", body):
            stop = _statement_end(code, m.end() + o.start(), end.start())
            if stop is None:
                break
            outputs.append((m.end() + o.start(), stop))
        else:
            if len(outputs) < 2:
                continue
            words = set(re.findall(rb"[A-Za-z_]\w*", body))
            extends = re.findall(rb"\bextends\s+([\w.]+)", body)
            single = (not words & {b"external", b"public", b"derivative", b"inverse"}
                      and all(e.split(b".")[-1] == b"Function" for e in extends)
                      and re.search(rb"\b(algorithm|protected)\b", body) is not None)
            found.append(_Function(name, m.start(), end.end(), tuple(outputs), single))
    return found


def tuple_function_names(files) -> frozenset[bytes]:
    """The simple names of the functions defined in *files* that declare several outputs, less the
    names some other function definition in them also has or some class extends (such a function
    keeps all its outputs and a call taking them is left alone)."""
    several: set[bytes] = set()
    others: set[bytes] = set()
    for f in files:
        try:
            st = Path(f).stat()
        except OSError:
            continue
        multi, other = _function_names(Path(f), st.st_mtime_ns, st.st_size)
        several |= multi
        others |= other
    return frozenset(several - others)


@functools.lru_cache(maxsize=8192)
def _function_names(file: Path, mtime_ns: int, size: int) -> tuple[frozenset[bytes], frozenset[bytes]]:
    """(names of the functions with several outputs, names of the other functions) defined in *file*."""
    try:
        data = file.read_bytes()
    except OSError:
        return frozenset(), frozenset()
    if b"function" not in data:
        return frozenset(), frozenset()
    code, _, _ = _code_mask(data)
    multi = frozenset(fn.name for fn in _functions(code))
    # a function that holds functions of its own gets no copy (see _functions): its name must not
    # be renamed in calls, whichever other definition of that name has one (Modelica.Fluid.Pipes:
    # two Internal.m_flow_of_dp_fric, one with nested functions)
    nested = frozenset(_nesting_function_names(code))
    # a function some class extends (its outputs are inherited) stays as it is; so does one that is
    # partial, replaceable or redeclared (a call may reach another definition than the copy's)
    # and so does a function named as another's derivative or inverse (its outputs must match)
    extended = frozenset(m.group(1).split(b".")[-1] for m in re.finditer(
        rb"\b(?:extends|derivative(?:\s*\([^()]*\))?\s*=|inverse\s*\(\s*\w+\s*=)\s*([A-Za-z_][\w.]*)", code))
    return multi - extended - nested, (frozenset(m.group(1) for m in _FUNCTION.finditer(code)) - multi) | extended | nested


def _nesting_function_names(code: bytes) -> list[bytes]:
    """The names of the function definitions of comment-free *code* that hold function definitions."""
    out = []
    for m in _FUNCTION.finditer(code):
        name = m.group(1)
        if name == b"extends" or _previous_word(code, m.start()) == b"end":
            continue
        end = re.compile(rb"\bend\s+" + re.escape(name) + rb"\s*;").search(code, m.end())
        if end is not None and _FUNCTION.search(code[m.end():end.start()]):
            out.append(name)
    return out


def _one_line(text: bytes) -> bytes:
    return re.sub(rb"\s*\n\s*", b" ", text)


def first_output_functions(data: bytes, tuple_names: frozenset[bytes] = frozenset()) -> tuple[bytes, list[int]]:
    """*data* with a ``<name>__tuple`` copy beside each function that declares several outputs, each
    such function whose name is in *tuple_names* read with its first output only (the others
    protected), and each call taking several outputs of a function in *tuple_names* renamed to the
    copy; and the lines of the functions changed. Lines are kept (byte offsets after an edit shift).

    *tuple_names* (:func:`tuple_function_names`) must hold the names for every file rumoca reads,
    so that no call taking all outputs reaches a function read with its first one."""
    if tuple_names:
        data = _rename_tuple_calls(data, tuple_names)
    if b"output" not in data:
        return data, []
    code, starts, ends = _code_mask(data)
    clean = _blank_comments(data, starts, ends)
    edits: list[tuple[int, int, bytes]] = []  # (start, end, replacement)
    changed: list[int] = []
    for fn in _functions(code):
        copy = _one_line(clean[fn.start:fn.end])
        copy = re.sub(rb"^function\s+" + re.escape(fn.name), b"function " + fn.name + TUPLE_SUFFIX, copy)
        if _previous_word(code, fn.start) in (b"pure", b"impure"):  # the copy is as pure as the function
            copy = _previous_word(code, fn.start) + b" " + copy
        copy = re.sub(rb"\bend\s+" + re.escape(fn.name) + rb"\s*;$", b"end " + fn.name + TUPLE_SUFFIX + b";", copy)
        edits.append((fn.end, fn.end, b" " + copy))
        if not fn.single or fn.name not in tuple_names:  # its calls taking all outputs might not be renamed
            continue
        moved = []
        for s, e in fn.outputs[1:]:
            decl = _one_line(clean[s:e])
            moved.append(re.sub(rb"^output\s+", b"", decl))
            edits.append((s, e, re.sub(rb"[^\n]", b"", data[s:e])))
        prot = re.compile(rb"\bprotected\b").search(code, fn.outputs[-1][1], fn.end)
        alg = re.compile(rb"\balgorithm\b").search(code, fn.outputs[-1][1], fn.end)
        if prot is not None:
            edits.append((prot.end(), prot.end(), b" " + b" ".join(moved)))
        else:
            edits.append((alg.start(), alg.start(), b"protected " + b" ".join(moved) + b" "))
        changed.append(data.count(b"\n", 0, fn.start) + 1)
    if not edits:
        return data, []
    out = bytearray()
    pos = 0
    for s, e, new in sorted(edits, key=lambda x: (x[0], x[1])):
        out += data[pos:s] + new
        pos = max(pos, e)
    out += data[pos:]
    return bytes(out), changed


def _rename_tuple_calls(data: bytes, tuple_names: frozenset[bytes]) -> bytes:
    """*data* with each ``(a, b, ...) := f(`` or ``(a, b, ...) = f(`` statement or equation whose
    function's simple name is in *tuple_names* calling ``f__tuple`` instead."""
    code, _, _ = _code_mask(data)
    inserts: list[int] = []
    for m in re.finditer(rb"\)\s*(?::=|=)\s*([A-Za-z_][\w.]*)\s*\(", code):
        if m.group(1).split(b".")[-1] not in tuple_names:
            continue
        depth, k = 0, m.start()
        while k >= 0:  # the '(' opening the left-hand side
            depth += {41: 1, 40: -1}.get(code[k], 0)
            if depth == 0:
                break
            k -= 1
        if k < 0 or b"," not in code[k + 1:m.start()]:
            continue
        before = code[:k].rstrip()
        if before and not before.endswith(b";") and _previous_word(code, k) not in _TUPLE_AFTER:
            continue
        inserts.append(m.end(1))
    out = bytearray()
    pos = 0
    for at in inserts:
        out += data[pos:at] + TUPLE_SUFFIX
        pos = at
    return bytes(out + data[pos:])


_TUPLE_AFTER = {b"then", b"else", b"loop", b"algorithm", b"equation"}


# --- parameters bound to a call of a function that asserts -------------------------------------
#
# rumoca 0.10.2 evaluates a parameter's binding when it builds the DAE, and an ``assert`` that the
# evaluation of a called function reaches is counted as one more equation: ``parameter Real p =
# g(...)`` with ``g`` asserting makes the model unbalanced ("unbalanced model: 2 equations, 1
# unknowns"). The MSL's ``Vectors.interpolate`` asserts in its loop over the table's segments, so a
# ``LossyGear`` whose ``lossTable`` has two rows or more (``Rotational.Examples.HeatLosses``) fails.
# Only when a model fails so, the front end is run again on a copy in which each Real parameter
# bound to a call of such a function is declared ``fixed = false`` and its binding becomes an
# initial equation (the same value, computed at initialisation, its asserts checked there).

_ASSERTING_SKIP_TYPES = {b"Integer", b"Boolean", b"String"}
_PARAMETER_DECL = re.compile(rb"\bparameter\s+([A-Za-z_][\w.]*)\s+([A-Za-z_]\w*)\s*")
_CLASS_HEADER = re.compile(rb"\b(?:model|block|class|record|connector|package|function)\s+[A-Za-z_]\w*")


def asserting_function_names(files) -> frozenset[bytes]:
    """The simple names of the functions defined in *files* whose text (as rumoca reads it) asserts."""
    names: set[bytes] = set()
    for f in files:
        try:
            st = Path(f).stat()
        except OSError:
            continue
        names |= _asserting_functions(Path(f), st.st_mtime_ns, st.st_size)
    return frozenset(names)


@functools.lru_cache(maxsize=8192)
def _asserting_functions(file: Path, mtime_ns: int, size: int) -> frozenset[bytes]:
    try:
        data = file.read_bytes()
    except OSError:
        return frozenset()
    if b"function" not in data or b"assert" not in data:
        return frozenset()
    data, _ = replace_library_bodies(data[3:] if data.startswith(BOM) else data)
    code, _, _ = _code_mask(data)
    out = set()
    for m in _FUNCTION.finditer(code):
        name = m.group(1)
        if name == b"extends" or _previous_word(code, m.start()) == b"end":
            continue
        end = re.compile(rb"\bend\s+" + re.escape(name) + rb"\s*;").search(code, m.end())
        if end is not None and re.search(rb"\bassert\s*\(", code[m.end():end.start()]):
            out.add(name)
    return frozenset(out)


def computed_parameter_bindings(data: bytes, names: frozenset[bytes]) -> tuple[bytes, list[int]]:
    """*data* with each scalar Real parameter bound to a call of a function in *names* declared
    ``fixed = false``, its binding an initial equation (see above); and the lines changed. Lines
    are kept (the binding's text keeps its line breaks), byte offsets after an edit shift."""
    if not names or b"parameter" not in data:
        return data, []
    code, _, _ = _code_mask(data)
    edits: list[tuple[int, int, bytes]] = []
    lines: list[int] = []
    for m in _PARAMETER_DECL.finditer(code):
        ctype, name = m.group(1), m.group(2)
        if ctype.split(b".")[-1] in _ASSERTING_SKIP_TYPES or _previous_word(code, m.start()) in {b"constant", b"final"}:
            continue
        k = m.end()
        mods: tuple[int, int] | None = None
        if code[k:k + 1] == b"(":
            close = _matching_paren(code, k)
            if close is None:
                continue
            mods = (k, close)
            k = close + 1
        eq = re.match(rb"\s*=(?!=)", code[k:])
        if eq is None:  # no binding, or an array (name[...]) or a modifier only
            continue
        start = k + eq.end()
        stop = _statement_end(code, start, len(code))
        if stop is None:
            continue
        # the binding ends before a description string or an annotation (strings are blanked in code)
        text_end = start + _binding_end(code, data, start, stop - 1)
        binding = code[start:text_end]
        calls = {c.split(b".")[-1] for c in re.findall(rb"(?<![\w.])([A-Za-z_][\w.]*)\s*\(", binding)}
        if not calls & names:
            continue
        if re.search(rb"\b(?:fixed)\s*=", code[mods[0]:mods[1]] if mods else b""):
            continue
        header = data[m.start():mods[0] + 1] + b"fixed = false, " + data[mods[0] + 1:mods[1] + 1] if mods else \
            data[m.start():m.end()].rstrip() + b"(fixed = false)"
        before = code[:m.start()]
        heads = list(_CLASS_HEADER.finditer(before))
        scope = before[heads[-1].end():] if heads else before
        sections = re.findall(rb"\b(public|protected)\b", scope)
        visibility = sections[-1] if sections else b"public"
        new = (header + data[text_end:stop - 1] + b"; initial equation " + name + b" = "
               + data[start:text_end].strip() + b"; " + visibility)
        edits.append((m.start(), stop, new))  # the declaration's ';' too: the new text ends in a keyword
        lines.append(data.count(b"\n", 0, m.start()) + 1)
    if not edits:
        return data, []
    out = bytearray(data)
    for s, e, new in reversed(edits):
        out[s:e] = new
    return bytes(out), lines


def _binding_end(code: bytes, data: bytes, start: int, stop: int) -> int:
    """The length of a binding in *code*[start:stop]: up to a description string or an annotation
    at depth 0 (strings are blanked in *code*, so they are found in *data*)."""
    depth = 0
    for k in range(start, stop):
        c = code[k]
        if c in b"([{":
            depth += 1
        elif c in b")]}":
            depth -= 1
        elif depth == 0 and (data[k:k + 1] == b'"' or re.match(rb"annotation\b", code[k:k + 11])):
            return len(code[start:k].rstrip())
    return len(code[start:stop].rstrip())


# --- function inputs sized by a package constant ------------------------------------------------
#
# rumoca 0.10.2 proves the extents of a function's arrays from the function's own inputs and
# locals; an input sized by a constant of the enclosing package, ``input MassFraction X[nX]`` in
# ``Modelica.Media.Interfaces.PartialSimpleMedium.density_phX``, stops it with "function shape
# proof: dependent extent is not an exact Integer expression over proven shape axes" wherever the
# function is merely reachable (every Modelica.Fluid source and vessel with such a medium). An
# input's declared size only constrains what a caller may pass (MLS 12.4.1: the argument's size
# must match); the function computes the same with ``X[:]``, so such inputs are read as ``X[:]``.
# The edit keeps every byte: ``[nX]`` becomes ``[: ]`` (the blanks inside the brackets).

_INPUT_DECL = re.compile(rb"\binput\s+[A-Za-z_][\w.]*\s+[A-Za-z_]\w*\s*\[([^\]]*)\]")
_DECLARED = rb"(?:\b(?:input|output|parameter|constant|Integer|Real|Boolean)\b[^;]*?)\b%s\b\s*(?:[=;(,\"\[]|$)"


def relax_input_extents(data: bytes) -> tuple[bytes, list[int]]:
    """*data* with each array dimension of a function input that is a bare name the function does
    not declare itself (a constant of an enclosing package) read as ``:``; and the lines changed."""
    if b"input" not in data or b"function" not in data:
        return data, []
    code, _, _ = _code_mask(data)
    out = bytearray(data)
    lines: list[int] = []
    for m in _FUNCTION.finditer(code):
        name = m.group(1)
        if name == b"extends" or _previous_word(code, m.start()) == b"end":
            continue
        if re.match(rb"\s*=", code[m.end():m.end() + 200]):  # a short class definition
            continue
        end = re.compile(rb"\bend\s+" + re.escape(name) + rb"\s*;").search(code, m.end())
        if end is None:
            continue
        body = code[m.end():end.start()]
        if _FUNCTION.search(body):  # nested functions: their declarations are not this one's
            continue
        unsized = re.sub(rb"\[[^\]]*\]", b"", body)  # names declared, not those in sizes
        for decl in _INPUT_DECL.finditer(body):
            dims = decl.group(1)
            first = m.end() + decl.start(1)
            offset = 0
            for dim in dims.split(b","):
                ident = dim.strip()
                if re.fullmatch(rb"[A-Za-z_]\w*", ident) and ident != b"end" and not re.search(
                        _DECLARED % re.escape(ident), unsized, re.M):
                    at = first + offset + dim.index(ident)
                    out[at:at + len(ident)] = b":" + b" " * (len(ident) - 1)
                    lines.append(data.count(b"\n", 0, at) + 1)
                offset += len(dim) + 1
    return bytes(out), sorted(set(lines))
