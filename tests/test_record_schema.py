"""The analysis record's typed description (pipeline/analysis/schema.py): a record the
analysis writes is of its kind, field by field; a damaged one is named by its first bad
field; a path names a field or is refused, as the claims register uses it."""

from __future__ import annotations

import copy
import json

import pytest

from pipeline.analysis.record import read_analysis, write_analysis
from pipeline.analysis.schema import (
    CompleteRecord,
    DivergedRecord,
    check_record,
    field_type,
    value_at,
)
from pipeline.analysis.stages import analyze_log
from pipeline.errors import LogError
from pipeline.logs import verify_log


@pytest.fixture(scope="module")
def record(short_logs) -> dict:
    return analyze_log(verify_log(short_logs["short_nominal"]))


def test_a_written_record_reads_back_whole_and_of_its_kind(record, tmp_path):
    path = write_analysis(record, tmp_path)
    back = read_analysis(path)
    assert check_record(back) is None
    assert back["dominant"] == record["dominant"] and back["theory"]["mu"] == record["theory"]["mu"]


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
    assert needle in (check_record({**bad, "schema": "s", "directions_sha256": None}) or "")


def test_a_missing_or_extra_field_is_named(record):
    whole = {**record, "schema": "s", "directions_sha256": None}
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


def test_the_off_schema_record_is_never_written(record, tmp_path):
    with pytest.raises(ValueError, match="off its schema: dominant: missing"):
        write_analysis({k: v for k, v in record.items() if k != "dominant"}, tmp_path)
    assert not (tmp_path / record["spec_name"]).exists()
    path = write_analysis(record, tmp_path)
    data = json.loads(path.read_text())
    data["bus_rate"]["lag1"] = "0.5"
    path.write_text(json.dumps(data))
    with pytest.raises(LogError, match=r"key bus_rate\.lag1: '0\.5' is not a number"):
        read_analysis(path)


def test_paths_name_fields_by_the_schema_and_read_by_value_at(record):
    assert field_type("dominant.lag1") is float
    assert field_type("theory.fastest_mode.axis") is int
    assert field_type("directions.-1.lag1") is float
    assert field_type("modes_along.share.any mode name") is float  # keyed by the data
    assert field_type("divergence.growth_factor", DivergedRecord) is float
    for bad in ("dominant.lag2", "theory.mu_max.x", "directions.last.lag1", "divergence.ratio"):
        with pytest.raises(KeyError):
            field_type(bad, CompleteRecord)
    assert value_at(record, "directions.-1.lag1") == record["directions"][-1]["lag1"]
    assert value_at(record, ("theory", "fastest_mode", "axis")) == \
        record["theory"]["fastest_mode"]["axis"]
    with pytest.raises(KeyError, match="lagg1"):
        value_at(record, "dominant.lagg1")
