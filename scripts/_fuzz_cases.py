"""The fuzzer's cases (``scripts/fuzz``, :mod:`_fuzz`): one bad input of each kind (a CSV, a spec,
an FMU archive, a Modelica source, a set of command-line options) written into its own
directory, with the command run on it and the names its error must mention.

:class:`Maker` builds them from the valid inputs (``_fuzz.Base``); :data:`MAKERS` holds one maker per
kind and :func:`plan` draws the kinds of a run in proportion to :data:`WEIGHTS`.
"""
from __future__ import annotations

import dataclasses
import os
import random
import shutil
import stat
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from _fuzz import Base

#: cells read as missing values (trackingbox.data.NA_VALUES)
NA_CELLS = ("", "NaN", "nan", "NAN", "NA", "N/A", "n/a", "null", "NULL", "None", "#N/A")
KINDS = ("csv", "spec", "fmu", "modelica", "cli")
#: share of the cases per kind
WEIGHTS = {"csv": 0.24, "spec": 0.26, "fmu": 0.15, "modelica": 0.10, "cli": 0.25}

# --------------------------------------------------------------------------- the twin every case runs

MODEL = """\
model FuzzTwin "First-order twin used by scripts/fuzz"
  parameter Real k(min = 0, max = 0.1, unit = "1/s") = 0.005 "loss coefficient";
  parameter Real tau(min = 1, max = 1000, unit = "s") = 60 "time constant";
  input Real u(start = 50, unit = "K") "inlet temperature";
  output Real y(unit = "K") "outlet temperature";
  Real x(start = 38, fixed = true, unit = "K") "state";
equation
  der(x) = (u - x) / tau - k * x;
  y = x;
  annotation(experiment(StartTime = 0, StopTime = 600, Interval = 10));
end FuzzTwin;
"""


# --------------------------------------------------------------------------- cases

@dataclasses.dataclass
class Case:
    """One bad input and the command run on it."""

    id: int
    kind: str
    name: str
    argv: list[str]
    hints: tuple[str, ...]          # the error must name one of these (case-insensitive)
    must_refuse: bool = True
    subprocess: bool = False        # through the console script (foreign native code)
    timeout: float = 120.0
    outcome: str = ""
    detail: str = ""
    seconds: float = 0.0


class Maker:
    """Writes each case's files into its own directory and builds its command line."""

    def __init__(self, base: Base, root: Path, rng: random.Random) -> None:
        self.base = base
        self.root = root
        self.rng = rng

    def dir(self, i: int) -> Path:
        d = self.root / f"{i:05d}"
        d.mkdir(parents=True, exist_ok=True)
        return d

    # -- helpers ---------------------------------------------------------------
    def spec_with(self, d: Path, text: str | None = None, *, csv: str | None = None,
                  twin: Path | None = None) -> Path:
        spec = d / "spec.toml"
        t = self.base.spec_text() if text is None else text
        if twin is not None:
            t = t.replace(self.base.fmu.as_posix(), twin.as_posix())
        spec.write_text(t)
        (d / "measurements.csv").write_text(self.base.csv_text() if csv is None else csv)
        return spec

    def command_on_spec(self, d: Path, spec: Path) -> tuple[list[str], tuple[str, ...]]:
        r = self.rng.random()
        if r < 0.7:
            return ["track", str(spec), "--out", str(d / "out" / "track")], ()
        if r < 0.9:
            return ["estimate", str(spec), "--maxiter", "1", "--popsize", "2", "--no-refine",
                    "--report", str(d / "out" / "estimate")], ()
        return ["generate", str(spec), "-o", str(d / "out" / "generated")], ()


def _cell_noise(rng: random.Random) -> str:
    return rng.choice(["abc", "1,5", "0x10", "--", "1e", "TRUE", "[1]", "1 2", "∞", "NaN", "nan", "inf", "-inf",
                       "1e400", "-1e308", "1e308", "", " ", "None", "null", "\x00", "１２"])


# CSV ------------------------------------------------------------------------------------------

