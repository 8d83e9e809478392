"""An onset parameter (``onset_of``) is screened where the target's variable crosses it.

The expectations are numpy's quantiles of the series the (stand-in) twin run returns, clipped to the
parameter's bounds, and the entry files as written.
"""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np
import pytest

from trackingbox.diagnose import fit as ft
from trackingbox.diagnose.library import load_effects
from trackingbox.errors import SpecError
from trackingbox.simulation.windows import Problem

ROOT = Path(__file__).resolve().parents[1]


def test_quartiles_inside_the_bounds_and_apart_from_the_start():
    rng = np.random.default_rng(7)
    v = rng.uniform(0.74, 0.88, 500)
    lo, hi, start = 0.4, 0.85, 0.5
    expected = [min(max(float(q), lo), hi) for q in np.quantile(v, [0.25, 0.5, 0.75])]
    assert ft.quartile_starts(np.append(v, np.nan), lo, hi, start) == pytest.approx(expected)
    # a quartile within 1 % of the range of the start is the start's own point
    assert ft.quartile_starts(v, lo, hi, expected[1]) == pytest.approx([expected[0], expected[2]])
    assert ft.quartile_starts([np.nan], lo, hi, start) == []


def test_onset_points_from_the_targets_variable(monkeypatch):
    problem = Problem(twin=Path("twin.fmu"), names=("effect.Rf", "scale_k", "scale_xOn"),
                      start=np.array([1e-4, 1e-9, 0.5]), lower=np.array([0.0, 0.0, 0.4]),
                      upper=np.array([6e-4, 5e-8, 0.85]), fixed={}, outputs={"QI-6150": "DI_product"},
                      sample_time=10.0, warmup=0.0)
    series = np.concatenate([np.full(5, 0.2), np.linspace(0.76, 0.82, 101)])  # the lead-in is left out
    asked = {}

    def fake_run(p, window, x):
        asked.update(p.outputs)
        return {tag: series for tag in p.outputs}

    monkeypatch.setattr(ft, "simulate_window", fake_run)
    effect = NS(parameters=[NS(name="k", onset_of=""), NS(name="xOn", onset_of="x"), NS(name="tau", onset_of="")])
    x = problem.start.copy()
    variables = ["effect.x", "effect.xs", "flash.x", "DI_product"]
    points = ft.onset_starts(effect, "effect", problem, NS(lead=5), x, {"k": "scale_k", "xOn": "scale_xOn"},
                             variables)
    assert set(asked.values()) == {"effect.x", "DI_product"} and asked["QI-6150"] == "DI_product"
    quart = np.quantile(series[5:], [0.25, 0.5, 0.75])
    assert [p[2] for p in points] == pytest.approx(quart)
    for p in points:
        assert p[:2] == pytest.approx(x[:2])
    # an entry without an onset costs no run
    asked.clear()
    assert ft.onset_starts(NS(parameters=[NS(name="k", onset_of="")]), "effect", problem, NS(lead=5), x,
                           {"k": "scale_k"}, variables) == [] and not asked


def test_an_array_target_pools_its_elements(monkeypatch):
    problem = Problem(twin=Path("twin.fmu"), names=("scale_xOn",), start=np.array([0.5]), lower=np.array([0.4]),
                      upper=np.array([0.85]), fixed={}, outputs={}, sample_time=10.0, warmup=0.0)
    runs = {"effect[1].x": np.linspace(0.55, 0.60, 50), "effect[2].x": np.linspace(0.70, 0.80, 50)}
    by_key = {}

    def fake_run(p, window, x):
        by_key.update(p.outputs)
        return {k: runs[v] for k, v in p.outputs.items()}

    monkeypatch.setattr(ft, "simulate_window", fake_run)
    effect = NS(parameters=[NS(name="xOn", onset_of="x")])
    points = ft.onset_starts(effect, "effect", problem, NS(lead=0), problem.start, {"xOn": "scale_xOn"},
                             ["effect[1].x", "effect[2].x", "effect[1].xs", "effects[1].x"])
    assert sorted(by_key.values()) == ["effect[1].x", "effect[2].x"]
    quart = np.quantile(np.concatenate(list(runs.values())), [0.25, 0.5, 0.75])
    assert [p[0] for p in points] == pytest.approx(quart)


def test_entries_declare_their_onsets(tmp_path):
    effects = load_effects(())
    assert {(e, p.name) for e, entry in effects.items() for p in entry.parameters if p.onset_of} == {
        ("soluble-scale", "xOn")}
    assert next(p for p in effects["soluble-scale"].parameters if p.name == "xOn").onset_of == "x"
    text = (ROOT / "codegen/effects/soluble-scale/effect.toml").read_text().replace('onset_of = "x"',
                                                                                     'onset_of = "1x"')
    folder = tmp_path / "soluble-scale"
    folder.mkdir()
    (folder / "effect.toml").write_text(text)
    (folder / "patch.mo.jinja").write_text((ROOT / "codegen/effects/soluble-scale/patch.mo.jinja").read_text())
    with pytest.raises(SpecError, match=r"parameter 'xOn': field 'onset_of' must name a variable"):
        load_effects([tmp_path])
