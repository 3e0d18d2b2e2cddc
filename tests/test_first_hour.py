"""What a new user meets in the first hour: a model callable that needs a column it was not
given, one bad spec, the messages they get."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytest_plugins = ["pytester"]

# A user's model: it reads the heater channel, which the spec does not hand over.
MODEL = """\
import pandas as pd


def helper(frame):
    return frame["heater_kw"] * 0.0


def simulate(frame):
    load = helper(frame)
    return pd.DataFrame({"time": frame["t"], "v": frame["speed"] + load})
"""

SPEC = """\
name: trip
reference: {path: trip.csv, time: t}
model: {callable: "usermodel:simulate", driven_by: [speed]%s}
sets:
  - {signal: v, ref: speed, sim: v}
  - {signal: v_again, ref: speed, sim: v}
"""


def _write(root: Path, inputs: str = "") -> None:
    t = np.arange(0.0, 60.0, 0.1)
    pd.DataFrame({"t": t, "speed": 10 + np.sin(t), "heater_kw": 2.0 + 0 * t}).to_csv(
        root / "trip.csv", index=False
    )
    (root / "usermodel.py").write_text(MODEL)
    (root / "trip.hevval.yaml").write_text(SPEC % inputs)


def test_a_column_the_model_was_not_given_names_inputs_the_line_and_what_it_got(
    pytester: pytest.Pytester,
) -> None:
    _write(pytester.path)
    result = pytester.runpytest("--hevval", "--hevval-no-history")
    result.assert_outcomes(errors=3)
    text = result.stdout.str()
    expected = (
        "trip.hevval.yaml:3: model.inputs: the model asked for the column 'heater_kw' at "
        "usermodel.py:5, which it was not given: it receives only the columns the spec names "
        "(the data file has this one); it got ['t', 'speed']; add 'heater_kw' to `inputs:` "
        "under `model:` in the spec"
    )
    assert expected in text
    assert "base.py" not in text
    # Giving it the column is the whole fix.
    _write(pytester.path, inputs=", inputs: [heater_kw]")
    pytester.runpytest("--hevval", "--hevval-no-history").assert_outcomes(passed=3)


def test_one_bad_spec_prints_its_error_once(pytester: pytest.Pytester) -> None:
    _write(pytester.path)
    result = pytester.runpytest("--hevval", "--hevval-no-history")
    text = result.stdout.str()
    assert text.count("the model asked for the column 'heater_kw'") == 1
    assert "During handling of the above exception" not in text
    assert text.count("not scored: the error of trip.hevval.yaml::v stops this spec") == 2


def test_hevval_run_names_the_model_line_too(pytester: pytest.Pytester) -> None:
    _write(pytester.path)
    done = pytester.run(
        sys.executable, "-m", "pytest_hevval", "run", "trip.hevval.yaml", "--no-history"
    )
    assert done.ret == 2
    (line,) = [entry for entry in done.stderr.lines if entry.strip()]
    assert line.startswith("hevval run: error: ")
    assert "usermodel.py:5" in line
    assert "add 'heater_kw' to `inputs:`" in line


def _records(root: Path) -> list[Path]:
    return sorted((root / ".hevval" / "history").glob("*.json"))


def test_a_local_run_is_not_recorded_unless_asked_and_says_so(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A laptop's runs stay out of the team's history; CI's go in; asking records any."""
    _write(pytester.path, inputs=", inputs: [heater_kw]")
    local = pytester.runpytest("--hevval")
    local.assert_outcomes(passed=3)
    local.stdout.fnmatch_lines(["history: not recorded (runs are recorded in CI, or when asked*"])
    assert _records(pytester.path) == []
    pytester.runpytest("--hevval", "--hevval-history").assert_outcomes(passed=3)
    assert len(_records(pytester.path)) == 1
    monkeypatch.setenv("CI", "true")
    in_ci = pytester.runpytest("--hevval")
    in_ci.stdout.fnmatch_lines(["history: recorded unknown in .hevval/history/*"])
    assert len(_records(pytester.path)) == 2
    monkeypatch.delenv("CI")
    quiet = pytester.runpytest("--hevval", "--hevval-no-history")
    quiet.stdout.no_fnmatch_line("history:*")
    assert len(_records(pytester.path)) == 2


def test_hevval_run_records_only_when_asked(pytester: pytest.Pytester) -> None:
    _write(pytester.path, inputs=", inputs: [heater_kw]")
    plain = pytester.run(sys.executable, "-m", "pytest_hevval", "run", "trip.hevval.yaml")
    assert plain.ret == 0
    plain.stdout.fnmatch_lines(["history: not recorded*hevval run --history*"])
    asked = pytester.run(
        sys.executable, "-m", "pytest_hevval", "run", "trip.hevval.yaml", "--history"
    )
    assert asked.ret == 0
    assert len(_records(pytester.path)) == 1


@pytest.mark.parametrize(
    ("asked", "refused", "environ", "expected"),
    [
        (False, False, {}, False),
        (True, False, {}, True),
        (False, False, {"CI": "true"}, True),
        (False, False, {"GITHUB_ACTIONS": "true"}, True),
        (True, True, {"CI": "true"}, False),
        (False, False, {"CI": "false"}, False),
    ],
)
def test_which_runs_are_recorded(
    asked: bool, refused: bool, environ: dict[str, str], expected: bool
) -> None:
    from pytest_hevval.history import records_this_run

    assert records_this_run(asked=asked, refused=refused, environ=environ) is expected


