"""What the API returns names its units: ISO 8601 times, Table-2 fields in mm or deg by name,
form rows without a nominal size (JSON and CSV)."""
import csv
import io
import json
from datetime import UTC, datetime

from identify.records import write_table
from service.schemas import JobStatus, Report, report_frame

STORED = {"poses": [{"pose": "a", "score": 1.0}],
          "features": [{"name": "circle diameter", "nominal": 108.0, "nominal_text": "108", "tolerance": 0.02,
                        "deviation": {"a": 0.011}, "worst_instance": {"a": "diameter"}},
                       # a job stored before form rows lost their nominal still shows none
                       {"name": "circle roundness", "nominal": 108.0, "nominal_text": "108", "tolerance": 0.015,
                        "deviation": {"a": 0.004}, "worst_instance": {"a": "roundness"}},
                       {"name": "slope angle", "nominal": 5.0, "nominal_text": "5 deg", "tolerance": 0.02,
                        "deviation": {"a": -0.03}, "worst_instance": {"a": "angle"}}]}


def test_job_times_are_iso_8601_utc():
    st = JobStatus(id="0" * 32, kind="simulation", state="succeeded", progress=1.0, message="",
                   created=1_700_000_000.25, started=1_700_000_001.0, finished=None)
    doc = json.loads(st.model_dump_json())
    assert doc["created"] == "2023-11-14T22:13:20.250000Z" and doc["finished"] is None
    assert datetime.fromisoformat(doc["started"]) == datetime.fromtimestamp(1_700_000_001.0, tz=UTC)


def test_report_fields_carry_units_and_form_rows_no_nominal(tmp_path):
    doc = json.loads(Report.from_stored("j", STORED).model_dump_json())
    rows = {r["name"]: r for r in doc["features"]}
    assert rows["circle diameter"] == {"name": "circle diameter", "nominal_mm": 108.0, "nominal_deg": None,
                                       "nominal_text": "108", "tolerance_mm": 0.02, "deviation_mm": {"a": 0.011},
                                       "worst_instance": {"a": "diameter"}, "in_tolerance": {"a": True}}
    assert rows["circle roundness"]["nominal_mm"] is None and rows["circle roundness"]["nominal_text"] == "-"
    assert rows["slope angle"]["nominal_deg"] == 5.0 and rows["slope angle"]["nominal_mm"] is None
    # the CSV a job stores and serves (report.csv, through the one table writer)
    table = list(csv.DictReader(io.StringIO(write_table(report_frame(STORED), tmp_path / "report.csv").read_text())))
    assert list(table[0]) == ["feature", "nominal_mm", "nominal_deg", "tolerance_mm", "pose", "deviation_mm",
                              "in_tolerance"]
    assert [r["nominal_mm"] for r in table] == ["108", "", ""]
    assert [r["nominal_deg"] for r in table] == ["", "", "5"]
    assert [float(r["deviation_mm"]) for r in table] == [0.011, 0.004, -0.03]
    assert [r["in_tolerance"] for r in table] == ["True", "True", "False"]
