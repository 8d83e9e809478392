"""Flat-model nodes as text for messages (an expression as Modelica, an equation's origin, a
literal), and the check that the front end did not lose the right-hand side of a ``der``
equation (:func:`check_lost_der_equations`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import CompileError
from .library import model_files
from .source import Location, ModelicaSource, span_sources
from .flat_model import kind_of


def literal_text(val: Any) -> str:
    if isinstance(val, dict) and len(val) == 1:
        kind, v = next(iter(val.items()))
        return f"the {kind} {v!r}"
    return repr(val)


def origin_text(origin: Any) -> str:
    kind, body = kind_of(origin)
    if kind == "ComponentEquation":
        comp = body.get("component") or "(top level)"
        return f"of component {comp}"
    if kind == "Connection":
        return f"connect({body.get('lhs')}, {body.get('rhs')})"
    return str(kind)


def span_hint(body: Any) -> str | None:
    """A word the source text at an expression's span must contain (to pick the right file)."""
    if not isinstance(body, dict):
        return None
    if "function" in body:
        return str(body["function"])
    name = body.get("name")
    if isinstance(name, dict) and isinstance(name.get("name"), str):
        return name["name"].rsplit(".", 1)[-1]
    return None


_OP_TEXT = {
    "add": "+", "sub": "-", "mul": "*", "div": "/", "exp": "^", "addelem": ".+", "subelem": ".-",
    "mulelem": ".*", "divelem": "./", "expelem": ".^", "lt": "<", "le": "<=", "gt": ">", "ge": ">=",
    "eq": "==", "neq": "<>", "ne": "<>", "and": "and", "or": "or",
}


def expression_text(node: Any, depth: int = 0) -> str:
    """Modelica-like text of a flat-model expression, for error messages."""
    if depth > 12:
        return "..."
    kind, body = kind_of(node)
    sub = lambda n: expression_text(n, depth + 1)  # noqa: E731
    try:
        if kind == "Literal":
            _k, val = kind_of(body["value"])
            if isinstance(val, bool):
                return "true" if val else "false"
            return repr(val) if isinstance(val, str) else f"{val}"
        if kind == "VarRef":
            subs = body.get("subscripts") or []
            return body["name"]["name"] + (("[" + ", ".join(_sub_text(s, depth) for s in subs) + "]") if subs else "")
        if kind == "Binary":
            op = _OP_TEXT.get(str(body["op"]).lower(), str(body["op"]))
            return f"({sub(body['lhs'])} {op} {sub(body['rhs'])})"
        if kind == "Unary":
            op = "-" if "minus" in str(body.get("op")).lower() else ("not " if str(body.get("op")).lower() == "not" else "")
            return f"{op}{sub(body.get('rhs', body.get('arg', body.get('expr'))))}"
        if kind == "BuiltinCall":
            return f"{str(body['function'])[:1].lower()}{str(body['function'])[1:]}(" + ", ".join(
                sub(a) for a in body.get("args") or []) + ")"
        if kind == "FunctionCall":
            return f"{body['name']['name']}(" + ", ".join(sub(a) for a in body.get("args") or []) + ")"
        if kind == "Array":
            els = body.get("elements", []) if isinstance(body, dict) else body
            k = body.get("kind", "Array") if isinstance(body, dict) else "Array"
            if k == "Horizontal":
                return "[" + ", ".join(sub(e) for e in els) + "]"
            if k == "Vertical":
                return "[" + "; ".join(sub(e).strip("[]") for e in els) + "]"
            return "{" + ", ".join(sub(e) for e in els) + "}"
        if kind == "Range":
            step = f"{sub(body['step'])}:" if body.get("step") is not None else ""
            return f"{sub(body['start'])}:{step}{sub(body['end'])}"
        if kind == "ArrayComprehension":
            its = ", ".join(f"{ix['name']} in {sub(ix['range'])}" for ix in body.get("indices") or [])
            return "{" + f"{sub(body['expr'])} for {its}" + "}"
        if kind == "Index":
            return sub(body["base"]) + "[" + ", ".join(_sub_text(s, depth) for s in body.get("subscripts") or []) + "]"
        if kind == "Tuple":
            return "(" + ", ".join("" if kind_of(e)[0] == "Empty" else sub(e) for e in body.get("elements") or []) + ")"
        if kind == "If":
            return "if ... then ... else ..."
        if kind == "Parenthesized":
            return sub(body.get("inner", body))
    except (KeyError, TypeError, AttributeError):
        pass
    return f"<{kind}>"


