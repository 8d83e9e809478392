"""Inspect (and, on request, patch) the twin's Modelica source for code generation.

The tracked model flips a flag on the component that owns each tracked
parameter and connects the component's conditional input, the pattern of the
Modelica Standard Library (``use_kht_in``/``kht_in``)::

    parameter Real kht = 1000 "Heat-transfer coefficient";
    parameter Boolean use_kht_in = false "Take kht from input kht_in";
    RealInput kht_in if use_kht_in "kht from outside";
  protected
    RealInput kht_internal "kht actually used";
  equation
    connect(kht_in, kht_internal);
    if not use_kht_in then
      kht_internal = kht;
    end if;

This module flattens the twin with the compiler's front end (rumoca), checks that every tracked parameter's
component offers that pattern, finds where a parameter is declared (file,
line, class) so that a refusal can say exactly what to add, and can write a
patched copy of the source that adds the pattern (``--rewrite``).
"""
from __future__ import annotations

import difflib
import logging
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


from ..compiler import library_path
from ..compiler.embedded import flatten
from ..compiler.library import resolve_libraries, source_root
from ..compiler.source import resolve_source
from ..errors import CompileError, SpecError, unknown_name
from .parameter_uses import receivers, structural_reason

logger = logging.getLogger(__name__)

__all__ = [
    "TwinSource", "ParameterSite", "Declaration", "load_twin", "parameter_site",
    "find_declaration", "pattern_lines", "rewrite_source", "stage_packages", "check_loads",
]


@dataclass(frozen=True)
class TwinSource:
    """The twin's Modelica source as loaded by rumoca.

    Attributes
    ----------
    path : Path
        Package directory or ``.mo`` file, as the spec names it (absolute).
    model : str
        Full class name of the twin.
    root : Path
        Directory that holds the top-level package (rumoca's source root).
    top : Path
        The top-level package directory or the single ``.mo`` file inside *root*.
    files : tuple[Path, ...]
        Every ``.mo`` file of the source, sorted.
    variables : dict
        rumoca's flat variables (name -> attribute dict).
    top_inputs, top_outputs : tuple[str, ...]
        The twin's own top-level inputs and outputs (sorted).
    type_names : dict
        Flat variable name -> type name (``Real``, ``Boolean``, ...).
    """

    path: Path
    model: str
    root: Path
    top: Path
    files: tuple[Path, ...]
    variables: dict[str, Any]
    top_inputs: tuple[str, ...]
    top_outputs: tuple[str, ...]
    type_names: dict[str, str]
    libraries: tuple[Path, ...] = ()
    flat: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    def is_boolean_parameter(self, name: str) -> bool:
        v = self.variables.get(name)
        return bool(v) and _is_parameter(v) and self.type_names.get(name) == "Boolean"

    def parameters(self) -> list[str]:
        return sorted(n for n, v in self.variables.items() if _is_parameter(v))


def _is_parameter(v: dict[str, Any]) -> bool:
    var = v.get("variability")
    return isinstance(var, dict) and ("Parameter" in var or "Constant" in var)


def _causality(v: dict[str, Any]) -> str:
    c = v.get("causality")
    if isinstance(c, dict):
        return next(iter(c), "")
    return str(c or "")


def _locate(path: Path) -> tuple[Path, Path, tuple[Path, ...], Path]:
    """(entry file, root, files, top) for a package directory or ``.mo`` file."""
    path = path.resolve()
    if path.is_dir():
        entry = path / "package.mo"
        if not entry.is_file():
            raise SpecError(f"[source] path {path} is a directory without package.mo")
        return entry, path.parent, tuple(sorted(path.rglob("*.mo"))), path
    if path.suffix != ".mo" or not path.is_file():
        raise SpecError(f"[source] path {path} is not a .mo file or a Modelica package directory")
    if path.name == "package.mo":
        return path, path.parent.parent, tuple(sorted(path.parent.rglob("*.mo"))), path.parent
    return path, path.parent, (path,), path


def _with_elements(variables: dict[str, Any]) -> dict[str, Any]:
    """*variables* plus an entry per element of every vector variable (``TI_body[2]`` beside
    ``TI_body``, whose ``dims`` are ``[N]``): specs name elements, as the FMU does."""
    out = dict(variables)
    for name, v in variables.items():
        dims = v.get("dims") or []
        if len(dims) == 1 and isinstance(dims[0], int) and "[" not in name:
            for k in range(1, dims[0] + 1):
                out.setdefault(f"{name}[{k}]", {**v, "name": f"{name}[{k}]", "dims": []})
    return out


