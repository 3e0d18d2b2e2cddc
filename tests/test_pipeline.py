"""One pipeline, one command line, one way to write a file."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest

from pytest_hevval import cli
from pytest_hevval.files import write_atomic
from pytest_hevval.options import OPTIONS
from tests.test_plugin import TREE_SPEC, write_data

pytest_plugins = ["pytester"]

# What a history record holds about the run itself rather than about the specs scored.
RUN_METADATA = ("started_utc", "tool_versions")


@pytest.fixture
def project(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> pytest.Pytester:
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.delenv("GITHUB_ACTIONS", raising=False)
    monkeypatch.delenv("HEVVAL_MODEL_VERSION", raising=False)
    pytester.makefile(".hevval.yaml", pack=TREE_SPEC)
    write_data(pytester.path)
    return pytester


def _only_record(folder: Path) -> dict:
    (path,) = sorted(folder.glob("*.json"))
    record = json.loads(path.read_text())
    for key in RUN_METADATA:
        record.pop(key)
    return record


def test_cli_and_pytest_write_the_same_history_record(project: pytest.Pytester) -> None:
    """The spec scored by `hevval run` and by `pytest --hevval` gives one and the same record."""
    project.runpytest(
        "--hevval",
        "--hevval-history",
        "--hevval-model-version=v1",
        "--hevval-history-dir=from-pytest",
    ).assert_outcomes(passed=6)
    code = cli.main(
        [
            "run",
            "pack.hevval.yaml",
            "--history",
            "--model-version=v1",
            "--history-dir=from-cli",
            "--quiet",
        ]
    )
    assert code == 0
    from_pytest = _only_record(project.path / "from-pytest")
    from_cli = _only_record(project.path / "from-cli")
    assert from_cli == from_pytest
    # Paths are relative to the project root on both sides, data files included.
    spec = from_cli["specs"][0]
    assert spec["spec"] == "pack.hevval.yaml"
    assert not os.path.isabs(spec["data"]["reference"]["path"])


def test_help_lists_every_subcommand(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    for command in ("run", "diagnose", "compare", "history"):
        assert f"    {command}  " in out, out


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    import pytest_hevval

    assert cli.main(["--version"]) == 0
    version, path = capsys.readouterr().out.strip().splitlines()
    assert version == f"pytest-hevval {pytest_hevval.__version__}"
    assert path.startswith("kernel: ")


@pytest.mark.parametrize("command", ["run", "diagnose", "compare", "history"])
def test_options_are_spelled_as_the_pytest_flags(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """An option a subcommand shares with pytest has the pytest flag's name, minus the prefix."""
    assert cli.main([command, "--help"]) == 0
    flags = {word.strip("[],") for word in capsys.readouterr().out.split() if word[:2] == "--"}
    pytest_names = {o.name for o in OPTIONS if o.name}
    for flag in flags - {"--help"}:
        name = flag[2:].split("=")[0]
        spelled_differently = {f"{n}" for n in pytest_names if n.replace("-", "") == name}
        assert not spelled_differently - {name}, f"{command} {flag} vs --hevval-{name}"
    # The two names that differed before are now the pytest ones.
    if command in ("compare", "history"):
        assert "--history-dir" in flags
        assert "--dir" not in flags
    if command == "compare":
        assert "--compare-fail" in flags


