"""The typed facts of a spec result (results/spec_facts.py): today's JSON and older forms."""

from __future__ import annotations

import json
from typing import Any

import pytest

from pytest_hevval.results.spec_facts import (
    AlignmentFacts,
    CampaignFacts,
    DataSources,
    LocalGrid,
    ModelData,
)

FILE_MODEL = {"path": "sim.csv", "hash": "xxh3_128", "digest": "ab12", "kind": "file"}
CALLABLE_MODEL = {
    "callable": "bus.model:simulate",
    "params": {"mass": 1500},
    "kind": "callable",
    "module_file": "bus/model.py",
    "module_sha256": "0c65",
}
FMU_MODEL = {
    "path": "car.fmu",
    "hash": "sha256",
    "digest": "ff",
    "kind": "fmu",
    "params": {},
    "guid": "{1234}",
    "unscored_outputs": {"label": "string"},
}
DATA = {
    "reference": {"path": "ref.parquet", "hash": "xxh3_128", "digest": "cd34"},
    "model": FILE_MODEL,
    "quality": {
        "action": "omit",
        "findings": [
            {"channel": "v", "kind": "flat line", "start_s": 1.5, "stop_s": 9.0, "detail": "8 s"}
        ],
    },
}
ALIGNMENT = {
    "rate_hz": 10.0,
    "start_s": 0.0,
    "stop_s": 99.9,
    "n_samples": 1000,
    "offset_s": 0.0,
    "offset_found": False,
    "coverage": 1.0,
    "by": "clock",
    "clock_offset_s": 5.0,
    "absolute_start": "2024-06-01T08:00:05+00:00",
}
LOCAL = {
    "window_s": 60,
    "spans_s": [[0.0, 60.0], [60.0, 99.9]],
    "phi_windows": [0.91, None],
    "window_conditions": ["heater", None],
    "regions": {
        "by": ["speed"],
        "edges": [[0.0, 50.0, 100.0]],
        "shape": [2],
        "counts": [700, 0],
        "labels": ["speed 0–50", "speed 50–100"],
        "min_samples": 20,
        "unvisited": [[1]],
        "outside": 300,
        "phi": [0.95, None],
    },
}
CAMPAIGN = {
    "name": "fleet",
    "recordings": ["A01", "A02"],
    "min_pass_rate": 0.9,
    "phi_quantile": [0.1, 0.85],
    "line": 11,
    "unused_models": ["exports/B9.csv"],
}


@pytest.mark.parametrize(
    ("kind", "data"),
    [
        (DataSources, DATA),
        (DataSources, {**DATA, "model": CALLABLE_MODEL}),
        (DataSources, {**DATA, "model": FMU_MODEL}),
        (AlignmentFacts, ALIGNMENT),
        (LocalGrid, LOCAL),
        (CampaignFacts, CAMPAIGN),
        (CampaignFacts, {**CAMPAIGN, "phi_quantile": None, "unused_models": []}),
    ],
)
def test_today_s_json_is_written_back_byte_for_byte(kind: Any, data: dict[str, Any]) -> None:
    expected = {k: v for k, v in data.items() if v != []}
    assert json.dumps(kind.from_dict(data).to_dict()) == json.dumps(expected)


def test_older_forms_load_and_keep_what_they_hold() -> None:
    # Records before ``hash``/``digest`` named a data file by its sha256; some held no data.
    old = DataSources.from_dict({"reference": {"path": "r.csv", "sha256": "99"}, "note": 1})
    assert old.reference is not None
    assert old.reference.identity == ("sha256", "99")
    assert old.to_dict() == {"reference": {"path": "r.csv", "sha256": "99"}, "note": 1}
    assert DataSources.from_dict({}).to_dict() == {}
    assert AlignmentFacts.from_dict({}).to_dict() == {}
    campaign = CampaignFacts.from_dict({"line": 3})
    assert campaign.name is None
    assert campaign.recordings is None
    assert ModelData.from_dict({"path": "m.csv"}).to_dict() == {"path": "m.csv"}


def test_paths_are_made_relative_where_the_result_names_files() -> None:
    data = DataSources.from_dict({**DATA, "model": CALLABLE_MODEL})
    moved = data.with_paths(lambda path: f"rel/{path}").to_dict()
    assert moved["reference"]["path"] == "rel/ref.parquet"
    assert moved["model"]["module_file"] == "rel/bus/model.py"
    campaign = CampaignFacts.from_dict(CAMPAIGN).with_paths(lambda path: f"rel/{path}")
    assert campaign.unused_models == ("rel/exports/B9.csv",)


@pytest.mark.parametrize(
    "data",
    [
        FILE_MODEL,
        CALLABLE_MODEL,
        {"path": "old.csv", "sha256": "77"},
        {"path": "unread.csv"},
        # A callable's JSON names no digest, whatever was set beside it.
        {**CALLABLE_MODEL, "digest": "ff", "hash": "xxh3_128"},
    ],
)
def test_a_model_s_identity_is_the_one_its_json_names(data: dict[str, Any]) -> None:
    from pytest_hevval.results.codec import data_identity

    model = ModelData.from_dict(data)
    assert model.identity == data_identity(model.to_dict())
