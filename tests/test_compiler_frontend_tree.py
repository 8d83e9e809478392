"""What the front end reads (a copy of the files a model can reach) and the flat models kept between
compiles (issue 35, item 1: a library is parsed once and reused)."""
from __future__ import annotations

from pathlib import Path

import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.embedded import run_frontend
from trackingbox.compiler.frontend import FlatCache, build_tree
from trackingbox.compiler.library import LibraryIndex, index_for
from trackingbox.compiler.source import resolve_source
from trackingbox.errors import CompileError

pytestmark = pytest.mark.compile

PKG = {
    "package.mo": "package Lib\nend Lib;\n",
    "Parts.mo": ("within Lib;\npackage Parts\n  model Tank\n    parameter Real k = 0.5;\n"
                 "    Real h(start = 1, fixed = true);\n  equation\n    der(h) = -k*h;\n  end Tank;\nend Parts;\n"),
    "Other.mo": "within Lib;\nmodel Other\n  Real z = time;\nend Other;\n",
    "Plant.mo": "within Lib;\nmodel Plant\n  Parts.Tank tank(k = 2);\nend Plant;\n",
}


def write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root


@pytest.fixture()
def lib(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("TRACKINGBOX_CACHE_DIR", str(tmp_path / "cache"))
    return write(tmp_path / "Lib", PKG)


def test_the_tree_holds_the_files_the_model_reaches_and_names_the_originals(lib, tmp_path):
    source = resolve_source(lib)
    tree = build_tree(source, "Lib.Plant", (), tmp_path / "t1")
    assert tree.pruned
    assert sorted(p.name for p in tree.originals.values()) == ["Parts.mo", "Plant.mo", "package.mo"]
    assert tree.entry.name == "Plant.mo"
    copy = tree.entry
    assert tree.rename(f"error at {copy}:3:5") == f"error at {lib / 'Plant.mo'}:3:5"


def test_the_cache_key_follows_the_used_files_only(lib, tmp_path):
    source = resolve_source(lib)
    key = build_tree(source, "Lib.Plant", (), tmp_path / "a").cache_key("Lib.Plant")
    (lib / "Other.mo").write_text("within Lib;\nmodel Other\n  Real z = 2*time;\nend Other;\n")
    assert build_tree(source, "Lib.Plant", (), tmp_path / "b").cache_key("Lib.Plant") == key
    (lib / "Parts.mo").write_text(PKG["Parts.mo"].replace("0.5", "0.25"))
    assert build_tree(source, "Lib.Plant", (), tmp_path / "c").cache_key("Lib.Plant") != key


def test_a_second_compile_takes_the_flat_model_from_the_cache(lib, tmp_path):
    source = resolve_source(lib)
    first = run_frontend(source, "Lib.Plant")
    second = run_frontend(source, "Lib.Plant")
    assert first["ok"] and not first.get("cached")
    assert second.get("cached") and second["flat"] == first["flat"]
    # a changed file of the model is read again
    (lib / "Parts.mo").write_text(PKG["Parts.mo"].replace("0.5", "0.25"))
    third = run_frontend(source, "Lib.Plant")
    assert third["ok"] and not third.get("cached")
    assert FlatCache().root.is_dir()


def test_the_cache_can_be_turned_off(lib, monkeypatch):
    monkeypatch.setenv("TRACKINGBOX_FRONTEND_CACHE", "0")
    source = resolve_source(lib)
    assert not run_frontend(source, "Lib.Plant").get("cached")
    assert not run_frontend(source, "Lib.Plant").get("cached")


def test_a_file_the_index_missed_is_found_on_the_whole_library(lib, tmp_path, monkeypatch):
    """Should the index leave out a file the model needs, the front end reports an unresolved
    name and the compile is repeated on the whole source: same result, never another class."""
    monkeypatch.setenv("TRACKINGBOX_FRONTEND_CACHE", "0")
    real = LibraryIndex.frontend_files

    def forgetful(self, model):
        return {f for f in real(self, model) if f.name != "Parts.mo"}

    monkeypatch.setattr(LibraryIndex, "frontend_files", forgetful)
    res = compile_model(lib, "Lib.Plant", backend="embedded", output=tmp_path / "p.fmu")
    assert res.states == 1


def test_the_model_compiles_the_same_from_the_tree(lib, tmp_path):
    import fmpy

    res = compile_model(lib, "Lib.Plant", backend="embedded", output=tmp_path / "p.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["tank.h"],
                            relative_tolerance=1e-9)
    assert out["tank.h"][-1] == pytest.approx(2.718281828459045 ** -2, rel=1e-6)
    assert index_for(resolve_source(lib)).classes["Lib.Parts.Tank"].line == 3


MEDIA = {
    "package.mo": "package Media\nend Media;\n",
    "Chain.mo": ("within Media;\npackage Chain\n  package A\n    constant Real cp = 1;\n  end A;\n"
                 "  package B\n    extends A(cp = 1);\n  end B;\n  package C\n    extends B(cp = 4);\n  end C;\n"
                 "end Chain;\n"),
}
USER = "model User\n  package M = Media.Chain.C;\n  Real c = M.cp*(1 + 0*time);\nend User;\n"


def test_an_edit_of_a_library_file_is_in_the_tree_or_the_whole_library_reading_refuses(tmp_path):
    """B's ``cp = 1`` repeats A's declaration under C's ``cp = 4`` (.package_overrides): the pruned tree
    reads B without it, lines kept; the whole-library reading, which gives rumoca the libraries as
    they are, cannot, and says so rather than letting rumoca read C.cp as 1."""
    media = write(tmp_path / "Media", MEDIA)
    user = tmp_path / "User.mo"
    user.write_text(USER)
    source = resolve_source(user)
    tree = build_tree(source, "User", (media,), tmp_path / "t")
    copy = next(c for c, o in tree.originals.items() if o.name == "Chain.mo")
    lines = copy.read_text().splitlines()
    assert lines[6].strip() == "extends A(      );" and len(lines) == MEDIA["Chain.mo"].count("\n")
    with pytest.raises(CompileError, match=r"must read .*Chain\.mo edited .*whole-library reading cannot"):
        build_tree(source, "User", (media,), tmp_path / "f", prune=False)
