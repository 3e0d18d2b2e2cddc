"""One run for both front ends: option values are checked once, by the run's rules, and each
front end's messages name its own flags; the run's one verdict gives the exit code."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pytest_hevval.cli import main
from pytest_hevval.results.verdict import Outcome, RunVerdict

#: A bad value of each option the run checks, and what the message says about it.
BAD_VALUES = [
    ("compare-fail", "zz", "rule 'zz' has no ':amount'"),
    ("ratchet", "abc", "margin must be a number (got 'abc')"),
]


@pytest.mark.parametrize(("name", "value", "problem"), BAD_VALUES)
def test_hevval_run_names_its_own_flag(
    name: str, value: str, problem: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Checked before any spec is read: the spec need not exist.
    code = main(["run", str(tmp_path / "absent.hevval.yaml"), f"--{name}", value])
    err = capsys.readouterr().err
    assert code == 2
    assert f"hevval run: error: --{name}: {problem}" in err
    assert "--hevval-" not in err


@pytest.mark.parametrize(("name", "value", "problem"), BAD_VALUES)
def test_pytest_names_its_own_flag(
    name: str, value: str, problem: str, pytester: pytest.Pytester
) -> None:
    result = pytester.runpytest("--hevval", "-p", "no:cacheprovider", f"--hevval-{name}={value}")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines([f"*--hevval-{name}: {problem}*"])


@pytest.mark.parametrize(
    ("value", "problem"),
    [("0", "must be ≥ 1 (got 0)"), ("two", "must be a whole number (got 'two')")],
)
def test_workers_are_checked_by_one_rule_on_both_front_ends(
    value: str,
    problem: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    pytester: pytest.Pytester,
) -> None:
    code = main(["run", str(tmp_path / "absent.hevval.yaml"), "--workers", value])
    assert code == 2
    assert f"hevval run: error: argument --workers: {problem}" in capsys.readouterr().err
    result = pytester.runpytest("--hevval", "-p", "no:cacheprovider", f"--hevval-workers={value}")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines([f"*--hevval-workers {problem}*"])


def test_the_verdict_gives_the_outcome() -> None:
    passed = RunVerdict(passed=True)
    assert passed.outcome is Outcome.PASSED
    # A report or the record that could not be written fails a run whose gates passed.
    assert passed.published(failed=True).outcome is Outcome.FAILED
    assert RunVerdict(passed=False).outcome is Outcome.FAILED
    # A spec that could not be scored is the input's fault, whatever else happened.
    assert RunVerdict(passed=False, errors=("a.hevval.yaml: bad",)).outcome is Outcome.ERROR
    # The files the run wrote never say whether publishing failed.
    assert "publishing_failed" not in passed.published(failed=True).to_dict()


def test_a_campaign_run_makes_each_results_json_once_and_judges_its_campaign_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`hevval run` of the example's ten-recording campaign with three reports, compared with
    the run before and recorded: each result is turned into JSON once (shared by the files that
    hold it), none is read back from JSON (the baseline is read as history compares it), and
    the campaign verdict is judged once, by the run's verdict."""
    import shutil

    from pytest_hevval.results import campaign
    from pytest_hevval.results.spec_result import SpecResult

    project = tmp_path / "project"
    example = Path(__file__).resolve().parents[1] / "example_project"
    shutil.copytree(example / "specs", project / "specs")
    shutil.copytree(example / "data", project / "data")
    shutil.copytree(example / "models", project / "models")
    shutil.copy(example / "pytest.ini", project / "pytest.ini")
    calls = {"to_dict": 0, "from_dict": 0, "verdict": 0}
    to_dict, from_dict, judge = SpecResult.to_dict, SpecResult.from_dict.__func__, campaign.verdict

    def counted_to_dict(self: SpecResult) -> dict[str, object]:
        calls["to_dict"] += 1
        return to_dict(self)

    def counted_from_dict(cls: type[SpecResult], data: object) -> SpecResult:
        calls["from_dict"] += 1
        return from_dict(cls, data)  # type: ignore[no-any-return]

    def counted_verdict(*args: object, **kwargs: object) -> object:
        calls["verdict"] += 1
        return judge(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.chdir(project)
    campaign_spec = ["run", "specs/i3-campaign-v2.hevval.yaml", "--quiet"]
    assert main([*campaign_spec, "--history", "--model-version", "v1"]) == 1
    monkeypatch.setattr(SpecResult, "to_dict", counted_to_dict)
    monkeypatch.setattr(SpecResult, "from_dict", classmethod(counted_from_dict))
    monkeypatch.setattr(campaign, "verdict", counted_verdict)
    code = main(
        [
            *campaign_spec,
            "--report",
            "json,md,evidence",
            "--history",
            "--model-version",
            "v2",
            "--compare",
            "latest",
            "--compare-fail",
            "phi:0.5",
        ]
    )
    assert code == 1  # the campaign fails its gate on purpose
    report = json.loads((project / ".hevval" / "report" / "report.json").read_text("utf-8"))
    assert sum(spec.get("recording", "").startswith("Trip") for spec in report["specs"]) == 10
    assert report["comparison"]["before"] == "v1"
    assert len(report["comparison"]["specs"]) == 10
    assert len(list((project / ".hevval" / "history").glob("*.json"))) == 2
    assert calls == {"to_dict": 10, "from_dict": 0, "verdict": 1}
