"""One run for both front ends: option values are checked once, by the run's rules, and each
front end's messages name its own flags; the run's one verdict gives the exit code."""

from __future__ import annotations

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
