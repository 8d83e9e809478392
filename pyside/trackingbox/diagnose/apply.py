"""The loop closed: ``diagnose --apply``.

A diagnosis names an effect and writes the patched twin and its spec; :func:`apply`
then re-estimates the parameters on the patched twin, re-pairs, re-tracks over the
same data, and measures the tracked parameter against the plant's truth (where the
case has one, e.g. a bench's ``truth.json``) before and after the patch. Where
several effects are hidden it iterates: diagnose the patched spec again, apply
what it names, until nothing more is named or ``rounds`` is reached.

Each phase is the same stage the commands run (:mod:`trackingbox.stages`), in this
order on a copy of the spec (the input spec is never written):

1. ``estimate`` on the training window; where the recipe says so (the evaporators),
   the estimates become the spec's starts (with their intervals), but for the
   parameters that vary in time (their estimate over a window is a mean); the recipe's *held* parameters and
   every parameter a patch added (a constant of the plant's structure, estimated
   jointly) move to ``[fixed]`` at their estimate: only the spec's own candidates
   are tracked;
2. ``pair`` (its ``[[pairs]]`` written), each pair's loop at least the recipe's
   ``closed_loop`` slow. A parameter the spec tracks in time (``[diagnose] varying``: the one whose
   error the patch should shrink) that ``pair``'s data checks refused to pair is paired all the same
   with the tag its relative gain chose (:func:`keep_varying`), the refusal written beside the figures:
   the refusal is ``pair``'s judgement of how well a loop would track on this record, and the
   comparison needs the parameter tracked before and after the patch, whatever that judgement. (On the
   evaporator's hidden-effect plants, which foul without the soluble scale of the bench's own plant, the
   fouling resistance reaches 1.9e-4 m2.K/W in 72 h instead of 3.1e-4; its tags move 0.6 times as much
   and ``pair`` refused effect.Rf on PI-6121 at a predicted 26 % of the error above the noise floor,
   limit 25 %, on the unpatched and the patched twin alike);
3. ``track`` over the whole record.

Every round's naming, the fitted effect parameters, the tracked parameter's error
(largest and median after settling) and the phases' wall times are written to
``<out>/apply.json`` atomically as each phase finishes: an interrupted run keeps
what it computed. A diagnosis that names nothing in the first round is an error
(:class:`ApplyError`): there is nothing to apply, and nothing is left in *out*.
"""
from __future__ import annotations

import json
import logging
import math
import shutil
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..errors import StaleCheckpointError, TrackingError
from ..io import write_text_atomic
from ..spec import load_spec

log = logging.getLogger(__name__)

#: ``note(text)``: one line of progress.
Note = Callable[[str], None]


class ApplyError(TrackingError):
    """``diagnose --apply`` cannot apply: nothing was named, or the case lacks what it needs."""


@dataclass(frozen=True)
class Recipe:
    """How a spec is re-estimated, re-paired and re-tracked (the demo's pipeline for its bench).

    Attributes
    ----------
    estimate
        Keyword arguments of :class:`trackingbox.stages.EstimateSettings`.
    varying
        Parameters that vary in time: their estimate is not written as a start.
    held
        Parameters held at their estimate (moved to ``[fixed]``), not tracked.
    closed_loop
        Floor (s) of each pair's closed-loop time (None: as ``pair`` tuned it).
    window
        ``track``'s metric window.
    settle
        s from which the tracked parameter's error counts (None: the spec's validation
        window's start, else the start of the record).
    write_estimates
        Write the estimates as the spec's starts (the evaporators); otherwise tracking starts from
        the spec's starts, as the demo's heat exchanger does (its estimate leaves the untracked
        error at noise level, and ``pair`` then finds nothing to track). Held parameters are
        fixed at their estimate either way.
    estimate_may_fail
        Go on from the spec's starts where ``estimate`` refuses the data (the evaporator's
        communication losses leave inputs without data; the demo does the same).
    """

    estimate: Mapping[str, Any] = field(default_factory=dict)
    varying: frozenset[str] = frozenset()
    held: frozenset[str] = frozenset()
    closed_loop: float | None = None
    window: str = "all"
    settle: float | None = None
    write_estimates: bool = False
    estimate_may_fail: bool = False