def csv_case(m: Maker, i: int) -> Case:
    rng, base, d = m.rng, m.base, m.dir(i)
    rows = list(base.csv_rows)
    variant = rng.choice([
        "empty", "header-only", "bom", "utf16", "latin1", "garbage", "nan-stretch", "all-nan", "text-cell",
        "inf-cell", "huge", "neg-huge", "dup-times", "unsorted", "reversed", "time-text", "no-time",
        "missing-tag", "dup-column", "ragged", "semicolon", "one-row", "megacell", "nul", "iso-mixed",
        "negative-time", "time-nan", "quotes", "long-form-bad", "crlf", "time-huge", "many-columns",
    ])
    must = variant not in ("bom", "crlf", "huge", "neg-huge", "nan-stretch", "negative-time", "many-columns",
                           "quotes", "iso-mixed")
    name = "measurements.csv"
    text: str | bytes
    if variant == "empty":
        text = ""
    elif variant == "header-only":
        text = "time,FI,TI\n"
    elif variant == "bom":
        text = "\ufeff" + base.csv_text(rows)
    elif variant == "utf16":
        text = base.csv_text(rows).encode("utf-16")
    elif variant == "latin1":
        text = base.csv_text(rows).replace("TI", "T\xc9").encode("latin-1")
    elif variant == "garbage":
        text = rng.randbytes(rng.randint(1, 5000))
    elif variant == "nul":
        text = base.csv_text(rows).replace("FI", "F\x00I", 1)
    elif variant in ("nan-stretch", "all-nan"):
        a = rng.randrange(len(rows)) if variant == "nan-stretch" else 0
        b = min(len(rows), a + rng.randint(5, 60)) if variant == "nan-stretch" else len(rows)
        col = rng.choice([1, 2])
        lines = ["time,FI,TI"] + [
            ",".join("" if (a <= k < b and j == col) else f"{v:g}" for j, v in enumerate(r))
            for k, r in enumerate(rows)]
        text = "\n".join(lines) + "\n"
    elif variant in ("text-cell", "inf-cell", "huge", "neg-huge", "quotes"):
        k = rng.randrange(len(rows))
        cell = {"text-cell": _cell_noise(rng), "inf-cell": rng.choice(["inf", "-inf", "1e400", "Infinity"]),
                "huge": "1e308", "neg-huge": "-1e308", "quotes": '"12.5"'}[variant]
        col = rng.choice([1, 2])
        lines = ["time,FI,TI"] + [",".join(cell if (kk == k and j == col) else f"{v:g}"
                                           for j, v in enumerate(r)) for kk, r in enumerate(rows)]
        text = "\n".join(lines) + "\n"
        if variant == "text-cell" and cell.strip() in NA_CELLS:
            must = False  # an empty or NA cell is a missing value, allowed in measurements
    elif variant == "dup-times":
        k = rng.randrange(1, len(rows))
        rows[k] = (rows[k - 1][0], *rows[k][1:])
        text = base.csv_text(rows)
    elif variant == "unsorted":
        k = rng.randrange(1, len(rows) - 1)
        rows[k], rows[k + 1] = rows[k + 1], rows[k]
        text = base.csv_text(rows)
    elif variant == "reversed":
        text = base.csv_text(rows[::-1])
    elif variant == "time-text":
        k = rng.randrange(len(rows))
        lines = base.csv_text(rows).splitlines()
        lines[k + 1] = "yesterday" + lines[k + 1][lines[k + 1].index(","):]
        text = "\n".join(lines) + "\n"
    elif variant == "time-nan":
        k = rng.randrange(len(rows))
        lines = base.csv_text(rows).splitlines()
        lines[k + 1] = rng.choice(["nan", "", "inf"]) + lines[k + 1][lines[k + 1].index(","):]
        text = "\n".join(lines) + "\n"
    elif variant == "time-huge":
        rows = [(t * 1e300, u, y) for t, u, y in rows]
        text = base.csv_text(rows)
    elif variant == "no-time":
        text = base.csv_text(rows).replace("time", rng.choice(["Time", "t", "tiem", ""]), 1)
    elif variant == "missing-tag":
        text = base.csv_text(rows).replace("TI", rng.choice(["TI2", "ti", "T I"]), 1)
    elif variant == "dup-column":
        text = base.csv_text(rows).replace("FI", "TI", 1)
    elif variant == "ragged":
        lines = base.csv_text(rows).splitlines()
        k = rng.randrange(1, len(lines))
        longer = rng.random() < 0.5
        lines[k] = lines[k] + rng.choice([",1", ",1,2,3"]) if longer else lines[k].rsplit(",", 1)[0]
        must = longer  # a short row is a missing value (allowed in measurements)
        text = "\n".join(lines) + "\n"
    elif variant == "semicolon":
        text = base.csv_text(rows).replace(",", ";")
    elif variant == "one-row":
        text = base.csv_text(rows[:1])
    elif variant == "megacell":
        k = rng.randrange(len(rows))
        lines = base.csv_text(rows).splitlines()
        lines[k + 1] = lines[k + 1].rsplit(",", 1)[0] + "," + "9" * 500 + "x" * (1 << 20)
        text = "\n".join(lines) + "\n"
    elif variant == "iso-mixed":
        lines = ["time,FI,TI"] + [f"2024-01-01T00:{int(t) // 60:02d}:{int(t) % 60:02d}Z,{u:g},{y:g}"
                                  if k % 2 else f"{t:g},{u:g},{y:g}" for k, (t, u, y) in enumerate(rows)]
        text = "\n".join(lines) + "\n"
    elif variant == "negative-time":
        rows = [(t - 500.0, u, y) for t, u, y in rows]
        text = base.csv_text(rows)
    elif variant == "long-form-bad":
        text = "tag,time,value\n" + "".join(f"{rng.choice(['FI', 'TI', ''])},{rng.choice(['1', 'x', '', '-5'])},"
                                            f"{rng.choice(['1', 'x', '', 'inf'])}\n" for _ in range(50))
    elif variant == "crlf":
        text = base.csv_text(rows).replace("\n", "\r\n")
    else:  # many-columns
        header = "time,FI,TI," + ",".join(f"c{j}" for j in range(2000))
        text = header + "\n" + "".join(f"{t:g},{u:g},{y:g}," + ",".join("0" for _ in range(2000)) + "\n"
                                       for t, u, y in rows)
    if rng.random() < 0.6:
        spec = m.spec_with(d, csv="")
        path = d / name
        (path.write_bytes if isinstance(text, bytes) else path.write_text)(text)  # type: ignore[operator]
        argv, _ = m.command_on_spec(d, spec)
    else:
        name = "inputs.csv"
        path = d / name
        data = text.replace("FI", "u") if isinstance(text, str) else text
        (path.write_bytes if isinstance(data, bytes) else path.write_text)(data)  # type: ignore[operator]
        # TI is not an input of the twin: drop it where the text is still CSV
        argv = ["simulate", str(base.fmu), "--inputs", str(path), "--output", "y", "-o",
                str(d / "out" / "result.csv")]
        must = True if variant != "bom" else must
        must = must or "TI" in (data if isinstance(data, str) else "")
    return Case(i, "csv", f"csv:{variant}:{argv[0]}", argv, (name, "time", "TI", "FI", "'u'"), must)


