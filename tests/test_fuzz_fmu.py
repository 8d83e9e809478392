"""FMU archives and foreign binaries (issue 13): bounded extraction, and native code that crashes, hangs or exits.

Archives are generated with hypothesis; the oracle is the rule written here:
an entry that is absolute or climbs out with ``..`` is refused, an archive that
inflates beyond the limit is refused, and nothing is ever left in the temp dir.
The crafted binaries are tiny C libraries built with gcc that export the FMI 2
co-simulation API and misbehave in one named function.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trackingbox.errors import FMUError
from trackingbox.fmu import FMUModel, read_info
from trackingbox.fmu.isolation import extract as _extract
from trackingbox.testing import crafted as crafted_fmus
from trackingbox.testing.crafted import Misbehaviour

FUZZ = settings(max_examples=40, deadline=10000, suppress_health_check=[HealthCheck.function_scoped_fixture])

SAFE = st.from_regex(r"[a-z]{1,8}(/[a-z]{1,8}){0,2}\.(txt|so|xml)", fullmatch=True)
UNSAFE = st.sampled_from(["../evil.txt", "a/../../evil.txt", "/tmp/evil.txt", "..", "x/..", "C:/evil.txt",
                          "a\\..\\b.txt"])


@FUZZ
@given(entries=st.lists(st.tuples(st.one_of(SAFE, UNSAFE), st.integers(min_value=0, max_value=3000)),
                        min_size=1, max_size=8, unique_by=lambda e: e[0]),
       limit=st.integers(min_value=500, max_value=8000))
def test_extraction_refuses_unsafe_or_oversized_archives_and_leaves_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, entries: list[tuple[str, int]], limit: int) -> None:
    work = Path(tempfile.mkdtemp(dir=tmp_path))
    monkeypatch.setenv("TRACKINGBOX_FMU_MAX_BYTES", str(limit))
    monkeypatch.setattr(tempfile, "tempdir", str(work / "tmp"))
    (work / "tmp").mkdir()
    archive = work / "a.fmu"
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as z:
        for name, size in entries:
            z.writestr(name, b"\0" * size)
    names = [n for n, _ in entries]
    unsafe = any(n.startswith("/") or "\\" in n or ":" in n or ".." in n.split("/") for n in names)
    too_big = sum(size for _, size in entries) > limit
    try:
        out = Path(_extract(archive))
    except FMUError as exc:
        assert unsafe or too_big, f"refused a safe archive: {exc}"
        assert "a.fmu" in str(exc)
        assert list((work / "tmp").iterdir()) == []  # nothing left behind
        return
    assert not (unsafe or too_big), "extracted an unsafe or oversized archive"
    extracted = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert extracted == sorted(names)
    assert out.parent == work / "tmp"
    shutil.rmtree(out)


def test_a_forged_size_cannot_get_past_the_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The header says 10 bytes; the entry inflates to 100 kB: counting the bytes written stops it."""
    monkeypatch.setenv("TRACKINGBOX_FMU_MAX_BYTES", "50000")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    archive = tmp_path / "forged.fmu"
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("resources/big.bin", b"\0" * 100_000)
    data = bytearray(archive.read_bytes())
    # patch the uncompressed size (little endian) in the local header and the central directory
    for sig, offset in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):
        at = data.find(sig)
        data[at + offset:at + offset + 4] = (10).to_bytes(4, "little")
    archive.write_bytes(bytes(data))
    with pytest.raises(FMUError, match="forged.fmu"):
        _extract(archive)
    assert list((tmp_path / "tmp").iterdir()) == []


def test_too_many_entries_is_refused_before_listing(tmp_path: Path) -> None:
    archive = tmp_path / "many.fmu"
    with zipfile.ZipFile(archive, "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription/>")
        for i in range(20_001):
            z.writestr(f"r/{i}", b"")
    with pytest.raises(FMUError, match=r"20002 archive entries"):
        read_info(archive)


# -- crafted binaries ---------------------------------------------------------------------------

#: name -> misbehaviour (trackingbox.testing.crafted): segfault or _exit(0) in fmi2Instantiate, a hang in
#: fmi2DoStep, a segfault from the fourth fmi2GetReal on (after the canary's reads)
CRAFTED = {"segv_instantiate": Misbehaviour(2, 1), "hang_dostep": Misbehaviour(6, 4),
           "exit_instantiate": Misbehaviour(2, 3), "segv_late": Misbehaviour(8, 1, nth=4),
           "well_behaved": Misbehaviour()}


@pytest.fixture(scope="module")
def crafted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    if not crafted_fmus.available():
        pytest.skip("crafted FMU binaries need a C compiler on Linux")
    return crafted_fmus.build(tmp_path_factory.mktemp("crafted"), CRAFTED)


@pytest.mark.parametrize(("name", "message"), [
    ("segv_instantiate", r"the FMU's binary crashed \(SIGSEGV\) in fmi2Instantiate"),
    ("exit_instantiate", r"the FMU's binary called exit\(0\) in fmi2Instantiate"),
    ("hang_dostep", r"the FMU's binary did not return from fmi2DoStep within 3 s"),
])
def test_the_canary_names_the_crash_exit_or_hang(crafted: dict[str, Path], monkeypatch: pytest.MonkeyPatch,
                                                 name: str, message: str) -> None:
    monkeypatch.setenv("TRACKINGBOX_FMU_TIMEOUT", "3")
    with pytest.raises(FMUError, match=message) as info:
        FMUModel(crafted[name])
    assert f"{name}.fmu" in str(info.value)


def test_a_well_behaved_binary_passes_the_canary_and_runs(crafted: dict[str, Path]) -> None:
    with FMUModel(crafted["well_behaved"]) as model:
        result = model.simulate(stop_time=3.0, output_interval=1.0)
    assert list(result["y"]) == [1.0, 1.0, 1.0, 1.0]  # the binary's fmi2GetReal returns 1.0


def test_a_crash_after_the_canary_is_named_by_the_supervisor(crafted: dict[str, Path], tmp_path: Path) -> None:
    """The console script: the fourth fmi2GetReal segfaults (the canary makes two); one error line, exit 2."""
    out = tmp_path / "run" / "result.csv"
    proc = subprocess.run([str(Path(sys.executable).parent / "trackingbox"), "simulate", str(crafted["segv_late"]), "--set", "u=1",
                           "--stop", "5", "--step", "1", "-o", str(out)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert errors == [f"error: FMU {crafted['segv_late']}: the FMU's binary crashed (SIGSEGV) in fmi2GetReal"]
    assert "Traceback" not in proc.stderr and not out.exists()
