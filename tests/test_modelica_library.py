"""The TrackingBox Modelica library as a modeller opens it in a diagram editor (issue 32, item 7).

Every class file of ``modelica/TrackingBox`` is read with the small Modelica reader below (tokens,
class definitions, element statements and their annotations: what a diagram editor reads, with no
front end in between) and checked against the conventions of the Modelica Standard Library:

* every class carries ``Documentation(info=...)`` with text in it; a short ``type`` defined
  inside another class (the SI types of ``Units``) is documented by its description string, as in
  ``Modelica.Units.SI``;
* every model, block and connector has an ``Icon`` with at least one graphic primitive, its own or
  inherited through ``extends`` from a class of the library that has one (as a diagram editor
  draws it); packages, functions, records and types need none;
* every public component of a connector type declared in a model or block has a
  ``Placement(transformation(extent=...))``; protected connectors (the ``*_internal`` halves of
  the conditional-input pattern) are not ports and are left unplaced, as in the MSL;
* the top package has a ``version`` annotation, and ``uses(Modelica(...))`` exactly when a class
  refers to ``Modelica.*``;
* each package directory's ``package.order`` names exactly the classes the directory holds;
* every class file parses with the front end of the embedded path (``rumoca.validate``), so the
  annotations are Modelica and not only text this reader accepts.

The reader is checked by small libraries written to ``tmp_path`` that lack one thing each: each
must give exactly the problem it plants.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ROOT / "modelica" / "TrackingBox"

# ----------------------------------------------------------------------------- tokens

_TOKEN = re.compile(r"""
    (?P<ws>\s+)
  | (?P<comment>//[^\n]*|/\*.*?\*/)
  | (?P<string>"(?:\\.|[^"\\])*")
  | (?P<ident>[A-Za-z_]\w*|'(?:\\.|[^'\\])+')
  | (?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<symbol>:=|==|<>|<=|>=|\.\+|\.-|\.\*|\./|\.\^|[(){}\[\];,.=+\-*/^<>:])
