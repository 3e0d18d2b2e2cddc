"""Tests of run history: records, the store, comparison rules, the ratchet, trends and CLI."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import uuid
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_hevval import history as h
from pytest_hevval.cli import main as cli_main
from pytest_hevval.errors import SpecError
from pytest_hevval.flags import COMMAND
from pytest_hevval.results.codec import dumps, json_number, json_numbers, plain_json
from pytest_hevval.results.recorded import RecordedPoint
from pytest_hevval.results.spec_result import SpecResult
from tests.recorded_runs import recorded

T0 = datetime(2024, 5, 1, 12, 0, 0, tzinfo=timezone.utc)
LAMBDAS = [0.99, 0.95, 0.93, 0.92, 0.97, 0.91, 0.94]


def signal(path: str = "E_batt/P_batt", **overrides: Any) -> dict[str, Any]:
    base: dict[str, Any] = {
        "path": path,
        "name": path.rsplit("/", 1)[-1],
        "set": 1,
        "level": 2,
        "alpha": 1.0,
        "unit": "kW",
        "lambdas": list(LAMBDAS),
        "lag_s": -0.2,
        "peak_correlation": 0.99,
        "mae": 1.2,
        "rms": 2.0,
        "delta_e": 0.8,
        "error_std": 1.9,
        "mean_error": 0.1,
        "thresholds": {"mae": 0.9},
        "failures": [],
        "passed": True,
    }
    base.update(overrides)
    return base


def spec(
    name: str = "trip A01",
    *,
    phi: float | None = 0.9412,
    signals: list[dict[str, Any]] | None = None,
    path: str | None = "specs/trip_a01.hevval.yaml",
) -> dict[str, Any]:
    result: dict[str, Any] = {
        "schema_version": 1,
        "name": name,
        "spec_hash": "sha256:abc",
        "phi": phi,
        "min_phi": 0.9,
        "passed": True,
        "data": {"reference": {"path": "ref.csv", "sha256": "r"}},
        "signals": signals if signals is not None else [signal()],
    }
    if path is not None:
        result["spec"] = path
    return result


def scored(**kwargs: Any) -> SpecResult:
    """A typed spec result, as scoring hands it on, from the plain data of :func:`spec`."""
    return SpecResult.from_dict(spec(**kwargs))


def record(
    version: str,
    when: datetime,
    specs: list[dict[str, Any]] | None = None,
    acceptance: str = "not-compared",
) -> dict[str, Any]:
    return h.make_record(
        specs or [spec()], model_version=version, started_utc=when, acceptance=acceptance
    )


# -- records --------------------------------------------------------------------------------


def test_make_record_carries_versions_hashes_and_values() -> None:
    rec = h.make_record(
        [spec()], model_version=" v1.2 ", tool_versions={"fmpy": "0.3"}, started_utc=T0
    )
    assert rec["schema_version"] == h.SCHEMA_VERSION == 4
    assert rec["model_version"] == "v1.2"
    assert rec["started_utc"] == "2024-05-01T12:00:00.000000Z"
    assert {"pytest-hevval", "numpy", "scipy", "python", "fmpy"} <= set(rec["tool_versions"])
    stored = rec["specs"][0]
    assert stored["spec_hash"] == "sha256:abc"
    assert stored["data"]["reference"]["sha256"] == "r"
    assert stored["phi"] == pytest.approx(0.9412)
    sig = stored["signals"][0]
    assert sig["lambdas"] == dict(zip(_names(), LAMBDAS, strict=True))
    assert (sig["lag_s"], sig["mae"], sig["passed"]) == (-0.2, 1.2, True)
    json.dumps(rec, allow_nan=False)


def test_make_record_accepts_engine_results_and_drops_figures() -> None:
    plain = SpecResult.from_dict(spec()).to_dict()
    engine = json.loads(json.dumps(plain))
    engine["signals"][0]["figures"] = {"png": "x" * 1000}
    rec = h.make_record([engine], model_version="v", started_utc=T0)
    stored = rec["specs"][0]
    assert stored["weights"] == engine["weights"]
    assert "figures" not in stored["signals"][0]
    assert stored["signals"][0]["children"] == []
    assert SpecResult.from_dict(stored).to_dict() == plain


def test_make_record_converts_nan_and_numpy_scalars() -> None:
    lambdas: list[Any] = [np.float64(0.5), float("nan"), *LAMBDAS[2:]]
    rec = h.make_record(
        [spec(phi=np.float64(0.8), signals=[signal(lambdas=lambdas, mae=np.float32(2.0))])],
        model_version="v",
        started_utc=T0 + timedelta(hours=2),
    )
    sig = rec["specs"][0]["signals"][0]
    assert [sig["lambdas"][n] for n in _names()[:2]] == [0.5, None]
    assert sig["mae"] == 2.0
    assert rec["specs"][0]["phi"] == 0.8
    assert type(rec["specs"][0]["phi"]) is float


@given(
    st.lists(
        st.one_of(
            st.floats(allow_nan=True, allow_infinity=True),
            st.integers(-(2**52), 2**52),
            st.none(),
        ),
        max_size=30,
    )
)
def test_a_column_of_numbers_becomes_json_as_each_number_does(values: list[Any]) -> None:
    """The tables' vectorised conversion agrees with the one for a single number: NaN, ±inf
    and None become null, everything else a Python float."""
    converted = json_numbers(values)
    assert converted == [json_number(v) for v in values]
    assert all(type(v) is float for v in converted if v is not None)
    assert json_numbers(np.array(values, dtype=np.float64)) == converted


_JSON_VALUES = st.recursive(
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner),
    max_leaves=20,
)


@given(_JSON_VALUES)
def test_the_results_file_layout_says_what_the_standard_encoder_says(value: Any) -> None:
    """``hevval run --json`` lays columns of numbers on one line; the text still reads back as
    the data, as the standard library's own indented text does."""
    assert json.loads(dumps(value)) == json.loads(json.dumps(value))
    assert json.loads(dumps(value, indent=None)) == json.loads(json.dumps(value))


def test_the_results_file_keeps_a_column_on_one_line_and_refuses_nan() -> None:
    text = dumps({"b": {"rms": [1.5, None, 2.0]}, "a": [{"x": 1}], "spans": [[0.0, 30.0]]})
    assert text == (
        '{\n  "a": [\n    {\n      "x": 1\n    }\n  ],\n'
        '  "b": {\n    "rms": [1.5, null, 2.0]\n  },\n  "spans": [[0.0, 30.0]]\n}\n'
    )
    for bad in (float("nan"), float("inf")):
        with pytest.raises(ValueError, match="not JSON compliant"):
            dumps({"rms": [bad]})


def test_make_record_converts_other_timezones_to_utc() -> None:
    plus_two = timezone(timedelta(hours=2))
    rec = record("v", datetime(2024, 5, 1, 14, 0, tzinfo=plus_two))
    assert rec["started_utc"] == "2024-05-01T12:00:00.000000Z"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"started_utc": datetime(2024, 5, 1)}, "timezone-aware"),
        ({"model_version": ""}, "model_version"),
    ],
)
def test_make_record_rejects_bad_arguments(kwargs: dict[str, Any], message: str) -> None:
    arguments: dict[str, Any] = {"model_version": "v", "started_utc": T0, **kwargs}
    with pytest.raises(h.HistoryError, match=message):
        h.make_record([spec()], **arguments)


def test_make_record_names_the_bad_key() -> None:
    with pytest.raises(h.HistoryError) as info:
        h.make_record(
            [spec(signals=[signal(lambdas=[1.0, 2.0])])], model_version="v", started_utc=T0
        )
    assert info.value.key == "specs[0].signals[0].lambdas"
    assert isinstance(info.value, ValueError)


def v1_record() -> dict[str, Any]:
    sig = signal()
    sig["lambdas"] = dict(zip(_names(), LAMBDAS, strict=True))
    return {
        "schema_version": 1,
        "version": "v0.9",
        "timestamp": (T0 - timedelta(days=1)).timestamp(),
        "tools": {"pytest-hevval": "0.0.9"},
        "results": [spec(signals=[sig])],
    }


def _names() -> tuple[str, ...]:
    from pytest_hevval.core.characteristics import CHARACTERISTICS

    return CHARACTERISTICS


def test_migrate_schema_1_to_4() -> None:
    migrated = h.migrate_record(v1_record())
    assert migrated["schema_version"] == 4
    assert (migrated["accepted"], migrated["acceptance"]) == (True, "earlier-schema")
    assert migrated["model_version"] == "v0.9"
    assert migrated["started_utc"] == "2024-04-30T12:00:00.000000Z"
    assert migrated["tool_versions"] == {"pytest-hevval": "0.0.9"}
    assert migrated["specs"][0]["signals"][0]["lambdas"] == dict(
        zip(_names(), LAMBDAS, strict=True)
    )


def test_migrate_schema_4_is_identity_after_validation() -> None:
    rec = record("v1", T0)
    assert h.migrate_record(json.loads(json.dumps(rec))) == rec


def test_a_schema_3_record_reads_as_an_accepted_baseline() -> None:
    schema3 = {
        key: value
        for key, value in record("v1", T0).items()
        if key not in ("accepted", "acceptance", "commit", "baseline")
    }
    migrated = h.migrate_record({**schema3, "schema_version": 3}, file="old.json")
    assert migrated == {
        **record("v1", T0),
        "tool_versions": schema3["tool_versions"],
        "accepted": True,
        "acceptance": "earlier-schema",
    }


