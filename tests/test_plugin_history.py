"""History through the plugin: records per run, gates against the past, the ratchet."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.test_plugin import TREE_SPEC, write_data

pytest_plugins = ["pytester"]


@pytest.fixture
def project(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> pytest.Pytester:
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.delenv("GITHUB_ACTIONS", raising=False)
    monkeypatch.delenv("HEVVAL_MODEL_VERSION", raising=False)
    pytester.makefile(".hevval.yaml", pack=TREE_SPEC)
    # A team that records every run, not only those in CI.
    pytester.makeini("[pytest]\nhevval_history = true\n")
    write_data(pytester.path)
    return pytester


def records(root: Path) -> list[dict]:
    folder = root / ".hevval" / "history"
    return [json.loads(p.read_text()) for p in sorted(folder.glob("*.json"))]


def test_every_run_is_recorded(project: pytest.Pytester) -> None:
    project.runpytest("--hevval", "--hevval-model-version=v1").assert_outcomes(passed=6)
    project.runpytest("--hevval", "--hevval-model-version=v2").assert_outcomes(passed=6)
    found = records(project.path)
    assert [r["model_version"] for r in found] == ["v1", "v2"]
    spec = found[0]["specs"][0]
    assert spec["spec"] == "pack.hevval.yaml"
    assert len(spec["spec_hash"]) == 64
    reference = spec["data"]["reference"]
    assert reference["hash"] in ("xxh3_128", "sampled-blake2b")
    assert len(reference["digest"]) == 32

    signal = next(s for s in spec["signals"] if s["path"] == "E/P/I")
    assert len(signal["lambdas"]) == 7
    assert {"numpy", "scipy", "pytest-hevval"} <= set(found[0]["tool_versions"])


def test_sha256_identifies_data_on_request(project: pytest.Pytester) -> None:
    project.runpytest("--hevval", "--hevval-hash=sha256").assert_outcomes(passed=6)
    reference = records(project.path)[0]["specs"][0]["data"]["reference"]
    assert reference["hash"] == "sha256"
    assert len(reference["digest"]) == 64


def test_no_history_flag(project: pytest.Pytester) -> None:
    project.runpytest("--hevval", "--hevval-no-history").assert_outcomes(passed=6)
    assert not (project.path / ".hevval" / "history").exists()


def test_model_version_from_environment(
    project: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("HEVVAL_MODEL_VERSION", "from-env")
    project.runpytest("--hevval").assert_outcomes(passed=6)
    assert records(project.path)[0]["model_version"] == "from-env"


def worsen(root: Path) -> None:
    """A small extra error in the model's current: still far above the 0.97 MAE threshold,
    but a drop of λ3 that ``lambda:0.002`` fails."""
    import pandas as pd

    frame = pd.read_csv(root / "data" / "sim.csv")
    frame["I"] = frame["I"] + 0.8
    frame["P"] = frame["V"] * frame["I"]
    frame.to_csv(root / "data" / "sim.csv", index=False)


def test_gate_fails_on_regression_that_still_passes_thresholds(project: pytest.Pytester) -> None:
    project.runpytest("--hevval", "--hevval-model-version=good").assert_outcomes(passed=6)
    worsen(project.path)
    plain = project.runpytest("--hevval", "--hevval-no-history")
    plain.assert_outcomes(passed=6)
    gated = project.runpytest(
        "--hevval", "--hevval-model-version=worse", "--hevval-compare-fail=lambda:0.002"
    )
    gated.assert_outcomes(passed=3, failed=3)
    gated.stdout.fnmatch_lines(
        [
            "E/P/I got worse than the baseline by more than --hevval-compare-fail allows:",
            "  pack.hevval.yaml::E/P/I: λ3 mae dropped 0.99* → 0.99* (allowed drop 0.002, *",
        ]
    )


def test_compare_shows_deltas(project: pytest.Pytester) -> None:
    project.runpytest("--hevval", "--hevval-model-version=a").assert_outcomes(passed=6)
    result = project.runpytest("--hevval", "--hevval-model-version=b", "--hevval-compare")
    result.assert_outcomes(passed=6)
    result.stdout.fnmatch_lines(["compare a → b", "pack.hevval.yaml (pack)", "*λ3 mae*", "*Φ*"])


def test_missing_baseline_fails_in_ci(
    project: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("CI", "true")
    result = project.runpytest("--hevval", "--hevval-compare-fail=phi:0.01")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines(["*no baseline record in *history; comparison needs one.*"])
    created = project.runpytest(
        "--hevval", "--hevval-compare-fail=phi:0.01", "--hevval-create-baseline"
    )
    created.assert_outcomes(passed=6)
    assert len(records(project.path)) == 1


def test_missing_baseline_is_a_note_locally(project: pytest.Pytester) -> None:
    result = project.runpytest("--hevval", "--hevval-compare")
    result.assert_outcomes(passed=6)
    result.stdout.fnmatch_lines(["*no baseline record in *; nothing to compare against yet*"])


def test_bad_compare_fail_expression_is_a_usage_error(project: pytest.Pytester) -> None:
    result = project.runpytest("--hevval", "--hevval-compare-fail=lamda:0.1")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert "lamda" in result.stderr.str()


def test_ratchet_tightens_and_never_loosens(project: pytest.Pytester) -> None:
    project.runpytest("--hevval", "--hevval-ratchet=0.01").assert_outcomes(passed=6)
    sidecar = project.path / "pack.hevval.thresholds.yaml"
    first = yaml.safe_load(sidecar.read_text())
    assert first["E/P/I"]["mae"] > 0.97  # tighter than the spec's 0.97
    text = sidecar.read_text()
    # A worse model: the ratchet keeps the old values, and the tightened gate now fails.
    write_data(project.path, fault="leaf")
    worse = project.runpytest("--hevval", "--hevval-ratchet=0.01")
    worse.assert_outcomes(passed=3, failed=3)
    assert sidecar.read_text() == text
    # The sidecar is what failed the items: the message shows the ratcheted threshold.
    worse.stdout.fnmatch_lines([f"*λ3 MAE = * < {first['E/P/I']['mae']:g} *"])


def test_xdist_controller_writes_one_record(project: pytest.Pytester) -> None:
    result = project.runpytest("--hevval", "-p", "xdist", "-n", "4")
    result.assert_outcomes(passed=6)
    assert len(records(project.path)) == 1


def test_two_processes_at_once_lose_nothing(project: pytest.Pytester) -> None:
    command = [sys.executable, "-m", "pytest", "--hevval", "-q", "-p", "no:cacheprovider"]
    runs = [
        subprocess.Popen(
            [*command, f"--hevval-model-version=p{i}"],
            cwd=project.path,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for i in range(2)
    ]
    assert [run.wait(timeout=120) for run in runs] == [0, 0]
    assert sorted(r["model_version"] for r in records(project.path)) == ["p0", "p1"]


def report_trends(root: Path) -> dict[str, list[dict]]:
    """Each signal's trend as the JSON report carries it (the HTML report draws the same)."""
    report = json.loads((root / ".hevval" / "report" / "report.json").read_text())
    (spec,) = report["specs"]
    return {signal["path"]: signal.get("history") for signal in spec["signals"]}