# spec -----------------------------------------------------------------------------------------

def _replace_line(text: str, key: str, value: str) -> str:
    out = []
    done = False
    for line in text.splitlines():
        if not done and line.split("=")[0].strip().strip('"') == key:
            line = f"{line.split('=')[0]}= {value}"
            done = True
        out.append(line)
    return "\n".join(out) + "\n"


def _drop_line(text: str, key: str) -> str:
    lines = text.splitlines()
    keep = [ln for ln in lines if ln.split("=")[0].strip().strip('"') != key]
    return "\n".join(keep) + "\n"


def spec_case(m: Maker, i: int) -> Case:
    rng, base, d = m.rng, m.base, m.dir(i)
    text = base.spec_text()
    hints: tuple[str, ...] = ("spec.toml",)
    raw: bytes | None = None
    keys = ["twin", "measurements", "sample_time", "name", "start", "min", "max", "variable", "parameter",
            "gain", "time_constant", "training", "validation", "hold_until", "tau"]
    bad_values = ['"text"', "[1, 2]", "true", "{ a = 1 }", '""', "1979-05-27T07:32:00Z", "[]", "[[1.0]]"]
    variant = rng.choice(["missing-key", "wrong-type", "unknown-key", "unknown-name", "range", "window",
                          "not-utf8", "bom", "truncated", "deep", "bigint", "nul", "dup-key", "empty",
                          "garbage", "no-parameters", "twin-path", "fixed-bounds", "huge-string",
                          "min-below-fmu", "hold-nan"])
    must = True
    if variant == "missing-key":
        key = rng.choice(keys)
        text = _drop_line(text, key)
        hints += (key,)
        must = key not in ("training", "validation", "hold_until", "tau")  # optional keys
    elif variant == "wrong-type":
        key = rng.choice(keys)
        strings = ("twin", "measurements", "name", "variable", "parameter")
        value = rng.choice(["1", "2.5", "true", "[1, 2]", "{ a = 1 }"] if key in strings else bad_values)
        text = _replace_line(text, key, value)
        hints += (key,)
    elif variant == "unknown-key":
        section = rng.choice(["", "[inputs]", "[[parameters]]", "[windows]", "[[pairs]]", "[tracking]"])
        key = rng.choice(["smaple_time", "gian", "extra", "windows2", "min_value"])
        text = text.replace(section, f"{section}\n{key} = 1", 1) if section else f"{key} = 1\n{text}"
        must = section not in ("[inputs]",)  # a new tag in [inputs] is an unknown column, also refused
        hints += (key,)
    elif variant == "unknown-name":
        which = rng.choice(['"u"', '"y"', '"k"', '"TI"', "tau"])
        new = {'"u"': '"uu"', '"y"': '"why"', '"k"': '"kk"', '"TI"': '"TI9"', "tau": "tua"}[which]
        text = text.replace(which, new) if rng.random() < 0.5 else text.replace(which, new, 1)
        hints += (new.strip('"'),)
    elif variant == "range":
        key, value = rng.choice([("sample_time", "0"), ("sample_time", "-10"), ("sample_time", "1e-300"),
                                 ("min", "0.06"), ("start", "0.5"), ("max", "0.0001"), ("gain", "0"),
                                 ("time_constant", "-5"), ("hold_until", "-1"), ("max", "5"),
                                 ("sample_time", "1e300"), ("tau", "-60"), ("tau", "1e9")])
        text = _replace_line(text, key, value)
        hints += (key, value, f"{float(value):g}")
    elif variant == "window":
        tr, va = rng.choice([("[600.0, 0.0]", None), ("[0.0, 800.0]", None), ("[0.0, nan]", None),
                             ("[0.0, inf]", None), ("[-100.0, 600.0]", None), ("[0.0, 600.0]", "[300.0, 900.0]"),
                             ("[0.0, 600.0]", "[1e9, 2e9]"), ("[5000.0, 6000.0]", None), ("[0.0, 0.0]", None),
                             ("[0.0, 600.0]", "[0.0, 600.0]"), ("[0.0]", None), ("[0.0, 600.0, 900.0]", None)])
        text = _replace_line(text, "training", tr)
        if va is not None:
            text = _replace_line(text, "validation", va)
        # a window beyond the data is refused by the stage that uses it (track uses none of them)
        must = va != "[1e9, 2e9]" and tr != "[5000.0, 6000.0]"
        hints += ("training", "validation", "window")
    elif variant == "not-utf8":
        raw = text.replace('"k"', '"k\xe9"').encode("latin-1")
    elif variant == "bom":
        raw = b"\xef\xbb\xbf" + text.encode()
        must = False
    elif variant == "truncated":
        raw = text.encode()[: rng.randrange(1, len(text))]
        must = False  # a cut after a complete table can still be valid TOML (then a missing key)
    elif variant == "deep":
        depth = rng.choice([1000, 100_000])
        text = _replace_line(text, "sample_time", "[" * depth + "]" * depth)
        hints += ("sample_time",)
    elif variant == "bigint":
        key = rng.choice(["sample_time", "start", "min", "max", "gain", "hold_until"])
        digits = rng.choice([20, 310, 5000])
        text = _replace_line(text, key, "9" * digits)
        hints += (key,)
        must = digits > 20 or key in ("start", "min", "max")  # 1e20 is a number; as a bound it is out of range
    elif variant == "nul":
        raw = text.replace("k", "k\x00", 1).encode()
    elif variant == "dup-key":
        text = text.replace("sample_time = 10.0", "sample_time = 10.0\nsample_time = 5.0")
    elif variant == "empty":
        raw = b""
    elif variant == "garbage":
        raw = rng.randbytes(rng.randint(1, 3000))
    elif variant == "no-parameters":
        text = text.split("[[parameters]]")[0] + "[windows]" + text.split("[windows]")[1].split("[[pairs]]")[0]
        must = False  # track without pairs may run untracked
        hints += ("parameters",)
    elif variant == "twin-path":
        target = rng.choice([d / "missing.fmu", d, d / "measurements.csv", d / "spec.toml", Path("/dev/null"),
                             Path("~nosuchuser/twin.fmu"), Path("/proc/self/mem")])
        text = text.replace(base.fmu.as_posix(), target.as_posix())
        hints += ("twin", target.name)
    elif variant == "fixed-bounds":
        text = _replace_line(text, "tau", rng.choice(["-1", "0", "1e9", "0.5"]))
        hints += ("tau",)
    elif variant == "huge-string":
        text = _replace_line(text, "variable", '"' + "T" * 200_000 + '"')
        hints += ("variable",)
    elif variant == "min-below-fmu":
        text = _replace_line(text, "min", "-0.01")
        hints += ("min", "'k'")
    else:  # hold-nan
        value = rng.choice(["nan", "inf", "1e308"])
        text = _replace_line(text, "hold_until", value)
        must = value != "1e308"  # finite: the start-up hold then covers all the data
        hints += ("hold_until",)
    spec = m.spec_with(d, text)
    if raw is not None:
        spec.write_bytes(raw)
    argv, _ = m.command_on_spec(d, spec)
    if variant == "no-parameters":
        argv = ["estimate", str(spec), "--maxiter", "1", "--popsize", "2", "--no-refine"]
        must = True
    return Case(i, "spec", f"spec:{variant}:{argv[0]}", argv, hints, must)


