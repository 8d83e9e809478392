"""An ``inner`` component's modifications made its class's defaults, for the front end.

rumoca 0.10.2 evaluates a parameter reached through an ``outer`` component, where it evaluates
structurally (the condition of an if-equation, an array size), from the *outer* declaration's class,
ignoring the modifications of the matching ``inner`` component. Every Modelica.Fluid component reads
``system.energyDynamics`` so: with ``inner Modelica.Fluid.System system(energyDynamics =
Modelica.Fluid.Types.Dynamics.FixedInitial)`` a vessel's ``if energyDynamics == FixedInitial then
medium.T = T_start`` took the branch of System's default (``DynamicFreeInitial``: no initial
equation) and the tank examples started from temperature 0 K. Nothing warns; the flat model's
binding of ``system.energyDynamics`` itself is right.

The front end is therefore given a copy of the inner's class in which the parameters the model's
``inner`` declaration modifies have the modified values as their defaults (:func:`patches`). For
the inner component this changes nothing (its modifications win either way); for the outer
references it gives the value Modelica prescribes. It is done only where it cannot change another
component: each value is a literal (a number, ``true``/``false``, a string, or a name rooted at a
top-level library package, e.g. an enumeration literal), the parameter is declared once in the
class's own text, and no file the model reaches declares another component of that class (other
than ``inner``/``outer``) or extends it. Lines are kept; byte offsets after an edit in that one
file move by the difference in length.

A modification whose value is a name (``system(massDynamics = systemMassDynamics)`` in
``Modelica.Fluid.Examples.IncompressibleFluidNetwork``, where the model's own parameter is bound to
``if Medium.singleState then Dynamics.SteadyState else ...``) cannot be copied into the class. The front
end evaluates that parameter's binding right, though: :func:`pending` names such modifications,
:func:`flat_values` reads their values from a first flat model (following the binding chain to a
literal), and the tree is built again with them (:func:`patches`' *values*). Before, every pipe of that
example took ``der(ms) = mb_flows`` instead of its steady mass balance ``0 = mb_flows`` (System's default
``massDynamics = energyDynamics``), and its warm-up ran 1-2 % slow.
"""
from __future__ import annotations

import logging
import re
from collections.abc import Callable, Iterable
from pathlib import Path

from .rewrite import _binding_end, _code_mask, _matching_paren

log = logging.getLogger(__name__)

_INNER = re.compile(rb"\binner\s+(?:outer\s+)?([A-Za-z_][\w.]*)\s+([A-Za-z_]\w*)\s*\(")
_LITERAL = re.compile(r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?|true|false|\"[^\"]*\"|[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+")
_MOD = re.compile(r"\s*(?:final\s+)?([A-Za-z_]\w*)\s*=\s*(.*?)\s*$", re.S)


def _split_top(text: str) -> list[str]:
    """*text* split at the commas outside parentheses, brackets and braces."""
    out, depth, start = [], 0, 0
    for k, c in enumerate(text):
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == "," and depth == 0:
            out.append(text[start:k])
            start = k + 1
    out.append(text[start:])
    return out


def _literal_mods(mods: str, roots: set[str]) -> dict[str, str]:
    """The ``name = literal`` modifications of *mods* (others, e.g. ``p(displayUnit = ...)`` or a
    value naming the model's own parameters, are left out)."""
    out: dict[str, str] = {}
    for part in _split_top(mods):
        m = _MOD.fullmatch(part)
        if not m:
            continue
        value = " ".join(m.group(2).split())
        if not _LITERAL.fullmatch(value):
            continue
        if re.fullmatch(r"[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+", value) and value.split(".")[0] not in roots:
            continue  # a name the class's scope might resolve otherwise
        out[m.group(1)] = value
    return out


def _named_mods(mods: str, roots: set[str]) -> dict[str, str]:
    """The ``name = other.name`` modifications of *mods* that :func:`_literal_mods` leaves out (a value
    naming the model's own parameter or a constant the class's scope might resolve otherwise)."""
    literal = _literal_mods(mods, roots)
    out: dict[str, str] = {}
    for part in _split_top(mods):
        m = _MOD.fullmatch(part)
        if m and m.group(1) not in literal and re.fullmatch(r"[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*", m.group(2).strip()):
            out[m.group(1)] = m.group(2).strip()
    return out


def _resolve(index, model: str, name: str) -> str | None:
    scope = model.split(".")
    for k in range(len(scope), -1, -1):
        full = ".".join(scope[:k] + [name])
        if full in index.classes:
            return full
    return None


def _other_uses(files: Iterable[Path], short: str) -> Path | None:
    """A file among *files* that declares a component of a class named *short* other than as
    inner/outer, or extends it."""
    decl = re.compile(rb"(?<![\w.])(?:[\w.]*\.)?" + re.escape(short.encode()) + rb"\s+[A-Za-z_]\w*\s*[(;\[]")
    ext = re.compile(rb"\bextends\s+(?:[\w.]*\.)?" + re.escape(short.encode()) + rb"\b(?!\s*\.)")
    for f in files:
        try:
            data = f.read_bytes()
        except OSError:
            continue
        if short.encode() not in data:
            continue
        code = _code_mask(data)[0]
        if ext.search(code) or any(_word_before(code, m.start()) not in (b"inner", b"outer")
                                   for m in decl.finditer(code)):
            return f
    return None


def _word_before(code: bytes, at: int) -> bytes:
    m = re.search(rb"(\w+)\s+$", code[max(0, at - 40):at])
    return m.group(1) if m else b""


