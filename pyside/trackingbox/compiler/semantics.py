"""Semantic checks the front end (rumoca) does not make: invalid Modelica it would accept.

Each check is small and sound: it rejects only what the Modelica specification
forbids, reading the text of the model's own class definition (comments and strings
blanked, nested classes checked in their own scope) or the flat model. A violation
raises :class:`~trackingbox.errors.CompileError` naming the rule (with its MLS
section), the file and the line. What is checked:

* the range of a ``for`` is a vector, not a scalar literal (``for i in 1 loop``; MLS 8.3.2);
* an ``Integer`` binding holds no ``^`` outside function arguments (exponentiation is Real; MLS 3.4);
* ``time`` is used only in models and blocks, not in records, connectors or functions (MLS 3.6.7);
* a component of a model or block class has no ``constant``/``parameter``/``discrete``/
  ``input``/``output`` prefix, and ``stream`` is not applied to a connector, model or block
  (MLS 4.4.2.2);
* a conditional component (``A a if cond;``) is used only in ``connect`` equations, never
  in other equations, bindings, modifications or calls (MLS 4.4.5);
* an array with an enumeration dimension (``x[E]``) is not indexed by an Integer literal
  (MLS 10.1);
* every constant has a declaration equation, and it is a constant expression: no
  parameters or variables of the model's top level in it (MLS 3.8.1; on the flat model;
  a field ``r.y`` may be made constant by a prefix on ``r``, which the flat model does not show).

One check is about valid Modelica instead: an if-equation guarded by ``initial()`` or
``terminal()`` without an else branch (``if terminal() then assert(...); end if;``) in the model's
own class is refused (:class:`UnsupportedConstructError`, as the README lists), because
rumoca 0.10.2 drops it (the ``assert`` in it included) from the flat model without a word; an
if-equation of asserts only guarded by ``initial()`` passes (:mod:`.if_asserts` has rumoca read
them outside it).
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import CompileError, UnsupportedConstructError
from .source import Location, ModelicaSource, _class_range, _code, _file_of, class_ranges

_HEAD = re.compile(
    r"\b(?:(?:partial|encapsulated|final|replaceable|redeclare|expandable|operator|pure|impure|inner|outer)\s+)*"
    r"(model|block|class|package|connector|record|function|type)\s+(?:extends\s+)?([A-Za-z_]\w*)")
_SHORT = re.compile(r"^\s*(?:(?:replaceable|redeclare|final|encapsulated|partial|expandable|operator)\s+)*"
                    r"(model|block|class|connector|record|type|package|function)\s+([A-Za-z_]\w*)\s*=\s*"
                    r"(enumeration\b)?")
_PREFIX = ("constant", "parameter", "discrete", "input", "output")
_DECL = re.compile(
    r"^\s*(?P<prefixes>(?:(?:final|inner|outer|replaceable|redeclare|each|flow|stream|constant|parameter|"
    r"discrete|input|output)\s+)*)(?P<type>[A-Za-z_][\w.]*)\s*(?:\[[^\]]*\]\s*)?(?P<name>[A-Za-z_]\w*)\b")
_KEYWORDS = {"equation", "algorithm", "initial", "public", "protected", "extends", "import", "annotation",
             "connect", "for", "if", "when", "while", "assert", "terminate", "reinit", "der", "end", "else",
             "elseif", "then", "loop", "return", "break", "external", "model", "block", "class", "connector",
             "record", "type", "package", "function", "operator", "expandable", "partial", "encapsulated"}
_ARRAY_DECL = re.compile(
    r"^\s*(?:(?:final|inner|outer|replaceable|redeclare|each|flow|stream|constant|parameter|discrete|input|output)"
    r"\s+)*[A-Za-z_][\w.]*\s*(?:\[(?P<tdims>[^\]]*)\])?\s*(?P<name>[A-Za-z_]\w*)\s*(?:\[(?P<dims>[^\]]*)\])?")


class InvalidModelError(CompileError):
    """The model breaks a rule of the Modelica language (it is not valid Modelica)."""


@dataclass(frozen=True)
class _Statement:
    text: str
    start: int  # offset in the file's code
    section: str  # "element" | "equation" | "algorithm"


@dataclass(frozen=True)
class _Scope:
    path: tuple[str, ...]
    kind: str  # model, block, record, connector, function, package, class, type
    statements: tuple[_Statement, ...]


def _blank(text: str) -> str:
    return re.sub(r"[^\n]", " ", text)


def _matching(text: str, k: int) -> int:
    """Index after the bracket closing the one opened at *k*."""
    depth = 0
    for j in range(k, len(text)):
        c = text[j]
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
            if depth == 0:
                return j + 1
    return len(text)


def _without_annotations(text: str) -> str:
    out = text
    for m in reversed(list(re.finditer(r"\bannotation\s*\(", text))):
        end = _matching(text, m.end() - 1)
        out = out[: m.start()] + _blank(out[m.start():end]) + out[end:]
    return out


def _split(text: str, base: int) -> list[_Statement]:
    """Statements (split at top-level ``;``) of a class body, with their section."""
    found: list[_Statement] = []
    depth, start, section = 0, 0, "element"
    for k, c in enumerate(text + ";"):
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == ";" and depth <= 0:
            piece = text[start:k]
            # leading section keywords belong to the statement they open
            while True:
                m = re.match(r"\s*(?:(initial\s+)?(equation|algorithm)|public|protected)\b", piece)
                if not m:
                    break
                if m.group(2):
                    section = m.group(2)
                piece = _blank(piece[: m.end()]) + piece[m.end():]
            if piece.strip():
                lead = len(piece) - len(piece.lstrip())  # a statement starts at its first word
                found.append(_Statement(piece[lead:], base + start + lead, section))
            start, depth = k + 1, 0
    return found


def _scopes(code: str, dotted: str) -> list[_Scope]:
    """The class *dotted* of *code* and every class nested in it, each with its own statements
    (nested class bodies blanked out of the enclosing one)."""
    rng = _class_range(code, dotted)
    if rng is None:
        return []
    ranges = [r for r in class_ranges(code) if rng[0] <= r[1] and r[2] <= rng[1]]
    scopes = []
    for path, lo, hi in ranges:
        head = _HEAD.match(code, lo)
        if head is None:
            continue
        body = code[head.end():hi]
        body = re.sub(r"\bend\s+[A-Za-z_]\w*\s*;\s*$", lambda m: _blank(m.group(0)), body)
        for _, ilo, ihi in ranges:  # children: blank them
            if lo < ilo and ihi <= hi:
                a, b = ilo - head.end(), ihi - head.end()
                if a >= 0:
                    body = body[:a] + _blank(body[a:b]) + body[b:]
        body = _without_annotations(body)
        scopes.append(_Scope(path, head.group(1), tuple(_split(body, head.end()))))
    return scopes


def _line(code: str, offset: int) -> int:
    return code.count("\n", 0, offset) + 1


def _top_level_eq(text: str) -> int:
    """Offset of the first ``=`` at bracket depth 0 that is a binding (not ``==``, ``<=``, ``>=``)."""
    depth = 0
    for k, c in enumerate(text):
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == "=" and depth == 0 and text[k - 1:k] not in ("<", ">", "=", ":") and text[k + 1:k + 2] != "=":
            return k
    return -1


def _condition_attribute(text: str) -> bool:
    """Whether a declaration ends with a condition attribute (``... if cond``, not an if-expression)."""
    depth = 0
    last_if = -1
    for m in re.finditer(r"[()\[\]{}]|\bif\b|\bthen\b", text):
        tok = m.group(0)
        if tok in "([{":
            depth += 1
        elif tok in ")]}":
            depth -= 1
        elif depth == 0 and tok == "if":
            last_if = m.end()
        elif depth == 0 and tok == "then":
            last_if = -1
    return last_if >= 0


class _Checker:
    def __init__(self, file: Path, model: str) -> None:
        self.file = file
        self.model = model
        self.code = _code(file)
        self.scopes = _scopes(self.code, model)
        self.kinds: dict[tuple[str, ...], str] = {s.path: s.kind for s in self.scopes}
        # short class definitions: type E = enumeration(...); model M2 = M; ...
        self.short: dict[tuple[str, ...], str] = {}
        for scope in self.scopes:
            for st in scope.statements:
                m = _SHORT.match(st.text)
                if m:
                    kind = "enumeration" if m.group(3) else m.group(1)
                    self.short[(*scope.path, m.group(2))] = kind

    def fail(self, rule: str, offset: int, detail: str) -> InvalidModelError:
        return InvalidModelError(
            f"invalid Modelica in {self.model}: {rule} at {self.file}:{_line(self.code, offset)}: {detail}")

    def kind_of(self, scope: tuple[str, ...], type_name: str) -> str | None:
        """The restriction of the class *type_name* as seen from *scope*: the innermost enclosing
        class (of the model's own definition) that declares it; None when it is declared elsewhere."""
        first = type_name.split(".")[0]
        if "." in type_name:
            return None
        for depth in range(len(scope), 0, -1):
            key = (*scope[:depth], first)
            if key in self.kinds:
                return self.kinds[key]
            if key in self.short:
                return self.short[key]
        return None

    def run(self) -> None:
        for scope in self.scopes:
            for st in scope.statements:
                self.event_operators(st)
                self.scalar_range(st)
                if st.section == "element":
                    decl = _DECL.match(st.text)
                    if decl and decl.group("type") not in _KEYWORDS and not _SHORT.match(st.text):
                        self.integer_power(st, decl)
                        self.prefixes(scope, st, decl)
            self.time_outside_models(scope)
            self.conditional_use(scope)
            self.enum_index(scope)

    # ---------------------------------------------------------------- checks
    def event_operators(self, st: _Statement) -> None:
        if st.section == "element":
            return
        m = re.search(r"\bif\s+(initial|terminal)\s*\(\s*\)\s*then\b", st.text)
        if m:  # rumoca keeps `if initial() then ... else ... end if` and initial() elsewhere
            rest = self.code[st.start + m.end():]
            end = re.search(r"\bend\s+if\s*;", rest)
            if end is not None and re.search(r"\belse(?:if)?\b", rest[:end.start()]):
                return
            if (end is not None and m.group(1) == "initial" and st.section == "equation"
                    and re.fullmatch(r"(?:\s*assert\s*\([^;]*\)\s*;)+\s*", rest[:end.start()])):
                return  # asserts only: read outside the if-equation with their guard (.if_asserts)
            raise UnsupportedConstructError(
                f"unsupported Modelica construct in {self.model}: built-in {m.group(1)}() at "
                f"{self.file}:{_line(self.code, st.start + m.start())}. The embedded backend cannot compile it "
                "(rumoca 0.10.2 drops an if-equation guarded by it without a word); use --backend openmodelica "
                "where omc is installed, or rewrite the model")

    def scalar_range(self, st: _Statement) -> None:
        if st.section == "element":
            return
        m = re.search(r"\bfor\s+\w+\s+in\s+([-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)\s+loop\b", st.text)
        if m:
            raise self.fail("the range of a for-loop must be a vector expression (MLS 8.3.2)",
                            st.start + m.start(), f"`for ... in {m.group(1)} loop` iterates over a scalar")

    def integer_power(self, st: _Statement, decl: re.Match[str]) -> None:
        if decl.group("type") != "Integer":
            return
        eq = _top_level_eq(st.text)
        if eq < 0:
            return
        expr = st.text[eq + 1:]
        while True:  # arguments of calls (integer(2^3) is an Integer) and subscripts do not count
            reduced = re.sub(r"\b[A-Za-z_][\w.]*\s*\([^()]*\)", "0", expr)
            reduced = re.sub(r"\[[^\[\]]*\]", "", reduced)
            if reduced == expr:
                break
            expr = reduced
        if "^" in expr:
            at = st.text.index("^", eq)
            raise self.fail("exponentiation `^` gives a Real result, which an Integer cannot be bound to (MLS 3.4)",
                            st.start + at, f"Integer {decl.group('name')} is bound to `{st.text[eq + 1:].strip()}`")

    def prefixes(self, scope: _Scope, st: _Statement, decl: re.Match[str]) -> None:
        words = decl.group("prefixes").split()
        kind = self.kind_of(scope.path, decl.group("type"))
        if kind is None:
            return
        bad = [w for w in words if w in _PREFIX]
        if bad and kind in ("model", "block"):
            raise self.fail(f"a component of {kind} class cannot have the prefix `{bad[0]}` (MLS 4.4.2.2)",
                            st.start + decl.start("prefixes") + decl.group("prefixes").index(bad[0]),
                            f"`{bad[0]} {decl.group('type')} {decl.group('name')}` where "
                            f"{decl.group('type')} is a {kind}")
        if "stream" in words and kind in ("model", "block", "connector"):
            raise self.fail("the prefix `stream` applies only to Real variables (MLS 4.4.2.2, 15.1)",
                            st.start + decl.start("prefixes") + decl.group("prefixes").index("stream"),
                            f"`stream {decl.group('type')} {decl.group('name')}` where "
                            f"{decl.group('type')} is a {kind}")

    def time_outside_models(self, scope: _Scope) -> None:
        if scope.kind not in ("record", "connector", "function"):
            return
        for st in scope.statements:  # a component called time would shadow the built-in
            decl = _DECL.match(st.text) if st.section == "element" else None
            if decl and decl.group("name") == "time":
                return
        for st in scope.statements:
            m = re.search(r"(?<![\w.])time\b", st.text)
            if m:
                raise self.fail(f"`time` is available only in models and blocks, not in a {scope.kind} (MLS 3.6.7)",
                                st.start + m.start(), f"{'.'.join(scope.path)} uses time")

    def conditional_use(self, scope: _Scope) -> None:
        conditional: dict[str, _Statement] = {}
        for st in scope.statements:
            if st.section != "element":
                continue
            decl = _DECL.match(st.text)
            if decl and decl.group("type") not in _KEYWORDS and _condition_attribute(st.text[decl.end():]):
                conditional[decl.group("name")] = st
        if not conditional:
            return
        names = "|".join(re.escape(n) for n in conditional)
        for st in scope.statements:
            if any(st is c for c in conditional.values()):
                continue
            text = st.text
            if st.section != "element":  # connect(...) is where a conditional component may appear
                for m in reversed(list(re.finditer(r"\bconnect\s*\(", text))):
                    end = _matching(text, m.end() - 1)
                    text = text[: m.start()] + _blank(text[m.start():end]) + text[end:]
            if st.section == "element" and re.match(r"\s*(?:extends|import)\b", text):
                continue
            iterators = set(re.findall(r"\bfor\s+([A-Za-z_]\w*)\s+in\b", text))
            iterators |= set(re.findall(r"[,(]\s*([A-Za-z_]\w*)\s+in\b", text))  # reductions: sum(x for x in v)
            for m in re.finditer(rf"(?<![\w.])({names})\b", text):
                if m.group(1) in iterators:
                    continue  # a loop or reduction iterator of the same name
                before = text[: m.start()].rstrip()
                after = text[m.end():]
                # a modifier or named argument `(name = ...)`: not a use of the component
                if (before.endswith(("(", ",")) or re.search(r"\b(?:each|final)$", before)) and \
                        re.match(r"(?:\.\w+)*\s*(?:=(?!=)|\()", after):
                    continue
                if st.section == "element":
                    decl = _DECL.match(text)
                    if decl and decl.start("name") == m.start():
                        continue  # a declaration of the same name (in another scope)
                raise self.fail("a conditional component may only be modified or used in connect equations "
                                "(MLS 4.4.5)", st.start + m.start(),
                                f"`{m.group(1)}` is declared with a condition at "
                                f"{self.file}:{_line(self.code, conditional[m.group(1)].start)}")

    def enum_index(self, scope: _Scope) -> None:
        enum_arrays: dict[str, list[bool]] = {}
        for st in scope.statements:
            if st.section != "element":
                continue
            m = _ARRAY_DECL.match(st.text)
            if not m or _SHORT.match(st.text) or (m.group("tdims") and m.group("dims")):
                continue
            name, dims = m.group("name"), m.group("dims") or m.group("tdims")
            if not dims:
                continue
            flags = [self.kind_of(scope.path, d.strip()) == "enumeration" for d in dims.split(",")]
            if any(flags):
                enum_arrays[name] = flags
        if not enum_arrays:
            return
        names = "|".join(re.escape(n) for n in enum_arrays)
        for st in scope.statements:
            for m in re.finditer(rf"(?<![\w.])({names})\s*\[([^\[\]]*)\]", st.text):
                decl = _DECL.match(st.text) if st.section == "element" else None
                if decl and decl.start("name") <= m.start() < decl.end("name") + 1:
                    continue
                subs = [s.strip() for s in m.group(2).split(",")]
                for flag, sub in zip(enum_arrays[m.group(1)], subs):
                    if flag and re.fullmatch(r"[-+]?\d+", sub):
                        raise self.fail("an array dimension declared by an enumeration type is indexed by "
                                        "its literals, not by Integers (MLS 10.1)", st.start + m.start(),
                                        f"`{m.group(0).strip()}`")


def check_source(source: ModelicaSource, model: str) -> None:
    """Reject *model* if the text of its own class definition breaks a rule listed in this
    module's docstring; :class:`InvalidModelError` names the rule, the file and the line."""
    file = _file_of(source, model)
    if file is None:
        return
    _Checker(file, model).run()


def _refs(node: Any) -> list[str]:
    """Names of the variables an expression node of the flat model refers to."""
    found: list[str] = []
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, dict):
            ref = n.get("VarRef")
            if isinstance(ref, dict):
                name = (ref.get("name") or {}).get("name")
                if isinstance(name, str):
                    found.append(name)
            stack.extend(n.values())
        elif isinstance(n, list):
            stack.extend(n)
    return found