def test_report_trends_show_earlier_runs_then_this_one(project: pytest.Pytester) -> None:
    for version in ("v1", "v2", "v3"):
        project.runpytest(
            "--hevval", f"--hevval-model-version={version}", "--hevval-report=json"
        ).assert_outcomes(passed=6)
    last = records(project.path)[-1]["specs"][0]
    trends = report_trends(project.path)
    assert set(trends) == {signal["path"] for signal in last["signals"]}
    for signal in last["signals"]:
        trend = trends[signal["path"]]
        assert [point["version"] for point in trend] == ["v1", "v2", "v3"]
        assert all(set(point) == {"version", "phi", "lambdas"} for point in trend)
        # This run comes last, as scored; the runs before it as recorded.
        assert trend[-1] == {"version": "v3", "phi": last["phi"], "lambdas": signal["lambdas"]}
    first = records(project.path)[0]["specs"][0]
    assert trends["E/P/I"][0]["phi"] == first["phi"]


def test_report_trends_show_the_newest_recorded_runs_of_a_long_history(
    project: pytest.Pytester,
) -> None:
    from datetime import datetime, timedelta, timezone

    from pytest_hevval.history import TREND_RUNS, HistoryStore, make_record

    project.runpytest("--hevval", "--hevval-model-version=seed").assert_outcomes(passed=6)
    seed = records(project.path)[0]
    store = HistoryStore(project.path / ".hevval" / "history")
    start = datetime(2024, 1, 1, tzinfo=timezone.utc)
    for i in range(TREND_RUNS + 5):
        store.append(
            make_record(
                seed["specs"], model_version=f"old-{i}", started_utc=start + timedelta(days=i)
            )
        )
    project.runpytest(
        "--hevval", "--hevval-model-version=now", "--hevval-report=json"
    ).assert_outcomes(passed=6)
    # Without an index (as on a fresh clone) the trends come from the newest records alone:
    # every signal is in each of them, so no older record is read and no index is built.
    assert not (project.path / ".hevval" / "history" / ".index").exists()
    expected = [f"old-{i}" for i in range(6, TREND_RUNS + 5)] + ["seed", "now"]
    assert len(expected) == TREND_RUNS + 1
    for trend in report_trends(project.path).values():
        assert [point["version"] for point in trend] == expected


