"""spec.toml: loading, every validation message, dumping and rewriting pairs."""
from __future__ import annotations

import re
import textwrap
from pathlib import Path

import pytest

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from trackingbox.errors import SpecError
from trackingbox.spec import (
    PairSpec,
    ParameterSpec,
    StateSpec,
    StoppageRule,
    dump_spec,
    load_spec,
    loads_spec,
    update_spec,
    write_pairs,
)

GOOD = """\
# the heat exchanger case
twin = "twin.fmu"                   # relative to this file
measurements = "data/measurements.csv"
sample_time = 10.0

[source]
path = "lib/TrackingBox"
model = "TrackingBox.Benches.HeatExchanger.Twin"

[inputs]
"FI-101" = "mHot_flow"
"TI-100" = "ThIn"

[outputs]
"TI-102" = "ThOut"
"LI-200" = "level"

[[parameters]]
name = "hx.kht"
start = 1000.0
min = 800.0
max = 1200

[[parameters]]
name = "hx.n"
start = 2.0
min = 1.0
max = 3.0

[fixed]
"hx.A" = 12

[windows]
training = [0.0, 14400.0]
validation = [14400, 28800.0]

[data]
stoppage = { tag = "FI-101", below = 0.05, settle = 60.0 }
max_gap = 120.0

[[pairs]]
variable = "TI-102"
parameter = "hx.kht"
gain = -0.004
time_constant = 300.0
lambda = 2.0

[[states]]
tag = "LI-200"
variable = "T200.level"
correction = "T200.m_flow_corr"
gain = 5.0

[tracking]
hold_until = 600.0
"""


def make_case(tmp_path: Path, text: str = GOOD) -> Path:
    """A spec directory with the files GOOD refers to."""
    (tmp_path / "twin.fmu").write_bytes(b"PK\x05\x06" + b"\0" * 18)
    (tmp_path / "data").mkdir(exist_ok=True)
    (tmp_path / "data" / "measurements.csv").write_text(
        "time,FI-101,TI-100,TI-102,LI-200\n0,1.0,80.0,60.0,0.5\n")
    (tmp_path / "lib" / "TrackingBox").mkdir(parents=True, exist_ok=True)
    path = tmp_path / "spec.toml"
    path.write_text(text)
    return path


def problems_of(path: Path) -> str:
    with pytest.raises(SpecError) as info:
        load_spec(path)
    return str(info.value)


def test_load_reads_every_field(tmp_path):
    spec = load_spec(make_case(tmp_path))
    assert spec.path == (tmp_path / "spec.toml").resolve()
    assert spec.twin == (tmp_path / "twin.fmu").resolve()
    assert spec.measurements == (tmp_path / "data" / "measurements.csv").resolve()
    assert spec.sample_time == 10.0
    assert spec.source.path == (tmp_path / "lib" / "TrackingBox").resolve()
    assert spec.source.model == "TrackingBox.Benches.HeatExchanger.Twin"
    assert spec.inputs == {"FI-101": "mHot_flow", "TI-100": "ThIn"}
    assert spec.outputs == {"TI-102": "ThOut", "LI-200": "level"}
    assert spec.parameters == (ParameterSpec("hx.kht", 1000.0, 800.0, 1200.0),
                               ParameterSpec("hx.n", 2.0, 1.0, 3.0))
    assert spec.parameter("hx.n").max == 3.0
    assert spec.fixed == {"hx.A": 12.0}
    assert spec.windows == {"training": (0.0, 14400.0), "validation": (14400.0, 28800.0)}
    assert spec.data.stoppage == StoppageRule("FI-101", 0.05, 60.0)
    assert spec.data.max_gap == 120.0
    assert spec.pairs == (PairSpec("TI-102", "hx.kht", -0.004, 300.0, 2.0),)
    assert spec.pairs[0].controller == "pi" and spec.pairs[0].kp is None
    assert spec.states == (StateSpec("LI-200", "T200.level", "T200.m_flow_corr", 5.0),)
    assert spec.tracking.hold_until == 600.0
    assert spec.tags == ("FI-101", "TI-100", "TI-102", "LI-200")


