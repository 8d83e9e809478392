"""A report as a list of blocks, written as Markdown (per stage) or one self-contained HTML page.

Every stage's report writer builds a :class:`Document` (headings, paragraphs,
tables, lists, images) and writes it as Markdown beside its PNG plots; the demo
puts the stages' documents into one HTML page with the plots embedded as
base64 PNG (:func:`html_page`), so the page opens anywhere without its folder.

Inline text may use three Markdown marks, rendered in both outputs:
```code```, ``**bold**`` and ``[text](link)``.

>>> doc = Document("Fit")
>>> doc.table(["tag", "NRMSE"], [["TI", "0.1"]], align="lr")
>>> print(doc.markdown())
# Fit
<BLANKLINE>
| tag | NRMSE |
|---|---:|
| TI | 0.1 |
<BLANKLINE>
"""
from __future__ import annotations

import base64
import html
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Union

from ..io import write_text_atomic

__all__ = ["Document", "StageReport", "html_page", "fmt"]

BlockKind = Literal["heading", "paragraph", "table", "bullets", "image"]


def fmt(x: float | None, spec: str = ".4g") -> str:
    """A number for a table: ``-`` for None/NaN.

    >>> fmt(0.123456), fmt(None), fmt(float("nan")), fmt(2.5, ".1f")
    ('0.1235', '-', '-', '2.5')
    """
    return "-" if x is None or not math.isfinite(x) else format(x, spec)


@dataclass(frozen=True)
class _Table:
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    align: str


@dataclass(frozen=True)
class _Image:
    path: Path
    alt: str


Block = tuple[BlockKind, Union[str, tuple[int, str], tuple[str, ...], _Table, _Image]]


