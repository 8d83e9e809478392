"""Compiled patched twins kept between diagnoses (:mod:`trackingbox.diagnose.fmucache`) and measurement tables
kept between the views of one process (:func:`trackingbox.data.view.read_measurements`).

The expectations come from outside the caches: the file's own bytes, a fresh read of the table,
and the screened candidate of a fresh compile.
"""
from __future__ import annotations


import numpy as np
import pytest

from trackingbox.spec import load_spec



def test_kept_fmu_comes_back_byte_for_byte_and_only_under_its_key(tmp_path, monkeypatch) -> None:
    from trackingbox.diagnose import fmucache

    monkeypatch.setenv("TRACKINGBOX_CACHE_DIR", str(tmp_path / "cache"))
    fmu = tmp_path / "a" / "TwinDiagnosed.fmu"
    fmu.parent.mkdir()
    fmu.write_bytes(b"PK\x03\x04 compiled twin")
    assert not fmucache.fetch("ab" * 32, tmp_path / "b" / "TwinDiagnosed.fmu")
    fmucache.store("ab" * 32, fmu)
    other = tmp_path / "b" / "TwinDiagnosed.fmu"
    assert fmucache.fetch("ab" * 32, other) and other.read_bytes() == fmu.read_bytes()
    assert not fmucache.fetch("cd" * 32, tmp_path / "c" / "TwinDiagnosed.fmu")
    monkeypatch.setenv("TRACKINGBOX_PATCH_CACHE", "0")
    assert not fmucache.fetch("ab" * 32, tmp_path / "d" / "TwinDiagnosed.fmu")


def test_cache_key_follows_every_library_file(tmp_path) -> None:
    # an edited hook in a library the twin is compiled beside must not hand back the old FMU
    from trackingbox.diagnose import fmucache

    lib = tmp_path / "Lib"
    (lib / "Sub").mkdir(parents=True)
    (lib / "package.mo").write_text("package Lib\nend Lib;\n")
    (lib / "Sub" / "A.mo").write_text("model A\n  parameter Real k = 1;\nend A;\n")
    key = fmucache.key("local", [lib])
    assert fmucache.key("local", [lib]) == key
    assert fmucache.key("other", [lib]) != key
    (lib / "Sub" / "A.mo").write_text("model A\n  parameter Real k = 2;\nend A;\n")
    assert fmucache.key("local", [lib]) != key
    (lib / "Sub" / "A.mo").write_text("model A\n  parameter Real k = 1;\nend A;\n")
    assert fmucache.key("local", [lib]) == key


def test_cache_key_follows_the_c_compiler_upgraded_in_place(tmp_path, monkeypatch) -> None:
    # the same $CC path answering with another version (an upgraded gcc) must not hand back the old FMU
    from trackingbox.diagnose import fmucache

    cc = tmp_path / "mycc"
    cc.write_text("#!/bin/sh\necho 'mycc (Test) 12.2.0'\n")
    cc.chmod(0o755)
    monkeypatch.setenv("CC", str(cc))
    key = fmucache.key("local")
    assert fmucache.c_compiler(str(cc)).endswith("=mycc (Test) 12.2.0")
    assert fmucache.key("local") == key
    cc.write_text("#!/bin/sh\necho 'mycc (Test) 13.10.1'\n")
    assert fmucache.c_compiler(str(cc)).endswith("=mycc (Test) 13.10.1")
    assert fmucache.key("local") != key
    monkeypatch.setenv("CC", str(tmp_path / "absent-cc"))
    assert fmucache.c_compiler(str(tmp_path / "absent-cc")).endswith("=-")


def test_measurement_table_is_read_again_when_the_file_changes(tmp_path) -> None:
    from trackingbox.data import view
    from trackingbox.data.view import kept_tables

    csv = tmp_path / "m.csv"
    csv.write_text("time,a,b\n0,1.0,2.0\n10,1.5,\n20,2.0,3.0\n")
    with kept_tables():
        _read_again_after_a_change(csv)
    assert not view._TABLES  # forgotten after the block