def test_usage_errors_name_the_command(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["history", "--bogus"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hevval history: error: unrecognized arguments: --bogus")
    assert "hevval history --help" in err
    assert cli.main(["frobnicate"]) == 2
    assert "invalid choice: 'frobnicate'" in capsys.readouterr().err


def test_run_refuses_a_bad_worker_count(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["run", "x.hevval.yaml", "--workers", "0"]) == 2
    assert "must be ≥ 1 (got 0)" in capsys.readouterr().err


def _umask() -> int:
    current = os.umask(0)
    os.umask(current)
    return current


def test_written_files_get_the_usual_mode_and_no_temporary_stays(tmp_path: Path) -> None:
    target = tmp_path / "deep" / "x.hevval.thresholds.yaml"
    assert write_atomic(target, "a: {mae: 0.9}\n")
    assert target.read_text() == "a: {mae: 0.9}\n"
    mode = stat.S_IMODE(target.stat().st_mode)
    assert mode == 0o666 & ~_umask()
    assert sorted(p.name for p in target.parent.iterdir()) == [target.name]


def test_replace_false_leaves_an_existing_file_alone(tmp_path: Path) -> None:
    target = tmp_path / "record.json"
    target.write_text("old")
    assert not write_atomic(target, "new", replace=False)
    assert target.read_text() == "old"
    assert write_atomic(target, "new")
    assert target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["record.json"]


def test_a_failed_write_keeps_the_old_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "report.json"
    target.write_text("old")

    def full_disk(*args: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", full_disk)
    with pytest.raises(OSError, match="No space left"):
        write_atomic(target, "new")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.json"]


def test_ratchet_sidecar_is_created_with_the_usual_mode(project: pytest.Pytester) -> None:
    project.runpytest("--hevval", "--hevval-ratchet").assert_outcomes(passed=6)
    sidecar = project.path / "pack.hevval.thresholds.yaml"
    assert sidecar.exists()
    assert stat.S_IMODE(sidecar.stat().st_mode) == 0o666 & ~_umask()


def _report_json(folder: Path) -> dict:
    document = json.loads((folder / "report.json").read_text("utf-8"))
    document.pop("generated_utc", None)
    return document


def _without_run_time(html: str) -> str:
    """The report's HTML without the one line that names when it was written."""
    import re

    return re.sub(r"\d{4}-\d\d-\d\d[T ]\d\d:\d\d:\d\d(\.\d+)?(Z|\+00:00| UTC)?", "<time>", html)


def test_cli_and_pytest_publish_the_same(project: pytest.Pytester) -> None:
    """A failing spec with a baseline and every output on: `hevval run` writes the same JSON
    and HTML reports (diagnosis and trend panels included), the same history record and the
    same comparison as `pytest --hevval`, and fails on the same regression."""
    for side in ("from-pytest", "from-cli"):
        assert (
            cli.main(
                [
                    "run",
                    "pack.hevval.yaml",
                    "--history",
                    "--model-version=v0",
                    f"--history-dir={side}",
                    "--quiet",
                ]
            )
            == 0
        )
    write_data(project.path, fault="middle")
    shared = [
        "--history",
        "--model-version=v1",
        "--report=json,html",
        "--compare",
        "--compare-fail=phi:0.01",
    ]
    result = project.runpytest(
        "--hevval",
        *(f"--hevval-{option.removeprefix('--')}" for option in shared),
        "--hevval-history-dir=from-pytest",
        "--hevval-report-dir=report-pytest",
    )
    assert result.ret == pytest.ExitCode.TESTS_FAILED
    code = cli.main(
        ["run", "pack.hevval.yaml", *shared, "--history-dir=from-cli", "--report-dir=report-cli"]
    )
    assert code == 1
    from_pytest = _report_json(project.path / "report-pytest")
    from_cli = _report_json(project.path / "report-cli")
    assert from_cli == from_pytest
    signals = {s["path"]: s for s in from_cli["specs"][0]["signals"]}
    assert "diagnosis" in signals["E/P"], "the failing signal's diagnosis panel"
    assert len(signals["E/P"]["history"]) == 2, "the trend over v0 and v1"
    html_pytest = (project.path / "report-pytest" / "report.html").read_text("utf-8")
    html_cli = (project.path / "report-cli" / "report.html").read_text("utf-8")
    assert _without_run_time(html_cli) == _without_run_time(html_pytest)
    records = {
        side: [json.loads(p.read_text()) for p in sorted((project.path / side).glob("*.json"))]
        for side in ("from-pytest", "from-cli")
    }
    for record in (*records["from-pytest"], *records["from-cli"]):
        for key in RUN_METADATA:
            record.pop(key)
        if record["baseline"] is not None:  # each side's own v0, recorded at its own time
            record["baseline"].pop("started_utc")
    assert records["from-cli"] == records["from-pytest"]
    assert [r["acceptance"] for r in records["from-cli"]] == ["not-compared", "regressed"]
    assert [r["model_version"] for r in records["from-cli"]] == ["v0", "v1"]


def test_cli_compares_and_ratchets_as_pytest_does(
    project: pytest.Pytester, capsys: pytest.CaptureFixture[str]
) -> None:
    """`hevval run --compare --ratchet` prints the comparison table pytest prints and writes
    the same threshold sidecar."""
    assert cli.main(["run", "pack.hevval.yaml", "--model-version=v0", "--quiet"]) == 0
    capsys.readouterr()
    result = project.runpytest(
        "--hevval",
        "--hevval-model-version=v1",
        "--hevval-compare",
        "--hevval-ratchet",
        "-p",
        "no:cacheprovider",
        "--hevval-no-history",
    )
    result.assert_outcomes(passed=6)
    sidecar = next(project.path.glob("pack.hevval.thresholds.yaml"))
    from_pytest = sidecar.read_text("utf-8")
    sidecar.unlink()
    code = cli.main(
        [
            "run",
            "pack.hevval.yaml",
            "--model-version=v1",
            "--compare",
            "--ratchet",
            "--quiet",
            "--no-history",
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    from_cli = sidecar.read_text("utf-8")
    strip = _without_run_time
    assert strip(from_cli) == strip(from_pytest)
    table = [line for line in out.splitlines() if "v0 → v1" in line or "Φ" in line]
    assert table, out
    pytest_lines = result.outlines
    for line in table:
        assert line in pytest_lines, line


def test_cli_accepts_a_run_by_hand_and_compares_with_the_accepted_record(
    project: pytest.Pytester, capsys: pytest.CaptureFixture[str]
) -> None:
    """`hevval run --accept` records an accepted baseline where none was; the next run compares
    with it and is accepted, and `hevval compare history:accepted` names the newest accepted
    record."""
    run = ["run", "pack.hevval.yaml", "--history", "--quiet", "--compare", "accepted"]
    assert cli.main([*run, "--model-version=v1", "--accept"]) == 0
    assert "(accepted as a baseline: manual)" in capsys.readouterr().out
    assert cli.main([*run, "--model-version=v2", "--compare-fail", "phi:0.01"]) == 0
    assert "(accepted as a baseline: no-regression)" in capsys.readouterr().out
    records = [
        json.loads(p.read_text()) for p in sorted((project.path / ".hevval/history").glob("*.json"))
    ]
    assert [(r["model_version"], r["acceptance"]) for r in records] == [
        ("v1", "manual"),
        ("v2", "no-regression"),
    ]
    assert records[1]["baseline"]["model_version"] == "v1"
    compared = ["compare", "history:accepted", "history:previous", "--format", "json"]
    assert cli.main(compared) == 0
    document = json.loads(capsys.readouterr().out)
    assert (document["comparison"]["before"], document["comparison"]["after"]) == ("v2", "v1")
