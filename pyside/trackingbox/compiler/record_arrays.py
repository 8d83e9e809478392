"""Arrays of records and of components used whole, sliced or through a field (issue 35).

Modelica.Fluid's pipes declare ``Medium.ThermodynamicState[nFM+1] statesFM`` and set it by
``statesFM[2:n+1] = mediums[1:n].state``; their velocities read ``mediums[i].d`` in a
comprehension. The flat model has no variable ``statesFM`` or ``mediums``: only the fields of
each element are variables (``pipe.statesFM[2].p``, ``pipe.mediums[1].state.p``). Here such a
reference keeps its Modelica meaning (MLS 10.6.3: an operation on arrays of records is one per
element, and a field access ``a[1:n].f`` of an array of components is the array of the elements'
fields):

* :func:`element_index` finds, once per model, every array of records or components by the
  subscripted prefixes of the variables' names (``pipe.statesFM`` with elements ``(1,)``,
  ``(2,)``, ...);
* :meth:`RecordArrays.component_paths` turns a reference to such an array (``VarRef``, then any
  ``Index`` and ``FieldAccess`` on it) into an array of the elements' names, subscripted with
  the Modelica subscripts (constants only, ``end`` included);
* :meth:`RecordArrays.path_value` makes the value of those names: a field that is a variable is
  its value (an array of the fields' values, of size the paths' size, then the field's), a
  record or a component is a :class:`.records.Record` of its fields' variables, so an array of
  records is an object array of :class:`.records.Record`;
* :func:`.records.difference` equates two arrays of records element by element, field by field.

Only names the flat model holds are built; a subscript that varies at run time is refused by the
translator's subscript rule (indices must be parameters or constants).
"""
from __future__ import annotations

import re
from collections.abc import Iterable
from typing import Any

import numpy as np

from ..errors import CompileError
from . import arrays as arr
from . import records
from .flat_model import Value, kind_of

_SUBSCRIPT = re.compile(r"\[(\d+(?:,\d+)*)\]\.")


def element_index(names: Iterable[str]) -> dict[str, tuple[int, ...]]:
    """The arrays of records or components among *names* (flat variable names): prefix -> its
    size (the largest index in each dimension), from every ``prefix[i,j].`` in a name.

    >>> element_index(["s[1].p", "s[2].p", "v[1].st.p", "v[2].st.p", "v[1].k", "x"])
    {'s': (2,), 'v': (2,)}
    """
    found: dict[str, set[tuple[int, ...]]] = {}
    for name in names:
        for m in _SUBSCRIPT.finditer(name):
            found.setdefault(name[:m.start()], set()).add(tuple(int(i) for i in m.group(1).split(",")))
    sizes: dict[str, tuple[int, ...]] = {}
    for prefix, idx in found.items():
        ranks = {len(i) for i in idx}
        if len(ranks) != 1:
            continue  # not one array (cannot happen for a flat model's names)
        rank = ranks.pop()
        sizes[prefix] = tuple(max(i[k] for i in idx) for k in range(rank))
    return sizes


def element_paths(prefix: str, size: tuple[int, ...]) -> np.ndarray:
    """The names of the elements of the array *prefix* of *size*: ``prefix[i,j]`` in an object array."""
    out = arr.new(size)
    for pos in np.ndindex(*size):
        out[pos] = prefix + "[" + ",".join(str(i + 1) for i in pos) + "]"
    return out


class RecordArrays:
    """The part of :class:`.flatten.FlatTranslator` for arrays of records and components."""

    def record_arrays(self) -> dict[str, tuple[int, ...]]:
        cached = self.__dict__.get("_record_arrays")
        if cached is None:
            cached = element_index(self.vars)
            self.__dict__["_record_arrays"] = cached
        return cached

    def component_paths(self, node: Any, env: dict[str, Value] | None) -> Any:
        """The element names a reference to an array of records or components stands for (an
        object array of str, or one str once subscripted to an element), or None when *node* is
        no such reference (a variable, a function's local, a record value, ...)."""
        kind, body = kind_of(node)
        if not isinstance(body, dict):
            return None
        if kind == "VarRef":
            name = body["name"]["name"]
            if (env is not None and name in env) or name in self.vars:
                return None
            size = self.record_arrays().get(name)
            if size is None:
                return None
            return self._subscripted_paths(element_paths(name, size), body.get("subscripts") or [], env, name)
        if kind == "Index":
            base = self.component_paths(body["base"], env)
            if base is None:
                return None
            return self._subscripted_paths(base, body.get("subscripts") or [], env, "an array of records")
        if kind == "FieldAccess":
            base = self.component_paths(body["base"], env)
            if base is None:
                return None
            field = str(body.get("field"))
            if isinstance(base, str):
                return f"{base}.{field}"
            return arr.map1(lambda p: f"{p}.{field}", base)
        return None

    def _subscripted_paths(self, paths: Any, subs: list[Any], env: dict[str, Value] | None, what: str) -> Any:
        if not subs:
            return paths
        if isinstance(paths, str):  # an element, subscripted again: not a name the flat model can hold
            raise CompileError(f"{len(subs)} subscripts for the element {paths!r} of {what} in {self.model}")
        picks = [self._subscript(s, paths, k, env) for k, s in enumerate(subs)]
        return arr.subscript(paths, picks, repr(what))

    def path_value(self, paths: Any) -> Value:
        """The value of element names from :meth:`component_paths`: a variable's value, a record (or a
        component) as the :class:`.records.Record` of its fields, an array of those."""
        if isinstance(paths, str):
            return self._one_path(paths)
        try:
            return records.combine(paths.shape, [self._one_path(p) for p in paths.ravel()],
                                   f"the array of {paths.ravel()[0] if paths.size else 'records'}, ...")
        except records.RecordError as exc:
            raise CompileError(f"{exc} in {self.model}") from None

    def _one_path(self, path: str) -> Value:
        if path in self.vars:
            return self.ref(path, [], None)
        size = self.record_arrays().get(path)
        if size is not None:  # an array of records inside a component: its elements in turn
            return self.path_value(element_paths(path, size))
        rec = records.gather(path, self.vars, lambda n: self._one_path(n))
        if rec is None:
            raise CompileError(f"unknown variable {path!r} referenced in {self.model}")
        return rec
