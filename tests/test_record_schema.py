"""The analysis record's typed structure (pipeline/analysis/schema.py): a record the
analysis writes is of its kind, field by field; its one serialisation reads back to the same
record and the same text; a damaged one is named by its first bad field; a path names a field
or is refused, as the claims register uses it."""

from __future__ import annotations

import copy
import dataclasses
import json

import pytest

from pipeline.analysis.record import read_analysis, write_analysis
from pipeline.analysis.schema import (
    CompleteRecord,
    DivergedRecord,
    Theory,
    check_record,
    field_type,
    record_from_json,
    to_json,
    value_at,
)
from pipeline.analysis.stages import analyze_log
from pipeline.errors import LogError
from pipeline.logs import verify_log


@pytest.fixture(scope="module")
def typed(short_logs) -> CompleteRecord:
    return analyze_log(verify_log(short_logs["short_nominal"]))


@pytest.fixture()
def record(typed) -> dict:
    """The record as JSON, as it is written (with the fields only a written record has)."""
    return {**to_json(typed), "schema": "s", "record_sha256": "0" * 64,
            "directions_sha256": "0" * 64}


def test_a_written_record_reads_back_whole_and_of_its_kind(typed, tmp_path):
    assert isinstance(typed, CompleteRecord) and typed.schema is None
    path = write_analysis(typed, tmp_path)
    text = path.read_text()
    back = read_analysis(path)
    assert isinstance(back, CompleteRecord) and back.schema == "breve-analysis/11"
    assert check_record(json.loads(text)) is None
    # The same record, field by field, with the three fields the writer sets.
    assert back == dataclasses.replace(typed, schema=back.schema,
                                       record_sha256=back.record_sha256,
                                       directions_sha256=back.directions_sha256)
    assert back.directions_sha256 is not None and back.record_sha256 is not None
    # One serialisation: the record read back and written again is the same text.
    again = write_analysis(back, tmp_path / "again")
    assert again.read_text() == text


def test_the_serialisation_keeps_field_order_and_leaves_out_only_absent_fields(typed):
    data = to_json(typed)
    assert list(data) == [f.name for f in dataclasses.fields(CompleteRecord)
                          if f.name not in ("schema", "record_sha256", "comparison",
                                            "directions_sha256")]
    assert list(data["theory"])[-2:] == ["window_steps_below_floor", "at_or_above_floor"]
    # A theory outside a window has no window counts: absent, not null.
    bare = to_json(dataclasses.replace(typed.theory, window_steps_below_floor=None,
                                       at_or_above_floor=None))
    assert "window_steps_below_floor" not in bare and "at_or_above_floor" not in bare
    # A required field that is null stays, as null (a quiet mode is held by no limit).
    quiet = data["prediction"]["modes"][-1]
    assert quiet["held_by"] is None and "held_by" in quiet
    written = {**data, "schema": "s", "directions_sha256": "0" * 64}
    assert record_from_json(written) == dataclasses.replace(typed, schema="s",
                                                            directions_sha256="0" * 64)
    assert isinstance(record_from_json(written).theory, Theory)


@pytest.mark.parametrize("path,value,needle", [
    (("dominant", "lag1"), "x", "dominant.lag1: 'x' is not a number"),
    (("dominant", "lag1"), True, "dominant.lag1: True is not a number"),  # a bool is no number
    (("theory", "fastest_mode", "axis"), 2.5, "theory.fastest_mode.axis: 2.5 is not an integer"),
    (("theory", "maps", "imex", "eigenvalues", "real", 3), None, "eigenvalues.real.3"),
    (("directions", 4, "lag1"), [], "directions.4.lag1"),
    (("prediction", "agrees"), 1, "prediction.agrees: 1 is not a bool"),
])
def test_a_field_of_the_wrong_type_is_named(record, path, value, needle):
    bad = copy.deepcopy(record)
    node = bad
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    assert needle in (check_record(bad) or "")


def test_a_missing_or_extra_field_is_named(record):
    whole = record
    assert check_record(whole) is None
    assert check_record({k: v for k, v in whole.items() if k != "harm"}) == "harm: missing"
    assert check_record({**whole, "harm2": {}}) == "harm2: not a field of the record"
    gone = copy.deepcopy(whole)
    del gone["theory"]["fastest_mode"]["gain"]
    assert check_record(gone) == "theory.fastest_mode.gain: missing"
    # NaN is a float (a lag-1 of a constant signal), not a damage
    nan = copy.deepcopy(whole)
    nan["dominant"]["lag1"] = float("nan")
    assert check_record(json.loads(json.dumps(nan))) is None