""", re.S | re.X)

CLASS_KINDS = {"model", "block", "connector", "package", "function", "record", "type", "class", "operator"}
CLASS_PREFIXES = {"partial", "encapsulated", "final", "replaceable", "redeclare", "expandable", "pure",
                  "impure", "inner", "outer"}
ELEMENT_PREFIXES = {"parameter", "constant", "input", "output", "flow", "stream", "discrete", "final",
                    "inner", "outer", "replaceable", "redeclare", "each"}


class ModelicaSyntaxError(ValueError):
    """The reader cannot follow the text (names the file and the line)."""


@dataclass(frozen=True)
class Token:
    kind: str
    text: str
    line: int


def tokenize(text: str, file: Path) -> list[Token]:
    tokens: list[Token] = []
    pos, line = 0, 1
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            raise ModelicaSyntaxError(f"{file}:{line}: unexpected character {text[pos]!r}")
        kind = m.lastgroup or ""
        if kind not in ("ws", "comment"):
            tokens.append(Token(kind, m.group(0), line))
        line += m.group(0).count("\n")
        pos = m.end()
    return tokens


# ----------------------------------------------------------------------------- annotations

@dataclass
class Arg:
    """One argument of a modification or annotation: ``name(sub...) = value``."""

    name: str
    sub: dict[str, Arg] | None = None
    value: list[Token] | None = None

    def get(self, *path: str) -> Arg | None:
        arg: Arg | None = self
        for name in path:
            arg = (arg.sub or {}).get(name) if arg is not None else None
        return arg


@dataclass
class Element:
    """A component declaration (one name of it)."""

    type_name: str
    name: str
    protected: bool
    annotation: Arg | None
    line: int


@dataclass
class ModelicaClass:
    kind: str
    name: str  # full name
    file: Path
    line: int
    partial: bool = False
    short: bool = False
    description: str = ""
    bases: list[str] = field(default_factory=list)  # extends (long) or the defining type (short)
    imports: dict[str, str] = field(default_factory=dict)
    elements: list[Element] = field(default_factory=list)
    annotation: Arg | None = None
    nested: bool = False

    @property
    def short_name(self) -> str:
        return self.name.rsplit(".", 1)[-1]

    @property
    def enclosing(self) -> str:
        return self.name.rsplit(".", 1)[0] if "." in self.name else ""


class _Reader:
    """Recursive reader of one class file's tokens."""

    def __init__(self, tokens: list[Token], file: Path):
        self.t = tokens
        self.i = 0
        self.file = file

    # -- helpers
    def peek(self, k: int = 0) -> Token | None:
        j = self.i + k
        return self.t[j] if j < len(self.t) else None

    def text(self, k: int = 0) -> str:
        tok = self.peek(k)
        return tok.text if tok else ""

    def error(self, what: str) -> ModelicaSyntaxError:
        tok = self.peek()
        line = tok.line if tok else (self.t[-1].line if self.t else 1)
        return ModelicaSyntaxError(f"{self.file}:{line}: {what} (at {self.text()!r})")

    def expect(self, text: str) -> Token:
        tok = self.peek()
        if tok is None or tok.text != text:
            raise self.error(f"expected {text!r}")
        self.i += 1
        return tok

    def name(self) -> str:
        parts = []
        if self.text() == ".":
            self.i += 1
        while True:
            tok = self.peek()
            if tok is None or tok.kind != "ident":
                raise self.error("expected a name")
            parts.append(tok.text)
            self.i += 1
            if self.text() == "." and self.peek(1) is not None and self.peek(1).kind == "ident":
                self.i += 1
                continue
            return ".".join(parts)

    def skip_group(self) -> list[Token]:
        """Skip a bracketed group starting at the current token; return its tokens."""
        start, depth = self.i, 0
        while self.i < len(self.t):
            ch = self.t[self.i].text
            if ch in "([{" and self.t[self.i].kind == "symbol":
                depth += 1
            elif ch in ")]}" and self.t[self.i].kind == "symbol":
                depth -= 1
                if depth == 0:
                    self.i += 1
                    return self.t[start:self.i]
            self.i += 1
        raise self.error("unbalanced brackets")

    def expression(self) -> list[Token]:
        """Tokens of an expression: up to ``,`` ``;`` ``)`` at depth 0, ``annotation``, or a
        string that follows a complete operand (the description)."""
        start = self.i
        while self.i < len(self.t):
            tok = self.t[self.i]
            if tok.kind == "symbol" and tok.text in "([{":
                self.skip_group()
                continue
            if tok.kind == "symbol" and tok.text in (",", ";", ")", "]", "}"):
                break
            if tok.kind == "ident" and tok.text == "annotation":
                break
            if tok.kind == "string" and self.i > start:
                prev = self.t[self.i - 1]
                if prev.kind in ("ident", "number", "string") or prev.text in (")", "]", "}"):
                    break
            self.i += 1
        return self.t[start:self.i]

    def modification(self) -> dict[str, Arg]:
        """``( argument {, argument} )``; the current token is ``(``."""
        self.expect("(")
        args: dict[str, Arg] = {}
        while self.text() != ")":
            if self.peek() is None:
                raise self.error("unterminated modification")
            while self.text() in ("each", "final"):
                self.i += 1
            if self.text() in ("redeclare", "replaceable"):  # not read: skip to the next argument
                self.expression()
            else:
                name = self.name()
                arg = Arg(name)
                if self.text() == "(":
                    arg.sub = self.modification()
                if self.text() in ("=", ":="):
                    self.i += 1
                    arg.value = self.expression()
                while self.peek() is not None and self.peek().kind == "string":
                    self.i += 1  # description of an element modification
                head, _, rest = name.partition(".")
                if rest:  # a.b = 1 is a(b = 1)
                    outer = args.setdefault(head, Arg(head, sub={}))
                    outer.sub = outer.sub or {}
                    outer.sub[rest] = arg
                else:
                    args[name] = arg
            if self.text() == ",":
                self.i += 1
            elif self.text() != ")":
                raise self.error("expected ',' or ')' in a modification")
        self.i += 1
        return args

    def comment(self) -> tuple[str, Arg | None]:
        """``[string {+ string}] [annotation(...)]``."""
        desc = ""
        while self.peek() is not None and self.peek().kind == "string":
            desc += self.peek().text[1:-1]
            self.i += 1
            if self.text() == "+":
                self.i += 1
        ann = None
        if self.text() == "annotation":
            self.i += 1
            ann = Arg("annotation", sub=self.modification())
        return desc, ann

    # -- classes
    def class_definition(self, enclosing: str, nested: bool) -> list[ModelicaClass]:
        start = self.peek()
        partial = False
        while self.text() in CLASS_PREFIXES:
            partial |= self.text() == "partial"
            self.i += 1
        kind = self.text()
        if kind == "operator" and self.text(1) in ("record", "function"):
            self.i += 1
            kind = self.text()
        if kind not in CLASS_KINDS:
            raise self.error("expected a class definition")
        self.i += 1
        short_name = self.name()
        full = f"{enclosing}.{short_name}" if enclosing else short_name
        cls = ModelicaClass(kind=kind, name=full, file=self.file, line=start.line if start else 1,
                            partial=partial, nested=nested)
        if self.text() == "=":  # short class definition
            self.i += 1
            cls.short = True
            while self.text() in ("input", "output", "flow", "stream"):
                self.i += 1
            cls.bases.append(self.name())
            if self.text() == "[":
                self.skip_group()
            if self.text() == "(":
                self.modification()
            cls.description, cls.annotation = self.comment()
            self.expect(";")
            return [cls]
        while self.peek() is not None and self.peek().kind == "string":
            cls.description += self.peek().text[1:-1]
            self.i += 1
            if self.text() == "+":
                self.i += 1
        out = [cls]
        section = "public"
        while True:
            tok = self.peek()
            if tok is None:
                raise self.error(f"missing 'end {short_name};'")
            word = tok.text
            if word == "end" and self.text(1) == short_name and self.text(2) == ";":
                self.i += 3
                return out
            if word in ("public", "protected"):
                section = word
                self.i += 1
                continue
            if word in ("equation", "algorithm") or (word == "initial" and self.text(1) in ("equation", "algorithm")):
                section = "equation"
                self.i += 2 if word == "initial" else 1
                continue
            if section == "equation":
                if word == "annotation":  # a class annotation may follow the equations
                    _, ann = self.comment()
                    cls.annotation = ann
                    self.expect(";")
                    continue
                self.skip_statement()
                continue
            if word == "annotation":
                _, cls.annotation = self.comment()
                self.expect(";")
                continue
            if word == "extends":
                self.i += 1
                cls.bases.append(self.name())
                if self.text() == "(":
                    self.modification()
                self.comment()
                self.expect(";")
                continue
            if word == "import":
                self.i += 1
                if self.peek(1) is not None and self.text(1) == "=":
                    alias = self.name()
                    self.expect("=")
                    cls.imports[alias] = self.name()
                else:
                    target = self.name()
                    if self.text() == "." and self.text(1) in ("*", "{"):
                        self.skip_statement()
                        continue
                    cls.imports[target.rsplit(".", 1)[-1]] = target
                self.comment()
                self.expect(";")
                continue
            if self._starts_class():
                out.extend(self.class_definition(full, nested=True))
                continue
            self.component_clause(cls, protected=(section == "protected"))

    def _starts_class(self) -> bool:
        k = 0
        while self.text(k) in CLASS_PREFIXES:
            k += 1
        return self.text(k) in CLASS_KINDS and self.text(k) != "operator" or (
            self.text(k) == "operator" and self.text(k + 1) in ("record", "function"))

    def skip_statement(self) -> None:
        while self.i < len(self.t):
            tok = self.t[self.i]
            if tok.kind == "symbol" and tok.text in "([{":
                self.skip_group()
                continue
            self.i += 1
            if tok.text == ";":
                return
        raise self.error("missing ';'")

    def component_clause(self, cls: ModelicaClass, protected: bool) -> None:
        while self.text() in ELEMENT_PREFIXES:
            self.i += 1
        line = self.peek().line if self.peek() else 0
        type_name = self.name()
        if self.text() == "[":
            self.skip_group()
        while True:
            name = self.name()
            if self.text() == "[":
                self.skip_group()
            if self.text() == "(":
                self.modification()
            if self.text() in ("=", ":="):
                self.i += 1
                self.expression()
            if self.text() == "if":
                self.i += 1
                self.expression()
            _, ann = self.comment()
            cls.elements.append(Element(type_name, name, protected, ann, line))
            if self.text() == ",":
                self.i += 1
                continue
            self.expect(";")
            return