def bench_recipe(bench: str | None, names: Any = ()) -> Recipe:
    """The demo's pipeline for *bench* (``scripts/demo --bench BENCH --until track``); generic otherwise."""
    from .. import demo

    if bench is None or bench not in demo.ESTIMATE_BUDGET:
        return Recipe()
    evaporator = bench in demo.EVAPORATORS
    closed = None
    if evaporator:
        from ..benches.evaporator import CLOSED_LOOP
        closed = CLOSED_LOOP
    return Recipe(estimate=dict(demo.ESTIMATE_BUDGET[bench]), varying=demo.bench_time_varying(bench, names),
                  held=demo.bench_estimate_only(bench, names), closed_loop=closed,
                  window=demo.TRACK_WINDOW.get(bench, "all"),
                  settle=12 * 3600.0 if bench == "evaporator" else None,
                  write_estimates=bench in demo.WRITE_ESTIMATES, estimate_may_fail=evaporator)


@dataclass(frozen=True)
class ParameterError:
    """The tracked parameter against the plant's truth after settling."""

    parameter: str
    settle: float
    max_error: float
    """Largest ``|tracked - truth|`` from *settle* on (the parameter's unit)."""
    median_error: float
    span: float
    """The parameter's bound range: the errors' scale."""

    def to_json(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "settle": self.settle, "max_error": _num(self.max_error),
                "median_error": _num(self.median_error), "span": self.span,
                "max_error_of_range": _num(self.max_error / self.span),
                "median_error_of_range": _num(self.median_error / self.span)}


@dataclass
class Retrack:
    """One pass of estimate → pair → track on a spec."""

    spec: Path
    csv: Path
    pairs: list[tuple[str, str]]
    estimates: dict[str, float]
    held: dict[str, float]
    errors: dict[str, ParameterError]
    timings: dict[str, float]
    note: str = ""
    kept: list[dict[str, str]] = field(default_factory=list)
    """Pairs of :func:`keep_varying`: ``variable``, ``parameter`` and ``refused`` (pair's reason)."""

    def to_json(self) -> dict[str, Any]:
        return {"spec": str(self.spec), "csv": str(self.csv), "pairs": [list(p) for p in self.pairs],
                "estimates": self.estimates, "held": self.held,
                "errors": {k: v.to_json() for k, v in self.errors.items()},
                "timings": {k: round(v, 3) for k, v in self.timings.items()},
                **({"note": self.note} if self.note else {}),
                **({"kept": self.kept} if self.kept else {})}


def keep_varying(result: Any, varying: Any) -> tuple[Any, list[dict[str, str]]]:
    """*result* (a :class:`~trackingbox.analysis.pair_stage.PairingResult`) with each parameter of
    *varying* that its data checks refused to pair given a pair all the same, and those pairs.

    The pair is the refused one (``pairing.rejected``: the relative gain array chose it, the data
    checks then refused it) whose relative gain is closest to 1, on a tag no chosen pair uses; its gain
    is the pairing's, its time constant the step test's. A parameter with no such refusal (every tag it moves at its
    noise floor, or no positive relative gain) stays unpaired, as ``pair`` left it.
    """
    from ..analysis.pairing_model import Pair

    pairing = result.pairing
    st = result.steptest
    used = {p.variable for p in pairing.pairs}
    paired = {p.parameter for p in pairing.pairs}
    added: list[Any] = []
    kept: list[dict[str, str]] = []
    for name in varying:
        if name in paired or name not in st.parameters:
            continue
        options = []
        for v, q, why in pairing.rejected:
            if q != name or v in used or v not in pairing.variables or v not in st.variables:
                continue
            i, j = pairing.variables.index(v), pairing.parameters.index(q)
            lam = float(pairing.rga[i, j]) if pairing.rga.size else math.nan
            if math.isfinite(lam) and lam > 0:
                options.append((abs(lam - 1.0), v, i, j, lam, why))
        if not options:
            continue
        _, v, i, j, lam, why = min(options, key=lambda o: o[0])
        tau = float(st.time_constants[st.variables.index(v), st.parameters.index(name)])
        added.append(Pair(v, name, lam, float(pairing.gains[i, j]), tau))
        used.add(v)
        kept.append({"variable": v, "parameter": name, "refused": why})
    if not added:
        return result, []
    names = {p.variable for p in added} | {p.parameter for p in added}
    pairing = replace(pairing, pairs=tuple(pairing.pairs) + tuple(added),
                      left_out=tuple((n, r) for n, r in pairing.left_out if n not in names))
    return replace(result, pairing=pairing), kept