# FMU archives ----------------------------------------------------------------------------------

_MD_VARIANTS = {
    "xml-malformed": "<fmiModelDescription fmiVersion='2.0'><ModelVariables>",
    "xml-xxe": ('<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>'
                '<fmiModelDescription fmiVersion="2.0" modelName="&e;" guid="g"/>'),
    "xml-laughs": ('<?xml version="1.0"?><!DOCTYPE l [<!ENTITY a "aaaaaaaaaa">'
                   + "".join(f'<!ENTITY {chr(98 + j)} "{("&" + chr(97 + j) + ";") * 10}">' for j in range(8))
                   + ']><fmiModelDescription fmiVersion="2.0" modelName="&i;" guid="g"/>'),
    "xml-version1": '<fmiModelDescription fmiVersion="1.0" modelName="m" guid="g"/>',
    "xml-version9": '<fmiModelDescription fmiVersion="9.9" modelName="m" guid="g"/>',
    "xml-empty": "",
    "xml-binary": None,
}


def _rezip(src: Path, dst: Path, *, drop: tuple[str, ...] = (), add: dict[str, bytes] | None = None,
           replace: dict[str, bytes] | None = None) -> None:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            if item.filename in drop:
                continue
            data = (replace or {}).get(item.filename, zin.read(item))
            zout.writestr(item.filename, data)
        for name, data in (add or {}).items():
            zout.writestr(name, data)


