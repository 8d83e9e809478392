"""scripts/bench_own_model: models written elsewhere through every stage, as docs/your-own-model.md does it.

Per case of ``trackingbox.testing.own_models`` (a twin nobody here wrote: the MSL's own examples left
unchanged, or a user's package on the MSL; its plant a variant with one degrading parameter and noisy
sensors): the historian is made, then the commands a user runs, in a fresh folder, each through the
console scripts: ``compile`` -> ``estimate --write`` -> ``pair --no-data-checks`` -> ``track`` ->
``gen-trackingbox --compile`` -> ``validate``. With ``--fixed CASE`` that case's twin is compiled
again with ``--parameters fixed`` (as other tools export FMUs) and goes through ``estimate`` ->
``pair`` -> ``track`` from a fresh spec.

Criteria (issue 30): on every paired tag, the tracked NRMSE at most 0.3 x the untracked on the
validation window (``validate``, the compiled box), and the compiled box within 0.01 of the Python
runtime (``validate``'s agreement, in units of each tracked parameter's range); the fixed-parameter
run must pair and track, its tracked NRMSE at most 0.3 x the untracked on every paired tag too
(``track``, the whole run). A stage that exits non-zero fails its case. Exit 1 when any criterion
fails. Beside each paired tag's figures, the NRMSE its sensor noise alone gives on the validation
window: where a tag's untracked error is already about that, tracking has nothing to remove there and
the ratio criterion cannot be met (the case fails, and the figures say why).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from trackingbox.fmu import read_info
from trackingbox.spec import load_spec
from trackingbox.testing.own_models import CASES, default_msl, repository_root, write_historian, write_spec

BIN = Path(sys.executable).parent
RATIO = 0.3
AGREEMENT = 0.01


class StageFailed(Exception):
    pass


def run(folder: Path, *argv: str, log: list[str]) -> tuple[str, float]:
    """Run one command in *folder*; its stdout and wall seconds, or StageFailed with its last stderr lines."""
    command = [str(BIN / argv[0]), *argv[1:]]
    began = time.perf_counter()
    done = subprocess.run(command, cwd=folder, capture_output=True, text=True)
    seconds = time.perf_counter() - began
    log.append(f"  $ {' '.join(argv)}   ({seconds:.1f} s, exit {done.returncode})")
    if done.returncode != 0:
        tail = "\n".join(done.stderr.strip().splitlines()[-3:])
        raise StageFailed(f"`{' '.join(argv)}` exited {done.returncode}: {tail}")
    return done.stdout, seconds


def compile_twin(case, folder: Path, msl: Path, output: str, *extra: str, log: list[str]) -> None:
    source = msl if case.twin_path == "MSL" else repository_root() / case.twin_path
    libraries = () if source == msl else ("--library", str(msl))
    run(folder, "trackingbox", "compile", str(source), "--model", case.twin_model, *libraries, "-o", output,
        "--backend", "embedded", *extra, log=log)


def pair_and_track(folder: Path, spec: str, max_time: float, log: list[str]) -> dict:
    run(folder, "trackingbox", "pair", spec, "--max-time", repr(max_time), "--no-data-checks", log=log)
    pairs = [(p.variable, p.parameter) for p in load_spec(folder / spec).pairs]
    if not pairs:
        raise StageFailed("pair wrote no pairs")
    out, _ = run(folder, "trackingbox", "track", spec, "--json", "--out", f"track_{Path(spec).stem}", log=log)
    return {"pairs": pairs, "track": json.loads(out)}


def noise_floor(case, folder: Path) -> dict[str, float]:
    """Per output tag, the NRMSE its sensor noise alone amounts to on the validation window (the plant's
    noise standard deviation over the measured range there). A twin that matched the plant exactly would
    score about this; a tracked one can score a little less, its controllers following some of the noise."""
    table = pd.read_csv(folder / "historian.csv")
    seconds = (pd.to_datetime(table["time"], format="ISO8601") - pd.to_datetime(table["time"].iloc[0],
                                                                                  format="ISO8601")).dt.total_seconds()
    start = case.training_hours * 3600.0
    window = table[seconds >= start]
    return {tag: sigma / float(window[tag].max() - window[tag].min()) for tag, (_, sigma) in case.outputs.items()}


def bench_case(name: str, work: Path, msl: Path, fixed: bool) -> dict:
    case = CASES[name]
    folder = work / name
    folder.mkdir(parents=True)
    log: list[str] = []
    result: dict = {"case": name, "title": case.title, "log": log, "failures": []}
    max_time = case.hours * 3600.0  # a step response settles within the case's run, or it cannot be tracked
    try:
        write_historian(case, folder, msl=msl)
        truth = json.loads((folder / "truth.json").read_text())
        result["truth"] = truth
        compile_twin(case, folder, msl, "twin.fmu", log=log)
        write_spec(case, folder, twin="twin.fmu", msl=msl)
        run(folder, "trackingbox", "estimate", "spec.toml", "--write", log=log)
        result["estimate"] = {p.name: p.start for p in load_spec(folder / "spec.toml").parameters}
        tracked = pair_and_track(folder, "spec.toml", max_time, log)
        result.update(tracked)
        out, _ = run(folder, "gen-trackingbox", "spec.toml", "-o", "generated", "--compile", "--json", log=log)
        generated = json.loads(out)
        fmu = generated.get("fmu") or next(str(p) for p in (folder / "generated").glob("*Tracked.fmu"))
        out, _ = run(folder, "trackingbox", "validate", "spec.toml", "--fmu", str(fmu), "--json", log=log)
        validation = json.loads(out)
        result["validate"] = validation
        result["noise_floor"] = noise_floor(case, folder)
        for variable, _ in tracked["pairs"]:
            v = validation["variables"][variable]
            if not v["nrmse_tracked"] <= RATIO * v["nrmse_untracked"]:
                result["failures"].append(f"{variable}: tracked NRMSE {v['nrmse_tracked']:.4g} above "
                                          f"{RATIO} x untracked {v['nrmse_untracked']:.4g} (validate)")
        if not validation["agreement"] <= AGREEMENT:
            result["failures"].append(f"box against the Python runtime {validation['agreement']:.3g} > {AGREEMENT}")
        if fixed:
            compile_twin(case, folder, msl, "twin_fixed.fmu", "--parameters", "fixed", log=log)
            variability = {v.name: v.variability for v in read_info(folder / "twin_fixed.fmu").variables}
            result["fixed_variability"] = {name: variability.get(name) for name, *_ in case.parameters}
            if set(result["fixed_variability"].values()) != {"fixed"}:
                raise StageFailed(f"compile --parameters fixed: variabilities {result['fixed_variability']}")
            fixed_folder = folder / "fixed"
            fixed_folder.mkdir()
            shutil.copy(folder / "historian.csv", fixed_folder / "historian.csv")
            shutil.copy(folder / "twin_fixed.fmu", fixed_folder / "twin_fixed.fmu")
            write_spec(case, fixed_folder, twin="twin_fixed.fmu", msl=msl)
            run(fixed_folder, "trackingbox", "estimate", "spec.toml", "--write", log=log)
            result["fixed"] = pair_and_track(fixed_folder, "spec.toml", max_time, log)
            for variable, _ in result["fixed"]["pairs"]:
                v = result["fixed"]["track"]["variables"][variable]
                if not v["nrmse_tracked"] <= RATIO * v["nrmse_untracked"]:
                    result["failures"].append(f"fixed: {variable}: tracked NRMSE {v['nrmse_tracked']:.4g} above "
                                              f"{RATIO} x untracked {v['nrmse_untracked']:.4g} (track)")
    except StageFailed as failed:
        result["failures"].append(str(failed))
    return result


def show(result: dict) -> None:
    print(f"== {result['case']}: {result['title']}")
    for line in result["log"]:
        print(line)
    truth = result.get("truth")
    if truth:
        print(f"  truth: {truth['parameter']} {truth['value']['start']:g} -> {truth['value']['end']:g} "
              f"(training mean {truth['training_mean']:.4g})")
    if "estimate" in result:
        print("  estimate: " + ", ".join(f"{k} = {v:.5g}" for k, v in result["estimate"].items()))
    for label, block in (("", result), ("fixed: ", result.get("fixed") or {})):
        if "track" not in block:
            continue
        if label:
            print("  fixed: twin_fixed.fmu's candidates have FMI variability "
                  + ", ".join(f"{k} {v}" for k, v in result["fixed_variability"].items()))
        print(f"  {label}pairs: " + ", ".join(f"{v} <- {p}" for v, p in block["pairs"]))
        for variable, _ in block["pairs"]:
            v = block["track"]["variables"][variable]
            print(f"  {label}track (whole run) {variable}: NRMSE untracked {v['nrmse_untracked']:.4g}, tracked "
                  f"{v['nrmse_tracked']:.4g}, ratio {v['nrmse_tracked'] / v['nrmse_untracked']:.4f}")
        for name, p in block["track"]["parameters"].items():
            final = p.get("final")
            if final is not None:
                print(f"  {label}tracked {name}: final {final:.5g}")
    validation = result.get("validate")
    if validation:
        for variable, _ in result["pairs"]:
            v = validation["variables"][variable]
            print(f"  validate {variable}: NRMSE untracked {v['nrmse_untracked']:.4g}, tracked (box) "
                  f"{v['nrmse_tracked']:.4g}, Python {v['nrmse_python']:.4g}, ratio "
                  f"{v['nrmse_tracked'] / v['nrmse_untracked']:.4f} (criterion <= {RATIO}); the sensor noise "
                  f"alone {result['noise_floor'][variable]:.4g}")
        print(f"  validate: box against the Python runtime {validation['agreement']:.3g} (criterion <= {AGREEMENT})")
    print("  " + ("PASS" if not result["failures"] else "FAIL: " + "; ".join(result["failures"])))
    sys.stdout.flush()


def main() -> int:
    ap = argparse.ArgumentParser(prog="bench_own_model", description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", action="append", choices=sorted(CASES), help="a case (repeatable; default all)")
    ap.add_argument("--fixed", default="cooling", help="the case also run as an FMU with fixed parameters "
                    "(default cooling; 'none': no such run)")
    ap.add_argument("--msl", type=Path, default=default_msl(), help="the MSL 4.0.0's Modelica directory")
    ap.add_argument("--keep", type=Path, help="work in this folder and keep it (default: a temporary one)")
    args = ap.parse_args()
    names = args.case or sorted(CASES)
    if args.fixed != "none" and args.fixed not in CASES:
        ap.error(f"--fixed: unknown case {args.fixed!r} (one of {', '.join(sorted(CASES))} or none)")
    if not (args.msl / "package.mo").is_file():
        print(f"error: the MSL is not at {args.msl} (--msl)", file=sys.stderr)
        return 2
    env_path = os.environ.get("MODELICAPATH")
    if env_path:
        print(f"note: MODELICAPATH={env_path} is set; the cases name their libraries themselves")
    work = args.keep or Path(tempfile.mkdtemp(prefix="bench-own-model-"))
    work.mkdir(parents=True, exist_ok=True)
    failed = 0
    try:
        for name in names:
            result = bench_case(name, work, args.msl, fixed=(name == args.fixed))
            show(result)
            failed += bool(result["failures"])
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)
    print(f"{len(names) - failed}/{len(names)} cases pass")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