def test_the_written_only_fields_are_required_on_disk(record):
    for key in ("schema", "directions_sha256"):
        assert check_record({k: v for k, v in record.items() if k != key}) == f"{key}: missing"
    # A complete log's record has a directions table: its hash is a string, never null.
    assert check_record({**record, "directions_sha256": None}).startswith(
        "directions_sha256: null")


def test_a_field_with_a_class_default_is_still_required(record):
    """The robot card's roll fields default to 0.0 in the code; a record without them is not
    read as μ_roll = 0."""
    card = {k: v for k, v in record["robot"].items() if k != "mu_roll"}
    assert check_record({**record, "robot": card}) == "robot.mu_roll: missing"


def test_an_absent_field_written_as_null_is_refused(record):
    assert check_record({**record, "comparison": None}).startswith("comparison: null")
    theory = {**record["theory"], "window_steps_below_floor": None}
    assert check_record({**record, "theory": theory}).startswith(
        "theory.window_steps_below_floor: null")


def test_the_off_schema_record_is_never_written(typed, tmp_path):
    bad = dataclasses.replace(typed, dominant=dataclasses.replace(typed.dominant, lag1="x"))
    with pytest.raises(ValueError, match=r"off its schema: dominant\.lag1: 'x' is not a number"):
        write_analysis(bad, tmp_path)
    assert not (tmp_path / typed.spec_name).exists()
    path = write_analysis(typed, tmp_path)
    data = json.loads(path.read_text())
    data["bus_rate"]["lag1"] = "0.5"
    path.write_text(json.dumps(data))
    with pytest.raises(LogError, match=r"key bus_rate\.lag1: '0\.5' is not a number"):
        read_analysis(path)


def test_paths_name_fields_by_the_schema_and_read_by_value_at(typed):
    assert field_type("dominant.lag1") == float | None  # undetermined without motion
    assert field_type("theory.fastest_mode.axis") is int
    assert field_type("directions.-1.lag1") == float | None
    assert field_type("directions.-1.sigma") is float
    assert field_type("modes_along.share.any mode name") is float  # keyed by the data
    assert field_type("divergence.growth_factor", DivergedRecord) is float
    for bad in ("dominant.lag2", "theory.mu_max.x", "directions.last.lag1", "divergence.ratio"):
        with pytest.raises(KeyError):
            field_type(bad, CompleteRecord)
    assert value_at(typed, "directions.-1.lag1") == typed.directions[-1].lag1
    assert value_at(typed, ("theory", "fastest_mode", "axis")) == typed.theory.fastest_mode.axis
    assert value_at(typed, "modes_along.share") is typed.modes_along.share
    with pytest.raises(KeyError, match="lagg1"):
        value_at(typed, "dominant.lagg1")
    # An optional field that is absent names nothing; a required null field reads None.
    with pytest.raises(KeyError, match="comparison"):
        value_at(typed, "comparison.lag1_flip")
    assert value_at(typed, "prediction.modes.-1.held_by") is None


def test_every_path_the_code_reads_names_a_field():
    """The paths the sweep table, stage 7's table and the harm table read (fixed in the
    code) are fields of the schema: a renamed field fails here, not as a silent NaN or —."""
    from pipeline.analysis.stages import COMPARE_ROWS
    from pipeline.reports.mechanism import HARM_ROWS
    from pipeline.sweep.point import FIGURES

    paths = [*FIGURES.values(), *(p for _, p in COMPARE_ROWS),
             *(p for _, _, p, _ in HARM_ROWS), *(c for *_, c in HARM_ROWS if c)]
    for path in paths:
        assert field_type(".".join(path)) in (float, int, str, float | None, str | None), path


def test_a_note_row_whose_path_names_no_field_is_refused(tmp_path):
    from pipeline.claims.seed_note import NOTE_FILE, load_note
    from pipeline.errors import SpecError

    text = NOTE_FILE.read_text().replace("ours: velocity_jump.median",
                                         "ours: velocity_jump.mediann")
    bad = tmp_path / "note.yaml"
    bad.write_text(text)
    with pytest.raises(SpecError, match=r"field rows\.\d+\.ours: 'velocity_jump\.mediann' has "
                                        r"no field 'mediann'"):
        load_note(bad)
    assert load_note(NOTE_FILE).rows