def truth_on(truth: Mapping[str, Any], name: str, t: np.ndarray) -> np.ndarray | None:
    """The plant's value of twin parameter *name* at times *t*: its trajectory in *truth* or its constant."""
    traj = (truth.get("trajectories") or {}).get(name)
    if traj is not None:
        return np.interp(t, np.asarray(traj["time"], float), np.asarray(traj["value"], float))
    value = (truth.get("parameters") or {}).get(name)
    return None if value is None else np.full(np.shape(t), float(value))


def parameter_errors(spec: Any, csv: Path, truth: Mapping[str, Any] | None, settle: float) -> dict[str, ParameterError]:
    """Each candidate the truth knows: its largest and median error from *settle* on (tracked: its
    trajectory in *csv*; left unpaired: its start, which it keeps)."""
    if not truth:
        return {}
    df = pd.read_csv(csv)
    t = df["time"].to_numpy(float)
    after = t >= settle
    out: dict[str, ParameterError] = {}
    for p in spec.parameters:
        column = f"parameter:{p.name}"
        true = truth_on(truth, p.name, t)
        if true is None or not after.any():
            continue
        # a candidate no pair drives stays at its start: its error is the start's
        value = df[column].to_numpy(float) if column in df.columns else np.full(t.shape, float(p.start))
        err = np.abs(value - true)[after]
        err = err[np.isfinite(err)]
        if err.size:
            out[p.name] = ParameterError(p.name, settle, float(err.max()), float(np.median(err)),
                                         float(p.max - p.min))
    return out