def read_classes(file: Path) -> list[ModelicaClass]:
    """The classes one ``.mo`` file defines (its own class first, then the nested ones)."""
    tokens = tokenize(file.read_text(encoding="utf-8"), file)
    reader = _Reader(tokens, file)
    within = ""
    if reader.text() == "within":
        reader.i += 1
        within = reader.name() if reader.text() != ";" else ""
        reader.expect(";")
    classes = reader.class_definition(within, nested=False)
    if reader.peek() is not None:
        raise reader.error("text after the end of the class")
    return classes


# ----------------------------------------------------------------------------- checks

def _has_text(tokens: list[Token] | None) -> bool:
    """A documentation string with more than markup in it."""
    if not tokens:
        return False
    text = "".join(t.text[1:-1] for t in tokens if t.kind == "string")
    return bool(re.sub(r"<[^>]*>|\s", "", text))


def _has_graphics(tokens: list[Token] | None) -> bool:
    """``{ Primitive(...), ... }`` with at least one primitive."""
    return bool(tokens) and any(t.kind == "ident" for t in tokens)


def _refers_to_msl(file: Path) -> bool:
    """Whether code (not a comment or a string) in *file* names ``Modelica.``..."""
    tokens = tokenize(file.read_text(encoding="utf-8"), file)
    return any(a.kind == "ident" and a.text == "Modelica" and b.text == "." for a, b in zip(tokens, tokens[1:]))