@pytest.mark.parametrize(("reason", "accepted"), sorted(h.ACCEPTANCE.items()))
def test_a_record_says_whether_it_is_an_accepted_baseline(reason: str, accepted: bool) -> None:
    baseline = h.make_record([spec()], model_version="v0", started_utc=T0, commit="abc123")
    rec = h.make_record(
        [spec()],
        model_version="v1",
        started_utc=T0 + timedelta(hours=1),
        acceptance=reason,
        commit="def456",
        baseline=baseline,
    )
    assert (rec["accepted"], rec["acceptance"]) == (accepted, reason)
    assert rec["commit"] == "def456"
    assert rec["baseline"] == {
        "model_version": "v0",
        "started_utc": "2024-05-01T12:00:00.000000Z",
        "commit": "abc123",
    }
    assert h.migrate_record(json.loads(json.dumps(rec))) == rec


def test_acceptance_that_contradicts_its_reason_names_the_file_and_key() -> None:
    rec = {**record("v1", T0), "acceptance": "regressed"}  # still "accepted": true
    with pytest.raises(h.HistoryError, match="acceptance 'regressed' means False") as info:
        h.migrate_record(rec, file="r.json")
    assert (info.value.file, info.value.key) == ("r.json", "accepted")
    with pytest.raises(h.HistoryError, match="unknown acceptance 'fine'"):
        h.migrate_record({**rec, "acceptance": "fine"}, file="r.json")
    with pytest.raises(h.HistoryError, match="unknown acceptance"):
        h.make_record([spec()], model_version="v1", started_utc=T0, acceptance="fine")


@pytest.mark.parametrize(
    ("compared", "found", "regressed", "create", "accept", "reason"),
    [
        (False, False, False, False, False, "not-compared"),
        (True, True, False, False, False, "no-regression"),
        (True, True, True, False, False, "regressed"),
        (True, True, True, True, False, "regressed"),
        (True, False, False, False, False, "no-baseline"),
        (True, False, False, True, False, "first-baseline"),
        (True, True, True, False, True, "manual"),
        (True, False, False, False, True, "manual"),
        (False, False, False, False, True, "manual"),
    ],
)
def test_acceptance_rule(
    compared: bool, found: bool, regressed: bool, create: bool, accept: bool, reason: str
) -> None:
    assert (
        h.acceptance(
            compared=compared,
            baseline_found=found,
            regressed=regressed,
            create_baseline=create,
            accept=accept,
        )
        == reason
    )


def test_the_newest_accepted_record_is_found_without_reading_the_others(
    tmp_path: Path, reads: list[str]
) -> None:
    from pytest_hevval.history import index as history_index

    store = h.HistoryStore(tmp_path)
    for hour, (version, reason) in enumerate(
        [("v1", "no-regression"), ("v2", "regressed"), ("v3", "no-baseline")]
    ):
        store.append(
            h.make_record(
                [spec()],
                model_version=version,
                started_utc=T0 + timedelta(hours=hour),
                acceptance=reason,
            )
        )
    assert store.latest()["model_version"] == "v3"  # latest keeps its meaning
    store.trends()  # builds the index
    index = history_index.load_index(tmp_path)
    assert index is not None
    assert {e.model_version: e.accepted for e in index.records.values()} == {
        "v1": True,
        "v2": False,
        "v3": False,
    }
    reads.clear()
    assert store.accepted()["model_version"] == "v1"
    assert [name.split("_")[1] for name in reads] == ["v1"]
    run, label = h.load_side("history:accepted", tmp_path)
    assert (label, run.specs[0].phi) == ("v1", spec()["phi"])


def test_history_accepted_names_what_to_do_when_nothing_is_accepted(tmp_path: Path) -> None:
    h.HistoryStore(tmp_path).append(
        h.make_record([spec()], model_version="v1", started_utc=T0, acceptance="regressed")
    )
    with pytest.raises(h.HistoryError, match=r"no record in .* is accepted") as info:
        h.load_side("history:accepted", tmp_path)
    assert "--hevval-accept" in str(info.value)


@pytest.mark.parametrize(
    ("document", "message"),
    [
        ({"schema_version": 99}, "newer than this pytest-hevval"),
        ({"schema_version": "two"}, "unknown schema_version"),
        ({"schema_version": 1, "version": "v", "timestamp": "yesterday"}, "timestamp"),
        ({"schema_version": 1, "version": "v", "timestamp": 0, "results": {}}, "results"),
        ({"schema_version": 2, "model_version": "v", "started_utc": "noon", "specs": []}, "ISO"),
        ([1, 2], "JSON object"),
    ],
)
def test_migrate_rejects_bad_documents(document: Any, message: str) -> None:
    with pytest.raises(h.HistoryError, match=message) as info:
        h.migrate_record(document, file="x.json")
    assert "x.json" in str(info.value)


def test_resolve_model_version_precedence(tmp_path: Path) -> None:
    env = {"HEVVAL_MODEL_VERSION": "from-env"}
    assert h.resolve_model_version("cli", env, tmp_path) == "cli"
    assert h.resolve_model_version("  ", env, tmp_path) == "from-env"
    assert h.resolve_model_version(None, env, tmp_path) == "from-env"


def _git(cwd: Path, *args: str) -> None:
    subprocess.run(
        ["git", "-c", "user.name=t", "-c", "user.email=t@example.com", *args],
        cwd=cwd,
        check=True,
        capture_output=True,
    )


def test_resolve_model_version_from_git(tmp_path: Path) -> None:
    _git(tmp_path, "init", "-q")
    (tmp_path / "model.txt").write_text("a")
    _git(tmp_path, "add", "model.txt")
    _git(tmp_path, "commit", "-q", "-m", "m")
    clean = h.resolve_model_version(None, {}, tmp_path)
    assert re.fullmatch(r"[0-9a-f]{7,40}", clean)
    (tmp_path / "model.txt").write_text("b")
    assert h.resolve_model_version(None, {}, tmp_path) == f"{clean}-dirty"


def test_resolve_model_version_outside_git_or_without_git(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path.parent))
    assert h.resolve_model_version(None, {}, tmp_path) == "unknown"
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    assert h.resolve_model_version(None, {}, tmp_path) == "unknown"


# -- store ----------------------------------------------------------------------------------

NAME = re.compile(r"^\d{8}T\d{6}\.\d{6}Z_[A-Za-z0-9.+-]+_[0-9a-f]{8}\.json$")


def test_store_round_trip_and_file_names(tmp_path: Path) -> None:
    store = h.HistoryStore(tmp_path / "hist")
    first = store.append(record("v1.0 beta/2", T0))
    second = store.append(record("v1.1", T0 + timedelta(days=1)))
    assert NAME.match(first.name)
    assert NAME.match(second.name)
    assert "_v1.0-beta-2_" in first.name
    records = store.records()
    assert [r["model_version"] for r in records] == ["v1.0 beta/2", "v1.1"]
    assert records[1] == record("v1.1", T0 + timedelta(days=1))
    assert store.problems == []
    assert not list((tmp_path / "hist").glob(".tmp-*"))


def test_a_record_file_holds_one_spec_per_line(tmp_path: Path) -> None:
    """Strict JSON that reads line by line: each top-level key, and each spec, on its own."""
    two = record("v1", T0)
    two["specs"] = two["specs"] * 2
    path = h.HistoryStore(tmp_path).append(two)
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[0] == "{"
    assert lines[-1] == "}"
    specs = [json.loads(line.rstrip(",")) for line in lines if line.startswith("  {")]
    assert specs == h.validate_record(two)["specs"]
    assert len(specs) == 2
    assert json.loads(path.read_text(encoding="utf-8")) == h.validate_record(two)


def test_numpy_numbers_are_stored_and_a_bad_value_is_named_by_its_key() -> None:
    data = {"a": [np.float64(0.5), np.int64(3), float("nan")], "b": {"c": (1.0, True)}}
    assert plain_json(data, strict=True) == {"a": [0.5, 3, None], "b": {"c": [1.0, True]}}
    with pytest.raises(h.HistoryError, match="cannot store a value of type set") as bad:
        plain_json({"specs": [{"signals": [{"x": {1, 2}}]}]}, strict=True, error=h.HistoryError)
    assert bad.value.key == "specs[0].signals[0].x"
    with pytest.raises(h.HistoryError, match="keys must be strings") as bad_key:
        plain_json({"specs": [{1: 2.0}]}, strict=True, error=h.HistoryError)
    assert bad_key.value.key == "specs[0]"


def test_store_is_append_only(tmp_path: Path) -> None:
    store = h.HistoryStore(tmp_path)
    rec = record("v1", T0)
    paths = [store.append(rec), store.append(rec)]
    assert paths[0] != paths[1]
    assert len(store.records()) == 2


def test_store_never_overwrites_an_existing_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = h.HistoryStore(tmp_path)
    taken = uuid.UUID(int=0xAAAAAAAA << 96)
    fresh = uuid.UUID(int=0xBBBBBBBB << 96)
    existing = tmp_path / f"20240501T120000.000000Z_v1_{taken.hex[:8]}.json"
    existing.write_text("precious")
    ids = iter([taken, fresh])
    monkeypatch.setattr(uuid, "uuid4", lambda: next(ids))
    path = store.append(record("v1", T0))
    assert path.name.endswith(f"_{fresh.hex[:8]}.json")
    assert existing.read_text() == "precious"


