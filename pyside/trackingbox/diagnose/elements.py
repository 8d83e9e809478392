"""What the other elements of a component array use when a patch puts an effect on one element.

The hook is a Boolean parameter of the component's class; on an array it takes one modifier for every
element, so the elements the finding is not on get what they use without it (split from :mod:`.library`).
"""

from __future__ import annotations

import re
from typing import Any

from ..errors import SpecError
from ..generate.filters import modelica_string

__all__ = ["element_fill", "hook_default", "hooked_inputs"]


def hook_default(index: Any, cls: str, hook: str, element: str) -> str | None:
    """What element *element* of class *cls* uses without its *hook* (``if not hook then x_internal = EXPR``):
    a number as written, or the element's own parameter (``effect[2].dBPR``); None when neither."""
    pat = re.compile(rf"\bif\s+not\s+{re.escape(hook)}\s+then\s+\w+\s*=\s*([^;]+?)\s*;")
    for base in index.bases(cls):
        found = index.body(base)
        m = pat.search(found[1]) if found is not None else None
        if m is not None:
            expr = m.group(1)
            if re.fullmatch(r"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?", expr):
                return expr
            if re.fullmatch(r"[A-Za-z_]\w*", expr):
                return f"{element}.{expr}"
            return None
    return None


def hooked_inputs(index: Any, cls: str, hook: str) -> list[str]:
    """The connectors of class *cls* (and its bases) declared conditional on the Boolean *hook*."""
    pat = re.compile(rf"\b([A-Za-z_]\w*)\s*(?:\([^;]*?\))?\s*if\s+{re.escape(hook)}\b")
    out: list[str] = []
    for base in index.bases(cls):
        found = index.body(base)
        if found is not None:
            out += [m.group(1) for m in pat.finditer(found[1]) if m.group(1) not in out]
    return out


def element_fill(n: int, index: Any, cls: str, hook: str, array_name: str, dims: str, i: int,
                 prefix: str, where: str) -> tuple[list[str], list[str]]:
    """Protected declarations and equations of a finding on element *i* of the component array *array_name*
    (*n* elements): the hook is on every element (an array takes one modifier), so the other elements' hooked inputs get
    what they use without it (0 for an added flow, their own parameter for a replaced one)."""
    off = f"{prefix}_off"
    default = hook_default(index, cls, hook, f"{array_name}[k]")
    if default is None:
        raise SpecError(f"{where}: cannot tell what the other elements of {array_name!r} use without the hook "
                        f"{hook!r} (no 'if not {hook} then ... = <number or parameter>' in {cls})")
    declarations = [f"  TrackingBox.Interfaces.RealOutput {off}[{dims}] "
                    f"{modelica_string(f'What the elements of {array_name} but {i} use without {hook}')};"]
    equations = [f"  for k in 1:{dims} loop\n    {off}[k] = {default};\n  end for;"]
    for connector in hooked_inputs(index, cls, hook):
        for lo, hi in ((1, i - 1), (i + 1, n)):
            if lo <= hi:
                equations.append(f"  for k in {lo}:{hi} loop\n    connect({off}[k], {array_name}[k].{connector});\n"
                                 f"  end for;")
    return declarations, equations