def retrack(spec_path: Path, out: Path, recipe: Recipe, truth: Mapping[str, Any] | None, *,
            hold: frozenset[str] = frozenset(), progress: Any = None) -> Retrack:
    """Copy *spec_path* into *out* and run estimate → pair → track there (see the module's docstring).

    *hold*: more parameters held at their estimate (a patch's).
    """
    from .. import stages
    from ..benches.evaporator import fix_parameters, slow_pairs
    from ..spec import write_pairs, write_spec, write_starts

    out.mkdir(parents=True, exist_ok=True)
    spec = load_spec(spec_path)
    path = write_spec(spec, out / "spec.toml", header=f"re-estimated, re-paired and re-tracked by diagnose --apply "
                                                      f"from {spec.path}")
    spec = load_spec(path)
    timings: dict[str, float] = {}
    note = ""
    t0 = time.perf_counter()
    estimates: dict[str, float] = {}
    held: dict[str, float] = {}
    # the estimate stage's outcome, kept: a re-track interrupted after it (diagnose --apply --resume) goes on
    # from it. Its fit is journaled (checkpoint.journal), but the identifiability check before it and the
    # profile-likelihood intervals after it are not, and they are most of its time (on the evaporator's 72 h,
    # vent-orifice: the fit 77 s of evaluations, the stage about 1700 s on a loaded machine)
    saved = out / "estimate" / "outcome.json"
    key = _estimate_key(path, recipe)
    found = _saved_outcome(saved, key)
    try:
        if found is not None:
            log.info("%s: the estimate of an earlier run of this re-track, reused (%s)", path, saved)
            if found.get("failed"):
                raise TrackingError(found["failed"])
            estimates, intervals = found["estimates"], {k: tuple(v) for k, v in found["intervals"].items()}
        else:
            # checkpointed: an interrupted re-track (diagnose --apply --resume) continues its estimation from
            # the journal instead of repeating its simulations
            checkpoint = out / "estimate" / "checkpoint.json"
            checkpoint.parent.mkdir(parents=True, exist_ok=True)
            try:
                est = _estimate_checkpointed(spec, recipe, checkpoint, progress)
            except TrackingError as exc:
                if recipe.estimate_may_fail:
                    write_text_atomic(saved, json.dumps({"key": key, "failed": str(exc)}) + "\n")
                raise
            estimates = {k: float(v) for k, v in est.parameters.items()}
            unc = est.uncertainty
            intervals = {iv.name: (float(iv.lower), float(iv.upper)) for iv in (unc.parameters if unc is not None else ())
                         if iv.determined and iv.lower <= iv.estimate <= iv.upper}
            write_text_atomic(saved, json.dumps({"key": key, "estimates": estimates,
                                                 "intervals": {k: list(v) for k, v in intervals.items()}}) + "\n")
    except TrackingError as exc:
        if not recipe.estimate_may_fail:
            raise
        note = f"estimate skipped, tracking starts from the spec's starts: {exc}"
        log.warning(note)
    else:
        keep = {k for k in estimates if k not in recipe.varying}
        hold_now = {k for k in keep if k in recipe.held or k in hold}
        starts = {k: v for k, v in estimates.items() if k in keep and k not in hold_now and recipe.write_estimates}
        if starts:
            spec = write_starts(path, starts, {k: v for k, v in intervals.items() if k in starts})
        if hold_now:  # with their intervals: the tracked parameters' bands carry them (trackingbox.identify.held)
            held = {k: estimates[k] for k in sorted(hold_now)}
            spec = load_spec(fix_parameters(path, held, intervals).path)
    timings["estimate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = stages.pair.run(spec, stages.PairSettings(), progress=progress)
    res, kept = keep_varying(res, [name for name, _ in spec.diagnose.varying])
    for k in kept:
        log.warning("%s paired with %s although pair refused it (%s): diagnose --apply compares the parameter "
                    "the spec tracks in time before and after the patch", k["parameter"], k["variable"], k["refused"])
    if not res.pairing.pairs:
        why = "; ".join(f"{x['name']}: {x['reason']}" for x in res.to_json().get("left_out", []))
        raise ApplyError(f"{path}: pair found no pairs, nothing to track (a record too short for the tracked "
                         f"parameters to move its tags beyond their noise?): {why or 'no reason given'}")
    spec = write_pairs(path, stages.pair.spec_pairs(spec, res))
    if recipe.closed_loop is not None:
        spec = slow_pairs(path, spec.pairing.closed_loop_min or spec.pairing.closed_loop or recipe.closed_loop)
    timings["pair"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    tr = stages.track.run(spec, stages.TrackSettings(out_dir=out / "track", window=recipe.window), progress=progress)
    timings["track"] = time.perf_counter() - t0
    settle = settle_time(spec, recipe)
    return Retrack(spec=path, csv=Path(tr.csv), pairs=[(p.variable, p.parameter) for p in spec.pairs],
                   estimates=estimates, held=held, errors=parameter_errors(spec, Path(tr.csv), truth, settle),
                   timings=timings, note=note, kept=kept)


def _estimate_checkpointed(spec: Any, recipe: Recipe, checkpoint: Path, progress: Any) -> Any:
    """The estimate stage with its journal beside *checkpoint*: resumed when the journal is this re-track's.

    A journal another run wrote (the spec, twin or settings changed since, e.g. a case folder copied or a
    spec edited) holds nothing this estimate may reuse: it is set aside (``.stale``, with a warning) and the
    estimate starts over, instead of failing on it (which, where the recipe lets the estimate fail, would track
    from the spec's starts). A journal that is corrupt or truncated still stops the run.
    """
    from .. import stages

    journal = checkpoint.with_suffix(".journal")

    def run(resume: bool) -> Any:
        return stages.estimate.run(spec, stages.EstimateSettings(**{**recipe.estimate, "checkpoint": checkpoint,
                                                                   "resume": resume}), progress=progress)

    if not journal.exists():
        return run(False)
    try:
        return run(True)
    except StaleCheckpointError as exc:
        stale = journal.with_name(journal.name + ".stale")
        journal.replace(stale)
        log.warning("%s; set aside as %s, the estimate starts over", exc, stale)
        return run(False)


def _estimate_key(spec_path: Path, recipe: Recipe) -> str:
    """What an estimate of a re-track depends on: the spec as copied (before any estimate is written), its
    measurements and twin (size and modification time) and the recipe's estimate settings."""
    import hashlib

    spec = load_spec(spec_path)
    files = [(str(f), f.stat().st_size, f.stat().st_mtime_ns) for f in (Path(spec.twin), Path(spec.measurements))
             if f.is_file()]
    text = json.dumps([spec_path.read_text(), files, sorted((k, repr(v)) for k, v in recipe.estimate.items())])
    return hashlib.sha256(text.encode()).hexdigest()


def _saved_outcome(path: Path, key: str) -> dict[str, Any] | None:
    """The estimate outcome saved at *path* when it was written for *key*, else None."""
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text())
    except ValueError:
        log.warning("%s: unreadable, the estimate is run again", path)
        return None
    return doc if isinstance(doc, dict) and doc.get("key") == key else None


def settle_time(spec: Any, recipe: Recipe) -> float:
    """s from which errors count: the recipe's, else the validation window's start, else 0."""
    if recipe.settle is not None:
        return float(recipe.settle)
    window = (getattr(spec, "windows", None) or {}).get("validation")
    return float(window[0]) if window else 0.0


@dataclass
class ApplyResult:
    """What :func:`apply` measured (``to_json()`` is ``apply.json``)."""

    out: Path
    before: Retrack | None = None
    rounds: list[dict[str, Any]] = field(default_factory=list)
    stopped: str = ""
    plot: Path | None = None

    def ratios(self) -> dict[str, float]:
        """Tracked parameter -> largest error after settling, last patched / unpatched."""
        last = next((r["retrack"] for r in reversed(self.rounds) if r.get("retrack")), None)
        if self.before is None or last is None:
            return {}
        out = {}
        for name, e in self.before.errors.items():
            after = last["errors"].get(name)
            if after and after["max_error"] is not None and e.max_error > 0:
                out[name] = after["max_error"] / e.max_error
        return out

    def to_json(self) -> dict[str, Any]:
        return {"before": self.before.to_json() if self.before else None, "rounds": self.rounds,
                "stopped": self.stopped, "ratio_max_error": self.ratios(),
                "plot": str(self.plot) if self.plot else None}

    def write(self) -> Path:
        target = self.out / "apply.json"
        write_text_atomic(target, json.dumps(self.to_json(), indent=2, default=str) + "\n")
        return target


def apply(spec: Any, settings: Any, *, truth: Mapping[str, Any] | None = None, recipe: Recipe | None = None,
          out: Path, rounds: int = 3, note: Note | None = None, progress: Any = None,
          resume: bool = False) -> ApplyResult:
    """Diagnose *spec*, apply what is named, re-estimate, re-pair, re-track; repeat up to *rounds* times.

    Parameters
    ----------
    spec
        The loaded spec to diagnose (never written).
    settings
        :class:`trackingbox.diagnose.stage.DiagnoseSettings` (``compile`` and ``out_dir`` are set here).
    truth
        The plant's truth (``truth.json``: ``parameters`` and ``trajectories``); None: no errors measured.
    recipe
        How to re-estimate, re-pair and re-track (:func:`bench_recipe`).
    out
        Folder of the rounds (``round<N>/patched``, ``round<N>/retrack``), ``before/`` and ``apply.json``.
    resume
        Reuse what *out*'s ``apply.json`` holds of an interrupted run of the same spec: each round's
        naming (its patched spec on disk) and the finished re-tracks; what is missing is computed.

    Raises
    ------
    ApplyError
        The first diagnosis names nothing (nothing is left in *out* where it did not exist before).
    """
    from .stage import diagnose

    say = note or (lambda text: log.info(text))
    recipe = recipe or Recipe()
    out = Path(out).resolve()
    existed = out.exists()
    result = ApplyResult(out=out)
    current = spec
    originals = frozenset(p.name for p in spec.parameters)
    named_once = False
    applied: list[str] = []  # effect@target already in the twin: not screened again
    done = _finished(out, spec) if resume else {"rounds": []}
    try:
        for r in range(1, max(rounds, 1) + 1):
            old = next((x for x in done["rounds"] if x.get("round") == r and x.get("named")
                        and Path(x.get("patch_spec", "")).is_file()), None)
            if old is not None:  # an interrupted run's naming: reused
                say(f"round {r}: {old['named']['effect']} on {old['named']['target']} (named by the interrupted run)")
                named_once = True
                applied.append(f"{old['named']['effect']}@{old['named']['target']}")
                entry = {k: v for k, v in old.items() if k != "retrack"}
                result.rounds.append(entry)
                if r == 1:
                    result.before = done.get("before_run")
                    if result.before is None:
                        t1 = time.perf_counter()
                        say("before: estimate, pair, track the unpatched twin")
                        result.before = retrack(Path(spec.path), out / "before", recipe, truth, progress=progress)
                        result.before.timings["total"] = time.perf_counter() - t1
                result.write()
                patched_path = Path(old["patch_spec"])
                patched = load_spec(patched_path)
                if old.get("retrack") and Path(old["retrack"]["csv"]).is_file():
                    entry["retrack"] = old["retrack"]
                else:
                    added = frozenset(p.name for p in patched.parameters) - originals
                    t1 = time.perf_counter()
                    again = retrack(patched_path, out / f"round{r}" / "retrack", recipe, truth, hold=added,
                                    progress=progress)
                    entry["retrack"] = again.to_json()
                    entry.setdefault("timings", {})["retrack"] = round(time.perf_counter() - t1, 3)
                result.write()
                current = patched
                continue
            t0 = time.perf_counter()
            say(f"round {r}: diagnose {current.path}")
            found = diagnose(current, replace(settings, compile=True, out_dir=out / f"round{r}" / "patched",
                                              exclude=tuple(settings.exclude) + tuple(applied)),
                             progress=progress)
            entry: dict[str, Any] = {"round": r, "spec": str(current.path), "verdict": found.verdict,
                                     "named": None, "timings": {"diagnose": round(time.perf_counter() - t0, 3)},
                                     "diagnose_phases": {k: v.to_json() for k, v in found.timings.items()}}
            if found.verdict == "unexplained":
                entry["unexplained"] = {t: [list(p) for p in ps] for t, ps in found.judgement.unexplained.items()}
            if found.named is None or found.patch_spec is None:
                if r == 1:
                    why = ("the named effect was not rendered into a patched spec (the spec needs [source])"
                           if found.named is not None else f"diagnosis verdict '{found.verdict}': no effect named")
                    raise ApplyError(f"{spec.path}: diagnose --apply has nothing to apply: {why}")
                result.rounds.append(entry)
                result.stopped = f"round {r} named nothing (verdict {found.verdict})"
                result.write()
                break
            named_once = True
            c = found.named
            applied.append(f"{c.effect}@{c.target}")
            entry["named"] = {"effect": c.effect, "target": c.target, "delta_bic": _num(c.delta_bic),
                              "parameters": {k: _num(v) for k, v in c.values.items()}}
            entry["patch_spec"] = str(found.patch_spec)
            say(f"round {r}: named {c.effect} on {c.target}")
            result.rounds.append(entry)
            result.write()
            if r == 1:  # the unpatched twin through the same pipeline (after a naming: else nothing to compare)
                t1 = time.perf_counter()
                say("before: estimate, pair, track the unpatched twin")
                result.before = retrack(Path(spec.path), out / "before", recipe, truth, progress=progress)
                result.before.timings["total"] = time.perf_counter() - t1
                result.write()
            patched = load_spec(found.patch_spec)
            added = frozenset(p.name for p in patched.parameters) - originals
            t1 = time.perf_counter()
            say(f"round {r}: estimate, pair, track the patched twin ({', '.join(sorted(added)) or 'no new parameter'} held)")
            again = retrack(found.patch_spec, out / f"round{r}" / "retrack", recipe, truth, hold=added,
                            progress=progress)
            entry["retrack"] = again.to_json()
            entry["timings"]["retrack"] = round(time.perf_counter() - t1, 3)
            result.write()
            current = patched
        else:
            result.stopped = f"bound of {rounds} rounds reached"
    except BaseException:
        if not named_once:  # nothing named (or the first diagnosis failed): nothing left behind
            shutil.rmtree(out if not existed else out / "round1", ignore_errors=True)
        raise
    if truth:
        result.plot = plot_errors(result, truth, spec)
    result.write()
    from ..report.diagnose import write_apply_report
    write_apply_report(result)
    return result


def _finished(out: Path, spec: Any) -> dict[str, Any]:
    """What ``out/apply.json`` holds of an earlier run of *spec*: its rounds and its unpatched re-track."""
    path = out / "apply.json"
    if not path.is_file():
        return {"rounds": []}
    try:
        doc = json.loads(path.read_text())
    except ValueError as exc:
        raise ApplyError(f"{path}: cannot resume from it: {exc}") from exc
    rounds = doc.get("rounds") or []
    if rounds and Path(rounds[0].get("spec", "")) != Path(spec.path):
        raise ApplyError(f"{path}: written for {rounds[0].get('spec')}, not {spec.path}; cannot resume from it")
    before = doc.get("before")
    run = None
    if before and Path(before.get("csv", "")).is_file():
        run = Retrack(spec=Path(before["spec"]), csv=Path(before["csv"]), pairs=[tuple(p) for p in before["pairs"]],
                      estimates=before.get("estimates", {}), held=before.get("held", {}),
                      errors={k: ParameterError(**{f: v[f] for f in ("parameter", "settle", "max_error",
                                                                      "median_error", "span")})
                              for k, v in before.get("errors", {}).items()},
                      timings=before.get("timings", {}), note=before.get("note", ""),
                      kept=before.get("kept", []))
    return {"rounds": rounds, "before_run": run}


def plot_errors(result: ApplyResult, truth: Mapping[str, Any], spec: Any) -> Path | None:
    """``<out>/apply.png``: each tracked parameter the truth knows, unpatched and after each round, and the truth."""
    from ..report import plots

    if result.before is None:
        return None
    names = list(result.before.errors)
    if not names:
        return None
    plt = plots.pyplot()
    fig, axes = plt.subplots(len(names), 1, figsize=(10, 3.4 * len(names)), squeeze=False,
                             layout="constrained")
    runs = [("unpatched", result.before.csv, plots.UNTRACKED, result.before.errors, result.before.spec)]
    colours = ("tab:blue", "tab:green", "tab:purple")
    for i, r in enumerate(x for x in result.rounds if x.get("retrack")):
        named = r["named"]
        errs = {k: ParameterError(**{f: v[f] for f in ("parameter", "settle", "max_error", "median_error", "span")})
                for k, v in r["retrack"]["errors"].items()}
        runs.append((f"round {r['round']}: + {named['effect']}@{named['target']}", Path(r["retrack"]["csv"]),
                     colours[i % len(colours)], errs, Path(r["retrack"]["spec"])))
    for ax, name in zip(axes[:, 0], names):
        first = pd.read_csv(runs[0][1], usecols=["time"])["time"].to_numpy(float)
        lines = []
        for label, csv, colour, errs, run_spec in runs:
            y, paired = _trajectory(csv, run_spec, name, first)
            e = errs.get(name)
            text = f"{label} (max error {e.max_error:.3g})" if e else label
            lines.append(plots.Line(y, text if paired else f"{text}, not paired: its start", colour))
        true = truth_on(truth, name, first)
        lines.append(plots.Line(true, "plant truth", plots.TRUTH, ":", 1.8))
        settle = result.before.errors[name].settle
        plots.series(ax, first / 3600.0, None, lines, ylabel=name,
                     title=f"{name}: tracked against the plant's truth before and after the patch "
                           f"(errors after {settle / 3600:g} h)")
        ax.axvline(settle / 3600.0, color="0.5", lw=0.8, ls="-.")
    return plots.save(fig, result.out / "apply.png")


def _trajectory(csv: Path, spec_path: Path, name: str, t: np.ndarray) -> tuple[np.ndarray, bool]:
    """Parameter *name* of a re-track on times *t*: its tracked column in *csv*, or (no pair drove it) its
    start in the run's spec, which it kept; and whether it was tracked."""
    column = f"parameter:{name}"
    if column in pd.read_csv(csv, nrows=0).columns:
        df = pd.read_csv(csv, usecols=["time", column])
        return np.interp(t, df["time"].to_numpy(float), df[column].to_numpy(float)), True
    spec = load_spec(spec_path)
    starts = {p.name: float(p.start) for p in spec.parameters}
    value = starts.get(name, dict(spec.fixed).get(name, math.nan))  # held: moved to [fixed] at its estimate
    return np.full(np.shape(t), float(value)), False


def _num(x: Any) -> float | None:
    return float(x) if x is not None and math.isfinite(float(x)) else None