def _declaration(code: bytes, data: bytes, start: int, stop: int, param: str) -> tuple[int, int] | None:
    """The byte range of the binding of *param*'s declaration in *code*[start:stop], if declared there
    once with a binding."""
    pat = re.compile(rb"\bparameter\s+[A-Za-z_][\w.]*(?:\s*\[[^\]]*\])?\s+" + re.escape(param.encode()) + rb"\b\s*")
    found = [m for m in pat.finditer(code, start, stop)]
    if len(found) != 1:
        return None
    k = found[0].end()
    if code[k:k + 1] == b"(":
        close = _matching_paren(code, k)
        if close is None:
            return None
        k = close + 1
        while code[k:k + 1].isspace():
            k += 1
    if code[k:k + 1] != b"=":
        return None
    k += 1
    end = code.find(b";", k, stop)
    if end < 0:
        return None
    while code[k:k + 1].isspace():
        k += 1
    return k, k + _binding_end(code, data, k, end)


def _inners(index, model: str, needed: set[Path]):
    """(component, class, literal modifications, named modifications) of each ``inner`` component of
    *model*'s own text whose class may be patched (no other use among *needed*)."""
    info = index.classes.get(model)
    if info is None:
        return
    data = info.file.read_bytes()
    text = data.decode("utf-8", errors="replace")
    lo, hi = len(text[:info.start].encode()), len(text[:info.end].encode())
    code = _code_mask(data)[0]
    roots = {r.name.removesuffix(".mo") for r in index.roots}
    for m in _INNER.finditer(code, lo, hi):
        close = _matching_paren(code, m.end() - 1)
        if close is None:
            continue
        mods = data[m.end():close].decode("utf-8", errors="replace")
        cls = _resolve(index, model, m.group(1).decode())
        if cls is None:
            continue
        other = _other_uses(needed, cls.rsplit(".", 1)[-1])
        if other is not None:
            log.debug("inner %s of %s: its class %s is used elsewhere (%s); defaults kept", m.group(2).decode(),
                      model, cls, other)
            continue
        yield m.group(2).decode(), cls, _literal_mods(mods, roots), _named_mods(mods, roots)


def pending(index, model: str, needed: set[Path]) -> set[str]:
    """Flat names (``system.massDynamics``) of the inner modifications whose values are names: their
    values come from a first flat model (:func:`flat_values`)."""
    return {f"{comp}.{param}" for comp, _, _, named in _inners(index, model, needed) for param in named}


def flat_values(flat: dict, names: set[str], roots: set[str]) -> dict[str, str]:
    """The values of *names* in the front end's *flat* model, as literals a class default may hold:
    the binding chain (``system.massDynamics`` -> ``systemMassDynamics`` -> ...) followed to a number,
    ``true``/``false`` or a name rooted at a package of *roots* (an enumeration literal); names whose chain
    ends elsewhere (an expression, a variable without binding) are left out."""
    variables = flat.get("variables", {})
    out: dict[str, str] = {}
    for name in sorted(names):
        at, seen = name, set()
        while at in variables and at not in seen:
            seen.add(at)
            binding = variables[at].get("binding")
            ref = binding.get("VarRef") if isinstance(binding, dict) else None
            lit = binding.get("Literal") if isinstance(binding, dict) else None
            if ref is not None and not ref.get("subscripts"):
                at = ref["name"]["name"]
                continue
            if lit is not None and len(lit.get("value", {})) == 1:
                kind, value = next(iter(lit["value"].items()))
                if kind == "Boolean":
                    out[name] = "true" if value else "false"
                elif kind in ("Integer", "Real") and not isinstance(value, bool):
                    out[name] = repr(value)
            break
        else:
            if at not in variables and at != name and at.split(".")[0] in roots:
                out[name] = at
    return out


def patches(index, model: str, needed: set[Path], values: dict[str, str] | None = None
            ) -> dict[Path, Callable[[bytes], bytes]]:
    """For the files of *needed* that hold the class of an ``inner`` component of *model*'s own text:
    the edit making that component's literal modifications the class's defaults (see the module).
    *values*: literals for its named modifications (``{"system.massDynamics": "Modelica...SteadyState"}``,
    :func:`flat_values`)."""
    edits: dict[Path, list[tuple[str, str, str]]] = {}
    for comp, cls, mods, named in _inners(index, model, needed):
        mods = {**mods, **{p: values[f"{comp}.{p}"] for p in named if f"{comp}.{p}" in (values or {})}}
        if mods:
            edits.setdefault(index.classes[cls].file, []).extend((cls, k, v) for k, v in mods.items())

    def patch_for(items: list[tuple[str, str, str]]) -> Callable[[bytes], bytes]:
        def patch(body: bytes) -> bytes:
            code = _code_mask(body)[0]
            cuts = []
            for cls, param, value in items:
                ci, short = index.classes[cls], re.escape(cls.rsplit(".", 1)[-1].encode())
                kind = re.escape(ci.kind.split()[-1].encode())
                heads = list(re.finditer(rb"\b" + kind + rb"\s+" + short + rb"\b", code))
                ends = list(re.finditer(rb"\bend\s+" + short + rb"\s*;", code))
                if len(heads) != 1 or len(ends) != 1:
                    continue  # the class is not found once in the text the front end reads: left as it is
                where = _declaration(code, body, heads[0].end(), ends[0].start(), param)
                if where is None:
                    continue
                old = body[where[0]:where[1]]
                cuts.append((where[0], where[1], value.encode() + b"\n" * old.count(b"\n")))
                log.debug("%s: default of %s.%s read by the front end as the inner's %s", ci.file, cls, param, value)
            out = bytearray(body)
            for s, e, new in sorted(cuts, reverse=True):
                out[s:e] = new
            return bytes(out)
        return patch

    return {f: patch_for(items) for f, items in edits.items()}