@dataclass
class Document:
    """A report under construction (a builder: blocks are appended, then written).

    Parameters
    ----------
    title : str
        The level-1 heading.
    """

    title: str
    blocks: list[Block] = field(default_factory=list)

    def heading(self, text: str, level: int = 2) -> None:
        """A heading (level 2 and below; the title is level 1)."""
        self.blocks.append(("heading", (level, text)))

    def paragraph(self, text: str) -> None:
        """A paragraph of inline text."""
        self.blocks.append(("paragraph", text))

    def bullets(self, items: Sequence[str]) -> None:
        """A bulleted list (nothing for an empty one)."""
        if items:
            self.blocks.append(("bullets", tuple(items)))

    def table(self, header: Sequence[str], rows: Sequence[Sequence[Any]], align: str = "") -> None:
        """A table; *align* has one letter per column, ``l`` or ``r`` (default: first left, the rest right)."""
        align = align or "l" + "r" * (len(header) - 1)
        if len(align) != len(header):
            raise ValueError(f"align {align!r} has {len(align)} letters for {len(header)} columns")
        self.blocks.append(("table", _Table(tuple(header), tuple(tuple(str(c) for c in r) for r in rows), align)))

    def code(self, text: str, language: str = "") -> None:
        """A preformatted block (a Modelica source, a diff), shown verbatim."""
        self.blocks.append(("code", (language, text)))

    def image(self, path: str | os.PathLike[str], alt: str) -> None:
        """A PNG plot (a file written beside the report)."""
        self.blocks.append(("image", _Image(Path(path), alt)))

    def extend(self, other: Document, shift: int = 1) -> None:
        """Append *other*'s title (as a heading) and blocks, headings moved *shift* levels down."""
        self.heading(other.title, 1 + shift)
        for kind, value in other.blocks:
            if kind == "heading":
                level, text = value  # type: ignore[misc]
                value = (min(level + shift, 6), text)
            self.blocks.append((kind, value))

    # ------------------------------------------------------------------ Markdown

    def markdown(self, base: str | os.PathLike[str] | None = None) -> str:
        """The document as Markdown; image links relative to *base* (the report's folder)."""
        out = [f"# {self.title}", ""] if self.title else []
        for kind, value in self.blocks:
            if kind == "heading":
                level, text = value  # type: ignore[misc]
                out += ["#" * level + " " + text, ""]
            elif kind == "paragraph":
                out += [str(value), ""]
            elif kind == "bullets":
                out += [f"- {item}" for item in value] + [""]  # type: ignore[union-attr]
            elif kind == "table":
                t: _Table = value  # type: ignore[assignment]
                out.append("| " + " | ".join(t.header) + " |")
                out.append("|" + "".join("---:|" if a == "r" else "---|" for a in t.align))
                out += ["| " + " | ".join(r) + " |" for r in t.rows]
                out.append("")
            elif kind == "code":
                language, text = value  # type: ignore[misc]
                fence = "~~~~" if "```" in text else "```"
                out += [f"{fence}{language}", text.rstrip("\n"), fence, ""]
            else:
                img: _Image = value  # type: ignore[assignment]
                link = os.path.relpath(img.path, base) if base is not None else img.path.as_posix()
                out += [f"![{img.alt}]({Path(link).as_posix()})", ""]
        return "\n".join(out)

    def write_markdown(self, path: str | os.PathLike[str]) -> Path:
        """Write :meth:`markdown` to *path* (atomically); image links relative to its folder."""
        path = Path(path)
        write_text_atomic(path, self.markdown(path.parent))
        return path

    # ------------------------------------------------------------------ HTML

    def html_body(self, level: int = 1) -> str:
        """The document as an HTML fragment, images embedded as base64 PNG."""
        out = [f"<h{level}>{_inline(self.title)}</h{level}>"] if self.title else []
        for kind, value in self.blocks:
            if kind == "heading":
                lv, text = value  # type: ignore[misc]
                lv = min(lv + level - 1, 6)
                out.append(f"<h{lv}>{_inline(text)}</h{lv}>")
            elif kind == "paragraph":
                out.append(f"<p>{_inline(str(value))}</p>")
            elif kind == "bullets":
                out.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in value) + "</ul>")  # type: ignore
            elif kind == "table":
                t: _Table = value  # type: ignore[assignment]
                cls = ['' if a == "l" else ' class="num"' for a in t.align]
                head = "".join(f"<th{c}>{_inline(h)}</th>" for c, h in zip(cls, t.header))
                body = "".join("<tr>" + "".join(f"<td{c}>{_inline(x)}</td>" for c, x in zip(cls, r)) + "</tr>"
                               for r in t.rows)
                out.append(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")
            elif kind == "code":
                _, text = value  # type: ignore[misc]
                out.append(f"<pre><code>{html.escape(text)}</code></pre>")
            else:
                img: _Image = value  # type: ignore[assignment]
                data = base64.b64encode(img.path.read_bytes()).decode("ascii")
                alt = html.escape(img.alt, quote=True)
                out.append(f'<figure><img alt="{alt}" src="data:image/png;base64,{data}">'
                           f"<figcaption>{html.escape(img.alt)}</figcaption></figure>")
        return "\n".join(out)


@dataclass(frozen=True)
class StageReport:
    """What a stage's report writer wrote.

    Attributes
    ----------
    markdown : Path
        The Markdown file.
    files : tuple of Path
        Every file written (plots, Markdown, JSON/CSV), in order.
    document : Document
        The report's content, for the demo's HTML page.
    """

    markdown: Path
    files: tuple[Path, ...]
    document: Document


_CODE = re.compile(r"`([^`]+)`")
_BOLD = re.compile(r"\*\*(.+?)\*\*")
_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")


def _inline(text: str) -> str:
    """Escape *text* for HTML and render ```code```, ``**bold**`` and ``[text](link)``.

    >>> _inline("kht < `x` **b** [r](a.md)")
    'kht &lt; <code>x</code> <b>b</b> <a href="a.md">r</a>'
    """
    s = html.escape(text, quote=False)
    s = _CODE.sub(r"<code>\1</code>", s)
    s = _BOLD.sub(r"<b>\1</b>", s)
    return _LINK.sub(r'<a href="\2">\1</a>', s)


_STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; color: #222; }
h1 { border-bottom: 2px solid #ccc; } h2 { border-bottom: 1px solid #ddd; margin-top: 2em; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; } th { background: #f3f3f3; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; }
figure { margin: 1em 0; } img { max-width: 100%; } figcaption { font-size: 0.85em; color: #555; }
code { background: #f3f3f3; padding: 0 0.2em; }
pre { background: #f6f6f6; padding: 0.6em; overflow-x: auto; font-size: 0.85em; }
"""


def html_page(title: str, documents: Sequence[Document]) -> str:
    """One self-contained HTML page: *documents* one after the other, plots embedded."""
    body = "\n".join(d.html_body(level=1 if i == 0 else 2) for i, d in enumerate(documents))
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f"<title>{html.escape(title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n{body}\n"
            "</body>\n</html>\n")
