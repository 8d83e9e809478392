"""How ``scripts/_bench_diagnose.py`` scores a name against a case's truth, by hand."""
from __future__ import annotations

import importlib.util
from pathlib import Path

from trackingbox.benches import bench_definition

_SPEC = importlib.util.spec_from_file_location(
    "_bench_diagnose", Path(__file__).resolve().parents[1] / "scripts" / "_bench_diagnose.py")
bench = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench)


def _row(effect, targets, named, instrument=None, verdict="effect"):
    e, _, t = named.partition("@")
    return {"expected_effect": effect, "expected_targets": targets, "instrument": instrument,
            "verdict": verdict, "named_effect": e or None, "named_target": t or None}


def test_a_name_is_right_only_on_a_target_the_plant_carries_the_effect_on():
    # the borate's offset is in the effect and in the flash tank: either target is a true name
    assert bench._judged(_row("bpr-offset", ["effect", "flash"], "bpr-offset@flash")) == "right"
    assert bench._judged(_row("bpr-offset", ["effect", "flash"], "bpr-offset@effect")) == "right"
    assert bench._judged(_row("bpr-offset", ["effect"], "bpr-offset@flash")) == "wrong"
    assert bench._judged(_row("bpr-offset", ["effect", "flash"], "steam-vent@effect")) == "wrong"
    assert bench._judged(_row("bpr-offset", ["effect"], "-", verdict="unexplained")) == "nothing"
    # anything named where nothing in the library was hidden is wrong
    assert bench._judged(_row(None, [], "level-density@LT_body")) == "wrong"


def test_another_entry_on_the_faulty_meter_is_the_instrument_not_a_right_name():
    row = _row("ds-meter", ["DS_product"], "sensor-bias@QI-6150", instrument="QI-6150")
    assert bench._judged(row) == "instrument"
    assert bench._judged(_row("ds-meter", ["DS_product"], "sensor-bias@TI-6151", instrument="QI-6150")) == "wrong"
    assert bench._judged(_row("ds-meter", ["DS_product"], "ds-meter@DS_product", instrument="QI-6150")) == "right"


def test_the_evaporator_cases_record_where_the_plant_carries_their_effect():
    hidden = bench_definition("evaporator").hidden
    assert hidden["borated-liquor"].targets == ("effect", "flash")
    assert hidden["borated-liquor"].to_json()["targets"] == ["effect", "flash"]
    assert hidden["density-meter"].instrument == "QI-6150"
    assert hidden["vent-orifice"].targets == ("effect",) and hidden["vent-orifice"].instrument is None
    assert hidden["ncg-after-restart"].targets == ()


def _rows(effect, targets, names, instrument=None, others=()):
    return {"expected_effect": effect, "expected_targets": targets, "instrument": instrument,
            "verdict": "effect", "others": list(others),
            "named_all": [tuple(n.split("@")) for n in names],
            "named_effect": names[0].split("@")[0], "named_target": names[0].split("@")[1]}


def test_every_finding_is_scored_not_only_the_first():
    # the right name first, a wrong one second: the wrong name counts
    assert bench._judged(_rows("steam-vent", ["effect"], ["steam-vent@effect", "shell-heat-loss@effect"])) == "wrong"
    # a wrong name first, the right one second: still wrong
    assert bench._judged(_rows("steam-vent", ["effect"], ["shell-heat-loss@effect", "steam-vent@effect"])) == "wrong"
    # a two-effect case with both its effects named on their targets: right
    both = _rows("steam-vent", ["effect[1]"], ["steam-vent@effect[1]", "shell-heat-loss@effect[2]"],
                 others=[("shell-heat-loss", "effect[2]")])
    assert bench._judged(both) == "right"
    # ... and with the second on the wrong element: wrong
    off = _rows("steam-vent", ["effect[1]"], ["steam-vent@effect[1]", "shell-heat-loss@effect[1]"],
                others=[("shell-heat-loss", "effect[2]")])
    assert bench._judged(off) == "wrong"
    # the right name beside another entry on the faulty meter: right; the meter's entry alone: instrument
    meter = ["ds-meter@DS_product", "sensor-bias@QI-6150"]
    assert bench._judged(_rows("ds-meter", ["DS_product"], meter, instrument="QI-6150")) == "right"
    assert bench._judged(_rows("ds-meter", ["DS_product"], meter[1:], instrument="QI-6150")) == "instrument"
    # where nothing in the library was hidden, any name is wrong
    assert bench._judged(_rows(None, [], ["sensor-drift@PI-6152"])) == "wrong"


def test_the_fall_the_noise_leaves_reachable_is_one_minus_noise_over_rms():
    # a residual of RMS 1.0 of which 0.8 is noise: removing every model error leaves 0.8, a 20 % fall
    assert abs(bench._reachable_fall({"noise": 0.8, "validation": {"rms": 1.0}}) - 0.2) < 1e-12
    # noise estimated above the residual: nothing to remove
    assert bench._reachable_fall({"noise": 1.2, "validation": {"rms": 1.0}}) == 0.0
    # a tag diagnose did not describe, or without a validation RMS: not known
    assert bench._reachable_fall(None) is None
    assert bench._reachable_fall({"noise": 0.1, "validation": {}}) is None