def acceptance_of(root: Path) -> list[tuple[str, bool, str]]:
    return [(r["model_version"], r["accepted"], r["acceptance"]) for r in records(root)]


GATE = "--hevval-compare-fail=lambda:0.002"


def regressing_run(project: pytest.Pytester, *options: str) -> pytest.RunResult:
    """Record model "good", worsen it, and run "worse" against the accepted baseline."""
    project.runpytest("--hevval", "--hevval-model-version=good").assert_outcomes(passed=6)
    worsen(project.path)
    return project.runpytest(
        "--hevval", "--hevval-model-version=worse", "--hevval-compare=accepted", GATE, *options
    )


def test_a_regressed_run_is_recorded_but_never_becomes_the_accepted_baseline(
    project: pytest.Pytester,
) -> None:
    project.runpytest("--hevval", "--hevval-model-version=good").assert_outcomes(passed=6)
    worsen(project.path)
    project.runpytest(
        "--hevval", "--hevval-model-version=worse", "--hevval-compare=accepted", GATE
    ).assert_outcomes(passed=3, failed=3)
    # The same model again: against the newest accepted record it fails again.
    accepted = project.runpytest(
        "--hevval", "--hevval-model-version=again", "--hevval-compare=accepted", GATE
    )
    accepted.assert_outcomes(passed=3, failed=3)
    accepted.stdout.fnmatch_lines(
        ["compare good → again", "*(not accepted as a baseline: regressed)"]
    )
    # Against "latest", the newest record whatever it is, the regressed model finds itself.
    latest = project.runpytest(
        "--hevval", "--hevval-model-version=last", "--hevval-compare=latest", GATE
    )
    latest.assert_outcomes(passed=6)
    latest.stdout.fnmatch_lines(["compare again → last"])
    assert acceptance_of(project.path) == [
        ("good", True, "not-compared"),
        ("worse", False, "regressed"),
        ("again", False, "regressed"),
        ("last", True, "no-regression"),
    ]
    baselines = [r["baseline"] and r["baseline"]["model_version"] for r in records(project.path)]
    assert baselines == [None, "good", "good", "again"]