def _read_again_after_a_change(csv) -> None:
    import os

    from trackingbox.data import view
    from trackingbox.data.table import read_table
    from trackingbox.data.view import read_measurements

    first = read_measurements(csv, ["a", "b"])
    assert len(view._TABLES) == 1
    fresh = read_table(csv, required=["a", "b"], allow_nan=True)
    np.testing.assert_array_equal(first.to_numpy(), fresh.to_numpy())
    first.loc[0, "a"] = -99.0  # a caller's change does not reach the next reader
    assert read_measurements(csv, ["a", "b"]).loc[0, "a"] == 1.0
    st = csv.stat()
    csv.write_text("time,a,b\n0,7.0,2.0\n10,1.5,\n20,2.0,3.0\n")
    os.utime(csv, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    assert read_measurements(csv, ["a", "b"]).loc[0, "a"] == 7.0


@pytest.mark.compile
@pytest.mark.slow
def test_screen_from_a_kept_fmu_equals_the_screen_from_a_fresh_compile(hx_heat_loss_case, tmp_path, monkeypatch):
    """Heat loss hidden on the heat-exchanger bench: the second work folder takes the FMU from the cache
    (no compile) and screens the candidate to the same numbers as the first, which compiled it."""
    from trackingbox.diagnose import library
    from trackingbox.diagnose.fit import screen_compiled
    from trackingbox.diagnose.residuals import where

    monkeypatch.setenv("TRACKINGBOX_CACHE_DIR", str(tmp_path / "cache"))
    spec = load_spec(hx_heat_loss_case.directory / "spec.toml")
    found = where(spec, estimate_options={"maxiter": 0, "refine_grid": 60.0})
    effect = library.load_effects(())["heat-loss"]
    compiled = screen_compiled(spec, found, effect, "hx", tmp_path / "first")
    assert list((tmp_path / "cache" / "patches").glob("*/*/*.fmu"))

    def no_compile(*args, **kwargs):
        raise AssertionError("compiled again although the cache holds the patch")

    monkeypatch.setattr(library, "compile_patch", no_compile)
    kept = screen_compiled(spec, found, effect, "hx", tmp_path / "second")
    assert kept.delta_bic == compiled.delta_bic and kept.values == compiled.values
    assert kept.pinned == compiled.pinned
    first, second = (next((tmp_path / d / "heat-loss-hx").glob("*.fmu")) for d in ("first", "second"))
    assert first.read_bytes() == second.read_bytes()


@pytest.fixture(scope="module")
def scale_case(fmu_cache, tmp_path_factory):
    from trackingbox.benches import make_bench

    return make_bench("evaporator", tmp_path_factory.mktemp("dg-onset") / "case", seed=0, hours=6.0,
                      hidden="burkeite-scale", plant_fmu=fmu_cache("TrackingBox.Benches.Evaporator.Hidden.BurkeiteScale"),
                      twin_fmu=fmu_cache("TrackingBox.Benches.Evaporator.Twin"))


@pytest.mark.compile
@pytest.mark.slow
def test_onset_points_ranked_on_training_give_the_candidate_of_every_point_run_on_both_windows(scale_case, tmp_path,
                                                                                               monkeypatch):
    """``soluble-scale`` (an onset, ``xOn``) on the evaporator: ranking its linearisation points on the training
    window and running validation at the best one only is the same candidate, to the last digit, as running
    every point on both windows and keeping the best (the ΔBIC is the training window's)."""
    from trackingbox.diagnose import fit as ft
    from trackingbox.diagnose import library
    from trackingbox.diagnose.fit import screen_compiled
    from trackingbox.diagnose.residuals import where

    spec = load_spec(scale_case.directory / "spec.toml")
    found = where(spec, estimate_options={"maxiter": 0, "refine_grid": 60.0})
    effect = library.load_effects(())["soluble-scale"]
    calls = []
    plain = ft.window_series
    monkeypatch.setattr(ft, "window_series", lambda *a, **k: calls.append(a[1].name) or plain(*a, **k))
    every = screen_compiled(spec, found, effect, "effect", tmp_path, rank_on_training=False)
    n_every, calls[:] = list(calls), []
    ranked = screen_compiled(spec, found, effect, "effect", tmp_path)
    assert np.isfinite(every.delta_bic)
    # several points (the start and the dry solids' quartiles), each 1 + 3 runs a window; validation once
    k = 1 + len(effect.parameters)
    points = n_every.count("training") // k
    assert points > 1 and n_every.count("validation") == points * k
    assert calls.count("training") == points * k and calls.count("validation") == k
    assert ranked.to_json() == every.to_json()  # ΔBIC, validation and noise gains, tags, values, reason
    assert ranked.pinned == every.pinned and ranked.nrmse_after == every.nrmse_after
    for t in every.validation_residual:
        np.testing.assert_array_equal(ranked.validation_residual[t], every.validation_residual[t])
