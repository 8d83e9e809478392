"""Members of expandable connectors that no connection makes present (MLS 9.1.3).

A variable declared in an ``expandable connector`` is only *potentially present*: it becomes a
variable of the model when a connection reaches it, and one that nothing connects is not part of
the flat model (the MSL's ``BusUsage``: its ``ControlBus`` declares ``realSignal2``, which the
example never connects). rumoca 0.10.2 keeps such members as unknowns without an equation, so a
valid bus model was refused as structurally singular. rumoca marks each variable
``from_expandable_connector`` and ``connected``; a member that is neither connected, nor bound,
nor read by any equation, algorithm or assert is removed here before the translation. One that
an equation reads stays, so such a model is still judged by its equations (MLS 9.1.3 makes an
unconnected member unusable there, and the structural check refuses it).
"""
from __future__ import annotations

from typing import Any, Iterator

_READERS = ("equations", "structured_equations", "assert_equations", "initial_equations",
            "initial_structured_equations", "initial_assert_equations", "algorithms",
            "initial_algorithms", "when_chains")


def _names(node: Any) -> Iterator[str]:
    """Every variable name a flat-model subtree refers to (``VarRef`` and component references)."""
    stack = [node]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            ref = item.get("VarRef")
            if isinstance(ref, dict):
                name = ref.get("name")
                if isinstance(name, dict):
                    name = name.get("name")
                if isinstance(name, str):
                    yield name
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)


def _read_names(flat: dict[str, Any]) -> set[str]:
    read: set[str] = set()
    for key in _READERS:
        read.update(_names(flat.get(key)))
    for v in (flat.get("variables") or {}).values():  # bindings, starts and attributes of others
        for attr in ("binding", "start", "min", "max", "nominal", "dims"):
            read.update(_names(v.get(attr)))
    return read


def absent_members(flat: dict[str, Any]) -> list[str]:
    """The potentially present members of expandable connectors that nothing connects or reads."""
    variables = flat.get("variables") or {}
    candidates = [name for name, v in variables.items()
                  if v.get("from_expandable_connector") is True and v.get("connected") is False
                  and v.get("binding") is None]
    if not candidates:
        return []
    read = _read_names(flat)

    def is_read(name: str) -> bool:  # a whole array, or one of its elements (`bus.u[2]`)
        return name in read or any(r.startswith(name + "[") for r in read)

    return [name for name in candidates if not is_read(name)]


def drop_absent_members(flat: dict[str, Any]) -> list[str]:
    """Remove :func:`absent_members` from *flat* (in place); returns their names."""
    gone = absent_members(flat)
    for name in gone:
        for key in ("variables", "variable_type_names", "variable_final_flags"):
            table = flat.get(key)
            if isinstance(table, dict):
                table.pop(name, None)
    return gone