def twin_libraries(path: str | Path, model: str, libraries: tuple[Path, ...] | list[Path] = ()
                   ) -> tuple[tuple[Path, ...], dict[str, str]]:
    """The libraries the twin *model* in *path* needs: *libraries* (``[source] libraries``,
    ``--library``), the shipped ``TrackingBox`` library (twins written against it), and those found
    beside the source and on ``MODELICAPATH`` (:func:`trackingbox.compiler.library.resolve_libraries`);
    also the top-level packages still not found (name -> where they are used)."""
    src = resolve_source(path)
    libs = [Path(p) for p in libraries]
    shipped = library_path()
    if source_root(src).resolve() != shipped.resolve() and shipped.resolve() not in {p.resolve() for p in libs}:
        libs.append(shipped)
    return resolve_libraries(src, model, libs)


def load_twin(path: str | Path, model: str, libraries: tuple[Path, ...] | list[Path] = ()) -> TwinSource:
    """Flatten the twin *model* from *path* with the compiler's front end and collect its flat variables.

    *libraries*: further Modelica libraries it uses (:func:`twin_libraries` adds the others it
    finds); the flat model is the one ``trackingbox compile`` makes (cached by content).

    Raises
    ------
    SpecError
        If the source does not exist.
    CompileError
        If the front end cannot flatten the model (a library it uses and nobody gave is named).
    """
    path = Path(path)
    if not path.exists():
        raise SpecError(f"[source] path {path} does not exist")
    entry, root, files, top = _locate(path)
    try:
        src = resolve_source(path)
        libs, missing = twin_libraries(path, model, libraries)
        flat = flatten(src, model, libs, missing)
    except CompileError as exc:
        hint = " (or name it in the spec's [source] libraries)" if "pass --library" in str(exc) else ""
        raise CompileError(f"cannot load twin model {model!r} from {path}: {exc}{hint}") from None
    variables = _with_elements(dict(flat["variables"]))
    top_inputs = tuple(sorted(n for n, v in variables.items() if "." not in n and _causality(v) == "Input"))
    top_outputs = tuple(sorted(n for n, v in variables.items() if "." not in n and _causality(v) == "Output"))
    return TwinSource(path=path.resolve(), model=model, root=root, top=top, files=files,
                      variables=variables, top_inputs=top_inputs, top_outputs=top_outputs,
                      type_names=dict(flat.get("variable_type_names", {})), libraries=tuple(libs), flat=flat)


@dataclass(frozen=True)
class ParameterSite:
    """Where a tracked parameter lives and how it is switched to an input.

    ``hx.kht`` gives component ``hx``, leaf ``kht``, flag ``hx.use_kht_in``,
    input ``hx.kht_in``.
    """

    name: str
    component: str
    leaf: str
    flag: str
    input: str
    has_pattern: bool
    #: a top-level parameter of the twin: the component parameters bound to it (``R = R1``), each driven
    receivers: tuple[ParameterSite, ...] = ()

    @property
    def inputs(self) -> tuple[str, ...]:
        """The conditional inputs the box drives for this parameter."""
        return tuple(r.input for r in self.receivers) if self.receivers else (self.input,)

    def leaves(self) -> tuple[ParameterSite, ...]:
        """The component sites this parameter is driven through (itself, or its receivers)."""
        return self.receivers if self.receivers else (self,)


def parameter_site(src: TwinSource, name: str, where: str) -> ParameterSite:
    """Check that *name* is a Real parameter of the twin that can follow an input, and where it is switched.

    A parameter of a component is switched on that component (``hx.kht`` -> ``hx.use_kht_in``);
    a top-level parameter of the twin through every component parameter bound to it by a
    modifier (``thermalResistor1(R = R1)``: its *receivers*).

    Raises
    ------
    SpecError
        For an unknown parameter (with "did you mean"), a top-level parameter that no component
        receives by a modifier, or a structural one (:func:`.parameter_uses.structural_reason`: why).
    """
    v = src.variables.get(name)
    if v is None or not _is_parameter(v):
        raise SpecError(unknown_name("parameter", name, src.parameters(), f"{where} (model {src.model})"))
    got = receivers(src.variables, name) if "." not in name else []
    why = structural_reason(src.variables, src.type_names, src.flat, name, allowed=frozenset(got))
    if why is not None:
        raise SpecError(f"parameter {name!r} in {where} cannot be tracked: {why}")
    if "." not in name:
        if not got:
            raise SpecError(
                f"parameter {name!r} in {where} belongs to the twin {src.model} itself and no component takes it "
                f"by a modifier (such as thermalResistor1(R = {name})): only parameters of components, or "
                f"top-level ones passed to them, can be switched to an input of the tracking box")
        sites = tuple(parameter_site(src, r, f"{where} (receiving {name})") for r in got)
        return ParameterSite(name=name, component="", leaf=name, flag="", input=sites[0].input,
                             has_pattern=all(x.has_pattern for x in sites), receivers=sites)
    component, leaf = name.rsplit(".", 1)
    flag = f"{component}.use_{leaf}_in"
    return ParameterSite(name=name, component=component, leaf=leaf, flag=flag,
                         input=f"{component}.{leaf}_in", has_pattern=src.is_boolean_parameter(flag))