def test_optional_tables_have_defaults(tmp_path):
    path = make_case(tmp_path, 'twin = "twin.fmu"\nmeasurements = "data/measurements.csv"\n'
                               'sample_time = 5\n[outputs]\n"TI-102" = "ThOut"\n')
    spec = load_spec(path)
    assert spec.source is None and spec.inputs == {} and spec.parameters == ()
    assert spec.data.stoppage is None and spec.data.max_gap is None
    assert spec.pairs == () and spec.states == () and spec.tracking.hold_until == 0.0
    assert spec.windows == {}


def test_dump_round_trip(tmp_path):
    spec = load_spec(make_case(tmp_path))
    text = dump_spec(spec, header="written by a test")
    assert text.startswith("# written by a test\n")
    assert loads_spec(text, spec.path) == spec
    # paths are written relative to the spec file, as a user would write them
    assert 'twin = "twin.fmu"' in text
    assert 'measurements = "data/measurements.csv"' in text


def test_dump_moves_relative_paths_with_the_file(tmp_path):
    spec = load_spec(make_case(tmp_path))
    elsewhere = tmp_path / "sub" / "copy.toml"
    elsewhere.parent.mkdir()
    from trackingbox.spec import write_spec

    write_spec(spec, elsewhere)
    assert 'twin = "../twin.fmu"' in elsewhere.read_text()
    assert load_spec(elsewhere).twin == spec.twin


def test_unknown_keys_at_every_level_named_with_table_and_file(tmp_path):
    text = (GOOD.replace("sample_time = 10.0", "sample_time = 10.0\nsampletime = 3")
            .replace('max = 1200\n', 'max = 1200\nstrat = 1\n')
            .replace("max_gap = 120.0", "max_gap = 120.0\nmaxgap = 1")
            .replace("lambda = 2.0", "lamda = 2.0")
            .replace("hold_until = 600.0", "hold_untill = 600.0")
            .replace('stoppage = { tag = "FI-101",', 'stoppage = { tagg = "FI-101", tag = "FI-101",'))
    msg = problems_of(make_case(tmp_path, text))
    assert str(tmp_path / "spec.toml") in msg
    assert "unknown key 'sampletime' in the top level (did you mean 'sample_time'?)" in msg
    assert "unknown key 'strat' in [[parameters]] #1 ('hx.kht') (did you mean 'start'?)" in msg
    assert "unknown key 'maxgap' in [data] (did you mean 'max_gap'?)" in msg
    assert "unknown key 'lamda' in [[pairs]] #1 (did you mean 'lambda'?)" in msg
    assert "unknown key 'hold_untill' in [tracking] (did you mean 'hold_until'?)" in msg
    assert "unknown key 'tagg' in [data.stoppage] (did you mean 'tag'?)" in msg
    assert "6 problems" in msg


def test_missing_required_keys(tmp_path):
    path = make_case(tmp_path, "[outputs]\n\n[[parameters]]\nname = 'k'\nstart = 1.0\n")
    msg = problems_of(path)
    for key in ("twin", "measurements", "sample_time"):
        assert f"missing required key {key!r} in the top level" in msg
    assert "missing required key 'min' in [[parameters]] #1 ('k')" in msg
    assert "missing required key 'max' in [[parameters]] #1 ('k')" in msg


def test_wrong_types(tmp_path):
    text = (GOOD.replace("sample_time = 10.0", 'sample_time = "10 s"')
            .replace("gain = -0.004", "gain = true")
            .replace('"TI-100" = "ThIn"', '"TI-100" = 3')
            .replace("training = [0.0, 14400.0]", "training = [0.0]"))
    msg = problems_of(make_case(tmp_path, text))
    assert "'sample_time' in the top level must be a number, got string '10 s'" in msg
    assert "'gain' in [[pairs]] #1 must be a number, got boolean True" in msg
    assert "'TI-100' in [inputs] must name an FMU variable (a string), got number 3" in msg
    assert "'training' in [windows] must be [start, stop] in seconds, got [0.0]" in msg


