"""What a new user meets in the first hour: a model callable that needs a column it was not
given, one bad spec, the messages they get."""

from __future__ import annotations

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
model: {callable: "usermodel:simulate"%s}
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
    _write(pytester.path, inputs=", inputs: [speed, heater_kw]")
    pytester.runpytest("--hevval", "--hevval-no-history").assert_outcomes(passed=3)


def test_one_bad_spec_prints_its_error_once(pytester: pytest.Pytester) -> None:
    _write(pytester.path)
    result = pytester.runpytest("--hevval", "--hevval-no-history")
    text = result.stdout.str()
    assert text.count("the model asked for the column 'heater_kw'") == 1
    assert "During handling of the above exception" not in text
    assert text.count("not scored: the error of trip.hevval.yaml::v (above) stops this spec") == 2


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
    _write(pytester.path, inputs=", inputs: [speed, heater_kw]")
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
    _write(pytester.path, inputs=", inputs: [speed, heater_kw]")
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