@dataclass(frozen=True)
class Declaration:
    """The source text that declares a parameter."""

    file: Path
    line: int
    class_name: str
    class_kind: str
    start: int          # offset of the declaration statement in the file
    end: int            # offset just past its ``;``


_CLASS_START = re.compile(
    r"\b(?:(?:partial|encapsulated|final|replaceable|expandable|pure|impure|operator)\s+)*"
    r"(model|block|class|connector|record|package|function|type)\s+([A-Za-z_]\w*)\b(?!\s*=)"
)


def _blank_comments_strings(text: str) -> str:
    """*text* with comments and string literals replaced by spaces (offsets kept)."""
    def blank(m: re.Match[str]) -> str:
        return re.sub(r"[^\n]", " ", m.group(0))
    return re.sub(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\])*"', blank, text, flags=re.S)


def _enclosing_class(code: str, offset: int) -> tuple[str, str, int, int] | None:
    """(kind, name, start, end) of the innermost class around *offset* in *code*."""
    best: tuple[str, str, int, int] | None = None
    for m in _CLASS_START.finditer(code):
        if m.start() > offset:
            break
        name = m.group(2)
        end = re.search(rf"\bend\s+{re.escape(name)}\s*;", code[m.end():])
        if end is None:
            continue
        stop = m.end() + end.end()
        if stop > offset:
            best = (m.group(1), name, m.start(), stop)
    return best


def find_declaration(src: TwinSource, name: str) -> Declaration | None:
    """Find the declaration of parameter *name* via rumoca's source location."""
    v = src.variables.get(name, {})
    var = v.get("variability") if isinstance(v, dict) else None
    loc = var.get("Parameter", {}).get("location") if isinstance(var, dict) else None
    if not loc:
        return None
    leaf = name.rsplit(".", 1)[-1]
    byte_start, line = int(loc["start"]), int(loc["start_line"])
    for file in src.files:
        raw = file.read_bytes()
        if raw[byte_start:byte_start + 9] != b"parameter":  # rumoca's offsets count bytes
            continue
        text = raw.decode("utf-8")
        start = len(raw[:byte_start].decode("utf-8", errors="replace"))
        code = _blank_comments_strings(text)
        semi = code.find(";", start)
        if semi < 0 or not re.search(rf"\b{re.escape(leaf)}\b", code[start:semi]):
            continue
        cls = _enclosing_class(code, start)
        if cls is None:
            continue
        return Declaration(file=file, line=line, class_name=cls[1], class_kind=cls[0],
                           start=start, end=semi + 1)
    return None


def _class_chain(code: str, offset: int) -> list[str]:
    """Names of the classes enclosing *offset*, outermost first."""
    chain: list[tuple[int, str]] = []
    for m in _CLASS_START.finditer(code):
        if m.start() > offset:
            break
        end = re.search(rf"\bend\s+{re.escape(m.group(2))}\s*;", code[m.end():])
        if end is not None and m.end() + end.end() > offset:
            chain.append((m.start(), m.group(2)))
    return [name for _, name in sorted(chain)]


def _connector_type(src: TwinSource) -> str:
    """Full name of a ``connector X = input Real`` the library defines.

    Falls back to a fully qualified type an existing conditional input uses,
    then to ``Modelica.Blocks.Interfaces.RealInput``.
    """
    short = re.compile(r"\bconnector\s+([A-Za-z_]\w*)\s*=\s*input\s+Real\b")
    found: list[str] = []
    for file in src.files:
        text = file.read_text(encoding="utf-8")
        code = _blank_comments_strings(text)
        within = re.match(r"\s*within\s*([\w.]*)\s*;", code)
        prefix = [p for p in (within.group(1).split(".") if within and within.group(1) else [])]
        for m in short.finditer(code):
            found.append(".".join(prefix + _class_chain(code, m.start()) + [m.group(1)]))
    if found:
        return sorted(found, key=lambda n: (n.count("."), n))[0]
    used = re.compile(r"([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)\s+\w+_in\s+if\s+use_\w+_in\b")
    for file in src.files:
        m = used.search(_blank_comments_strings(file.read_text(encoding="utf-8")))
        if m:
            return m.group(1)
    return "Modelica.Blocks.Interfaces.RealInput"