def fmu_case(m: Maker, i: int) -> Case:
    rng, base, d = m.rng, m.base, m.dir(i)
    fmu = d / "twin.fmu"
    variant = rng.choice(["crafted"] * 6 + ["not-zip", "truncated", "empty", "empty-zip", "no-md", "traversal",
                                            "absolute", "bomb", "many", "md-variant", "vr-unknown", "dup-names",
                                            "no-binary", "symlink", "bad-bounds", "directory"])
    must = True
    sub = False
    timeout = 120.0
    hints: tuple[str, ...] = ("twin.fmu",)
    if variant == "crafted":
        which = rng.choice(sorted(base.crafted))
        shutil.copy(base.crafted[which], fmu)
        variant = f"crafted-{which}"
        sub = True
        must = which != "well_behaved" and which != "segv_free"
        timeout = 150.0
    elif variant == "not-zip":
        fmu.write_bytes(rng.randbytes(rng.randint(1, 20000)))
    elif variant == "truncated":
        data = base.fmu.read_bytes()
        fmu.write_bytes(data[: rng.randrange(1, len(data))])
    elif variant == "empty":
        fmu.write_bytes(b"")
    elif variant == "empty-zip":
        zipfile.ZipFile(fmu, "w").close()
    elif variant == "no-md":
        _rezip(base.fmu, fmu, drop=("modelDescription.xml",))
    elif variant in ("traversal", "absolute"):
        name = rng.choice(["../../evil.txt", "../evil.so", "resources/../../x"]) if variant == "traversal" \
            else rng.choice(["/tmp/evil.txt", "//x", "C:/x"])
        _rezip(base.fmu, fmu, add={name: b"evil"})
    elif variant == "bomb":
        os.link(base.bomb, fmu) if base.bomb.stat().st_dev == d.stat().st_dev else shutil.copy(base.bomb, fmu)
        timeout = 180.0
    elif variant == "many":
        os.link(base.many, fmu) if base.many.stat().st_dev == d.stat().st_dev else shutil.copy(base.many, fmu)
    elif variant == "md-variant":
        which = rng.choice(sorted(_MD_VARIANTS))
        data = _MD_VARIANTS[which]
        payload = rng.randbytes(3000) if data is None else data.encode()
        _rezip(base.fmu, fmu, replace={"modelDescription.xml": payload})
        variant = which
    elif variant in ("vr-unknown", "dup-names", "bad-bounds"):
        with zipfile.ZipFile(base.fmu) as z:
            md = z.read("modelDescription.xml").decode()
        if variant == "vr-unknown":
            md = md.replace('valueReference="', 'valueReference="99999', 1)
            must = False  # a value reference is an opaque number: the FMU's binary judges it
        elif variant == "dup-names":
            md = md.replace('name="k"', 'name="y"', 1)
        else:
            md = md.replace('name="k"', 'name="k" min="1" max="0"', 1) if 'min=' not in md else \
                md.replace('min="0"', 'min="5"', 1)
            must = False
        _rezip(base.fmu, fmu, replace={"modelDescription.xml": md.encode()})
    elif variant == "no-binary":
        with zipfile.ZipFile(base.fmu) as z:
            bins = [n for n in z.namelist() if n.startswith("binaries/")]
        _rezip(base.fmu, fmu, drop=tuple(bins))
    elif variant == "symlink":
        with zipfile.ZipFile(base.fmu) as zin, zipfile.ZipFile(fmu, "w") as zout:
            for item in zin.infolist():
                zout.writestr(item, zin.read(item))
            info = zipfile.ZipInfo("resources/link")
            info.external_attr = (stat.S_IFLNK | 0o777) << 16
            zout.writestr(info, "/etc/passwd")
        must = False
    else:  # directory
        fmu.mkdir()
    if variant == "no-binary":
        must = False  # inspect reads the description only; simulate and track refuse
    r = rng.random()
    out = d / "out"
    if r < 0.3:
        argv = ["inspect", str(fmu)]
        if variant.startswith("crafted") or variant in ("bomb", "many", "symlink", "vr-unknown", "bad-bounds",
                                                          "traversal", "absolute"):
            argv = ["simulate", str(fmu), "--stop", "50", "--set", "u=1", "-o", str(out / "result.csv")]
    elif r < 0.7:
        argv = ["simulate", str(fmu), "--stop", "50", "--set", "u=1", "-o", str(out / "result.csv")]
    else:
        spec = m.spec_with(d, twin=fmu)
        if variant.startswith("crafted"):
            spec.write_text(spec.read_text().replace('"y"', '"y"').replace("tau = 60.0", ""))
        argv = ["track", str(spec), "--out", str(out / "track")]
    if variant.startswith("crafted-segv_free") or variant == "crafted-well_behaved":
        must = False
    if variant.startswith("crafted") and argv[0] == "track":
        must = must  # the twin's names differ from the spec's: refused before loading, or by the canary
    return Case(i, "fmu", f"fmu:{variant}:{argv[0]}", argv, hints + ("FMU",), must, sub, timeout)