def test_bounds_start_and_windows(tmp_path):
    text = (GOOD.replace("min = 800.0\nmax = 1200", "min = 1200.0\nmax = 1200")
            .replace("start = 2.0\nmin = 1.0", "start = 0.5\nmin = 1.0")
            .replace("validation = [14400, 28800.0]", "validation = [28800.0, 14400]"))
    msg = problems_of(make_case(tmp_path, text))
    assert "lower bound min = 1200.0 is not below upper bound max = 1200.0 in [[parameters]] #1 ('hx.kht')" in msg
    assert "start = 0.5 is outside its bounds [1.0, 3.0] in [[parameters]] #2 ('hx.n')" in msg
    assert "window 'validation' in [windows] has start 28800.0 >= stop 14400.0" in msg


def test_missing_files(tmp_path):
    path = make_case(tmp_path)
    (tmp_path / "twin.fmu").unlink()
    (tmp_path / "data" / "measurements.csv").unlink()
    msg = problems_of(path)
    assert f"twin file 'twin.fmu' does not exist (looked for {tmp_path / 'twin.fmu'})" in msg
    assert "measurements file 'data/measurements.csv' does not exist" in msg
    # without the file check the same spec loads
    assert load_spec(path, check_files=False).twin == tmp_path / "twin.fmu"


def test_tags_must_be_columns_of_the_measurements(tmp_path):
    path = make_case(tmp_path)
    (tmp_path / "data" / "measurements.csv").write_text("time,FI-101,TI-100,TI-103,LI-200\n0,1,2,3,4\n")
    msg = problems_of(path)
    assert "tag 'TI-102' is not a column of measurements.csv (did you mean 'TI-103'" in msg


def test_pairs_and_rules_naming_unknown_tags_or_parameters(tmp_path):
    text = (GOOD.replace('variable = "TI-102"', 'variable = "TI-120"')
            .replace('parameter = "hx.kht"', 'parameter = "hx.khtt"')
            .replace('stoppage = { tag = "FI-101"', 'stoppage = { tag = "FI-11"')
            .replace("lambda = 2.0", 'lambda = 2.0\ncontroller = "pid"'))
    msg = problems_of(make_case(tmp_path, text))
    assert "unknown tag 'TI-120' as variable in [[pairs]] #1" in msg
    assert "(did you mean 'TI-102'" in msg
    assert "unknown parameter 'hx.khtt' in [[pairs]] #1" in msg
    assert "(did you mean 'hx.kht'" in msg
    assert "unknown tag 'FI-11' in [data.stoppage] (did you mean 'FI-101'?)" in msg
    assert "unknown controller 'pid' in [[pairs]] #1" in msg


def test_spec_parameter_unknown_name_suggests(tmp_path):
    spec = load_spec(make_case(tmp_path))
    with pytest.raises(SpecError, match=re.escape("unknown parameter 'hx.kth'")) as info:
        spec.parameter("hx.kth")
    assert "did you mean 'hx.kht'" in str(info.value)


def test_invalid_toml_names_the_file(tmp_path):
    path = make_case(tmp_path, "twin = \n")
    with pytest.raises(SpecError, match="not valid TOML"):
        load_spec(path)