@dataclass
class Library:
    root: Path
    classes: dict[str, ModelicaClass]
    files: dict[Path, list[ModelicaClass]]

    def resolve(self, name: str, scope: ModelicaClass) -> ModelicaClass | None:
        """The library class *name* denotes inside *scope* (imports, then outward lookup)."""
        head, _, rest = name.partition(".")
        cur: ModelicaClass | None = scope
        while cur is not None:
            if head in cur.imports:
                return self.classes.get(cur.imports[head] + ("." + rest if rest else ""))
            cur = self.classes.get(cur.enclosing)
        prefix = scope.name
        while True:
            candidate = f"{prefix}.{name}" if prefix else name
            if candidate in self.classes:
                return self.classes[candidate]
            if not prefix:
                return None
            prefix = prefix.rsplit(".", 1)[0] if "." in prefix else ""

    def has_icon(self, cls: ModelicaClass, seen: frozenset[str] = frozenset()) -> bool:
        icon = cls.annotation.get("Icon") if cls.annotation else None
        if icon is not None and _has_graphics((icon.get("graphics") or Arg("")).value):
            return True
        for base in cls.bases:
            found = self.resolve(base, cls)
            if found is not None and found.name not in seen and self.has_icon(found, seen | {cls.name}):
                return True
        return False

    def is_connector(self, type_name: str, scope: ModelicaClass) -> bool:
        found = self.resolve(type_name, scope)
        return found is not None and found.kind == "connector"


def load_library(root: Path) -> Library:
    classes: dict[str, ModelicaClass] = {}
    files: dict[Path, list[ModelicaClass]] = {}
    for file in sorted(root.rglob("*.mo")):
        found = read_classes(file)
        files[file] = found
        for cls in found:
            classes[cls.name] = cls
    return Library(root, classes, files)