# Modelica ----------------------------------------------------------------------------------------

_CONSTRUCTS = {
    "when": "  when x > 40 then\n    reinit(x, 38);\n  end when;\n",
    "discrete": "  discrete Real d(start = 0);\n",
    "pre": "  Real p = pre(x);\n",
    "sample": "  Boolean s = sample(0, 1);\n",
    "algorithm": "algorithm\n  y2 := x;\n",
    "external": None,
    "edge": "  Boolean b = x > 40;\n  Boolean e = edge(b);\n",
}


def modelica_case(m: Maker, i: int) -> Case:
    rng, d = m.rng, m.dir(i)
    src = d / "FuzzTwin.mo"
    text: str | bytes = MODEL
    model = "FuzzTwin"
    variant = rng.choice(["construct"] * 4 + ["truncate", "delete-char", "garbage", "utf16", "empty",
                                              "unknown-model", "missing-file", "deep-expr", "unbalanced",
                                              "undeclared", "nul", "directory", "long-line"])
    must = True
    hints: tuple[str, ...] = ("FuzzTwin", src.name)
    if variant == "construct":
        which = rng.choice(sorted(_CONSTRUCTS))
        snippet = _CONSTRUCTS[which]
        if which == "external":
            text = MODEL.replace("model FuzzTwin", 'function f\n  input Real a;\n  output Real b;\n'
                                 'external "C" b = sin(a);\nend f;\nmodel FuzzTwin').replace(
                "y = x;", "y = f(x);")
            text = "package P\n" + text.replace("end FuzzTwin;", "end FuzzTwin;\nend P;")
            model = "P.FuzzTwin"
        elif which == "algorithm":
            text = MODEL.replace("  Real x", "  Real y2;\n  Real x").replace("  annotation", snippet + "  annotation")
        elif which == "when":
            text = MODEL.replace("  annotation", snippet + "  annotation")
        else:
            text = MODEL.replace("equation", snippet + "equation")
        variant = f"construct-{which}"
    elif variant == "truncate":
        text = MODEL[: rng.randrange(10, len(MODEL) - 5)]
    elif variant == "delete-char":
        k = rng.randrange(len(MODEL))
        while MODEL[k] not in ";()=\"":
            k = rng.randrange(len(MODEL))
        text = MODEL[:k] + MODEL[k + 1:]
        must = False  # some deletions leave valid Modelica (a quote pair, a bracket in a string)
    elif variant == "garbage":
        text = rng.randbytes(rng.randint(1, 4000))
    elif variant == "utf16":
        text = MODEL.encode("utf-16")
    elif variant == "empty":
        text = ""
    elif variant == "unknown-model":
        model = rng.choice(["FuzzTwn", "Pkg.FuzzTwin", "", "FuzzTwin.x"])
        hints += (model or "--model",)
    elif variant == "missing-file":
        src = d / "Nowhere.mo"
        text = ""
        hints = ("Nowhere.mo",)
    elif variant == "deep-expr":
        text = MODEL.replace("y = x;", "y = " + "(" * 5000 + "x" + ")" * 5000 + ";")
        must = False  # valid Modelica: compiled or refused for its depth, never a crash
    elif variant == "unbalanced":
        text = MODEL.replace("  y = x;\n", "")
    elif variant == "undeclared":
        text = MODEL.replace("y = x;", "y = x + zz;")
        hints += ("zz",)
    elif variant == "nul":
        text = MODEL.replace("equation", "equ\x00ation")
    elif variant == "long-line":
        text = MODEL.replace("y = x;", "y = x" + " + 0" * 50_000 + ";")
        must = False
    else:  # directory without package.mo
        src = d / "pkg"
        src.mkdir()
        (src / "FuzzTwin.mo").write_text(MODEL)
        hints = ("pkg", "package.mo")
    if variant != "missing-file" and variant != "directory":
        (src.write_bytes if isinstance(text, bytes) else src.write_text)(text)  # type: ignore[operator]
    argv = ["compile", str(src), "--model", model, "--backend", "embedded", "-o", str(d / "out" / "m.fmu")]
    return Case(i, "modelica", f"modelica:{variant}", argv, hints, must, False, 240.0 if not must else 150.0)


# command-line options ---------------------------------------------------------------------------

_BAD_NUMBERS = ["nan", "inf", "-inf", "-1", "0", "-0", "1e308", "1e-300", "abc", "", "1e400", "0x10"]
_BAD_INTS = ["-1", "0", "-5", "nan", "1.5", "abc", "999999999999999999999"]