def test_store_without_hard_links(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def no_link(src: object, dst: object) -> None:
        raise PermissionError("hard links not supported")

    monkeypatch.setattr(os, "link", no_link)
    store = h.HistoryStore(tmp_path)
    store.append(record("v1", T0))
    store.append(record("v1", T0))
    assert len(store.records()) == 2
    assert not list(tmp_path.glob(".tmp-*"))


def test_store_skips_bad_files_and_reports_them(tmp_path: Path) -> None:
    store = h.HistoryStore(tmp_path)
    store.append(record("v1", T0))
    (tmp_path / "partial.json").write_text('{"schema_version": 2, "model_')
    (tmp_path / "empty.json").write_text("")
    (tmp_path / "other.json").write_text('{"hello": 1}')
    (tmp_path / "binary.json").write_bytes(b"\xff\xfe\x00")
    (tmp_path / "v1.json").write_text(json.dumps(v1_record()))
    (tmp_path / ".tmp-abc.part").write_text("{")
    records = store.records()
    assert [r["model_version"] for r in records] == ["v0.9", "v1"]
    problems = {p.path.name: p.message for p in store.problems}
    assert set(problems) == {"partial.json", "empty.json", "other.json", "binary.json"}
    assert "not valid JSON" in problems["partial.json"]
    assert "schema_version" in problems["other.json"]


def test_store_latest_and_find(tmp_path: Path) -> None:
    store = h.HistoryStore(tmp_path)
    assert store.latest() is None
    for i, version in enumerate(["a", "b", "a", "c"]):
        store.append(record(version, T0 + timedelta(days=i)))
    latest = store.latest()
    assert latest is not None
    assert latest["model_version"] == "c"
    earlier = store.latest(before=T0 + timedelta(days=2))
    assert earlier is not None
    assert earlier["model_version"] == "b"
    found = store.find("a")
    assert found is not None
    assert found["started_utc"].startswith("2024-05-03")
    assert store.find("zzz") is None
    assert store.versions() == ["a", "b", "c"]
    with pytest.raises(h.HistoryError, match="timezone-aware"):
        store.latest(before=datetime(2024, 1, 1))


def test_store_missing_folder_reads_as_empty(tmp_path: Path) -> None:
    assert h.HistoryStore(tmp_path / "nope").records() == []


def test_store_unwritable_location_is_a_history_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(h.HistoryError, match="history folder"):
        h.HistoryStore(blocker / "hist").append(record("v", T0))


WRITER = """
import sys
from datetime import datetime, timezone
from pytest_hevval.history import HistoryStore, make_record
store = HistoryStore(sys.argv[1])
when = datetime(2024, 5, 1, tzinfo=timezone.utc)
spec = {"name": "s", "phi": 0.5, "signals": [
    {"path": "a/b", "lambdas": [0.5] * 7, "writer": sys.argv[2]}]}
for i in range(20):
    spec["signals"][0]["n_samples"] = i
    spec["signals"][0]["name"] = sys.argv[2]
    store.append(make_record([spec], model_version="same", started_utc=when))
"""


def test_two_concurrent_writers_lose_nothing(tmp_path: Path) -> None:
    procs = [
        subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path), name])
        for name in ("w1", "w2")
    ]
    assert [p.wait(timeout=120) for p in procs] == [0, 0]
    store = h.HistoryStore(tmp_path)
    records = store.records()
    assert store.problems == []
    written = sorted(
        (r["specs"][0]["signals"][0]["name"], r["specs"][0]["signals"][0]["n_samples"])
        for r in records
    )
    assert written == sorted((w, i) for w in ("w1", "w2") for i in range(20))


# -- the index ------------------------------------------------------------------------------
#
# The answers a run takes from the index (baseline, trends, versions, problems) must be those a
# full read of every record gives; the reads it saves are counted through the one function
# that reads a file.


TREND = 3  # short trends, so that a few records already trim and refill them


def full_trends(directory: Path, limit: int) -> dict[tuple[str, str], list[RecordedPoint]]:
    """Each signal's trend as the report built it from a full read, kept to its newest runs."""
    trends: dict[tuple[str, str], list[RecordedPoint]] = {}
    for rec in h.HistoryStore(directory).records():
        version = str(rec.get("model_version", "?"))
        for spec_result in rec.get("specs", []):
            for sig in spec_result.get("signals", []):
                trends.setdefault((spec_result.get("spec", ""), sig["path"]), []).append(
                    RecordedPoint.from_json(version, spec_result.get("phi"), sig["lambdas"])
                )
    return {key: points[-limit:] for key, points in trends.items()}


