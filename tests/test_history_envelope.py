"""The run envelope: the run document, report.json and the history record around one result."""

from __future__ import annotations

import json
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pytest

from pytest_hevval import history as h
from pytest_hevval.results.codec import dumps
from pytest_hevval.results.envelope import (
    RUN_SCHEMA_VERSION,
    history_record,
    read_document,
    run_document,
)
from pytest_hevval.results.spec_result import RESULT_SCHEMA_VERSION
from pytest_hevval.results.verdict import RunVerdict

DATA = Path(__file__).parent / "data" / "history"
T0 = datetime(2024, 5, 1, 12, 0, 0, tzinfo=timezone.utc)
FACTS = {"model_version": "v3", "started_utc": "2024-05-01T12:00:00.000000Z", "tool_versions": {}}


def spec_data(key: str = "specs/a.hevval.yaml", phi: float = 0.95) -> dict[str, Any]:
    signal = {
        "path": "E_batt",
        "name": "E_batt",
        "set": 1,
        "level": 1,
        "alpha": 1.0,
        "lambdas": {"mae": 0.9, "rms": 0.8},
        "lag_s": 0.0,
        "peak_correlation": 1.0,
        "mae": 0.1,
        "rms": 0.2,
        "passed": True,
    }
    return {
        "schema_version": RESULT_SCHEMA_VERSION,
        "name": key.rsplit("/", 1)[-1],
        "spec": key,
        "phi": phi,
        "passed": True,
        "signals": [signal],
    }


def test_the_run_document_says_the_one_schema_its_results_carry() -> None:
    document = run_document([spec_data()], facts=FACTS, verdict=RunVerdict(passed=True), errors=())
    assert document["schema_version"] == RUN_SCHEMA_VERSION == RESULT_SCHEMA_VERSION
    assert document["specs"][0]["schema_version"] == document["schema_version"]
    assert document["run"] == FACTS
    # One spec: its own fields also sit at the top level, as documented.
    assert document["phi"] == 0.95
    assert document["spec"] == "specs/a.hevval.yaml"
    assert "campaigns" not in document
    assert "errors" not in document
    two = run_document(
        [spec_data(), spec_data("specs/b.hevval.yaml")],
        facts=FACTS,
        verdict=RunVerdict(passed=False),
        errors=[{"spec": "c", "error": "bad"}],
    )
    assert "phi" not in two
    assert two["passed"] is False
    assert two["errors"] == [{"spec": "c", "error": "bad"}]


@pytest.mark.parametrize("version", [1, 2, None])
def test_run_documents_of_this_and_earlier_versions_read_alike(version: int | None) -> None:
    document = run_document([spec_data()], facts=FACTS, verdict=RunVerdict(passed=True))
    if version is None:
        del document["schema_version"]
    else:
        document["schema_version"] = version  # 0.x wrote 1 there
    found = read_document(json.loads(dumps(document)), file="run.json")
    assert found.kind == "run"
    assert found.source == "hevval run"
    assert found.facts == FACTS
    assert [s["spec"] for s in found.specs] == ["specs/a.hevval.yaml"]


def test_a_report_reads_as_its_results_without_facts() -> None:
    report = {
        "report_schema_version": 1,
        "generated_by": "pytest-hevval 0.2.0",
        "summary": {},
        "specs": [spec_data(), "not a spec"],
    }
    found = read_document(report, file="report.json")
    assert found.kind == "report"
    assert found.source == "hevval run"
    assert found.facts == {}
    assert len(found.specs) == 1


@pytest.mark.parametrize("name", ["schema1_camry_hwfet.json", "schema2_camry_hwfet.json"])
def test_history_records_of_every_schema_read_as_the_current_one(name: str) -> None:
    found = read_document(json.loads((DATA / name).read_text("utf-8")), file=name)
    assert found.kind == "record"
    assert found.source == "history record"
    assert found.content["schema_version"] == h.SCHEMA_VERSION
    assert found.facts["model_version"] == found.content["model_version"]
    assert found.content["acceptance"] == "earlier-schema"
    assert all(isinstance(s["signals"][0]["lambdas"], dict) for s in found.specs)


def test_a_record_written_through_the_envelope_reads_back_unchanged() -> None:
    record = history_record(
        [spec_data()],
        model_version="v3",
        tool_versions={"numpy": "2"},
        started_utc=T0,
        acceptance="manual",
        commit=None,
        baseline=None,
    )
    assert record == h.make_record(
        [spec_data()],
        model_version="v3",
        tool_versions={"numpy": "2"},
        started_utc=T0,
        acceptance="manual",
    ) | {"tool_versions": {"numpy": "2"}}
    assert read_document(json.loads(dumps(record))).content == record


def test_documents_it_cannot_read_are_named_with_their_key() -> None:
    newer = run_document([spec_data()], facts=FACTS, verdict=RunVerdict(passed=True))
    newer["schema_version"] = RUN_SCHEMA_VERSION + 1
    with pytest.raises(h.HistoryError) as info:
        read_document(newer, file="new.json")
    assert str(info.value).startswith("new.json: schema_version: ")
    assert "newer than this pytest-hevval understands" in str(info.value)
    with pytest.raises(h.HistoryError, match="neither a history record nor a run result"):
        read_document({"x": 1}, file="other.json")
    with pytest.raises(h.HistoryError, match="newer than this pytest-hevval"):
        read_document({"schema_version": 99, "model_version": "v"}, file="rec.json")


def test_compare_reads_every_document_through_the_envelope(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from pytest_hevval.cli import main

    before = tmp_path / "before.json"
    before.write_text(
        dumps(run_document([spec_data()], facts=FACTS, verdict=RunVerdict(passed=True)))
    )
    after = tmp_path / "report.json"
    after.write_text(json.dumps({"report_schema_version": 1, "specs": [spec_data(phi=0.9)]}))
    assert main(["compare", str(before), str(after), "--format", "json"]) == 0
    compared = json.loads(capsys.readouterr().out)
    assert compared["comparison"]["specs"][0]["phi"]["delta"] == pytest.approx(-0.05)