def pattern_lines(leaf: str, connector: str) -> dict[str, list[str]]:
    """The declaration and equation lines of the conditional-input pattern for *leaf*."""
    return {
        "declarations": [
            f'parameter Boolean use_{leaf}_in = false "= true to take {leaf} from input {leaf}_in";',
            f'{connector} {leaf}_in if use_{leaf}_in "{leaf} from outside (e.g. a tracking box)";',
        ],
        "protected": [f'{connector} {leaf}_internal "{leaf} actually used";'],
        "equations": [
            f"connect({leaf}_in, {leaf}_internal);",
            f"if not use_{leaf}_in then",
            f"  {leaf}_internal = {leaf};",
            "end if;",
        ],
    }


def refusal_message(src: TwinSource, site: ParameterSite) -> str:
    """Say exactly what to add to the twin's source for *site* to be trackable."""
    decl = find_declaration(src, site.name)
    lines = pattern_lines(site.leaf, _connector_type(src))
    where = (f"class {decl.class_name} ({_rel(decl.file, src.root)}:{decl.line})" if decl
             else f"the class of component {site.component!r}")
    ind = "      "
    return (
        f"parameter {site.name!r} cannot be tracked: {where} has no conditional input "
        f"{site.flag.rsplit('.', 1)[1]!r}. Add beside the declaration of {site.leaf}:\n"
        + "\n".join(ind + s for s in lines["declarations"])
        + "\n  in its protected section:\n" + "\n".join(ind + s for s in lines["protected"])
        + f"\n  in its equation section (and use {site.leaf}_internal instead of {site.leaf} in its equations):\n"
        + "\n".join(ind + s for s in lines["equations"])
        + "\n  or run again with --rewrite to write a patched copy of the source"
    )


def _rel(path: Path, base: Path) -> str:
    try:
        return str(path.relative_to(base))
    except ValueError:
        return str(path)


def _patch_class_text(text: str, decl: Declaration, leaf: str, connector: str) -> str:
    """Return *text* with the conditional-input pattern added to the declaring class."""
    code = _blank_comments_strings(text)
    cls = _enclosing_class(code, decl.start)
    assert cls is not None
    _, cname, cstart, cend = cls
    body_code = code[cstart:cend]
    # The class body after the class header; we only rename uses in equation/algorithm sections.
    sec = re.search(r"\b(equation|algorithm)\b", body_code)
    end_kw = re.search(rf"\bend\s+{re.escape(cname)}\s*;\s*$", body_code)
    assert end_kw is not None
    eq_start = cstart + (sec.start() if sec else end_kw.start())
    # Other declarations whose bindings use the parameter would have to become variables.
    decl_code = code[cstart:eq_start]
    uses = [m.start() + cstart for m in re.finditer(rf"(?<![.\w]){re.escape(leaf)}\b", decl_code)]
    other = [u for u in uses if not (decl.start <= u < decl.end)]
    if other:
        line = text.count("\n", 0, other[0]) + 1
        raise SpecError(
            f"cannot rewrite {leaf!r} in class {cname} ({decl.file}:{line}): another declaration uses it in a "
            f"binding or modifier, which would have to become a time-varying variable; edit the source by hand"
        )
    lines = pattern_lines(leaf, connector)
    indent = re.match(r"[ \t]*", text[text.rfind("\n", 0, decl.start) + 1:]).group(0)  # type: ignore[union-attr]
    end_indent = indent[:-2] if len(indent) >= 2 else ""
    # 1) rename uses in the equation/algorithm sections (not in comments/strings, not after a
    #    dot); 2) add the pattern's equations; 3) add the declarations.
    tail_start, tail_end = eq_start, cstart + end_kw.start()
    rename_end = tail_end  # comments and strings are blanked in `code`, so only real uses match
    out = []
    pos = tail_start
    seg_code = code[tail_start:rename_end]
    for m in re.finditer(rf"(?<![.\w]){re.escape(leaf)}\b", seg_code):
        a = tail_start + m.start()
        out.append(text[pos:a])
        out.append(f"{leaf}_internal")
        pos = a + len(leaf)
    renamed_tail = "".join(out) + text[pos:tail_end]
    eq_lines = "".join(f"{indent}{s}\n" for s in lines["equations"])
    if sec and sec.group(1) == "equation":
        hdr_end = text.find("\n", eq_start) + 1
        renamed_tail = renamed_tail[: hdr_end - eq_start] + eq_lines + renamed_tail[hdr_end - eq_start:]
    else:
        renamed_tail = f"{end_indent}equation\n" + eq_lines + renamed_tail
    decl_lines = "".join(f"\n{indent}{s}" for s in lines["declarations"])
    prot = f"\n{end_indent}protected" + "".join(f"\n{indent}{s}" for s in lines["protected"]) + f"\n{end_indent}public"
    return (text[:decl.end] + decl_lines + prot + text[decl.end:tail_start] + renamed_tail + text[tail_end:])