def problems(root: Path) -> list[str]:
    """Everything the library at *root* (the top package's directory) lacks, one line each."""
    lib = load_library(root)
    out: list[str] = []
    for file, found in lib.files.items():
        rel = file.relative_to(root.parent)
        expected = root.name if file == root / "package.mo" else None
        own = found[0]
        if expected is not None and own.name != expected:
            out.append(f"{rel}: defines {own.name}, expected the top package {expected}")
        for cls in found:
            where = f"{rel}:{cls.line} {cls.kind} {cls.name}"
            doc = cls.annotation.get("Documentation", "info") if cls.annotation else None
            if cls.nested and cls.short and cls.kind == "type":
                if not cls.description.strip():
                    out.append(f"{where}: no description string")
            elif doc is None or not _has_text(doc.value):
                out.append(f"{where}: no Documentation(info=...)")
            if cls.kind in ("model", "block", "connector", "class") and not lib.has_icon(cls):
                out.append(f"{where}: no Icon (own or inherited)")
            if cls.kind in ("model", "block"):
                for el in cls.elements:
                    if el.protected or not lib.is_connector(el.type_name, cls):
                        continue
                    place = el.annotation.get("Placement", "transformation", "extent") if el.annotation else None
                    if place is None or not place.value:
                        out.append(f"{rel}:{el.line} {cls.name}: connector {el.name} ({el.type_name}) "
                                   "has no Placement(transformation(extent=...))")
    top = lib.classes.get(root.name)
    if top is None:
        out.append(f"{root / 'package.mo'}: no top package {root.name}")
    else:
        version = top.annotation.get("version") if top.annotation else None
        if version is None or not version.value or not version.value[0].text.strip('" '):
            out.append(f"{root.name}/package.mo: the top package has no version annotation")
        uses = top.annotation.get("uses") if top.annotation else None
        used = sorted((uses.sub or {}).keys()) if uses is not None else []
        refers = sorted(f.relative_to(root.parent).as_posix() for f in lib.files if _refers_to_msl(f))
        if refers and "Modelica" not in used:
            out.append(f"{root.name}/package.mo: classes refer to Modelica.* ({', '.join(refers[:3])}) "
                       "but the top package has no uses(Modelica(version=...))")
        if "Modelica" in used and not refers:
            out.append(f"{root.name}/package.mo: uses(Modelica(...)) but no class refers to Modelica.*")
    for directory in sorted({f.parent for f in lib.files}):
        order = directory / "package.order"
        if not (directory / "package.mo").is_file():
            continue
        held = {f.stem for f in directory.glob("*.mo") if f.name != "package.mo"}
        held |= {d.name for d in directory.iterdir() if (d / "package.mo").is_file()}
        held |= {c.short_name for c in lib.files[directory / "package.mo"][1:]
                 if c.enclosing == lib.files[directory / "package.mo"][0].name}
        listed = order.read_text(encoding="utf-8").split() if order.is_file() else []
        rel = order.relative_to(root.parent)
        if set(listed) != held or len(listed) != len(set(listed)):
            missing, extra = sorted(held - set(listed)), sorted(set(listed) - held)
            out.append(f"{rel}: lists {len(listed)} classes; missing {missing}, not in the package {extra}")
    return out


# ----------------------------------------------------------------------------- the library

def test_library_is_complete_for_a_diagram_editor():
    found = problems(LIBRARY)
    assert found == [], f"{len(found)} problems:\n" + "\n".join(found)


def _front_end_errors(file: Path) -> list[str]:
    import rumoca

    return [f"{file}:{getattr(d, 'line', '?')}: {str(getattr(d, 'message', d)).splitlines()[0]}"
            for d in rumoca.validate(str(file)) if getattr(d, "level", "") == "error"]


def test_every_class_file_parses_with_the_front_end():
    """The annotations are Modelica the front end reads (rumoca, the embedded path's parser), not only
    text the reader above accepts; an unbalanced annotation is an error there."""
    errors = [e for f in sorted(LIBRARY.rglob("*.mo")) for e in _front_end_errors(f)]
    assert errors == []


def test_the_front_end_rejects_an_unbalanced_annotation(tmp_path):
    lib = _write(tmp_path, {**GOOD, "Box.mo": GOOD["Box.mo"].replace('Text(textString="%name")}),',
                                                                       'Text(textString="%name")})),')})
    assert _front_end_errors(lib / "Box.mo"), "the front end must report the extra parenthesis"


def test_reader_finds_every_class_file_and_the_known_ports():
    lib = load_library(LIBRARY)
    assert len(lib.files) == len(list(LIBRARY.rglob("*.mo")))
    hx = lib.classes["TrackingBox.Fluid.HeatExchanger"]
    ports = {el.name: el for el in hx.elements if lib.is_connector(el.type_name, hx)}
    # the four fluid ports, the two conditional inputs, and the two protected internal halves
    assert {n for n, el in ports.items() if not el.protected} == {"port_a1", "port_b1", "port_a2", "port_b2",
                                                                   "kht_in", "Q_flow_loss_in"}
    assert {n for n, el in ports.items() if el.protected} == {"kht_internal", "Q_flow_loss_internal"}
    units = [c for c in lib.files[LIBRARY / "Units.mo"] if c.nested]
    assert len(units) >= 20 and all(c.kind == "type" and c.short for c in units)


# ----------------------------------------------------------------------------- the reader can fail