def check_flat(flat: dict, model: str, where: Callable[[str | None, dict | None], list[Location]]) -> None:
    """Reject constants without a declaration equation, or bound to a non-constant expression
    (MLS 3.8.1). *where(pattern, span)* locates a declaration (see ``FlatTranslator.location``)."""
    variables = flat.get("variables") or {}

    def kind(v: dict) -> str:
        var = v.get("variability")
        return next(iter(var)) if isinstance(var, dict) and var else str(var)

    for name, v in variables.items():
        if not isinstance(v, dict) or kind(v) != "Constant":
            continue
        leaf = name.rsplit(".", 1)[-1]
        binding = v.get("binding")
        if binding is None:
            locs = where(rf"(?:[\w.]+\s+)+{re.escape(leaf)}\b", v.get("source_span"))
            at = f" at {locs[0]}" if locs else ""
            raise InvalidModelError(f"invalid Modelica in {model}: a constant needs a declaration equation "
                                    f"(MLS 3.8.1){at}: constant {name} has no value")
        for ref in _refs(binding):
            base = re.sub(r"\[[^\]]*\]", "", ref)
            if "." in base:
                # a field of a component: a `constant` on the enclosing component makes it constant
                # (MLS 4.4.4.1), which the flat model does not show (r.y of `constant R r` stays a parameter)
                continue
            other = variables.get(base)
            if isinstance(other, dict) and kind(other) != "Constant":
                locs = where(rf"(?:[\w.]+\s+)+{re.escape(leaf)}\b", v.get("source_span"))
                at = f" at {locs[0]}" if locs else ""
                raise InvalidModelError(
                    f"invalid Modelica in {model}: the declaration equation of a constant must be a constant "
                    f"expression (MLS 3.8.1){at}: constant {name} depends on {kind(other).lower()} {base}")
