"""The classes of the shipped benches (each bench's models and its Validation package), found on disk."""
from __future__ import annotations

from pathlib import Path

from trackingbox.compiler import library_path

BENCHES = library_path() / "Benches"


def _classes(folder: Path, prefix: str) -> list[str]:
    return sorted(
        f"{prefix}.{f.stem}" for f in folder.glob("*.mo") if f.name != "package.mo"
    )


def bench_models() -> list[str]:
    out = []
    for bench in sorted(p for p in BENCHES.iterdir() if p.is_dir()):
        out += _classes(bench, f"TrackingBox.Benches.{bench.name}")
    return out


def validation_models() -> list[str]:
    out = []
    for bench in sorted(p for p in BENCHES.iterdir() if p.is_dir()):
        if (bench / "Validation").is_dir():
            out += _classes(bench / "Validation", f"TrackingBox.Benches.{bench.name}.Validation")
    return out