def test_write_pairs_keeps_everything_else(tmp_path):
    path = make_case(tmp_path)
    before = load_spec(path)
    new_pairs = [PairSpec("TI-102", "hx.n", 1.5, 120.0, 1.0, kp=0.3, ti=200.0),
                 PairSpec("LI-200", "hx.kht", -2e-4, 900.0, 3.0, controller="sliding")]
    written = write_pairs(path, new_pairs)
    after = load_spec(path)
    assert after == written
    assert after.pairs == tuple(new_pairs)
    # nothing else changed, comments included
    from dataclasses import replace

    assert replace(after, pairs=()) == replace(before, pairs=())
    text = path.read_text()
    assert text.startswith("# the heat exchanger case\n")
    assert "# relative to this file" in text
    assert text.count("[[pairs]]") == 2


def test_write_pairs_rejects_unknown_tag_and_leaves_file(tmp_path):
    path = make_case(tmp_path)
    original = path.read_text()
    with pytest.raises(SpecError, match="unknown tag 'XI-1'"):
        write_pairs(path, [PairSpec("XI-1", "hx.kht", 1.0, 1.0, 1.0)])
    assert path.read_text() == original


def test_write_pairs_empty_removes_pairs(tmp_path):
    path = make_case(tmp_path)
    write_pairs(path, [])
    spec = load_spec(path)
    assert spec.pairs == ()
    assert spec.tracking.hold_until == 600.0  # the table after [[pairs]] survived
    assert "[[pairs]]" not in path.read_text()


def test_example_in_architecture_doc_is_valid(tmp_path):
    """The spec.toml example in docs/architecture.md loads (files created beside it)."""
    doc = Path(__file__).resolve().parents[1] / "docs" / "architecture.md"
    text = doc.read_text()
    block = text.split("### spec.toml", 1)[1].split("```toml", 1)[1].split("```", 1)[0]
    (tmp_path / "twin.fmu").write_bytes(b"")
    (tmp_path / "measurements.csv").write_text("time,FI-101,TI-102,LI-200\n")
    (tmp_path / "modelica" / "TrackingBox").mkdir(parents=True)
    path = tmp_path / "spec.toml"
    path.write_text(textwrap.dedent(block))
    spec = load_spec(path)
    assert spec.pairs[0].parameter == "hx.kht"
    assert spec.states[0].correction == "T200.m_flow_corr"


# --------------------------------------------------------------------------- update_spec (tomlkit writer)

#: A spec as a person writes it: comments everywhere, odd spacing, inline tables,
#: pairs in the middle of the file followed by a comment about the next table.
HANDWRITTEN = """\
# heat exchanger, plant 3
twin   =   "twin.fmu"   # compiled by hand
measurements = "data/measurements.csv"
sample_time=10.0
parameters = [
    { name = "hx.kht", start = 1000, min = 800.0, max = 1200.0 },   # W/K
    {name="hx.n",start=2.0,min=1.0,max=3.0},
]

[inputs]  # what drives the twin
"FI-101" = "mHot_flow"
"TI-100"="ThIn"

[outputs]
"TI-102" = "ThOut"
"LI-200" = "level"
"""

HANDWRITTEN_TABLES = """\
# heat exchanger, plant 3
twin = "twin.fmu"
measurements = "data/measurements.csv"
sample_time = 10.0

[outputs]
"TI-102" = "ThOut"
"LI-200" = "level"

[[parameters]]
name    = "hx.kht"      # the one we track
start   =   1000        # from the datasheet
min = 800.0
max = 1200.0

[[parameters]]
  name = "hx.n"
  start = 2.0
  min = 1.0
  max = 3.0

[[pairs]]   # written by trackingbox pair
variable = "TI-102"
parameter = "hx.kht"
gain = -0.004
time_constant = 300.0
lambda = 2.0

# the tank level is compensated, not tracked
[[states]]
tag = "LI-200"
variable = "T200.level"
correction = "T200.m_flow_corr"
gain = 5.0

[tracking]
hold_until = 600.0   # start-up
"""