@dataclass(frozen=True)
class Rewrite:
    """A patched copy of the twin's source."""

    path: Path          # the patched package directory or .mo file (same layout as the original)
    diff: str           # unified diff, original -> patched


def rewrite_source(src: TwinSource, sites: list[ParameterSite], out_root: Path) -> Rewrite:
    """Copy the twin's source under *out_root* and add the pattern for every site without it.

    Raises
    ------
    SpecError
        If a declaration cannot be found or cannot be rewritten safely.
    """
    connector = _connector_type(src)
    decls: dict[tuple[Path, str, str], tuple[Declaration, str]] = {}
    for site in sites:
        if site.has_pattern:
            continue
        decl = find_declaration(src, site.name)
        if decl is None:
            raise SpecError(f"cannot find the declaration of parameter {site.name!r} in {src.path}")
        # components of the same class share one patch
        decls.setdefault((decl.file, decl.class_name, site.leaf), (decl, site.leaf))
    patched: dict[Path, str] = {}
    # Patch from the end of each file backwards: a patch only changes text at or
    # after its own declaration, so the offsets of earlier declarations stay valid.
    for decl, leaf in sorted(decls.values(), key=lambda d: (str(d[0].file), -d[0].start)):
        text = patched.get(decl.file, decl.file.read_text(encoding="utf-8"))
        patched[decl.file] = _patch_class_text(text, decl, leaf, connector)
    out_root = out_root.resolve()
    dest_top = out_root / src.top.name
    if dest_top.exists():
        shutil.rmtree(dest_top) if dest_top.is_dir() else dest_top.unlink()
    out_root.mkdir(parents=True, exist_ok=True)
    if src.top.is_dir():
        shutil.copytree(src.top, dest_top)
    else:
        shutil.copy2(src.top, dest_top)
    diffs = []
    for file in sorted(patched):
        rel = file.relative_to(src.root)
        new = patched[file]
        (out_root / rel).write_text(new, encoding="utf-8")
        old = file.read_text(encoding="utf-8")
        diffs.append("".join(difflib.unified_diff(
            old.splitlines(keepends=True), new.splitlines(keepends=True),
            fromfile=f"a/{rel.as_posix()}", tofile=f"b/{rel.as_posix()}")))
    new_path = out_root / src.path.relative_to(src.root)
    return Rewrite(path=new_path, diff="".join(diffs))


def stage_packages(dest: Path, library: Path, generated: Path) -> Path:
    """Copy the twin's top-level package and the generated package side by side into *dest*.

    Returns the staged generated package directory (load it with ``roots=[dest]``).
    """
    dest.mkdir(parents=True, exist_ok=True)
    target = dest / library.name
    if library.is_dir():
        shutil.copytree(library, target, dirs_exist_ok=True)
    else:
        shutil.copy2(library, target)
    shutil.copytree(generated, dest / generated.name, dirs_exist_ok=True)
    return dest / generated.name


def check_loads(package_dir: Path, model: str, root: Path, libraries: tuple[Path, ...] | list[Path] = ()) -> None:
    """Flatten *model* from the generated package (with *libraries*); CompileError if it does not.

    This is the guard that keeps generated Modelica from ever being written
    when it would not even flatten. The packages staged beside it under *root*
    are found there.
    """
    try:
        src = resolve_source(package_dir)
        libs, missing = resolve_libraries(src, model, [Path(p) for p in libraries])
        flatten(src, model, libs, missing)
    except CompileError as exc:
        raise CompileError(f"generated model {model} does not flatten: {exc}") from None