def cli_case(m: Maker, i: int) -> Case:
    rng, base, d = m.rng, m.base, m.dir(i)
    spec = m.spec_with(d)
    out = d / "out"
    fmu = str(base.fmu)
    sim = ["simulate", fmu, "--set", "u=50", "--stop", "100", "--step", "10"]
    variant = rng.choice([
        "simulate-num", "simulate-set", "simulate-out", "estimate-num", "estimate-int", "estimate-out",
        "track-int", "track-out", "track-resume", "pair-num", "pair-int", "validate-num", "bench-num",
        "unknown-flag", "missing-file", "diagnose-int", "inspect-path", "generate-out", "weird-path",
    ])
    hints: tuple[str, ...] = ()
    must = True
    if variant == "simulate-num":
        opt = rng.choice(["--step", "--stop", "--start", "--tolerance"])
        value = rng.choice(_BAD_NUMBERS + ["1e-9", "2", "1e9"])
        argv = [*sim, "-o", str(out / "r.csv")]
        k = argv.index(opt) if opt in argv else None
        if k is not None:
            argv[k + 1] = value
        else:
            argv += [opt, value]
        hints = (opt,)
        must = not (opt == "--tolerance" and value in ("1e-300",))
        if (opt, value) in (("--stop", "1e308"), ("--start", "-1"), ("--start", "0"), ("--start", "-0"),
                            ("--start", "2"), ("--step", "2"), ("--tolerance", "1e-9")):
            must = False
    elif variant == "simulate-set":
        item = rng.choice(["k=-1", "k=1e9", "k=nan", "tau=0", "zz=1", "k", "=1", "k=1=2", "u=inf", "y=3",
                           "k=0x1", "k=1e400", "time=5"])
        argv = [*sim, "--set", item, "-o", str(out / "r.csv")]
        hints = ("--set", item.split("=")[0] or "NAME")
    elif variant == "simulate-out":
        target = _bad_output(rng, d, [base.fmu])
        argv = [*sim, "-o", str(target)]
        hints = ("-o", "--out", target.name or str(target), "output")
    elif variant == "estimate-num":
        opt = rng.choice(["--warmup", "--global-grid"])
        value = rng.choice(_BAD_NUMBERS + ["1e9"])
        argv = ["estimate", str(spec), "--maxiter", "1", "--popsize", "2", "--no-refine", opt, value]
        hints = (opt,)
        must = value not in ("0", "-0") or opt != "--warmup"
    elif variant == "estimate-int":
        opt = rng.choice(["--seed", "--workers", "--maxiter", "--popsize", "--refine-iterations"])
        value = rng.choice(_BAD_INTS)
        argv = ["estimate", str(spec), "--no-refine", opt, value]
        if opt != "--maxiter":
            argv += ["--maxiter", "1"]
        if opt != "--popsize":
            argv += ["--popsize", "2"]
        hints = (opt,)
        must = not (value == "0" and opt in ("--maxiter", "--seed", "--refine-iterations"))
        must = must and not (value == "999999999999999999999" and opt in ("--seed", "--refine-iterations"))
    elif variant == "estimate-out":
        target = _bad_output(rng, d, [spec, d / "measurements.csv", base.fmu])
        argv = ["estimate", str(spec), "--maxiter", "1", "--popsize", "2", "--no-refine", "--report", str(target)]
        hints = ("--report", target.name or str(target), "report")
        must = target not in (Path("."), Path(""), d / "existing_dir")  # a writable directory: fine
    elif variant == "track-int":
        value = rng.choice(_BAD_INTS)
        argv = ["track", str(spec), "--out", str(out / "track"), "--checkpoint-every", value]
        hints = ("--checkpoint-every",)
        must = value != "999999999999999999999"  # never checkpoint: allowed
    elif variant == "track-out":
        target = _bad_output(rng, d, [spec, d / "measurements.csv", base.fmu])
        opt = rng.choice(["--out", "--report"])
        argv = ["track", str(spec), opt, str(target)]
        hints = (opt, target.name or str(target), "output", "report")
        must = target not in (Path("."), Path(""), d / "existing_dir")
    elif variant == "track-resume":
        ck = out / "track" / "checkpoint.json"
        ck.parent.mkdir(parents=True)
        ck.write_bytes(rng.choice([b"", b"{", b"[]", b'{"version": 99}', rng.randbytes(200),
                                   b'{"version": 1, "spec": "x", "rows": -5}', b"null"]))
        (ck.parent / "tracking.csv").write_text("time\n0\n")  # a run to resume
        argv = ["track", str(spec), "--out", str(ck.parent), "--resume"]
        hints = ("checkpoint",)
    elif variant == "pair-num":
        opt = rng.choice(["--step", "--interval", "--window", "--tolerance", "--max-time", "--noise-ratio",
                          "--min-reach", "--max-ratio", "--at", "--baseline-tolerance", "--rank-tol"])
        value = rng.choice(["nan", "inf", "-1", "0", "-inf", "1e308"])
        argv = ["pair", str(spec), "--no-write", "--workers", "1", opt, value]
        hints = (opt,)
        must = not (value == "0" and opt in ("--noise-ratio", "--min-reach", "--at"))
        must = must and not (value == "1e308" and opt in ("--noise-ratio", "--max-time", "--max-ratio", "--at",
                                                          "--baseline-tolerance", "--min-reach"))
        must = must and not (value == "inf" and opt in ("--max-time",))
    elif variant == "pair-int":
        opt = rng.choice(["--workers", "--samples"])
        argv = ["pair", str(spec), "--no-write", opt, rng.choice(_BAD_INTS)]
        hints = (opt,)
    elif variant == "validate-num":
        argv = ["validate", str(spec), "--fmu", fmu, "--band", rng.choice(["nan", "-1", "0", "inf", "-inf"])]
        hints = ("--band", "[source]", "validation", "pairs")
    elif variant == "bench-num":
        opt = rng.choice(["--hours", "--days", "--noise-scale"])
        argv = ["bench", rng.choice(["heat-exchanger", "evaporator"]), "--out", str(out / "bench"), opt,
                rng.choice(["nan", "-1", "0", "inf", "-inf", "1e308"])]
        hints = (opt,)
        if opt == "--noise-scale" and argv[-1] == "0":
            argv[-1] = "-2"
    elif variant == "unknown-flag":
        cmd = rng.choice(["track", "estimate", "simulate", "pair", "inspect", "compile", "validate"])
        argv = [cmd, str(spec), rng.choice(["--frobnicate", "--sed", "-x", "--stop=", "--json=1"])]
        hints = ("unrecognized", "usage", "argument", "error")
    elif variant == "missing-file":
        missing = str(d / "nope" / rng.choice(["spec.toml", "twin.fmu", "in.csv"]))
        argv = rng.choice([["track", missing], ["estimate", missing], ["inspect", missing],
                           ["simulate", missing, "--stop", "1", "-o", str(out / "r.csv")],
                           ["simulate", fmu, "--inputs", missing, "-o", str(out / "r.csv")],
                           ["pair", missing], ["validate", str(spec), "--fmu", missing],
                           ["generate", missing], ["diagnose", missing]])
        hints = (Path(missing).name, "nope")
    elif variant == "diagnose-int":
        opt = rng.choice(["--fit-best", "--workers", "--maxiter"])
        value = rng.choice(_BAD_INTS)
        argv = ["diagnose", str(spec), opt, value]
        hints = (opt,)
        must = not (value == "999999999999999999999" and opt in ("--fit-best",))
        must = must and not (value == "0" and opt == "--maxiter")  # 0: refinement only
    elif variant == "inspect-path":
        target = rng.choice([d, Path("/dev/null"), Path("/proc/self/status"), d / "spec.toml"])
        argv = ["inspect", str(target)]
        hints = (target.name,)
    elif variant == "generate-out":
        src = d / "FuzzTwin.mo"
        src.write_text(MODEL)
        spec.write_text(spec.read_text() + f'\n[source]\npath = "{src.name}"\nmodel = "FuzzTwin"\n')
        target = _bad_output(rng, d, [spec, src])
        argv = ["generate", str(spec), "-o", str(target)]
        must = target not in (Path("."), Path(""), d / "existing_dir")
        hints = ("-o", target.name or str(target), "output", "spec.toml")
    else:  # weird-path
        weird = rng.choice(["a\x00b.toml", "~nosuchuser/spec.toml", "x" * 5000 + ".toml", "/" + "a/" * 3000,
                            "-", "/dev/zero"])
        argv = [rng.choice(["track", "estimate", "inspect", "pair"]), weird]
        hints = ("spec", "file", "FMU", weird[:20])
    return Case(i, "cli", f"cli:{variant}:{argv[0]}", argv, hints, must)