def full_answers(directory: Path, limit: int, versions: list[str]) -> dict[str, Any]:
    """Everything the index serves, from a full read of every record."""
    store = h.HistoryStore(directory)
    entries = store.entries()
    newest = entries[::-1]
    middle = entries[len(entries) // 2].started_utc if entries else T0
    return {
        "trends": full_trends(directory, limit),
        "latest": entries[-1].record if entries else None,
        "before": next((e.record for e in newest if e.started_utc < middle), None),
        "newest2": [e.path.name for e in newest[:2]],
        "found": {
            v: next((e.record for e in newest if e.record["model_version"] == v), None)
            for v in versions
        },
        "versions": list(dict.fromkeys(e.record["model_version"] for e in entries)),
        "accepted": next((e.record for e in newest if e.record["accepted"]), None),
        "problems": [(p.path.name, p.message) for p in store.problems],
        "middle": middle,
    }


QUERIES = ("trends", "latest", "before", "newest2", "found", "versions", "accepted")


def index_answers(
    directory: Path,
    limit: int,
    versions: list[str],
    middle: datetime,
    first: str = "trends",
) -> dict[str, Any]:
    """The same answers through the index, each from a store of its own (a run of its own).

    ``first`` is asked first: it alone sees the folder as the last change left it, with the
    index brought up to date in the same call; the others find that index saved.
    """

    def ask(query: str) -> Any:
        store = h.HistoryStore(directory, trend_runs=limit)
        if query == "trends":
            return store.trends(), store.problems
        if query == "latest":
            return store.latest(), store.problems
        if query == "before":
            return store.latest(before=middle), store.problems
        if query == "newest2":
            return [e.path.name for e in store.newest(2)], store.problems
        if query == "found":
            return {v: store.find(v) for v in versions}, store.problems
        if query == "accepted":
            return store.accepted(), store.problems
        return store.versions(), store.problems

    answers: dict[str, Any] = {"middle": middle}
    for query in (first, *(q for q in QUERIES if q != first)):
        answers[query], problems = ask(query)
        listed = [(p.path.name, p.message) for p in problems]
        assert answers.setdefault("problems", listed) == listed, query
    return answers


def assert_same_as_full_read(
    directory: Path, limit: int = TREND, versions: list[str] | None = None
) -> None:
    expected = full_answers(directory, limit, versions or ["v0", "v1", "v2", "nope"])
    assert (
        index_answers(directory, limit, versions or ["v0", "v1", "v2", "nope"], expected["middle"])
        == expected
    )


@pytest.fixture
def reads(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Names of the files the store reads, in order."""
    from pytest_hevval.history import store as store_module

    seen: list[str] = []
    real = store_module.read_json

    def counting(path: Path | str, *args: Any, **kwargs: Any) -> Any:
        seen.append(Path(path).name)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(store_module, "read_json", counting)
    return seen


def two_signal_record(
    version: str, when: datetime, phi: float, extra: bool = False
) -> dict[str, Any]:
    signals = [signal("E_batt/P_batt", lambdas=[phi] * 7), signal("E_batt/U_batt")]
    if extra:
        signals.append(signal("E_batt/I_batt", lambdas=[phi / 2] * 7))
    # Every fourth hour's run regressed: not every record is an accepted baseline.
    acceptance = "regressed" if when.hour % 4 == 3 else "no-regression"
    specs = [spec(phi=phi, signals=signals), spec("B", path="b.hevval.yaml")]
    return record(version, when, specs, acceptance)


def fill(directory: Path, count: int, start: int = 0) -> list[Path]:
    store = h.HistoryStore(directory, trend_runs=TREND)
    return [
        store.append(two_signal_record(f"v{i % 3}", T0 + timedelta(hours=i), 0.5 + i / 100))
        for i in range(start, start + count)
    ]


def test_index_is_built_once_then_read_instead_of_the_records(
    tmp_path: Path, reads: list[str]
) -> None:
    fill(tmp_path, 6)
    assert not (tmp_path / ".index").exists()  # appending alone builds no index
    store = h.HistoryStore(tmp_path, trend_runs=TREND)
    trends = store.trends()
    assert len(reads) == 6
    assert (tmp_path / ".index" / "index").is_file()
    assert (tmp_path / ".index" / ".gitignore").read_text().splitlines()[-1] == "*"
    assert [p.version for p in trends[("specs/trip_a01.hevval.yaml", "E_batt/P_batt")]] == [
        "v0",
        "v1",
        "v2",
    ]
    reads.clear()
    assert h.HistoryStore(tmp_path, trend_runs=TREND).trends() == trends
    assert reads == []
    latest = h.HistoryStore(tmp_path, trend_runs=TREND).latest()
    assert latest is not None
    assert reads == [sorted(p.name for p in tmp_path.glob("*.json"))[-1]]
    reads.clear()
    found = h.HistoryStore(tmp_path, trend_runs=TREND).find("v0")
    assert found is not None
    assert found["started_utc"].startswith("2024-05-01T15")
    assert len(reads) == 1
    reads.clear()
    assert h.HistoryStore(tmp_path, trend_runs=TREND).versions() == ["v0", "v1", "v2"]
    assert reads == []
    assert_same_as_full_read(tmp_path)


def test_index_is_extended_by_appends_and_by_records_merged_in_with_older_names(
    tmp_path: Path, reads: list[str]
) -> None:
    main = tmp_path / "main"
    fill(main, 5, start=10)
    h.HistoryStore(main, trend_runs=TREND).trends()
    fill(main, 2, start=20)  # a run appends and adds its record to the index
    reads.clear()
    h.HistoryStore(main, trend_runs=TREND).trends()
    assert reads == []
    # A branch recorded runs before the newest ones on main; merging brings their files.
    branch = tmp_path / "branch"
    merged = fill(branch, 3, start=12) + fill(branch, 1, start=30)
    for path in merged:
        (main / path.name).write_bytes(path.read_bytes())
    reads.clear()
    h.HistoryStore(main, trend_runs=TREND).trends()
    assert sorted(reads) == sorted(p.name for p in merged)
    reads.clear()
    assert_same_as_full_read(main)


@pytest.mark.parametrize(
    "damage",
    [
        "garbage",
        "truncated",
        "a list",
        "another version",
        "another trend length",
        "a point of an unknown record",
        "a record listed twice",
        "a short trend not complete",
        "a trend out of order",
        "NaN",
        "deep",
        "a folder",
        "a named pipe",
        "deleted",
    ],
)
def test_index_damaged_stale_or_deleted_is_rebuilt(
    tmp_path: Path, reads: list[str], damage: str
) -> None:
    fill(tmp_path, 5)
    h.HistoryStore(tmp_path, trend_runs=TREND).trends()
    index_file = tmp_path / ".index" / "index"
    good = json.loads(index_file.read_text())
    bad = json.loads(index_file.read_text())
    if damage == "another version":
        bad["pytest_hevval"] = "0.0.0-other"
    elif damage == "a point of an unknown record":
        bad["trends"][0][3][0][0] = "nope.json"
    elif damage == "a record listed twice":
        for column in bad["records"].values():
            column.append(column[0])
    elif damage == "a short trend not complete":
        bad["trends"][0][2] = False
        bad["trends"][0][3] = bad["trends"][0][3][:1]
    elif damage == "another trend length":
        bad["trend_runs"] = TREND + 1
    elif damage == "a trend out of order":
        bad["trends"][0][3].reverse()
    elif damage == "NaN":
        bad["trends"][0][3][0][1] = float("nan")
    text = {
        "garbage": b"\x00\xff not json",
        "truncated": index_file.read_bytes()[:200],
        "a list": b"[]",
        "deep": b"[" * 100_000 + b"]" * 100_000,
    }.get(damage, json.dumps(bad).encode())
    index_file.unlink()
    if damage == "a folder":
        index_file.mkdir()
    elif damage == "a named pipe":
        os.mkfifo(index_file)
    elif damage != "deleted":
        index_file.write_bytes(text)
    reads.clear()
    assert_same_as_full_read(tmp_path)
    if damage == "a folder":
        assert index_file.is_dir()  # left alone; each run reads every record, as before
        return
    rewritten = json.loads(index_file.read_text())["records"]
    assert sorted(rewritten["name"]) == sorted(good["records"]["name"])
    reads.clear()
    h.HistoryStore(tmp_path, trend_runs=TREND).trends()
    assert reads == []


def test_a_folder_without_an_index_is_read_from_its_newest_records(
    tmp_path: Path, reads: list[str]
) -> None:
    """A fresh clone (no index: it is never committed): the baseline and the trends of the
    run's signals come from the newest records alone, newest first, and answer as a full read
    does; the index is built once something asks for older data."""
    files = fill(tmp_path, 30)
    full = full_answers(tmp_path, TREND, ["v0"])
    keys = [("specs/trip_a01.hevval.yaml", "E_batt/P_batt"), ("b.hevval.yaml", "E_batt/P_batt")]
    reads.clear()
    store = h.HistoryStore(tmp_path, trend_runs=TREND)
    assert store.latest() == full["latest"]
    assert store.accepted() == full["accepted"]
    # Hour 29 is accepted: the newest record is the baseline either way, read once more.
    assert reads == [files[-1].name, files[-1].name]
    reads.clear()
    trends = store.trends(keys)
    assert trends == {key: full["trends"][key] for key in keys}
    assert reads == [path.name for path in files[::-1][:TREND]]
    assert not (tmp_path / ".index").exists()
    # A signal of this run that no record holds (a spec a pull request adds): the older
    # records are searched for its paths, not parsed, and none is.
    reads.clear()
    assert store.trends([*keys, ("new.hevval.yaml", "x")]) == trends
    assert reads == [path.name for path in files[::-1][:TREND]]
    assert not (tmp_path / ".index").exists()
    # One that older records hold: those are parsed.
    old = ("specs/trip_a01.hevval.yaml", "E_batt/I_batt")
    with_extra = two_signal_record("v9", T0 - timedelta(days=1), 0.3, extra=True)
    first = h.HistoryStore(tmp_path).append(with_extra)
    reads.clear()
    found = store.trends([*keys, old])
    assert found[old] == [RecordedPoint("v9", 0.3, dict.fromkeys(_names(), 0.15))]
    assert reads == [*(path.name for path in files[::-1][:TREND]), first.name]
    # Something that asks for every record builds the index, which the next run reads.
    assert store.versions()[0] == "v9"
    reads.clear()
    assert h.HistoryStore(tmp_path, trend_runs=TREND).trends(keys) == trends
    assert reads == []


def test_a_folder_without_an_index_is_read_whole_where_names_cannot_be_trusted(
    tmp_path: Path, reads: list[str]
) -> None:
    files = fill(tmp_path, 8)
    keys = [("specs/trip_a01.hevval.yaml", "E_batt/P_batt")]
    # A record whose start time is not the one its name carries, among the newest.
    newest = json.loads(files[-1].read_text())
    files[-1].write_text(json.dumps({**newest, "started_utc": "2030-01-01T00:00:00.000000Z"}))
    full = full_answers(tmp_path, TREND, ["v0"])
    reads.clear()
    assert h.HistoryStore(tmp_path, trend_runs=TREND).latest() == full["latest"]
    # The newest, then every record to build the index, then the baseline it names.
    assert len(reads) == 2 + len(files)
    shutil.rmtree(tmp_path / ".index")
    # A file whose name is not a record's: its time is unknown, so every file is read.
    (tmp_path / "copied.json").write_text(json.dumps(newest))
    full = full_answers(tmp_path, TREND, ["v0"])
    reads.clear()
    store = h.HistoryStore(tmp_path, trend_runs=TREND)
    assert store.trends(keys) == {key: full["trends"][key] for key in keys}
    assert len(reads) == len(files) + 1
    assert store.latest() == full["latest"]


def test_index_that_cannot_be_written_costs_time_only(tmp_path: Path) -> None:
    fill(tmp_path, 4)
    (tmp_path / ".index").write_text("in the way")
    assert_same_as_full_read(tmp_path)
    fill(tmp_path, 1, start=4)
    assert (tmp_path / ".index").read_text() == "in the way"
    assert_same_as_full_read(tmp_path)


def test_removed_record_rereads_only_what_its_trends_lost(tmp_path: Path, reads: list[str]) -> None:
    paths = fill(tmp_path, 12)
    h.HistoryStore(tmp_path, trend_runs=TREND).trends()
    paths[2].unlink()  # in no trend: nothing to read again
    reads.clear()
    h.HistoryStore(tmp_path, trend_runs=TREND).trends()
    assert reads == []
    assert_same_as_full_read(tmp_path)
    paths[-1].unlink()  # the newest: each trend needs one older point again
    reads.clear()
    h.HistoryStore(tmp_path, trend_runs=TREND).trends()
    # The oldest run kept is read again with the one before it, and nothing else.
    assert reads == [paths[-3].name, paths[-4].name]
    assert_same_as_full_read(tmp_path)


@pytest.mark.parametrize(("kept", "points"), [(3, 3), (2, 2)])
def test_a_signal_only_old_records_hold_keeps_its_points(
    tmp_path: Path, reads: list[str], kept: int, points: int
) -> None:
    store = h.HistoryStore(tmp_path, trend_runs=TREND)
    old = [
        store.append(two_signal_record("v0", T0 + timedelta(hours=i), 0.6, extra=True))
        for i in range(kept + 2)
    ]
    fill(tmp_path, 4, start=10)
    h.HistoryStore(tmp_path, trend_runs=TREND).trends()
    for path in old[-2:]:
        path.unlink()
    key = ("specs/trip_a01.hevval.yaml", "E_batt/I_batt")
    reads.clear()
    assert len(h.HistoryStore(tmp_path, trend_runs=TREND).trends()[key]) == points
    assert reads == [path.name for path in reversed(old[:kept])]
    # Read back to the first record: the trend now knows it has every point, and says so.
    reads.clear()
    assert len(h.HistoryStore(tmp_path, trend_runs=TREND).trends()[key]) == points
    assert reads == []
    assert_same_as_full_read(tmp_path)


def test_record_changed_by_hand_is_read_again(tmp_path: Path, reads: list[str]) -> None:
    paths = fill(tmp_path, 4)
    h.HistoryStore(tmp_path, trend_runs=TREND).trends()
    text = paths[-1].read_text()
    paths[-1].write_text(text.replace('"v0"', '"v0-edited"'))  # another size
    reads.clear()
    trends = h.HistoryStore(tmp_path, trend_runs=TREND).trends()
    # A changed record is one gone and one new: the trends it leaves get their oldest points
    # back first (the oldest kept run, then the one before), then it is read as new.
    assert reads == [paths[1].name, paths[0].name, paths[-1].name]
    assert trends[("b.hevval.yaml", "E_batt/P_batt")][-1].version == "v0-edited"
    assert_same_as_full_read(tmp_path, versions=["v0", "v0-edited", "v1"])


def test_record_changed_to_the_same_size_is_caught_when_read_as_baseline(tmp_path: Path) -> None:
    paths = fill(tmp_path, 4)
    h.HistoryStore(tmp_path, trend_runs=TREND).trends()
    # Same size: the index cannot see it, but the baseline is read and checked against it.
    paths[-1].write_text(paths[-1].read_text().replace('"v0"', '"w0"'))
    latest = h.HistoryStore(tmp_path, trend_runs=TREND).latest()
    assert latest is not None
    assert latest["model_version"] == "w0"
    assert_same_as_full_read(tmp_path, versions=["v0", "w0"])


def test_bad_files_are_listed_as_a_full_read_lists_them(tmp_path: Path, reads: list[str]) -> None:
    fill(tmp_path, 3)
    (tmp_path / "partial.json").write_text('{"schema_version": 2, "model_')
    (tmp_path / "empty.json").write_text("")
    (tmp_path / "other.json").write_text('{"hello": 1}')
    (tmp_path / "binary.json").write_bytes(b"\xff\xfe\x00")
    (tmp_path / "future.json").write_text(json.dumps({"schema_version": 99}))
    (tmp_path / "folder.json").mkdir()
    os.mkfifo(tmp_path / "pipe.json")  # never opened: a read would wait for a writer
    (tmp_path / "v1.json").write_text(json.dumps(v1_record()))
    for name in ("schema1_camry_hwfet.json", "schema2_camry_hwfet.json"):
        stored = Path(__file__).parent / "data" / "history" / name
        (tmp_path / name).write_bytes(stored.read_bytes())
    assert_same_as_full_read(tmp_path, versions=["v0", "v0.9"])
    store = h.HistoryStore(tmp_path, trend_runs=TREND)
    reads.clear()
    store.trends()
    # Bad content is remembered; a folder or a pipe may be replaced by a file of the same
    # size, so they are looked at again (and refused before anything is read).
    assert reads == ["folder.json", "pipe.json"]
    assert {p.path.name for p in store.problems} == {
        "partial.json",
        "empty.json",
        "other.json",
        "binary.json",
        "future.json",
        "folder.json",
        "pipe.json",
    }
    assert "newer than this pytest-hevval" in str(
        next(p for p in store.problems if p.path.name == "future.json")
    )
    (tmp_path / "partial.json").write_text(json.dumps(record("v9", T0 + timedelta(days=9))))
    reads.clear()
    found = store.find("v9")
    assert found is not None
    assert found["started_utc"].startswith("2024-05-10")
    assert sorted(reads) == ["folder.json", "partial.json", "partial.json", "pipe.json"]
    assert_same_as_full_read(tmp_path, versions=["v9", "v0.9"])


def test_index_is_never_taken_for_a_record(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    fill(tmp_path, 3)
    h.HistoryStore(tmp_path).trends()
    assert (tmp_path / ".index" / "index").is_file()
    store = h.HistoryStore(tmp_path)
    assert len(store.records()) == 3
    assert store.problems == []
    assert cli_main(["history", "--history-dir", str(tmp_path)]) == 0
    assert "skipped" not in capsys.readouterr().err


@pytest.mark.skipif(shutil.which("git") is None, reason="needs git")
def test_index_stays_out_of_a_committed_history(tmp_path: Path) -> None:
    history = tmp_path / ".hevval" / "history"
    fill(history, 2)
    h.HistoryStore(history).trends()
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    status = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=all"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    listed = sorted(line[3:] for line in status.splitlines())
    assert listed == sorted(f".hevval/history/{p.name}" for p in history.glob("*.json"))


RUN = """
import sys
from datetime import datetime, timedelta, timezone
from pytest_hevval.history import HistoryStore, make_record
folder, name = sys.argv[1], sys.argv[2]
when = datetime(2024, 5, 1, tzinfo=timezone.utc)
for i in range(12):
    store = HistoryStore(folder, trend_runs=100)
    store.trends()  # reads and updates the index, as a run's report does
    spec = {"name": "s", "spec": "s.hevval.yaml", "phi": i / 100, "signals": [
        {"path": "a", "lambdas": [i / 100] * 7}, {"path": name, "lambdas": [0.5] * 7}]}
    store.append(make_record([spec], model_version=f"{name}-{i}",
                             started_utc=when + timedelta(minutes=i)))
"""


def test_concurrent_runs_lose_no_record_and_leave_a_sound_index(tmp_path: Path) -> None:
    # One index to start from, so that every run also extends it when it appends.
    h.HistoryStore(tmp_path, trend_runs=100).append(record("seed", T0 - timedelta(days=1)))
    h.HistoryStore(tmp_path, trend_runs=100).trends()
    runs = [subprocess.Popen([sys.executable, "-c", RUN, str(tmp_path), f"p{k}"]) for k in range(3)]
    assert [run.wait(timeout=300) for run in runs] == [0, 0, 0]
    from pytest_hevval.history.index import load_index

    assert load_index(tmp_path, 100) is not None  # whole after every race
    trends = h.HistoryStore(tmp_path, trend_runs=100).trends()
    versions = sorted(point.version for point in trends[("s.hevval.yaml", "a")])
    assert versions == sorted(f"p{k}-{i}" for k in range(3) for i in range(12))
    assert_same_as_full_read(tmp_path, limit=100, versions=["p0-11", "p1-0", "seed"])


def test_threads_appending_and_reading_at_once_lose_nothing(tmp_path: Path) -> None:
    from concurrent.futures import ThreadPoolExecutor

    h.HistoryStore(tmp_path, trend_runs=100).append(record("seed", T0 - timedelta(days=1)))
    h.HistoryStore(tmp_path, trend_runs=100).trends()

    def run(k: int) -> None:
        for i in range(8):
            store = h.HistoryStore(tmp_path, trend_runs=100)
            store.trends()
            store.append(record(f"t{k}-{i}", T0 + timedelta(minutes=i)))

    with ThreadPoolExecutor(4) as pool:
        list(pool.map(run, range(4)))
    trends = h.HistoryStore(tmp_path, trend_runs=100).trends()
    assert len(trends[("specs/trip_a01.hevval.yaml", "E_batt/P_batt")]) == 33
    assert_same_as_full_read(tmp_path, limit=100, versions=["t0-0", "t3-7"])


# Steps of a history's life, checked against a full read after each one.
# Steps of a history's life, checked against a full read after each one. Runs come most
# often, so that trends fill up, get trimmed, and lose points to the deletions that follow.
_KINDS = [
    "run",
    "run",
    "run",
    "merge",
    "hand-named",
    "rewrite",
    "bad",
    "folder",
    "delete",
    "delete newest",
    "drop index",
    "read",
]
_STEP = st.tuples(
    st.sampled_from(_KINDS),
    st.integers(0, 3),
    st.integers(0, 40),
    st.booleans(),
    st.sampled_from(QUERIES),
)


@settings(max_examples=80, deadline=None)
@given(steps=st.lists(_STEP, min_size=1, max_size=14), limit=st.integers(1, 4))
def test_index_answers_equal_a_full_read_whatever_happens(
    steps: list[tuple[str, int, int, bool, str]], limit: int
) -> None:
    from pytest_hevval.history import store as store_module

    real_read = store_module.read_json
    reads: list[str] = []

    def counting(path: Path | str, *args: Any, **kwargs: Any) -> Any:
        reads.append(Path(path).name)
        return real_read(path, *args, **kwargs)

    with (
        tempfile.TemporaryDirectory() as tmp,
        mock.patch.object(store_module, "read_json", counting),
    ):
        folder = Path(tmp)
        for number, (kind, version, hour, extra, first) in enumerate(steps):
            # Equal start times happen (hours repeat); the file name then decides the order.
            when = T0 + timedelta(hours=hour)
            rec = two_signal_record(f"v{version}", when, 0.4 + number / 50, extra=extra)
            store = h.HistoryStore(folder, trend_runs=limit)
            files = sorted(folder.glob("*.json"))
            if kind == "run":
                store.append(rec)
            elif kind == "merge":  # written elsewhere, copied in later
                elsewhere = h.HistoryStore(folder / "elsewhere").append(rec)
                (folder / elsewhere.name).write_bytes(elsewhere.read_bytes())
            elif kind == "hand-named":  # a name whose order is not its record's
                (folder / f"00-{number}-copy.json").write_text(json.dumps(rec))
            elif kind == "rewrite" and files:  # by hand, to another size
                target = files[hour % len(files)]
                old_size = target.stat().st_size if target.is_file() else -1
                named = re.match(r"(\d{8}T\d{6}\.\d{6})Z_", target.name)
                if named:
                    # A record keeps the start time its name carries, which a folder without
                    # an index is read by (other values may be edited).
                    started = datetime.strptime(named[1], "%Y%m%dT%H%M%S.%f")
                    rec = {**rec, "started_utc": h.format_utc(started.replace(tzinfo=timezone.utc))}
                text = json.dumps(rec)
                text += " " * (len(text.encode()) == old_size)
                if target.is_dir():
                    target.rmdir()
                target.write_text(text)
            elif kind == "bad":
                (folder / f"bad-{number}.json").write_text(["", "{", '{"a": 1}'][version % 3])
            elif kind == "folder":
                (folder / f"folder-{number}.json").mkdir()
            elif kind == "delete newest":
                entries = h.HistoryStore(folder).entries()
                if entries:
                    entries[-1].path.unlink()
            elif kind == "delete" and files:
                target = files[hour % len(files)]
                if target.is_dir():
                    target.rmdir()
                else:
                    target.unlink()
            elif kind == "drop index":
                shutil.rmtree(folder / ".index", ignore_errors=True)
            elif kind == "read":
                store.trends()
            expected = full_answers(folder, limit, ["v0", "v1", "v2", "v3"])
            middle = expected["middle"]
            assert index_answers(folder, limit, ["v0", "v1", "v2", "v3"], middle, first) == (
                expected
            )
            # Once up to date, the index is read alone: only files that cannot be remembered
            # (folders named *.json here) are looked at again.
            reads.clear()
            h.HistoryStore(folder, trend_runs=limit).trends()
            assert all(name.startswith("folder-") for name in reads)


# -- compare grammar ------------------------------------------------------------------------


def test_parse_compare_fail_examples() -> None:
    rules = h.parse_compare_fail("phi:0.01, lambda:0.02,MAE:1%,lambda4:0.5e-1, lag:0.3")
    assert [(r.field, r.amount, r.relative) for r in rules] == [
        ("phi", 0.01, False),
        ("lambda", 0.02, False),
        ("mae", 1.0, True),
        ("rms", 0.05, False),
        ("lag", 0.3, False),
    ]
    assert rules[2].allowed(0.8) == pytest.approx(0.008)
    assert rules[0].allowed(0.8) == 0.01


@pytest.mark.parametrize(
    ("expr", "fragments"),
    [
        ("mea:0.1", ["unknown field 'mea'", "did you mean 'mae'", "valid fields: phi"]),
        ("phi:abc", ["'abc'", "e.g. phi:0.01"]),
        ("phi:-1", ["'-1'", "non-negative"]),
        ("phi", ["no ':amount'"]),
        ("", ["empty rule"]),
        ("phi:0.1,", ["empty rule"]),
        ("phi:1%%", ["'1%%'"]),
    ],
)
def test_parse_compare_fail_errors(expr: str, fragments: list[str]) -> None:
    with pytest.raises(h.HistoryError) as info:
        h.parse_compare_fail(expr)
    message = str(info.value)
    assert message.startswith("--hevval-compare-fail: ")
    for fragment in fragments:
        assert fragment in message


def changed(values: dict[int, float]) -> list[float]:
    lambdas = list(LAMBDAS)
    for index, value in values.items():
        lambdas[index] = value
    return lambdas


def test_compare_deltas_and_membership() -> None:
    before = record(
        "v1",
        T0,
        [spec(), spec("B", path="b.hevval.yaml", phi=0.5)],
    )
    after_signals = [
        signal(lambdas=changed({2: 0.90}), mae=1.5, lag_s=-0.5),
        signal("new/sig"),
    ]
    current = [spec(phi=0.93, signals=after_signals), spec("C", path="c.hevval.yaml")]
    comparison = h.compare(recorded(current), recorded(before))
    assert comparison.before_label == "v1"
    assert comparison.added_specs == ("c.hevval.yaml",)
    assert comparison.removed_specs == ("b.hevval.yaml",)
    (one,) = comparison.specs
    assert one.phi.delta == pytest.approx(0.93 - 0.9412)
    assert one.added_signals == ("new/sig",)
    (sig,) = one.signals
    assert sig.field("mae").delta == pytest.approx(0.90 - 0.93)  # λ3 comes first
    assert sig.errors[1].field == "mae"
    assert sig.errors[1].delta == pytest.approx(0.3)
    assert sig.field("lag_s").delta == pytest.approx(-0.3)
    json.dumps(comparison.to_dict(), allow_nan=False)


def _with_data(reference: dict[str, Any], model: dict[str, Any] | None = None) -> dict[str, Any]:
    one = spec()
    one["data"] = {"reference": {"path": "ref.csv", **reference}}
    if model is not None:
        one["data"]["model"] = {"path": "model.csv", "kind": "file", **model}
    return one


@pytest.mark.parametrize(
    ("before", "after", "changed"),
    [
        # Records from before the algorithm was stored carry "sha256" alone.
        ({"sha256": "aa"}, {"hash": "sha256", "digest": "aa"}, ()),
        ({"sha256": "aa"}, {"hash": "sha256", "digest": "bb"}, ("reference",)),
        (
            {"hash": "xxh3_128", "digest": "aa"},
            {"hash": "xxh3_128", "digest": "bb"},
            ("reference",),
        ),
        # Different algorithms cannot tell whether the file changed: no claim either way.
        ({"sha256": "aa"}, {"hash": "xxh3_128", "digest": "bb"}, ()),
        ({"hash": "xxh3_128", "digest": "aa"}, {"hash": "sampled-blake2b", "digest": "bb"}, ()),
        ({}, {"hash": "xxh3_128", "digest": "bb"}, ()),
    ],
)
def test_compare_says_data_changed_only_for_the_same_hash(
    before: dict[str, str], after: dict[str, str], changed: tuple[str, ...]
) -> None:
    comparison = h.compare(
        recorded([_with_data(after, model={"hash": "sha256", "digest": "m"})]),
        recorded(record("v1", T0, [_with_data(before, model={"hash": "sha256", "digest": "m"})])),
    )
    (one,) = comparison.specs
    assert one.data_changed == changed
    notes = [n for n in comparison.notes if "data changed" in n]
    assert notes == ([f"{one.key}: data changed (reference)"] if changed else [])
    assert one.to_dict()["data_changed"] == list(changed)


def test_stored_old_records_compare_with_new_ones() -> None:
    old = json.loads(
        (Path(__file__).parent / "data" / "history" / "schema2_camry_hwfet.json").read_text()
    )
    digest = old["specs"][0]["data"]["reference"]["sha256"]
    new = json.loads(json.dumps(old["specs"]))
    new[0]["data"]["reference"] = {
        "path": new[0]["data"]["reference"]["path"],
        "hash": "sha256",
        "digest": digest,
    }
    assert h.compare(recorded(new), recorded(old)).specs[0].data_changed == ()
    new[0]["data"]["reference"]["digest"] = "0" * 64
    assert h.compare(recorded(new), recorded(old)).specs[0].data_changed == ("reference",)


def test_regressions_absolute_relative_and_lag() -> None:
    before = record("v1", T0)
    current = [spec(phi=0.93, signals=[signal(lambdas=changed({2: 0.90, 0: 0.985}), lag_s=-0.6)])]
    comparison = h.compare(recorded(current), recorded(before))

    def hits(expr: str) -> set[tuple[str | None, str]]:
        return {(r.signal, r.field) for r in h.regressions(comparison, h.parse_compare_fail(expr))}

    assert hits("phi:0.02") == set()
    assert hits("phi:0.01") == {(None, "phi")}
    assert hits("lambda:0.02") == {("E_batt/P_batt", "mae")}
    assert hits("lambda:0.001") == {("E_batt/P_batt", "mae"), ("E_batt/P_batt", "lag_correlation")}
    assert hits("lambda1:1%") == set()  # 0.005 < 1 % of 0.99
    assert hits("lambda1:0.1%") == {("E_batt/P_batt", "lag_correlation")}
    assert hits("lag:0.5") == set()
    assert hits("lag:0.3") == {("E_batt/P_batt", "lag")}
    (reg,) = h.regressions(comparison, h.parse_compare_fail("mae:0.02"))
    assert (reg.spec, reg.before, reg.after, reg.allowed) == (
        "specs/trip_a01.hevval.yaml",
        0.93,
        0.90,
        0.02,
    )
    assert "λ3 mae dropped 0.93 → 0.9" in str(reg)
    (lag,) = h.regressions(comparison, h.parse_compare_fail("lag:0.1"))
    assert str(lag).startswith(
        "specs/trip_a01.hevval.yaml::E_batt/P_batt: |lag| grew 0.2 s → 0.6 s"
    )
    assert "mae:0.02" in str(reg)


def test_regressions_equal_runs_and_improvements_pass() -> None:
    before = record("v1", T0)
    better = [spec(phi=0.99, signals=[signal(lambdas=[1.0] * 7, lag_s=0.0)])]
    rules = h.parse_compare_fail("phi:0,lambda:0,lag:0")
    assert h.regressions(h.compare(recorded(before), recorded(before)), rules) == []
    assert h.regressions(h.compare(recorded(better), recorded(before)), rules) == []


def test_regressions_value_becoming_undefined() -> None:
    before = record("v1", T0)
    current = [spec(phi=None, signals=[signal(lambdas=changed({4: float("nan")}))])]
    found = h.regressions(
        h.compare(recorded(current), recorded(before)), h.parse_compare_fail("phi:1,anomaly:1")
    )
    assert {(r.field, r.after) for r in found} == {("phi", None), ("anomaly", None)}
    assert "undefined" in str(found[0])


def test_missing_baseline_decisions(tmp_path: Path) -> None:
    ci = h.missing_baseline(ci=True, create_baseline=False, directory=tmp_path)
    assert ci.fails
    assert str(tmp_path) in ci.message
    assert "--hevval-accept" in ci.message
    assert "hevval-history" in ci.message
    assert "commit the history folder" in ci.message
    local = h.missing_baseline(ci=False, create_baseline=False, directory=tmp_path)
    assert local.action == "note"
    assert not local.fails
    created = h.missing_baseline(ci=True, create_baseline=True, directory=tmp_path, wanted="v9")
    assert created.action == "record"
    assert "'v9'" in created.message


def test_messages_name_the_flag_of_the_front_end_in_use(tmp_path: Path) -> None:
    ci = h.missing_baseline(ci=True, create_baseline=False, directory=tmp_path, front_end=COMMAND)
    assert "run once with --accept " in ci.message
    assert "--hevval-accept" not in ci.message
    local = h.missing_baseline(
        ci=False, create_baseline=False, directory=tmp_path, recorded=False, front_end=COMMAND
    )
    assert "record one with --history," in local.message
    created = h.missing_baseline(
        ci=False, create_baseline=True, directory=tmp_path, front_end=COMMAND
    )
    assert "(--create-baseline or --accept)" in created.message
    with pytest.raises(h.HistoryError) as rule:
        h.parse_compare_fail("phi", front_end=COMMAND)
    assert str(rule.value).startswith("--compare-fail: ")
    with pytest.raises(h.HistoryError) as margin:
        h.parse_margin("2", front_end=COMMAND)
    assert str(margin.value).startswith("--ratchet: ")
    with pytest.raises(h.HistoryError, match="pass --model-version or set HEVVAL_MODEL_VERSION"):
        h.make_record([spec()], model_version=" ", started_utc=T0, front_end=COMMAND)
    blocked = tmp_path / "file"
    blocked.write_text("")
    with pytest.raises(h.HistoryError, match="folder with --history-dir"):
        h.HistoryStore(blocked / "history", front_end=COMMAND).append(record("v1", T0))
    # pytest's spelling stays the default.
    with pytest.raises(h.HistoryError) as under_pytest:
        h.parse_compare_fail("phi")
    assert str(under_pytest.value).startswith("--hevval-compare-fail: ")


@pytest.mark.parametrize(
    ("argv", "flag"),
    [(["--compare-fail", "phi"], "--compare-fail"), (["--ratchet", "2"], "--ratchet")],
)
def test_hevval_run_names_its_own_flags(
    tmp_path: Path, argv: list[str], flag: str, capsys: pytest.CaptureFixture[str]
) -> None:
    spec_file = tmp_path / "x.hevval.yaml"
    spec_file.write_text("name: x\n", encoding="utf-8")
    assert cli_main(["run", str(spec_file), "--no-history", "--quiet", *argv]) == 2
    err = capsys.readouterr().err
    assert f"error: {flag}: " in err
    assert "--hevval-" not in err


@pytest.mark.parametrize(
    ("env", "expected"),
    [
        ({}, False),
        ({"CI": "true"}, True),
        ({"CI": "false"}, False),
        ({"CI": "0", "GITHUB_ACTIONS": "true"}, True),
        ({"GITLAB_CI": ""}, False),
    ],
)
def test_is_ci(env: dict[str, str], expected: bool) -> None:
    assert h.is_ci(env) is expected


# -- ratchet --------------------------------------------------------------------------------


def test_ratchet_tightens_and_never_loosens() -> None:
    result = scored(signals=[signal(lambdas=changed({2: 0.95, 3: 0.85}), thresholds={})])
    current = {"E_batt/P_batt": {"mae": 0.9, "rms": 0.9}}
    proposed = h.ratchet_thresholds(result, current, 0.01)
    assert proposed == {"E_batt/P_batt": {"mae": 0.94, "rms": 0.9}}
    assert h.ratchet_thresholds(result, current, 0.5) == current


def test_ratchet_uses_the_stricter_of_given_and_as_run_thresholds() -> None:
    result = scored(signals=[signal(lambdas=changed({2: 0.80}), thresholds={"mae": 0.85})])
    assert h.ratchet_thresholds(result, {"E_batt/P_batt": {"mae": 0.5}}, 0.0) == {
        "E_batt/P_batt": {"mae": 0.85}
    }


def test_ratchet_keeps_undefined_and_ungated() -> None:
    result = scored(signals=[signal(lambdas=changed({2: float("nan")}))])
    assert h.ratchet_thresholds(result, {}, 0.01) == {"E_batt/P_batt": {"mae": 0.9}}
    ungated = scored(signals=[signal(thresholds={})])
    assert h.ratchet_thresholds(ungated, {}, 0.01) == {}


def test_ratchet_rounds_down_so_the_run_still_passes() -> None:
    result = scored(signals=[signal(lambdas=changed({2: 0.93339}), thresholds={"mae": 0.1})])
    value = h.ratchet_thresholds(result, {}, 0.0)["E_batt/P_batt"]["mae"]
    assert value == 0.9333


@given(
    achieved=st.lists(st.floats(0, 1) | st.none(), min_size=7, max_size=7),
    current=st.floats(0, 1),
    margin=st.floats(0, 0.99),
)
def test_ratchet_property_monotone_and_idempotent(
    achieved: list[float | None], current: float, margin: float
) -> None:
    result = scored(signals=[signal(lambdas=achieved, thresholds={})])
    start = {"E_batt/P_batt": dict.fromkeys(("mae", "emergent"), current)}
    once = h.ratchet_thresholds(result, start, margin)
    for name, value in once["E_batt/P_batt"].items():
        assert value >= current
        index = list(_names()).index(name)
        if achieved[index] is not None and value > current:
            assert value <= achieved[index]  # type: ignore[operator]
    assert h.ratchet_thresholds(result, once, margin) == once


def test_sidecar_path_names() -> None:
    assert h.sidecar_path("specs/trip.hevval.yaml") == Path("specs/trip.hevval.thresholds.yaml")
    assert h.sidecar_path(Path("a/x.yml")) == Path("a/x.thresholds.yaml")


def test_ratchet_spec_writes_reviewable_sidecar_and_is_idempotent(tmp_path: Path) -> None:
    spec_path = tmp_path / "trip.hevval.yaml"
    spec_path.write_text("name: trip\n")
    result = scored(signals=[signal(lambdas=changed({2: 0.95}))])
    kwargs: dict[str, Any] = {"margin": 0.01, "model_version": "v7", "created_utc": T0}
    outcome = h.ratchet_spec(spec_path, result, {"E_batt/P_batt": {"mae": 0.9}}, **kwargs)
    assert outcome.written
    assert outcome.tightened == (("E_batt/P_batt", "mae", 0.9, 0.94),)
    text = outcome.path.read_text()
    assert "model version v7" in text
    assert "margin 0.01" in text
    assert "2024-05-01" in text
    assert h.load_sidecar(spec_path) == {"E_batt/P_batt": {"mae": 0.94}}
    later = dict(kwargs, created_utc=T0 + timedelta(days=1), model_version="v8")
    again = h.ratchet_spec(spec_path, result, {"E_batt/P_batt": {"mae": 0.9}}, **later)
    assert not again.written
    assert again.tightened == ()
    assert outcome.path.read_text() == text
    assert "unchanged" in again.summary()
    assert "0.9000 → 0.9400" in outcome.summary()


def test_ratchet_spec_without_gain_writes_nothing(tmp_path: Path) -> None:
    spec_path = tmp_path / "trip.hevval.yaml"
    result = scored(signals=[signal(lambdas=changed({2: 0.905}))])
    outcome = h.ratchet_spec(spec_path, result, {}, margin=0.01, model_version="v", created_utc=T0)
    assert not outcome.written
    assert not outcome.path.exists()


def test_ratchet_spec_keeps_entries_of_absent_signals(tmp_path: Path) -> None:
    spec_path = tmp_path / "trip.hevval.yaml"
    h.write_sidecar(
        spec_path, {"old/sig": {"rms": 0.8}}, model_version="v0", created_utc=T0, margin=0.01
    )
    result = scored(signals=[signal(lambdas=changed({2: 0.99}))])
    h.ratchet_spec(spec_path, result, {}, margin=0.01, model_version="v", created_utc=T0)
    assert h.load_sidecar(spec_path) == {"old/sig": {"rms": 0.8}, "E_batt/P_batt": {"mae": 0.98}}


def test_merge_thresholds_sidecar_only_tightens() -> None:
    merged = h.merge_thresholds(
        {"a": {"mae": 0.9, "rms": 0.8}}, {"a": {"mae": 0.7, "rms": 0.85}, "b": {"anomaly": 0.5}}
    )
    assert merged == {"a": {"mae": 0.9, "rms": 0.85}, "b": {"anomaly": 0.5}}


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        ("a:\n  mea: 0.9\n", ["a.mea", "did you mean 'mae'"]),
        ("a:\n  mae: 1.5\n", ["a.mae", "[0, 1]"]),
        ("a:\n  mae: yes\n", ["a.mae"]),
        ("a: [1, 2]\n", ["a: expected"]),
        ("- 1\n", ["expected a mapping"]),
        ("a:\n  mae: [\n", ["not valid YAML", ".thresholds.yaml:"]),
    ],
)
def test_load_sidecar_errors(tmp_path: Path, text: str, fragments: list[str]) -> None:
    spec_path = tmp_path / "t.hevval.yaml"
    h.sidecar_path(spec_path).write_text(text)
    with pytest.raises(SpecError) as info:
        h.load_sidecar(spec_path)
    message = str(info.value)
    assert "t.hevval.thresholds.yaml" in message
    assert "--hevval-ratchet" in message
    for fragment in fragments:
        assert fragment in message


def test_load_sidecar_missing_or_empty(tmp_path: Path) -> None:
    spec_path = tmp_path / "t.hevval.yaml"
    assert h.load_sidecar(spec_path) == {}
    h.sidecar_path(spec_path).write_text("# only a header\n")
    assert h.load_sidecar(spec_path) == {}


@pytest.mark.parametrize("text", ["abc", "-0.1", "1", "nan"])
def test_parse_margin_errors(text: str) -> None:
    with pytest.raises(h.HistoryError, match="--hevval-ratchet"):
        h.parse_margin(text)


# -- trends ---------------------------------------------------------------------------------


def three_runs() -> list[dict[str, Any]]:
    return [
        record("v1", T0, [spec(phi=0.95, signals=[signal(), signal("x/y")])]),
        record("v2", T0 + timedelta(days=1), [spec(phi=0.96)]),
        record(
            "v3",
            T0 + timedelta(days=2),
            [spec(phi=0.90, signals=[signal(lambdas=changed({2: 0.5}))]), spec("B", path="b")],
        ),
    ]


def test_history_table_filters() -> None:
    runs = three_runs()
    rows = h.history_table([recorded(r) for r in reversed(runs)])
    assert [(r.model_version, r.spec) for r in rows] == [
        ("v1", "specs/trip_a01.hevval.yaml"),
        ("v2", "specs/trip_a01.hevval.yaml"),
        ("v3", "specs/trip_a01.hevval.yaml"),
        ("v3", "b"),
    ]
    assert [r.phi for r in h.history_table([recorded(r) for r in runs], spec="trip A01")] == [
        0.95,
        0.96,
        0.90,
    ]
    sig_rows = h.history_table([recorded(r) for r in runs], spec="specs/*", signal="E_batt/*")
    assert [r.value("mae") for r in sig_rows] == [0.93, 0.93, 0.5]
    assert h.history_table([recorded(r) for r in runs], signal="y") == h.history_table(
        [recorded(r) for r in runs], signal="x/y"
    )
    text = h.render_history_table(sig_rows)
    assert "v3" in text
    assert "0.5000" in text
    assert "λ7" in text
    assert h.render_history_table([]) == "(no recorded runs match)"


def test_detect_steps_finds_a_known_drop() -> None:
    rng = np.random.default_rng(1)
    series = np.r_[np.full(20, 0.95), np.full(20, 0.90)] + rng.normal(0, 0.004, 40)
    (step,) = h.detect_steps(series, min_size=0.01)
    assert step.index == 20
    assert step.regression
    assert step.size == pytest.approx(-0.05, abs=0.01)


def test_detect_steps_finds_two_steps_and_the_direction() -> None:
    series = [0.9] * 6 + [0.8] * 6 + [0.95] * 6
    steps = h.detect_steps(series, min_size=0.01)
    assert [(s.index, s.regression) for s in steps] == [(6, True), (12, False)]
    errors = h.detect_steps([1.0] * 5 + [2.0] * 5, min_size=0.1, higher_is_better=False)
    assert [s.regression for s in errors] == [True]


@pytest.mark.parametrize("seed", range(10))
def test_detect_steps_no_false_step_on_flat_noise(seed: int) -> None:
    rng = np.random.default_rng(seed)
    series = 0.9 + rng.normal(0, 0.01, 300)
    assert h.detect_steps(series, min_size=0.005) == []


def test_detect_steps_respects_min_size_and_skips_missing() -> None:
    assert h.detect_steps([0.9] * 5 + [0.895] * 5, min_size=0.01) == []
    assert len(h.detect_steps([0.9] * 5 + [0.895] * 5, min_size=0.001)) == 1
    (step,) = h.detect_steps([0.9, None, 0.9, 0.9, math.nan, 0.7, 0.7, 0.7], min_size=0.1)
    assert step.index == 5
    assert h.detect_steps([0.9], min_size=0.0) == []
    with pytest.raises(h.HistoryError, match="min_size"):
        h.detect_steps([1.0, 2.0], min_size=-1.0)


@pytest.mark.parametrize("suffix", [".png", ".svg"])
def test_plot_history(tmp_path: Path, suffix: str) -> None:
    runs = three_runs()
    out = h.plot_history(
        h.history_table([recorded(r) for r in runs], signal="E_batt/P_batt"),
        tmp_path / f"h{suffix}",
    )
    head = out.read_bytes()[:200]
    if suffix == ".png":
        assert head.startswith(b"\x89PNG")
    else:
        assert b"<svg" in head or b"<?xml" in head


def test_plot_history_rejects_unknown_format(tmp_path: Path) -> None:
    with pytest.raises(h.HistoryError, match=r"\*\.png or \*\.svg"):
        h.plot_history(h.history_table([recorded(r) for r in three_runs()]), tmp_path / "h.jpg")


# -- CLI ------------------------------------------------------------------------------------


@pytest.fixture
def history_dir(tmp_path: Path) -> Path:
    store = h.HistoryStore(tmp_path / "hist")
    for rec in three_runs():
        store.append(rec)
    return tmp_path / "hist"


def test_history_main_table_steps_json_and_plot(
    history_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_json = tmp_path / "rows.json"
    plot = tmp_path / "p.png"
    argv = ["--history-dir", str(history_dir), "--signal", "E_batt/P_batt", "--json", str(out_json)]
    assert cli_main(["history", *argv, "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    assert "v1" in out
    assert "v3" in out
    assert "λ3" in out
    assert json.loads(out_json.read_text())["rows"][2]["lambdas"]["mae"] == 0.5
    assert plot.stat().st_size > 0


def test_history_main_reports_drops(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    store = h.HistoryStore(tmp_path)
    for i, phi in enumerate([0.95, 0.95, 0.95, 0.90, 0.90, 0.90]):
        store.append(record(f"v{i}", T0 + timedelta(days=i), [spec(phi=phi)]))
    assert cli_main(["history", "--history-dir", str(tmp_path)]) == 0
    assert "drop: specs/trip_a01.hevval.yaml Φ 0.9500 → 0.9000 from model version v3" in (
        capsys.readouterr().out
    )


def test_history_main_empty_and_bad_args(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli_main(["history", "--history-dir", str(tmp_path)]) == 1
    assert "no readable records" in capsys.readouterr().err
    assert cli_main(["history", "--bogus"]) == 2
    assert "unrecognized arguments" in capsys.readouterr().err


def test_compare_main_formats(
    history_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run.json"
    run.write_text(json.dumps({"specs": [spec(phi=0.97)]}))
    base = ["history:v1", str(run), "--history-dir", str(history_dir)]
    assert cli_main(["compare", *base]) == 0
    table = capsys.readouterr().out
    assert "v1 → run.json" in table
    assert "λ3 mae" in table
    assert "MAE [kW]" in table
    assert "0.9500" in table
    assert "0.9700" in table
    assert "+0.0200" in table
    assert table.index("λ1") < table.rindex("Φ")

    assert cli_main(["compare", *base, "--format", "md"]) == 0
    md = capsys.readouterr().out
    assert "| λ3 mae | 0.9300 | 0.9300 | 0 |" in md
    assert "### Φ" in md

    out = tmp_path / "cmp.json"
    assert cli_main(["compare", *base, "--format", "json", "--output", str(out)]) == 0
    document = json.loads(out.read_text())
    assert document["comparison"]["specs"][0]["phi"]["delta"] == pytest.approx(0.02)


def test_compare_main_fail_rules_and_latest(
    history_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["history:v1", "history:latest", "--history-dir", str(history_dir)]
    assert cli_main(["compare", *argv, "--compare-fail", "phi:0.1"]) == 0
    assert "no regressions" in capsys.readouterr().out
    assert cli_main(["compare", *argv, "--compare-fail", "phi:0.01,mae:0.1"]) == 1
    out = capsys.readouterr().out
    assert "2 regression(s)" in out
    assert "mae dropped 0.93 → 0.5" in out


def test_compare_main_previous(
    history_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert (
        cli_main(
            ["compare", "history:previous", "history:latest", "--history-dir", str(history_dir)]
        )
        == 0
    )
    assert "compare v2 → v3" in capsys.readouterr().out
    single = tmp_path / "single"
    h.HistoryStore(single).append(record("v1", T0))
    assert (
        cli_main(["compare", "history:previous", "history:latest", "--history-dir", str(single)])
        == 2
    )
    assert "only one readable record" in capsys.readouterr().err


def test_compare_main_reads_record_files(
    history_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    files = sorted(history_dir.glob("*.json"))
    assert cli_main(["compare", str(files[0]), str(files[1]), "--format", "json"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert (document["comparison"]["before"], document["comparison"]["after"]) == ("v1", "v2")


@pytest.mark.parametrize(
    ("argv", "fragments"),
    [
        (["history:v9", "history:latest"], ["no record of model version 'v9'", "v1, v2, v3"]),
        (["missing.json", "history:latest"], ["missing.json: no such file"]),
        (["history:latest", "history:latest", "--compare-fail", "phy:1"], ["did you mean 'phi'"]),
        (["history:latest", "history:latest", "--format", "xml"], ["invalid choice"]),
    ],
)
def test_compare_main_errors(
    history_dir: Path, argv: list[str], fragments: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli_main(["compare", *argv, "--history-dir", str(history_dir)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hevval compare: error: ")
    for fragment in fragments:
        assert fragment in err


def test_compare_main_rejects_foreign_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("[1")
    other = tmp_path / "other.json"
    other.write_text('{"x": 1}')
    assert cli_main(["compare", str(bad), str(other)]) == 2
    assert "bad.json: not valid JSON" in capsys.readouterr().err
    assert cli_main(["compare", str(other), str(other)]) == 2
    assert "neither a history record nor a run result" in capsys.readouterr().err


def test_package_import_stays_light() -> None:
    code = (
        "import sys, pytest_hevval.history; "
        "print('matplotlib' in sys.modules, 'pytest' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=os.environ
    ).stdout
    assert out.split() == ["False", "False"]
