"""The example project, run as a user runs it: real measurements, the paper's bus tree."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

EXAMPLE = Path(__file__).resolve().parent.parent / "example_project"
PAPER = {
    "lag_correlation",
    "derivative_match",
    "mae",
    "rms",
    "anomaly",
    "error_std",
    "emergent",
}


@pytest.fixture(scope="module")
def run_payload(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("example") / "run.json"
    run = subprocess.run(
        [sys.executable, "-m", "pytest_hevval", "run", "specs", "--json", str(out),
         "--no-history", "--quiet"],
        cwd=EXAMPLE,
        capture_output=True,
        text=True,
        timeout=600,
    )  # fmt: skip
    assert run.returncode in (0, 1), run.stderr
    return dict(json.loads(out.read_text()))


@pytest.fixture(scope="module")
def results(run_payload: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {spec["name"]: spec for spec in run_payload["specs"]}


def test_every_case_is_scored(results: dict[str, dict]) -> None:
    assert len(results) >= 10
    for spec in results.values():
        assert 0.0 <= spec["phi"] <= 1.0
        # The paper's seven, plus the standard metrics a spec switches on (none gated there).
        extra = {"iso18571", "theil"} if "A02 motorway" in spec["name"] else set()
        assert all(set(s["lambdas"]) == PAPER | extra for s in spec["signals"])


def test_i3_fit_trip_passes_and_others_are_validated(results: dict[str, dict]) -> None:
    fit = next(s for name, s in results.items() if "A01" in name)
    assert fit["passed"] is True
    assert fit["phi"] > 0.93
    held_out = [s for name, s in results.items() if "i3" in name and "A01" not in name]
    assert held_out, "the i3 model must be validated on trips not used for fitting"


def test_bus_error_is_localised_at_engine_torque(results: dict[str, dict]) -> None:
    bus = next(s for name, s in results.items() if "bus" in name)
    origins = {s["path"] for s in bus["signals"] if s["origin"]}
    assert "FCcum/FCinst/Teng" in origins
    assert [s["path"] for s in bus["signals"]][:4] == [
        "FCcum",
        "FCcum/FCinst",
        "FCcum/FCinst/Neng",
        "FCcum/FCinst/Teng",
    ]


def test_camry_cold_start_costs_more_than_hot(results: dict[str, dict]) -> None:
    cold = results["Camry FTP cold-start UDDS"]
    hot = results["Camry FTP hot-start UDDS"]
    cold_cum = cold["signals"][0]
    hot_cum = hot["signals"][0]
    assert cold_cum["mae"] > hot_cum["mae"]


def test_i3_campaign_scores_every_trip_and_excludes_the_fit_trip(
    run_payload: dict[str, Any],
) -> None:
    (campaign,) = run_payload["campaigns"]
    recordings = {r["id"]: r for r in campaign["recordings"]}
    assert len(recordings) == 10
    assert campaign["excluded"] == ["TripA01"]
    assert recordings["TripA01"]["role"] == "calibration"
    assert all(r["hash"] and len(r["digest"]) >= 32 for r in recordings.values())
    # The fit trip passes, but only the nine validation trips count toward the pass rate.
    assert recordings["TripA01"]["passed"] is True
    validation = [r for r in recordings.values() if r["role"] == "validation"]
    assert campaign["pass_rate"] == sum(r["passed"] for r in validation) / 9
    assert set(campaign["worst"]) <= {r["id"] for r in validation}


def test_the_readmes_say_the_count_the_example_gives(run_payload: dict[str, Any]) -> None:
    """What a new user is told to expect is what the run says (pytest counts the same items)."""
    from pytest_hevval.report.sentences import outcome_line
    from pytest_hevval.results.spec_result import SpecResult

    line = outcome_line([SpecResult.from_dict(spec) for spec in run_payload["specs"]])
    for readme in (EXAMPLE.parent / "README.md", EXAMPLE / "README.md"):
        assert line in readme.read_text(encoding="utf-8"), readme
    failed = int(line.split(" items, ")[1].split(" fail")[0])
    items = int(line.split("; ")[1].split(" items")[0])
    top = (EXAMPLE.parent / "README.md").read_text(encoding="utf-8")
    assert f"{failed} failed, {items - failed} passed" in top
