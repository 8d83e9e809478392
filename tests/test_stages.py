"""The stage contract (``trackingbox.stages``): one shape for the six stages, settings built from arguments one way."""
from __future__ import annotations

import argparse
import dataclasses
import inspect
import typing
from pathlib import Path

import pytest

from trackingbox import cli, stages
from trackingbox.commands import pair as pair_command
from trackingbox.commands._progress import Progress
from trackingbox.estimation import DEFAULT_GLOBAL_GRID, DEFAULT_WARMUP
from trackingbox.stages.contract import settings_from_args

MODULES = ("estimate", "pair", "track", "generate", "validate", "diagnose")


@pytest.mark.parametrize("name", MODULES)
def test_every_stage_has_frozen_settings_and_one_run_signature(name: str) -> None:
    module = getattr(stages, name)
    settings = [v for v in vars(module).values()
                if inspect.isclass(v) and dataclasses.is_dataclass(v) and v.__name__.endswith("Settings")]
    assert len(settings) == 1, settings
    assert settings[0].__dataclass_params__.frozen  # type: ignore[attr-defined]
    params = inspect.signature(module.run).parameters
    assert list(params)[:2] == ["spec", "settings"]
    assert params["progress"].kind is inspect.Parameter.KEYWORD_ONLY and params["progress"].default is None
    result = typing.get_type_hints(module.run)["return"]
    assert dataclasses.is_dataclass(result) and callable(getattr(result, "to_json", None))


def _parsed(argv: list[str]) -> argparse.Namespace:
    return cli.build_parser().parse_args(argv)


def test_a_command_builds_the_settings_an_equal_direct_construction_gives(tmp_path: Path) -> None:
    args = _parsed(["pair", str(tmp_path / "spec.toml"), "--step", "0.1", "--one-sided", "--method", "both",
                    "--freeze", "holdControllers=1", "--samples", "32"])
    assert pair_command.settings(args) == stages.PairSettings(step=0.1, two_sided=False, method="both",
                                                              freeze=(("holdControllers", 1.0),), samples=32)
    args = _parsed(["estimate", str(tmp_path / "spec.toml"), "--seed", "4", "--no-refine", "--jacobian", "fd"])
    # the command's own defaults (a 4 h warm-up, a 60 s global grid) are what it passes, as before
    assert settings_from_args(stages.EstimateSettings, args) == stages.EstimateSettings(
        seed=4, refine=False, jacobian="fd", warmup=DEFAULT_WARMUP, global_grid=DEFAULT_GLOBAL_GRID)


def test_settings_from_args_refuses_a_name_the_settings_do_not_have() -> None:
    with pytest.raises(TypeError, match="EstimateSettings has no setting 'seeds'"):
        settings_from_args(stages.EstimateSettings, argparse.Namespace(), seeds=3)


def test_the_estimation_reports_reach_the_one_progress_line(capsys: pytest.CaptureFixture[str]) -> None:
    lines: list[tuple] = []
    report = stages.estimate.progress_lines(lambda *a, **k: lines.append((a, k)))
    report("global", 3, 10, 0.25)
    report("refine", 4, 20, 0.125)
    assert lines == [(("global search", 3, 10, "best NRMSE 0.25"), {"unit": "generation"}),
                     (("refinement", 4, 20, "rms NRMSE 0.125"), {"unit": "simulation"})]
    progress = Progress(every=0.0)
    stages.estimate.progress_lines(progress)("global", 10, 10, 0.5)
    assert "global search: generation 10/10, best NRMSE 0.5" in capsys.readouterr().err
