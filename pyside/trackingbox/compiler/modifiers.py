"""Find the modifications that rumoca 0.10.2 loses, before they give wrong numbers.

rumoca flattens most modifications right, but in four situations it silently
drops or mixes up values (each found by flattening small models; see
``tests/test_compiler_arrays.py``):

* **Merging into a nested modification through ``extends``.** In
  ``extends W(o(i(a = 7)))`` the modification of ``o.i`` replaces, rather than
  merges with, what the declaration ``Outer o(i(b = 3))`` (or ``i``'s own
  declaration) says about ``o.i``: ``o.i.b`` loses its value, a start value
  given there is lost, and so are bounds.
* **A class redeclaration with a modification**
  (``redeclare model M = Base(k = 5)``): the modification is dropped. Where it gives only
  literal values, :mod:`.redeclare_short` has rumoca read it through a short class, which it
  keeps; where it stands in a component's modification and means the same as a modification of
  the components the class types, :mod:`.redeclare_components` has rumoca read it so; a function
  redeclaration with a modification is kept as written.
* **A value given together with attributes, inside a nested modification.** In
  ``extends Base(k(max = 5) = 3)``, ``model D = C(k(min = 1) = 3)`` or
  ``A a(c(k(max = 5) = 3))`` the value 3 and the attributes are both dropped
  (``k`` keeps its default), while ``C c(k(max = 5) = 3)`` (a declaration's own
  elements) and ``extends Base(k = 3)`` are kept.
* **A package that extends another with a modified constant**
  (``package Water2 extends Water(cp = 1000)``): when a model uses both, the
  base package's constant takes the modified value too.

The check works on the source text (comments and strings blanked) of the classes
the model uses, found by Modelica's lookup from the model's own scope
(:mod:`.library`), so a class that only shares a name with one the model uses is
never read; within those classes it errs on the side of refusing. Lost
bounds, units or nominal values change no number and give a warning instead
(the benches rely on that: ``extends PartialBench(hx(kht = 910))``).
"""
from __future__ import annotations

import logging
import re
from pathlib import Path

from ..errors import UnsupportedConstructError
from .library import ClassInfo, LibraryIndex
from .modification_parse import Mod, parse_modification  # noqa: F401 (tests read parse_modification from here)
from .package_overrides import (check_overridden_constants, family_reads_modified, only_in_extends, only_in_imports,
                                taken_branches)
from . import redeclare_components
from .redeclare_short import short_class_handles
from .source import Location, ModelicaSource

log = logging.getLogger(__name__)

# attributes whose loss changes no simulated number
_HARMLESS = {"min", "max", "nominal", "unit", "displayUnit", "quantity", "stateSelect"}
_KINDS = r"(?:model|block|class|package|connector|record|function|type|operator)"


def _values_with_attributes(mods: list[Mod], depth: int, first: int, path: str = "") -> list[tuple[str, Mod]]:
    """Elements ``name(sub...) = value`` at nesting *depth* >= *first* (1 = the clause's own elements)."""
    found = []
    for m in mods:
        name = f"{path}.{m.name}" if path else m.name
        if depth >= first and m.has_value and m.subs:
            found.append((name, m))
        found.extend(_values_with_attributes(m.subs, depth + 1, first, name))
    return found


_SHORT_CLASS = re.compile(rf"\b{_KINDS}\s+([A-Za-z_]\w*)\s*=\s*(?:(?:input|output)\s+)?([A-Za-z_][\w.]*)\s*(?:\[[^\]]*\]\s*)?\(")
_DECLARATION = re.compile(r"(?<![.\w])([A-Za-z_][\w.]*)\s+([A-Za-z_]\w*)\s*(?:\[[^\]]*\]\s*)?\(")
_NOT_TYPES = {"extends", "end", "import", "within", "if", "then", "else", "elseif", "and", "or", "not", "in",
              "loop", "annotation", "return", "der", "equation", "algorithm", "connect", "assert", "when",
              "while", "for", "redeclare", "replaceable", "constrainedby"} | set(_KINDS[3:-1].split("|"))


def modifier_check(source: ModelicaSource, libraries: tuple[Path, ...] | list[Path] = ()) -> ModifierCheck:
    """A :class:`ModifierCheck` of *source* and the libraries it is compiled with."""
    from .library import index_for

    return ModifierCheck(index_for(source, libraries))