def _sub_text(s: Any, depth: int) -> str:
    kind, body = kind_of(s)
    if kind == "Index":
        return str(body["value"])
    if kind == "Colon":
        return ":"
    if kind == "Expr":
        return expression_text(body["expr"], depth + 1)
    return "?"


def _ref_text(node: Any) -> str:
    """``x[3,1]`` for a flat variable reference with constant subscripts (best effort)."""
    kind, body = kind_of(node)
    if kind != "VarRef" or not isinstance(body, dict):
        return "?"
    subs = []
    for sub in body.get("subscripts") or []:
        skind, sbody = kind_of(sub)
        subs.append(str(sbody.get("value")) if skind == "Index" and isinstance(sbody, dict) else ":")
    return str(body["name"]["name"]) + (f"[{','.join(subs)}]" if subs else "")


def check_lost_der_equations(flat: dict[str, Any], source: ModelicaSource, model: str,
                             libraries: tuple[Path, ...] = ()) -> None:
    """Refuse a flat model in which the front end lost the right-hand side of a ``der`` equation.

    rumoca 0.10.2 flattens ``der(x[i]) = a[i] - x[i]`` in a for-loop into
    ``der(x[3]) - 0.0`` for some iterations (the embedded backend writes such
    equations so that rumoca gets them right, :mod:`.rewrite`; this is the safety
    net). The signature: a residual ``der(v) - literal`` whose literal carries the
    equation's own span, and the source text at that span is not that literal (it
    is the loop's iterator). A literal the user wrote, ``der(x[i]) = 0``, spans its
    own text and passes.

    Raises
    ------
    CompileError
        Naming the model, each equation lost (variable) and the line of its loop.
    """
    suspects = []
    for eq in flat.get("equations") or []:
        kind, body = kind_of(eq.get("residual"))
        if kind != "Binary" or not isinstance(body, dict) or body.get("op") != "Sub":
            continue
        lkind, lhs = kind_of(body.get("lhs"))
        while lkind == "Parenthesized" and isinstance(lhs, dict):
            lkind, lhs = kind_of(lhs.get("inner"))
        rkind, rhs = kind_of(body.get("rhs"))
        if lkind != "BuiltinCall" or str(lhs.get("function", "")).lower() != "der" or rkind != "Literal":
            continue
        span = eq.get("span")
        if isinstance(span, dict) and isinstance(span.get("start"), int) and rhs.get("span") == span:
            suspects.append((_ref_text((lhs.get("args") or [None])[0]), rhs, span))
    if not suspects:
        return
    from .source import BOM

    files = model_files(source, model, libraries=libraries)
    known = span_sources(flat, files)
    lost = []
    for var, lit, span in suspects:
        candidates = [known[span["source"]]] if span.get("source") in known else list(files)
        text, loc = None, None
        for file in candidates:
            try:
                data = file.read_bytes()
            except OSError:
                continue
            data = data[3:] if data.startswith(BOM) else data
            if span.get("end", span["start"]) <= len(data):
                text = data[span["start"]:span.get("end", span["start"])].decode("utf-8", "replace").strip()
                loc = Location(file, data.count(b"\n", 0, span["start"]) + 1)
                break
        value = kind_of(lit.get("value"))[1]
        try:
            genuine = text is not None and float(text) == float(value)
        except (TypeError, ValueError):
            genuine = False
        if not genuine:
            lost.append(f"der({var}) = ... came back as der({var}) = {value}"
                        + (f" (for-loop at {loc})" if loc else ""))
    if lost:
        shown = "; ".join(lost[:8]) + (f"; and {len(lost) - 8} more" if len(lost) > 8 else "")
        raise CompileError(
            f"the Modelica front end (rumoca) lost the right-hand side of {len(lost)} equation(s) of "
            f"{model}: {shown}. This is a rumoca bug with der(...) = ... in for-loops; write the left-hand "
            "side in parentheses, (der(x[i])) = ..., or use --backend openmodelica")
