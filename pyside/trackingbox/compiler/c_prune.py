"""Leave out of CasADi's generated C the adjoint derivative that nothing here calls.

CasADi 3.8.2's ``DaeBuilder.export_fmu`` always generates, beside the model function
``<ident>`` and its forward derivative ``fwd1_<ident>`` (``fmi3GetDirectionalDerivative``, used by
:mod:`trackingbox.sensitivity`), the adjoint ``adj1_<ident>`` (``fmi3GetAdjointDerivative``), and
offers no option to switch it off. Nothing in trackingbox or in the MSL harness calls it, and on a
model built of large traced functions it is a large part of the C (the Modelica.Fluid examples with
IF97 water: 11.5 of ``MeasuringTemperature``'s 31.4 MB), which gcc then compiles.

:func:`drop_adjoint` makes the exported ``adj1_<ident>`` return 1 (CasADi's failure flag: the FMU's
``fmi3GetAdjointDerivative`` then returns ``fmi3Error``; the model description says
``providesAdjointDerivatives="false"``) and removes every generated function ``casadi_f<N>`` that
no remaining code names. A function is kept whenever its name appears anywhere outside its own
definition in the code that stays (its ``#define`` to the prefixed symbol aside), so the model
function and the forward derivative keep all they call.
"""
from __future__ import annotations

import re

_HEADER = re.compile(
    r"^static int (casadi_f\d+)\(const casadi_real\*\* arg, casadi_real\*\* res, "
    r"casadi_int\* iw, casadi_real\* w, int mem\) \{\n", re.M)
_NAME = re.compile(r"\bcasadi_f(\d+)(?!\d)")
_PREFIX_DEFINE = re.compile(r"^#define casadi_f\d+ CASADI_PREFIX\(f\d+\)\n", re.M)  # names, not uses


def _adjoint_entry(ident: str) -> re.Pattern[str]:
    return re.compile(
        rf"^(CASADI_SYMBOL_EXPORT int adj1_{re.escape(ident)}\(const casadi_real\*\* arg, casadi_real\*\* res, "
        r"casadi_int\* iw, casadi_real\* w, int mem\)\{\n)  return casadi_f\d+\(arg, res, iw, w, mem\);\n\}\n",
        re.M)


def drop_adjoint(text: str, ident: str) -> tuple[str, bool]:
    """*text* (CasADi's C for the model *ident*) without its adjoint; (new text, whether it had one).

    >>> c = ('/* g:(i0)->(o0) */\\nstatic int casadi_f0(const casadi_real** arg, casadi_real** res, '
    ...      'casadi_int* iw, casadi_real* w, int mem) {\\n  return 0;\\n}\\n\\n'
    ...      'CASADI_SYMBOL_EXPORT int adj1_m(const casadi_real** arg, casadi_real** res, casadi_int* iw, '
    ...      'casadi_real* w, int mem){\\n  return casadi_f0(arg, res, iw, w, mem);\\n}\\n')
    >>> new, found = drop_adjoint(c, "m")
    >>> found, "casadi_f0" in new, "return 1;" in new
    (True, False, True)
    """
    entry = _adjoint_entry(ident)
    found = entry.search(text)
    if found is None:
        return text, False
    text = text[:found.start()] + found.group(1) + "  (void)arg; (void)res; (void)iw; (void)w; (void)mem;\n" \
        "  return 1; /* trackingbox: the adjoint derivative is not generated */\n}\n" + text[found.end():]
    spans: dict[str, tuple[int, int]] = {}
    calls: dict[str, set[str]] = {}
    outside: list[str] = []
    at = 0
    for m in _HEADER.finditer(text):
        name, start, end = m.group(1), m.start(), text.index("\n}\n", m.end()) + 3
        comment = text.rfind("\n", 0, start - 1) + 1  # the line before: CasADi's /* name:(...) */
        if text.startswith("/*", comment) and text.endswith("*/\n", comment, start):
            start = comment
        spans[name] = (start, end)
        calls[name] = {f"casadi_f{n}" for n in _NAME.findall(text, m.end(), end)} - {name}
        outside.append(text[at:start])
        at = end
    outside.append(text[at:])
    live: set[str] = set()
    todo = [f"casadi_f{n}" for part in outside for n in _NAME.findall(_PREFIX_DEFINE.sub("", part))]
    while todo:
        name = todo.pop()
        if name in live or name not in spans:
            continue
        live.add(name)
        todo.extend(calls[name])
    pieces: list[str] = []
    at = 0
    for name, (start, end) in sorted(spans.items(), key=lambda kv: kv[1][0]):
        if name not in live:
            pieces.append(text[at:start])
            at = end
    pieces.append(text[at:])
    return "".join(pieces), True