class ModifierCheck:
    """The modification patterns rumoca gets wrong, looked for in the classes a model uses.

    The classes are those Modelica's lookup reaches from the model
    (:meth:`.library.LibraryIndex.used_classes`), each read as its own text (its nested classes
    are classes of their own, its annotations blanked); a class elsewhere in the package or in a
    library that merely shares a name is never read.
    """

    def __init__(self, index: LibraryIndex):
        self.index = index
        self._texts: dict[str, str] = {}
        self._declared: dict[tuple[str, tuple[str, ...]], list[list[Mod]]] = {}

    def used_classes(self, model: str) -> list[ClassInfo]:
        """The classes *model* uses (its own class first)."""
        return [self.index.classes[n] for n in self.index.used_classes(model)]

    def body(self, c: ClassInfo) -> str:
        if c.name not in self._texts:
            self._texts[c.name] = self.index.own_code(c, annotations=False)
        return self._texts[c.name]

    def _location(self, c: ClassInfo, offset: int) -> Location:
        return Location(*self.index.location(c, offset))

    # --------------------------------------------------------------- checks
    def declared_subs(self, used: list[ClassInfo], component: str) -> list[list[Mod]]:
        """Modifications of every declaration of *component* among *used* classes."""
        key = (component, tuple(c.name for c in used))
        if key not in self._declared:
            self._declared[key] = self._find_declarations(used, component)
        return self._declared[key]

    def _find_declarations(self, used: list[ClassInfo], component: str) -> list[list[Mod]]:
        # "Type component[...](" : the name and a parenthesis, preceded by a type name
        pattern = re.compile(rf"(?<![.\w]){re.escape(component)}\s*(?:\[[^\]]*\]\s*)?\(")
        type_before = re.compile(r"(?<![.\w])([A-Za-z_][\w.]*)\s+$")
        found = []
        for c in used:
            text = self.body(c)
            for m in pattern.finditer(text):
                before = type_before.search(text, max(0, m.start() - 120), m.start())
                if before is None or before.group(1) in ("extends", "end", "import", "within", "if", "then",
                                                          "else", "and", "or", "not", "in", "loop"):
                    continue
                mods, _ = parse_modification(text, m.end() - 1)
                found.append(mods)
        return found

    def _lost(self, comp: str, ext: Mod, used: list[ClassInfo]) -> tuple[set[str], set[str]]:
        """What ``extends B(comp(ext))`` drops: (value-changing, harmless) names.

        Two sources are replaced rather than merged: the modification of
        ``ext.name`` inside a declaration of *comp* (``Outer comp(i(b = 3))``),
        and, when the extends clause gives a value, the attributes declared with
        the element itself (``parameter Real q(min = 0)``).
        """
        changing: set[str] = set()
        harmless: set[str] = set()
        given = {s.name for s in ext.subs}
        for decl_mods in self.declared_subs(used, comp):
            for d in decl_mods:
                if d.name != ext.name:
                    continue
                for key in {s.name for s in d.subs} - given:
                    (harmless if key in _HARMLESS else changing).add(key)
                if d.has_value and not ext.has_value:
                    changing.add(f"the value of {ext.name}")
        if ext.has_value:  # a new value: start/fixed of the element no longer matter
            for decl_mods in self.declared_subs(used, ext.name):
                for key in {d.name for d in decl_mods} - given:
                    (harmless if key in _HARMLESS | {"start", "fixed"} else changing).add(key)
        return changing, harmless

    def check(self, model: str) -> list[str]:
        """Refuse what rumoca would get wrong; return warnings for lost bounds and units."""
        used = self.used_classes(model)
        check_overridden_constants(self, model, used)  # a package constant modified twice in a chain
        warnings: list[str] = []
        for c in used:
            text = self.body(c)
            for m in re.finditer(r"\bextends\s+([\w.]+)\s*\(", text):
                mods, _ = parse_modification(text, m.end() - 1)
                base = m.group(1).rsplit(".", 1)[-1]
                use = self._use_of(used, m.group(1), c) if c.kind == "package" and any(
                    x.has_value for x in mods) else None
                if use is not None:
                    raise UnsupportedConstructError(
                        f"unsupported Modelica construct in {model}: package {c.simple} extends {base} with a "
                        f"modified constant at {self._location(c, m.start())}, and {model} {use}"
                    )
                for comp in mods:  # extends B(p(q ...)): p.q replaces what p's declarations say about q
                    for inner in comp.subs:
                        changing, harmless = self._lost(comp.name, inner, used)
                        where = self._location(c, m.start())
                        path = f"{comp.name}.{inner.name}"
                        if changing:
                            raise UnsupportedConstructError(
                                f"unsupported Modelica construct in {model}: the modification of {path} in "
                                f"'extends {m.group(1)}(...)' at {where} would lose "
                                f"{', '.join(sorted(changing))} declared for it elsewhere (rumoca 0.10.2 "
                                "replaces instead of merging a nested modification given through extends); "
                                "repeat those modifications in the extends clause or modify the component "
                                "where it is declared"
                            )
                        if harmless:
                            warnings.append(f"{path}: {', '.join(sorted(harmless))} declared for it are not "
                                            f"kept through 'extends {m.group(1)}(...)' at {where}")
            self._check_values_with_attributes(model, c, text)
            for m in re.finditer(rf"\bredeclare\s+(?:(?:replaceable|final|each)\s+)*({_KINDS})\s+\w+\s*=\s*[\w.]+\s*\(",
                                 text):
                if m.group(1) == "function" or short_class_handles(text, m.start()):
                    continue  # kept by rumoca / read through a short class (see .redeclare_short)
                if redeclare_components.plan(self.index, c.name, text, m.start()) is not None:
                    continue  # read as a modification of the components (see .redeclare_components)
                raise UnsupportedConstructError(
                    f"unsupported Modelica construct in {model}: class redeclaration with a modification at "
                    f"{self._location(c, m.start())} (rumoca 0.10.2 drops the modification, and it sets more "
                    "than literal values, which the embedded path reads through a short class); declare a "
                    "short class with the modification and redeclare to it"
                )
        return warnings

    def _check_values_with_attributes(self, model: str, c: ClassInfo, text: str) -> None:
        """Refuse ``name(attributes) = value`` where rumoca drops both (see the module docstring)."""
        clauses: list[tuple[str, int, int]] = []  # (what, offset of the clause, first depth that loses)
        for m in re.finditer(r"\bextends\s+([\w.]+)\s*\(", text):
            clauses.append((f"'extends {m.group(1)}(...)'", m.start(), 1))
        for m in _SHORT_CLASS.finditer(text):
            clauses.append((f"'{m.group(1)} = {m.group(2)}(...)'", m.start(), 1))
        for m in _DECLARATION.finditer(text):
            if m.group(1) in _NOT_TYPES or m.group(2) in _NOT_TYPES:
                continue
            clauses.append((f"the declaration of {m.group(2)}", m.start(), 2))
        for what, start, first in clauses:
            paren = text.index("(", start)
            mods, _ = parse_modification(text, paren)
            for name, mod in _values_with_attributes(mods, 1, first):
                leaf = name.rsplit(".", 1)[-1]
                raise UnsupportedConstructError(
                    f"unsupported Modelica construct in {model}: the modification of {name} in {what} at "
                    f"{self._location(c, mod.offset)} gives {leaf} a value together with modifications of its "
                    f"own ({', '.join(sub.name for sub in mod.subs)}); rumoca 0.10.2 drops both there, so {leaf} "
                    f"would silently keep its default. Give the value alone there ({leaf} = ...) and put "
                    f"bounds, units or start where {leaf} is declared"
                )

    def _only_as_replaceable_default(self, c: ClassInfo, name: str, target: ClassInfo | None) -> bool:
        """Whether *name* stands in *c* only as the default or constraining class of a replaceable
        package (``replaceable package Medium = Modelica.Media.Interfaces.PartialMedium``) and
        names a partial package: a model cannot be simulated with such a package left in place (its
        functions are partial), so its constants are read through the package that replaces it."""
        if target is None or not target.partial or target.kind != "package":
            return False
        text = self.body(c)
        esc = re.escape(name)
        every = len(re.findall(rf"(?<![\w.]){esc}(?![\w])", text))
        default = len(re.findall(rf"\breplaceable\s+package\s+\w+\s*=\s*{esc}(?![\w.])"
                                 rf"|\bconstrainedby\s+{esc}(?![\w.])", text))
        return every > 0 and every == default

    def _use_of(self, used: list[ClassInfo], ext: str, extender: ClassInfo) -> str | None:
        """How the class that *extender* extends by the name *ext* is used by name in a used class
        (a name there, or a prefix of one, resolves to exactly that class), besides that extends
        clause and the class's own name in its own text (``package P ... end P;``): the end of the
        refusal's sentence, or None where it is not used so."""
        idx = self.index
        simple = ext.rsplit(".", 1)[-1]
        targets = [b for b in idx.bases(extender.name) if b.rsplit(".", 1)[-1] == simple]
        if not targets:
            return None
        target = targets[0]
        for c in used:
            for name in c.names:
                if c is extender and name == ext:
                    continue
                if c.name == target and name == c.simple:  # its own header and `end` name no use
                    continue
                if self._only_as_replaceable_default(c, name, idx.classes.get(target)):
                    continue
                if only_in_imports(self.body(c), name):  # an import is no use; a name using it is
                    continue
                parts = name.split(".")
                for k in range(1, len(parts) + 1):
                    found = idx.lookup(".".join(parts[:k]), c.name)
                    if found is None:
                        break
                    if found != target:
                        continue
                    if c.kind == "package" and only_in_extends(self.body(c), name):
                        branches = taken_branches(self, used, target)
                        if branches is not None and len(branches) <= 1:
                            break  # another package's extends of the base (see .package_overrides)
                        if not family_reads_modified(self, used, target):
                            break
                        if branches is not None:
                            where = "; ".join(f"{b.rsplit('.', 1)[-1]} at {self._location(info, at)}"
                                              for b, (info, at) in sorted(branches.items()))
                            return (f"takes several packages extending {simple} with different values ({where}), "
                                    f"whose classes read the modified constants: rumoca 0.10.2 computes one "
                                    f"package's functions with another's constants")
                    return (f"also uses {simple} itself: rumoca 0.10.2 would give {simple}'s constant the "
                            "modified value too")
        return None