def _bad_output(rng: random.Random, d: Path, inputs: list[Path]) -> Path:
    """An output location that cannot or must not be written."""
    (d / "afile").write_text("x")
    ro = d / "readonly"
    ro.mkdir(exist_ok=True)
    ro.chmod(0o555)
    existing = d / "existing_dir"
    existing.mkdir(exist_ok=True)
    # as root a read-only directory is writable: not a bad output there
    readonly = [ro / "out.csv", ro / "sub" / "x"] if os.geteuid() != 0 else []
    choices = [d / "afile" / "out.csv", *readonly, Path("/proc/trackingbox/x"),
               Path(""), Path("."), existing, *inputs, Path("/dev/full"), Path("~nosuchuser/x"),
               d / ("y" * 300) / "x"]
    return rng.choice(choices)


MAKERS: dict[str, Callable[[Maker, int], Case]] = {
    "csv": csv_case, "spec": spec_case, "fmu": fmu_case, "modelica": modelica_case, "cli": cli_case,
}


def plan(n: int, kinds: list[str], rng: random.Random) -> list[str]:
    """Kinds of the *n* cases, in proportion to WEIGHTS, shuffled."""
    total = sum(WEIGHTS[k] for k in kinds)
    counts = {k: int(n * WEIGHTS[k] / total) for k in kinds}
    k = 0
    while sum(counts.values()) < n:
        counts[kinds[k % len(kinds)]] += 1
        k += 1
    out = [kind for kind, c in counts.items() for _ in range(c)]
    rng.shuffle(out)
    return out