GOOD = {
    "package.mo": '''within;
package Lib "A library"
  annotation (version="1.0.0", Documentation(info="<html><p>Two classes.</p></html>"));
end Lib;
''',
    "package.order": "Port\nBox\n",
    "Port.mo": '''within Lib;
connector Port = input Real "A signal" annotation (
  Icon(graphics={Rectangle(extent={{-100,100},{100,-100}})}),
  Documentation(info="<html><p>Input signal.</p></html>"));
''',
    "Box.mo": '''within Lib;
model Box "A box with one port"
  parameter Real k = 1 "Gain";
  Port u "Input" annotation (Placement(transformation(extent={{-120,-10},{-100,10}})));
  Real y "Output";
protected
  Port u_internal "Not a port";
equation
  connect(u, u_internal);
  y = k*u_internal;
  annotation (Icon(graphics={Rectangle(extent={{-100,100},{100,-100}}), Text(textString="%name")}),
    Documentation(info="<html><p>y = k u.</p></html>"));
end Box;
''',
}

BOX_ICON = 'Icon(graphics={Rectangle(extent={{-100,100},{100,-100}}), Text(textString="%name")}),'
PORT_ICON = 'Icon(graphics={Rectangle(extent={{-100,100},{100,-100}})}),'
PLACEMENT = ' annotation (Placement(transformation(extent={{-120,-10},{-100,10}})))'
MUTATIONS = [  # (file, text replaced, replacement, the problem expected)
    ("Box.mo", BOX_ICON, "", "model Lib.Box: no Icon"),
    ("Box.mo", ',\n    Documentation(info="<html><p>y = k u.</p></html>")', "",
     "model Lib.Box: no Documentation(info=...)"),
    ("Box.mo", PLACEMENT, "", "Lib.Box: connector u (Port) has no Placement"),
    ("Port.mo", PORT_ICON, "", "connector Lib.Port: no Icon"),
    ("package.mo", 'version="1.0.0", ', "", "the top package has no version annotation"),
    ("package.mo", 'version="1.0.0"', 'version="1.0.0", uses(Modelica(version="4.0.0"))',
     "uses(Modelica(...)) but no class refers to Modelica.*"),
    ("Box.mo", 'Real y "Output";', 'Modelica.Blocks.Interfaces.RealOutput y "Output";',
     "refer to Modelica.* (Lib/Box.mo) but the top package has no uses"),
    ("package.order", "Box\n", "", "package.order: lists 1 classes; missing ['Box']"),
    ("Box.mo", '"<html><p>y = k u.</p></html>"', '"<html><p> </p></html>"',
     "model Lib.Box: no Documentation(info=...)"),
]


def _write(root: Path, files: dict[str, str]) -> Path:
    lib = root / "Lib"
    lib.mkdir()
    for name, text in files.items():
        (lib / name).write_text(text, encoding="utf-8")
    return lib


def test_a_complete_small_library_passes(tmp_path):
    assert problems(_write(tmp_path, GOOD)) == []


@pytest.mark.parametrize("file, old, new, needle", MUTATIONS,
                         ids=["icon", "documentation", "placement", "connector-icon", "version", "uses-unused",
                              "uses-missing", "package-order", "empty-documentation"])
def test_a_library_lacking_one_thing_gives_exactly_that_problem(tmp_path, file, old, new, needle):
    files = dict(GOOD)
    assert files[file].count(old) == 1, "the mutation must apply once"
    files[file] = files[file].replace(old, new)
    found = problems(_write(tmp_path, files))
    assert len(found) == 1 and needle in found[0], found


def test_an_icon_is_inherited_through_extends(tmp_path):
    files = dict(GOOD)
    files["package.order"] = "Port\nBox\nBigBox\n"
    files["BigBox.mo"] = ('within Lib;\nmodel BigBox "Box with k = 2"\n  extends Box(k = 2);\n'
                          '  annotation (Documentation(info="<html><p>k = 2.</p></html>"));\nend BigBox;\n')
    assert problems(_write(tmp_path, files)) == []


def test_the_reader_names_the_line_it_cannot_follow(tmp_path):
    files = dict(GOOD)
    files["Box.mo"] = files["Box.mo"].replace("end Box;", "end Bx;")
    with pytest.raises(ModelicaSyntaxError, match=r"Box\.mo:\d+: missing 'end Box;'"):
        problems(_write(tmp_path, files))