#: What HANDWRITTEN_TABLES must become after the starts and pairs below are written:
#: typed by hand, not produced by the code.
HANDWRITTEN_TABLES_AFTER = """\
# heat exchanger, plant 3
twin = "twin.fmu"
measurements = "data/measurements.csv"
sample_time = 10.0

[outputs]
"TI-102" = "ThOut"
"LI-200" = "level"

[[parameters]]
name    = "hx.kht"      # the one we track
start   =   912.5        # from the datasheet
min = 800.0
max = 1200.0

[[parameters]]
  name = "hx.n"
  start = 2.0
  min = 1.0
  max = 3.0

[[pairs]]   # written by trackingbox pair
variable = "TI-102"
parameter = "hx.n"
gain = 1.5
time_constant = 120.0
lambda = 1.0
kp = 0.25
ti = 200.0

[[pairs]]
variable = "LI-200"
parameter = "hx.kht"
gain = -0.0002
time_constant = 900.0
lambda = 3.0
controller = "sliding"

# the tank level is compensated, not tracked
[[states]]
tag = "LI-200"
variable = "T200.level"
correction = "T200.m_flow_corr"
gain = 5.0

[tracking]
hold_until = 600.0   # start-up
"""

NEW_PAIRS = (PairSpec("TI-102", "hx.n", 1.5, 120.0, 1.0, kp=0.25, ti=200.0),
             PairSpec("LI-200", "hx.kht", -2e-4, 900.0, 3.0, controller="sliding"))


def test_update_spec_gives_the_hand_written_text(tmp_path):
    """Starts and pairs written into a commented spec: exactly the text typed above."""
    path = make_case(tmp_path, HANDWRITTEN_TABLES)
    written = update_spec(path, pairs=NEW_PAIRS, starts={"hx.kht": 912.5})
    assert path.read_text() == HANDWRITTEN_TABLES_AFTER
    assert written == load_spec(path)
    # the values load back with a plain TOML reader too
    raw = tomllib.loads(path.read_text())
    assert raw["parameters"][0]["start"] == 912.5
    assert [(p["variable"], p["parameter"]) for p in raw["pairs"]] == [("TI-102", "hx.n"),
                                                                     ("LI-200", "hx.kht")]
    assert raw["pairs"][1]["gain"] == -2e-4


def test_update_spec_is_idempotent(tmp_path):
    path = make_case(tmp_path, HANDWRITTEN_TABLES)
    update_spec(path, pairs=NEW_PAIRS, starts={"hx.kht": 912.5})
    once = path.read_bytes()
    update_spec(path, pairs=NEW_PAIRS, starts={"hx.kht": 912.5})
    assert path.read_bytes() == once


def test_update_spec_inline_tables_keep_layout(tmp_path):
    """Starts inside inline tables change in place; the pairs go to the end of the file."""
    path = make_case(tmp_path, HANDWRITTEN)
    update_spec(path, starts={"hx.kht": 1100.0, "hx.n": 2.5}, pairs=NEW_PAIRS[:1])
    text = path.read_text()
    before, after = HANDWRITTEN.split("parameters = [", 1)
    assert text.startswith(before)  # comments, spacing and unquoted oddities untouched
    assert ('parameters = [\n'
            '    { name = "hx.kht", start = 1100.0, min = 800.0, max = 1200.0 },   # W/K\n'
            '    {name="hx.n",start=2.5,min=1.0,max=3.0},\n'
            ']\n') in text
    assert text.endswith('"LI-200" = "level"\n\n[[pairs]]\nvariable = "TI-102"\nparameter = "hx.n"\n'
                         'gain = 1.5\ntime_constant = 120.0\nlambda = 1.0\nkp = 0.25\nti = 200.0\n')
    assert text.count("[inputs]  # what drives the twin\n") == 1
    raw = tomllib.loads(text)
    assert raw["pairs"] == [{"variable": "TI-102", "parameter": "hx.n", "gain": 1.5,
                             "time_constant": 120.0, "lambda": 1.0, "kp": 0.25, "ti": 200.0}]
    assert [p["start"] for p in raw["parameters"]] == [1100.0, 2.5]


