"""Blanking comments, strings and nested classes keeps every offset and line (hand-worked texts)."""
from __future__ import annotations

from trackingbox.compiler.source import blanked, strip_comments
from trackingbox.compiler.source_scan import _code_mask


def test_code_mask_blanks_comments_strings_and_quoted_names_keeping_lines():
    data = b'x = 1; // one\ny = "a\nb"; /* c\n d */ \'q.r\' = 2;'
    code, starts, ends = _code_mask(data)
    assert code == b"x = 1;       \ny =   \n  ;     \n" + b" " * 11 + b" = 2;"
    assert len(code) == len(data) and code.count(b"\n") == data.count(b"\n")
    assert [data[s:e] for s, e in zip(starts, ends)] == [b"// one", b'"a\nb"', b"/* c\n d */", b"'q.r'"]


def test_code_mask_answers_the_same_when_asked_again():
    data = b"a /* b */ c"
    first = _code_mask(data)
    again = _code_mask(bytes(bytearray(data)))  # an equal text, another object
    assert again == first == (b"a         c", [2], [9])
    again[1].append(99)  # the caller's lists are its own
    assert _code_mask(data)[1] == [2]


def test_blanked_and_strip_comments():
    assert blanked("ab\n\ncd e") == "  \n\n    "
    assert blanked("") == ""
    assert strip_comments('a = "s\nt"; // c\nb') == "a =   \n  ;     \nb"
