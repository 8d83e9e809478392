"""Property-based fuzzing of spec.toml loading (issue 13): any bytes give a Spec or one SpecError.

The oracle for accepted specs is the spec's documented contract, checked here
with plain Python: a finite positive sample time; windows finite, ordered and
disjoint; every candidate's bounds ordered with its start inside.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trackingbox.errors import SpecError
from trackingbox.spec import load_spec
from trackingbox.testing.specs import first_order_spec

VALID = first_order_spec(start=0.005, lower=0.001, upper=0.05, training=(0.0, 600.0), validation=(600.0, 1200.0),
                         hold_until=50.0)

KEYS = ("sample_time", "start", "min", "max", "training", "validation", "hold_until", "twin", "name")

#: TOML values of every kind, including the troublesome ones the issue lists
TOML_VALUES = st.one_of(
    st.integers(min_value=-10**400, max_value=10**400).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(
        lambda x: "nan" if math.isnan(x) else ("inf" if x == math.inf else "-inf" if x == -math.inf else repr(x))),
    st.text(max_size=30).map(lambda s: '"' + s.replace("\\", "\\\\").replace('"', '\\"')
                             .encode("unicode_escape").decode("ascii").replace("\\\\\\\\", "\\\\") + '"'),
    st.booleans().map(lambda b: "true" if b else "false"),
    st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), max_size=4).map(
        lambda xs: "[" + ", ".join("nan" if math.isnan(x) else "inf" if x == math.inf else "-inf"
                                   if x == -math.inf else repr(x) for x in xs) + "]"),
    st.integers(min_value=1, max_value=3000).map(lambda n: "[" * n + "]" * n),
)

FUZZ = settings(max_examples=60, deadline=10000, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _replace(text: str, key: str, value: str) -> str:
    out, done = [], False
    for line in text.splitlines():
        if not done and line.split("=")[0].strip() == key:
            line, done = f"{key} = {value}", True
        out.append(line)
    return "\n".join(out) + "\n"


def _check_contract(spec: object) -> None:
    """What every loaded spec promises, checked independently of the loader."""
    ts = spec.sample_time  # type: ignore[attr-defined]
    assert isinstance(ts, float) and math.isfinite(ts) and ts > 0
    windows = spec.windows  # type: ignore[attr-defined]
    for lo, hi in windows.values():
        assert math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi
    if len(windows) == 2:
        (a0, a1), (b0, b1) = windows.values()
        assert a1 <= b0 or b1 <= a0, "training and validation windows overlap"
    for p in spec.parameters:  # type: ignore[attr-defined]
        assert all(math.isfinite(v) for v in (p.start, p.min, p.max))
        assert p.min < p.max and p.min <= p.start <= p.max
    hold = spec.tracking.hold_until  # type: ignore[attr-defined]
    assert math.isfinite(hold) and hold >= 0


def _load(path: Path) -> object | None:
    """The spec, or None after checking the refusal is one bounded SpecError naming the file."""
    try:
        return load_spec(path, check_files=False)
    except SpecError as exc:
        message = str(exc)
        assert path.name in message
        assert len(message) < 4000
        return None


def test_the_valid_spec_loads(tmp_path: Path) -> None:
    (tmp_path / "spec.toml").write_text(VALID)
    _check_contract(load_spec(tmp_path / "spec.toml", check_files=False))


@FUZZ
@given(key=st.sampled_from(KEYS), value=TOML_VALUES)
def test_any_value_for_a_key_loads_within_contract_or_is_refused(tmp_path: Path, key: str, value: str) -> None:
    path = tmp_path / "spec.toml"
    path.write_text(_replace(VALID, key, value), encoding="utf-8")
    spec = _load(path)
    if spec is not None:
        _check_contract(spec)


@FUZZ
@given(data=st.binary(max_size=400))
def test_any_bytes_give_a_spec_or_one_spec_error(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / "spec.toml"
    path.write_bytes(data)
    spec = _load(path)
    if spec is not None:
        _check_contract(spec)


@FUZZ
@given(cut=st.integers(min_value=0, max_value=len(VALID)), junk=st.binary(max_size=20))
def test_a_truncated_or_corrupted_spec_is_refused_or_within_contract(tmp_path: Path, cut: int, junk: bytes) -> None:
    path = tmp_path / "spec.toml"
    path.write_bytes(VALID.encode()[:cut] + junk)
    spec = _load(path)
    if spec is not None:
        _check_contract(spec)


@pytest.mark.parametrize(("training", "validation", "refused"), [
    ("[0.0, 600.0]", "[600.0, 1200.0]", False),   # touching is not overlapping
    ("[0.0, 700.0]", "[600.0, 1200.0]", True),
    ("[600.0, 1200.0]", "[0.0, 600.0]", False),
    ("[0.0, 1200.0]", "[300.0, 600.0]", True),    # one inside the other
    ("[0.0, nan]", "[600.0, 1200.0]", True),
    ("[0.0, inf]", "[600.0, 1200.0]", True),
])
def test_windows_are_finite_and_disjoint(tmp_path: Path, training: str, validation: str, refused: bool) -> None:
    path = tmp_path / "spec.toml"
    path.write_text(_replace(_replace(VALID, "training", training), "validation", validation))
    if refused:
        with pytest.raises(SpecError, match="training"):
            load_spec(path, check_files=False)
    else:
        assert set(load_spec(path, check_files=False).windows) == {"training", "validation"}


@pytest.mark.parametrize("value", ["9" * 400, "[" * 5000 + "]" * 5000])
def test_huge_integers_and_deep_nesting_are_refused(tmp_path: Path, value: str) -> None:
    path = tmp_path / "spec.toml"
    path.write_text(_replace(VALID, "sample_time", value))
    with pytest.raises(SpecError) as info:
        load_spec(path, check_files=False)
    assert len(str(info.value)) < 600


def test_a_spec_that_is_not_utf8_names_the_line(tmp_path: Path) -> None:
    path = tmp_path / "spec.toml"
    path.write_bytes(VALID.replace('"k"', '"k\xe9"').encode("latin-1"))
    with pytest.raises(SpecError, match=r"line 12: not UTF-8"):
        load_spec(path, check_files=False)