def test_hevval_run_finds_the_project_root_as_pytest_does(pytester: pytest.Pytester) -> None:
    """Run from the spec's folder, `hevval run` imports the model from the folder that holds
    the pytest configuration, as `pytest --hevval` does."""
    pytester.makeini("[pytest]\n")
    (pytester.path / "models").mkdir()
    (pytester.path / "models" / "__init__.py").write_text("")
    (pytester.path / "models" / "user.py").write_text(MODEL)
    folder = pytester.path / "validation"
    folder.mkdir()
    _write(folder, inputs=", inputs: [heater_kw]")
    text = (folder / "trip.hevval.yaml").read_text().replace("usermodel:", "models.user:")
    (folder / "trip.hevval.yaml").write_text(text)
    (folder / "usermodel.py").unlink()
    done = subprocess.run(
        [sys.executable, "-m", "pytest_hevval", "run", ".", "--no-history"],
        cwd=folder,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    assert "[validation/trip.hevval.yaml]" in done.stdout


def test_project_root(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from pytest_hevval.cli import project_root

    inner = tmp_path / "repo" / "validation"
    inner.mkdir(parents=True)
    (inner / "a.hevval.yaml").write_text("")
    monkeypatch.chdir(inner)
    assert project_root(["a.hevval.yaml"]) == inner  # nothing configured: here
    (tmp_path / "repo" / "pyproject.toml").write_text("[project]\nname = 'x'\n")
    assert project_root(["a.hevval.yaml"]) == inner  # a pyproject without pytest's section
    (tmp_path / "repo" / "pyproject.toml").write_text("[tool.pytest.ini_options]\n")
    assert project_root(["a.hevval.yaml::TripA"]) == tmp_path / "repo"
    (inner / "pytest.ini").write_text("[pytest]\n")
    assert project_root([str(inner / "a.hevval.yaml")]) == inner


@pytest.mark.parametrize("unbuffered", [False, True], ids=["buffered", "unbuffered"])
def test_a_closed_pipe_ends_hevval_run_without_a_traceback(
    pytester: pytest.Pytester, unbuffered: bool
) -> None:
    """Buffered, as a user's shell runs it, the whole output is written as the run ends; with
    PYTHONUNBUFFERED, line by line while it runs. Either way the closed pipe is handled."""
    _write(pytester.path, inputs=", inputs: [heater_kw]")
    environment = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    if unbuffered:
        environment["PYTHONUNBUFFERED"] = "1"
    child = subprocess.Popen(
        [sys.executable, "-m", "pytest_hevval", "run", "trip.hevval.yaml", "--details"],
        cwd=pytester.path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=environment,
    )
    assert child.stdout is not None
    assert child.stderr is not None
    child.stdout.close()  # the reader goes before the first line, as `| head -0` would
    with child.stderr:
        errors = child.stderr.read()
    assert child.wait(timeout=120) == 1
    assert "Traceback" not in errors
    assert "BrokenPipeError" not in errors


def test_a_column_the_model_does_not_return_names_the_spec_line(
    pytester: pytest.Pytester,
) -> None:
    _write(pytester.path, inputs=", inputs: [heater_kw]")
    spec = pytester.path / "trip.hevval.yaml"
    spec.write_text(spec.read_text().replace("sim: v}", "sim: vee}", 1))
    done = pytester.run(
        sys.executable, "-m", "pytest_hevval", "run", "trip.hevval.yaml", "--no-history"
    )
    assert done.ret == 2
    assert (
        "trip.hevval.yaml:5: sets[0].sim: column 'vee': model usermodel:simulate: no such column "
        "in the model's output; it has 2 columns: 'time', 'v'"
    ) in done.stderr.str()


def test_an_unquoted_expression_gets_a_hint_to_quote_it(pytester: pytest.Pytester) -> None:
    _write(pytester.path)
    spec = pytester.path / "trip.hevval.yaml"
    spec.write_text(spec.read_text().replace("ref: speed,", "ref: speed [km/h] * 1,", 1))
    done = pytester.run(sys.executable, "-m", "pytest_hevval", "run", "trip.hevval.yaml")
    assert done.ret == 2
    assert "trip.hevval.yaml:5: invalid YAML" in done.stderr.str()
    assert "quote a value that holds *, :, [, ], & or #" in done.stderr.str()


def test_the_spec_line_says_phi_against_its_minimum_then_why_the_spec_fails(
    pytester: pytest.Pytester,
) -> None:
    _write(pytester.path, inputs=", inputs: [heater_kw]")
    spec = pytester.path / "trip.hevval.yaml"
    spec.write_text(
        spec.read_text().replace("sim: v}", "sim: v * 1.3}", 1)
        + "thresholds: {mae: 0.99}\nmin_phi: 0.5\n"
    )
    result = pytester.runpytest("--hevval")
    result.stdout.fnmatch_lines(
        ["trip: Φ = 0.* ≥ min 0.5, FAIL on its signals  *trip.hevval.yaml*"]
    )
    result.assert_outcomes(passed=2, failed=1)