def test_accept_records_a_regression_as_the_baseline_and_reports_it(
    project: pytest.Pytester,
) -> None:
    result = regressing_run(project, "--hevval-accept")
    # Accepting the regressions is the point: they are reported, and fail nothing.
    result.assert_outcomes(passed=6)
    result.stdout.fnmatch_lines(
        [
            "*regression(s):",
            "  pack.hevval.yaml::E/P/I: λ3 mae dropped *",
            "*(accepted as a baseline: manual)",
        ]
    )
    # The accepted regression is the new baseline: the same model passes against it.
    project.runpytest(
        "--hevval", "--hevval-model-version=next", "--hevval-compare=accepted", GATE
    ).assert_outcomes(passed=6)
    assert acceptance_of(project.path) == [
        ("good", True, "not-compared"),
        ("worse", True, "manual"),
        ("next", True, "no-regression"),
    ]


def test_a_missing_baseline_is_recorded_unaccepted_unless_created(
    project: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    project.runpytest(
        "--hevval", "--hevval-model-version=first", "--hevval-compare=accepted"
    ).assert_outcomes(passed=6)
    monkeypatch.setenv("CI", "true")
    failed = project.runpytest("--hevval", "--hevval-compare=accepted", GATE)
    assert failed.ret == pytest.ExitCode.USAGE_ERROR
    failed.stderr.fnmatch_lines(["*no accepted baseline record in *history; comparison needs*"])
    project.runpytest(
        "--hevval",
        "--hevval-model-version=base",
        "--hevval-compare=accepted",
        GATE,
        "--hevval-create-baseline",
    ).assert_outcomes(passed=6)
    assert acceptance_of(project.path) == [
        ("first", False, "no-baseline"),
        ("base", True, "first-baseline"),
    ]


def test_accept_is_given_on_the_command_line_only(project: pytest.Pytester) -> None:
    project.makeini("[pytest]\nhevval_history = true\nhevval_accept = true\n")
    result = project.runpytest("--hevval", "--hevval-model-version=v1", "--hevval-compare")
    result.assert_outcomes(passed=6)
    assert acceptance_of(project.path) == [("v1", False, "no-baseline")]


@pytest.mark.parametrize("processes", [[], ["-p", "xdist", "-n", "2"]], ids=["serial", "xdist"])
def test_a_regression_fails_the_run_alike_in_every_output(
    project: pytest.Pytester, processes: list[str]
) -> None:
    """The terminal, report.md, report.json, report.html, JUnit XML and the exit code say one
    verdict when only a regression fails the run."""
    import xml.etree.ElementTree as ET

    result = regressing_run(
        project, "--hevval-report=html,json,md", "--junitxml=junit.xml", *processes
    )
    assert result.ret == pytest.ExitCode.TESTS_FAILED
    suite = ET.parse(project.path / "junit.xml").getroot().find("testsuite")
    assert suite is not None
    failures = int(suite.get("failures", "-1"))
    assert failures > 0
    folder = project.path / ".hevval" / "report"
    report = json.loads((folder / "report.json").read_text())
    summary = report["summary"]
    assert summary["passed"] is False
    assert summary["specs_failed"] == 1
    # Every failing item is a signal or the Φ of the spec: as many as JUnit counts.
    assert summary["outcome"].endswith(
        f"6 items, {failures} fail ({failures} by regression): "
        f"{summary['signals_failed']} of 5 signals, {failures - summary['signals_failed']} of 1 Φ"
    )
    regressions = report["verdict"]["regressions"]
    assert len(regressions) == summary["regressions"] > 0
    assert "pack.hevval.yaml::E/P/I" in {
        item["spec"] + "::" + item["signal"] for item in regressions
    }
    good = records(project.path)[0]
    against = f"against good ({good['started_utc'][:10]} {good['started_utc'][11:16]} UTC)"
    count = len(regressions)
    assert summary["outcome"].startswith(f"{count} regression{'s' * (count != 1)} {against}; ")
    markdown = (folder / "report.md").read_text().splitlines()
    assert markdown[0] == f"### ❌ hevval: {summary['outcome']}"
    assert "| ❌ | pack |" in "\n".join(markdown)
    # The comparison follows the spec table, its regressions first.
    at = markdown.index(f"#### Compared with {against[len('against ') :]}")
    assert markdown[at + 2].startswith(f"❌ {count} regression")
    html = (folder / "report.html").read_text()
    assert summary["outcome"] in html
    assert 'class="fail"' in html
    # The terminal's last line of the summary tree says the same.
    result.stdout.fnmatch_lines([summary["outcome"]])


def test_a_spec_that_cannot_be_scored_fails_the_verdict_of_the_reports(
    project: pytest.Pytester,
) -> None:
    project.makefile(".hevval.yaml", lost=TREE_SPEC.replace("data/sim.csv", "data/gone.csv"))
    result = project.runpytest("--hevval", "--hevval-report=json,md")
    result.assert_outcomes(passed=6, errors=6)
    folder = project.path / ".hevval" / "report"
    report = json.loads((folder / "report.json").read_text())
    assert report["summary"]["passed"] is False
    (error,) = report["verdict"]["errors"]
    assert error.startswith("lost.hevval.yaml: ")
    assert "gone.csv" in error
    assert report["summary"]["outcome"].startswith("1 spec could not be scored; ")
    markdown = (folder / "report.md").read_text()
    assert markdown.startswith("### ❌ hevval: 1 spec could not be scored; ")


def test_the_comparison_is_in_report_md_and_alone_in_comparison_md(
    project: pytest.Pytester,
) -> None:
    # A model version that would break a Markdown table, and raw HTML.
    project.runpytest("--hevval", "--hevval-model-version=v1|<i>").assert_outcomes(passed=6)
    worsen(project.path)
    result = project.runpytest(
        "--hevval",
        "--hevval-model-version=v2",
        "--hevval-compare=accepted",
        GATE,
        "--hevval-report=md,json",
    )
    result.assert_outcomes(passed=3, failed=3)
    folder = project.path / ".hevval" / "report"
    report = json.loads((folder / "report.json").read_text())
    assert (report["comparison"]["before"], report["comparison"]["after"]) == ("v1|<i>", "v2")
    alone = (folder / "comparison.md").read_text()
    markdown = (folder / "report.md").read_text()
    assert alone.splitlines()[0] == markdown.splitlines()[0]
    assert alone.startswith("### ❌ hevval: 7 regressions against v1\\|&lt;i&gt; (")
    assert "<i>" not in alone
    section = alone[alone.index("#### Compared with v1\\|&lt;i&gt; (") :]
    assert section.split("<sub>")[0] in markdown
    lines = section.splitlines()
    # Changes the tables' four decimals cannot show are none (λ1, and λ6 of E/P).
    assert lines[2] == "❌ 7 regressions; 9 values of Φ and λ worse, 4 better."
    assert lines[4].startswith("- pack.hevval.yaml::E: λ3 mae dropped 1 → 0.9935")
    table = lines[lines.index("**Worst changes**") + 2 :]
    assert table[0].startswith("| | where | quantity | before | after | Δ | 95 % intervals")
    rows = [row for row in table[2:] if row.startswith("| ") and not row.startswith("| |")]
    # The regressions first, each with both runs' intervals; then Φ's drop, which no rule
    # of lambda:0.002 covers.
    assert [row.split(" | ")[0] for row in rows[:9]] == ["| ❌"] * 7 + ["| 🔻"] * 2
    assert all(" → [" in row for row in rows)
    assert rows[0].endswith("| -0.0076 | [0.9996, 0.9996] → [0.9920, 0.9920] (disjoint) |")
    assert rows[7].startswith("| 🔻 | `pack.hevval.yaml` | Φ | 0.9964 | 0.9951 | -0.0014 | ")
    assert [row.split(" | ")[0] for row in rows[9:]] == ["| 🔺"] * 4  # the best changes
    assert "<details>" not in alone  # both tables show every change already
    # A run that compares with nothing leaves no comparison behind.
    project.runpytest("--hevval", "--hevval-report=md").assert_outcomes(passed=6)
    assert not (folder / "comparison.md").exists()
