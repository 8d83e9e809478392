"""What the twin's flat model says about a parameter the box is to drive: which component
parameters receive a top-level one by a modifier (:func:`receivers`) and why one cannot follow
an input (:func:`structural_reason`). Used where a spec names a parameter (:mod:`.source`) and
by the variants of library classes (:mod:`.variants`).
"""
from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

__all__ = ["references", "receivers", "structural_reason"]


def references(expr: Any) -> Iterator[str]:
    """The names of the variables a rumoca flat expression refers to."""
    if isinstance(expr, dict):
        ref = expr.get("VarRef")
        if isinstance(ref, dict):
            name = (ref.get("name") or {}).get("name")
            if isinstance(name, str):
                yield name
        for value in expr.values():
            yield from references(value)
    elif isinstance(expr, list):
        for value in expr:
            yield from references(value)


def _bound_to(v: Mapping[str, Any], name: str) -> bool:
    """True if the flat variable *v*'s binding is exactly a reference to *name*."""
    binding = v.get("binding")
    return isinstance(binding, dict) and set(binding) == {"VarRef"} and list(references(binding)) == [name]


def receivers(variables: Mapping[str, Mapping[str, Any]], name: str) -> list[str]:
    """Component parameters whose binding is the top-level parameter *name* itself (``R = R1``)."""
    return sorted(n for n, v in variables.items() if n != name and "[" not in n and _bound_to(v, name))


def structural_reason(variables: Mapping[str, Mapping[str, Any]], type_names: Mapping[str, str],
                      flat: Mapping[str, Any], name: str, *, allowed: frozenset[str] = frozenset()) -> str | None:
    """Why the parameter *name* cannot follow an input of the tracking box, or None if it can.

    *allowed*: variables whose binding may be *name* itself (the receivers of a top-level one).
    """
    v = variables.get(name, {})
    if v.get("evaluate"):
        return "it is declared with annotation(Evaluate = true): the tool uses its value when it translates the model"
    kind = type_names.get(name, "Real")
    if kind != "Real":
        return f"it is a {kind} parameter (sizes and switches are structural)"
    for other, w in variables.items():
        if other == name:
            continue
        for role, key in (("binding", "binding"), ("start value", "start"), ("fixed attribute", "fixed"),
                          ("min", "min"), ("max", "max"), ("nominal", "nominal")):
            expr = w.get(key)
            if expr is None or name not in set(references(expr)):
                continue
            if key == "binding" and other in allowed and _bound_to(w, name):
                continue
            what = "parameter" if isinstance(w.get("variability"), dict) and "Parameter" in w["variability"] \
                else "variable"
            return (f"it is used in the {role} of the {what} {other!r}, which the tool computes from it once "
                    f"(at initialisation): that value would not follow the box")
    if "." not in name:
        for section in ("equations", "initial_equations", "algorithms", "initial_algorithms"):
            if name in set(references(flat.get(section))):
                where = section.replace("_", " ")
                return (f"it is used in the twin's own {where}: only a parameter passed to components by "
                        f"modifiers (R = {name}) can be driven from a model that extends the twin")
    return None