def test_update_spec_removing_pairs_keeps_the_comment_of_the_next_table(tmp_path):
    path = make_case(tmp_path, HANDWRITTEN_TABLES)
    spec = update_spec(path, pairs=[])
    assert spec.pairs == ()
    text = path.read_text()
    head, tail = HANDWRITTEN_TABLES.split("[[pairs]]", 1)
    tail = tail.split("lambda = 2.0\n", 1)[1]
    assert text == head.rstrip("\n") + "\n" + tail


def test_update_spec_only_changes_start_lines(tmp_path):
    path = make_case(tmp_path)  # GOOD
    update_spec(path, starts={"hx.n": 1.75})
    changed = [(a, b) for a, b in zip(GOOD.splitlines(), path.read_text().splitlines()) if a != b]
    assert changed == [("start = 2.0", "start = 1.75")]
    assert len(path.read_text().splitlines()) == len(GOOD.splitlines())


@pytest.mark.parametrize("starts, message", [
    ({"hx.khtt": 900.0}, "unknown parameter 'hx.khtt' in [[parameters]] (did you mean 'hx.kht'?)"),
    ({"hx.kht": 5000.0}, "start 5000.0 of 'hx.kht' is outside its bounds [800.0, 1200.0]"),
    ({"hx.n": float("nan")}, "start nan of 'hx.n' is outside its bounds"),
])
def test_update_spec_bad_starts_leave_file(tmp_path, starts, message):
    path = make_case(tmp_path, HANDWRITTEN_TABLES)
    with pytest.raises(SpecError) as info:
        update_spec(path, starts=starts, pairs=NEW_PAIRS)
    assert message in str(info.value) and str(path) in str(info.value)
    assert path.read_text() == HANDWRITTEN_TABLES
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".part")] == []


def test_write_starts_in_estimation_is_the_same_writer(tmp_path):
    from trackingbox.estimation import write_starts

    path = make_case(tmp_path, HANDWRITTEN_TABLES)
    spec = write_starts(path, {"hx.kht": 912.5})
    assert spec.parameter("hx.kht").start == 912.5
    assert path.read_text() == HANDWRITTEN_TABLES.replace("start   =   1000 ", "start   =   912.5 ")


def test_a_path_that_is_a_loop_of_symbolic_links_is_one_clear_error(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A robustness run found ``RuntimeError: Symlink loop`` escaping the spec's path resolution (a traceback)."""
    from trackingbox import cli

    (tmp_path / "twin.fmu").symlink_to("twin.fmu")  # a link to itself
    (tmp_path / "a.csv").symlink_to("b.csv")
    (tmp_path / "b.csv").symlink_to("a.csv")  # two links to each other
    (tmp_path / "src").symlink_to("src")
    spec = tmp_path / "spec.toml"
    spec.write_text('twin = "twin.fmu"\nmeasurements = "a.csv"\nsample_time = 10.0\n'
                    '[source]\npath = "src"\nmodel = "M"\n[outputs]\ny = "y"\n')
    with pytest.raises(SpecError) as err:
        load_spec(spec)
    text = str(err.value)
    assert f"twin file 'twin.fmu' is a loop of symbolic links (looked for {tmp_path / 'twin.fmu'})" in text
    assert f"measurements file 'a.csv' is a loop of symbolic links (looked for {tmp_path / 'a.csv'})" in text
    assert "path 'src' in [source] is a loop of symbolic links" in text
    assert cli.main(["estimate", str(spec)]) == 2
    err_text = capsys.readouterr().err
    assert err_text.startswith("error: ") and "Traceback" not in err_text and "RuntimeError" not in err_text
    (tmp_path / "loop.toml").symlink_to("loop.toml")  # the spec path itself
    assert cli.main(["estimate", str(tmp_path / "loop.toml")]) == 2
    line = capsys.readouterr().err.strip()
    assert line.startswith("error: spec file") and "\n" not in line
