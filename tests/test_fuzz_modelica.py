"""Property-based fuzzing of the compile path (issue 13): broken Modelica gives one CompileError, no FMU.

Bounded: a handful of examples (each runs the front end in its own process).
"""
from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trackingbox.compiler import compile_model
from trackingbox.errors import CompileError

MODEL = """\
model Small "a first-order lag"
  parameter Real k(min = 0, unit = "1/s") = 0.1 "rate";
  input Real u(unit = "1") "input";
  Real x(start = 0, fixed = true, unit = "1") "state";
equation
  der(x) = k * (u - x);
end Small;
"""

#: cuts that always break the class: inside the declarations or before 'end Small;'
CUTS = st.integers(min_value=10, max_value=len(MODEL) - len("end Small;\n") - 1)

pytestmark = pytest.mark.compile


@settings(max_examples=4, deadline=120_000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=CUTS, junk=st.sampled_from(["", ";", "(", "end", "\x00", "é"]))
def test_a_truncated_model_is_one_compile_error_and_no_fmu(tmp_path: Path, cut: int, junk: str) -> None:
    source = tmp_path / f"Small{cut}.mo"
    source.write_text(MODEL[:cut] + junk, encoding="utf-8")
    out = tmp_path / f"out{cut}.fmu"
    with pytest.raises(CompileError) as info:
        compile_model(source, "Small", backend="embedded", output=out)
    assert source.name in str(info.value) or "Small" in str(info.value)
    assert not out.exists()


@settings(max_examples=3, deadline=120_000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(min_size=1, max_size=300))
def test_binary_garbage_is_one_compile_error_and_no_fmu(tmp_path: Path, data: bytes) -> None:
    source = tmp_path / "Garbage.mo"
    source.write_bytes(data)
    out = tmp_path / "garbage.fmu"
    with pytest.raises(CompileError):
        compile_model(source, "Garbage", backend="embedded", output=out)
    assert not out.exists()
