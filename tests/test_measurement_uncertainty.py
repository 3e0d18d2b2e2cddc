"""Measurement uncertainty: the rule, the spec keys and their errors, and the plugin end to end."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pytest_hevval.core.measurement import MeasurementUncertainty, error_limit
from pytest_hevval.defaults import UNCERTAINTY_SIGMA, WITHIN_UNCERTAINTY
from pytest_hevval.errors import SpecError
from pytest_hevval.report import model as report_model
from pytest_hevval.report.sentences import failure_sentence, within_uncertainty_lines
from pytest_hevval.report.text import render_markdown
from pytest_hevval.results.measurement import ErrorCheck, check_error
from pytest_hevval.results.spec_result import Failure, SignalResult, SpecResult
from pytest_hevval.spec.load import parse_spec_text

pytest_plugins = ["pytester"]

# -- the rule ----------------------------------------------------------------------------------


def test_expanded_uncertainty_is_the_root_sum_square_of_abs_and_rel_times_reference_rms() -> None:
    declared = MeasurementUncertainty(abs=0.3, rel=0.01, sigma=2.0)
    # RMS(y_ref) = 40 → rel part 0.4; √(0.3² + 0.4²) = 0.5 at 2σ, so u_D = 0.25.
    assert declared.expanded(40.0) == pytest.approx(0.5)
    assert declared.standard(40.0) == pytest.approx(0.25)
    # A figure stated at 1σ is the standard uncertainty itself.
    assert MeasurementUncertainty(abs=0.3, sigma=1.0).standard(0.0) == pytest.approx(0.3)
    # The sign of the reading does not matter.
    assert declared.expanded(-40.0) == pytest.approx(0.5)


def test_limit_and_margin_are_in_the_signal_unit() -> None:
    assert error_limit(0.95, 20.0) == pytest.approx(1.0)
    check = check_error(1.23, 0.95, 20.0)
    assert check.limit == pytest.approx(1.0)
    assert check.margin == pytest.approx(0.23)
    assert check.uncertainty is None
    assert check.within is None


@pytest.mark.parametrize(
    ("abs_", "within"),
    [(0.30, True), (0.23, True), (0.22, False), (0.0, False)],
)
def test_a_miss_is_within_when_its_margin_is_at_most_the_expanded_uncertainty(
    abs_: float, within: bool
) -> None:
    # Limit (1 − 0.95)·20 = 1.0; error 1.23: margin 0.23.
    check = check_error(1.23, 0.95, 20.0, MeasurementUncertainty(abs=abs_), 0.0)
    assert check.margin == pytest.approx(0.23)
    assert check.uncertainty == pytest.approx(abs_)
    assert check.within is within


def test_default_basis_is_two_sigma() -> None:
    assert UNCERTAINTY_SIGMA == 2.0
    assert WITHIN_UNCERTAINTY == "fail"
    check = check_error(1.1, 0.95, 20.0, MeasurementUncertainty(abs=0.2), 0.0)
    assert check.sigma == 2.0
    assert check.standard_uncertainty == pytest.approx(0.1)


def test_failure_sentence_gives_the_margin_and_the_verdict() -> None:
    check = check_error(1.23, 0.95, 20.4, MeasurementUncertainty(abs=0.3, sigma=2), 0.0)
    text = failure_sentence("λ4 RMS", "rms", 0.9397, 0.95, check, "kW")
    assert text == (
        "λ4 RMS = 0.9397 < 0.95: RMS 1.23 kW is 0.21 kW over its limit 1.02 kW; "
        "measurement uncertainty ±0.3 kW (2σ): within measurement uncertainty"
    )
    beyond = check_error(1.23, 0.95, 20.4, MeasurementUncertainty(abs=0.1, sigma=3), 0.0)
    assert failure_sentence("λ3 MAE", "mae", 0.9397, 0.95, beyond, None).endswith(
        "MAE 1.23 is 0.21 over its limit 1.02; measurement uncertainty ±0.1 (3σ): "
        "beyond measurement uncertainty"
    )


def test_the_rule_bounds_what_a_sensor_error_can_do_to_rms_and_mae() -> None:
    """The basis of the rule: a reference error δ moves RMS and MAE by at most RMS(δ)."""
    rng = np.random.default_rng(3)
    error = rng.normal(0.4, 1.0, 5000)
    for delta in (np.full(5000, 0.3), rng.normal(0, 0.3, 5000), 0.01 * rng.normal(50, 5, 5000)):
        bound = math.sqrt(float(np.mean(delta**2)))
        shifted = error + delta
        rms_shift = abs(np.sqrt(np.mean(shifted**2)) - np.sqrt(np.mean(error**2)))
        mae_shift = abs(np.mean(np.abs(shifted)) - np.mean(np.abs(error)))
        assert rms_shift <= bound + 1e-12
        assert mae_shift <= bound + 1e-12


def test_failure_round_trips_and_old_records_load() -> None:
    check = check_error(1.23, 0.95, 20.4, MeasurementUncertainty(abs=0.3, rel=0.01), 10.0)
    failure = Failure("rms", 0.9397, 0.95, check)
    data = json.loads(json.dumps(failure.to_dict()))
    assert data["measurement"]["within"] is True
    back = Failure.from_dict(data)
    assert back == failure
    assert back.within_uncertainty
    old = Failure.from_dict({"characteristic": "mae", "value": 0.8, "threshold": 0.9})
    assert old.check is None
    assert not old.within_uncertainty
    assert "measurement" not in old.to_dict()
    assert ErrorCheck.from_dict(check.to_dict()) == check


# -- the spec ----------------------------------------------------------------------------------

MINIMAL = """\
reference: {path: ref.csv, time: t}
model: {path: sim.csv, time: t}
sets:
  - signal: P
    unit: kW
    uncertainty: UNCERTAINTY
"""


def _parse(uncertainty: str, extra: str = "") -> object:
    text = MINIMAL.replace("UNCERTAINTY", uncertainty) + extra
    return parse_spec_text(text, Path("/p/t.hevval.yaml"))


def test_uncertainty_and_measurement_keys_load() -> None:
    spec = _parse("{abs: 0.5, rel: 0.01, sigma: 3}", "measurement: {within_uncertainty: pass}\n")
    node = spec.sets[0]  # type: ignore[attr-defined]
    assert node.uncertainty == MeasurementUncertainty(abs=0.5, rel=0.01, sigma=3.0, line=6)
    assert spec.measurement.within_uncertainty == "pass"  # type: ignore[attr-defined]
    plain = _parse("{rel: 0.02}")
    assert plain.sets[0].uncertainty.sigma == UNCERTAINTY_SIGMA  # type: ignore[attr-defined]
    assert plain.sets[0].uncertainty.abs == 0.0  # type: ignore[attr-defined]
    assert plain.measurement.within_uncertainty == "fail"  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("uncertainty", "extra", "message"),
    [
        (
            "{abs: -0.5}",
            "",
            "/p/t.hevval.yaml:6: sets[0].uncertainty.abs: must be 0 or more (got -0.5); give "
            "the sensor's absolute accuracy in the signal's unit, e.g. abs: 0.5",
        ),
        (
            "{rel: one percent}",
            "",
            "/p/t.hevval.yaml:6: sets[0].uncertainty.rel: must be a number (got 'one percent'); "
            "give the accuracy as a fraction of the reading, e.g. rel: 0.01 for 1 %",
        ),
        (
            "{rel: 1.5}",
            "",
            "/p/t.hevval.yaml:6: sets[0].uncertainty.rel: must be a fraction of the reading "
            "below 1 (got 1.5); write 1 % as rel: 0.01",
        ),
        (
            "{abs: 0.5, sigma: 0}",
            "",
            "/p/t.hevval.yaml:6: sets[0].uncertainty.sigma: must be greater than 0 (got 0); "
            "give the coverage factor the figures are stated at, e.g. sigma: 2 for ±2σ",
        ),
        (
            "{abs: 0.5, rell: 0.01}",
            "",
            "/p/t.hevval.yaml:6: sets[0].uncertainty.rell: unknown key; did you mean 'rel'?",
        ),
        (
            "{sigma: 2}",
            "",
            "/p/t.hevval.yaml:6: sets[0].uncertainty: needs abs (in the signal's unit), rel (a "
            "fraction of the reading) or both; write e.g. uncertainty: {abs: 0.5, rel: 0.01, "
            "sigma: 2} for ±(0.5 + 1 %) at 2σ",
        ),
        (
            "0.5",
            "",
            "/p/t.hevval.yaml:6: sets[0].uncertainty: must be a mapping of keys to values "
            "(got 0.5)",
        ),
        (
            "{abs: 0.5}",
            "measurement: {within_uncertainty: ignore}\n",
            "/p/t.hevval.yaml:7: measurement.within_uncertainty: must be one of fail, pass "
            "(got 'ignore')",
        ),
        (
            "{abs: 0.5}",
            "measurement: {within: pass}\n",
            "/p/t.hevval.yaml:7: measurement.within: unknown key; allowed keys: within_uncertainty",
        ),
    ],
)
def test_bad_uncertainty_is_a_spec_error_with_what_to_do(
    uncertainty: str, extra: str, message: str
) -> None:
    with pytest.raises(SpecError) as info:
        _parse(uncertainty, extra)
    assert str(info.value) == message


# -- reports on plain result data --------------------------------------------------------------


def _signal_dict(within: list[Failure], failures: list[Failure]) -> dict[str, object]:
    return {
        "path": "P",
        "name": "P",
        "set": 1,
        "level": 1,
        "alpha": 1.0,
        "unit": "kW",
        "lambdas": {"mae": 0.97, "rms": 0.9397},
        "thresholds": {"rms": 0.95},
        "failures": [f.to_dict() for f in failures],
        "within_uncertainty": [f.to_dict() for f in within],
        "passed": not failures,
        **{"lag_s": 0.0, "peak_correlation": 1.0, "mae": 1.0, "rms": 1.23},
    }


def test_report_model_marks_a_passing_miss_within_uncertainty() -> None:
    check = check_error(1.23, 0.95, 20.4, MeasurementUncertainty(abs=0.3), 0.0)
    data = _signal_dict([Failure("rms", 0.9397, 0.95, check)], [])
    signal = SignalResult.from_dict(data)
    statuses = {c.characteristic: c.status for c in report_model.cells(signal)}
    assert statuses["rms"] == "within"
    (line,) = report_model.measurement_lines(signal)
    assert line.endswith("within measurement uncertainty; passes")
    result = {"name": "power", "spec": "p.hevval.yaml", "phi": 1.0, "signals": [data]}
    markdown = render_markdown([SpecResult.from_dict(result)])
    assert "**Measurement uncertainty of power**" in markdown
    assert "RMS 1.23 kW is 0.21 kW over its limit 1.02 kW" in markdown


def test_signal_result_keeps_the_note_through_json() -> None:
    from pytest_hevval.core.characteristics import signal_characteristics

    t = np.arange(0.0, 60.0, 0.1)
    ref = 10 + np.sin(t)
    chars = signal_characteristics(ref, ref + 0.05, dt=0.1)
    check = check_error(chars.rms, 0.99, chars.reference_range, MeasurementUncertainty(abs=1), 0)
    signal = SignalResult(
        path="P",
        name="P",
        set=1,
        level=1,
        position=1,
        alpha=1.0,
        line=4,
        lambdas=chars.values,
        characteristics=chars,
        thresholds={"rms": 0.99},
        failures=[],
        unit="kW",
        within_uncertainty=[Failure("rms", chars.lambda_rms, 0.99, check)],
    )
    data = json.loads(json.dumps(signal.to_dict()))
    back = SignalResult.from_dict(data)
    assert back.passed
    assert back.within_uncertainty == signal.within_uncertainty
    assert within_uncertainty_lines(back) == within_uncertainty_lines(signal)
    del data["within_uncertainty"]
    assert SignalResult.from_dict(data).within_uncertainty == []


# -- end to end --------------------------------------------------------------------------------

SPEC = """\
name: power
reference: {path: ref.csv, time: t}
model: {path: sim.csv, time: t}
thresholds: {rms: 0.98}
MEASUREMENT
sets:
  - signal: P
    unit: kW
    uncertainty: {abs: ABS, sigma: 2}
  - signal: speed
    unit: km/h
"""


def _project(pytester: pytest.Pytester, abs_: float, measurement: str = "") -> None:
    """Power with a constant 1 kW model error over a 40 kW range: λ4 = 0.975 < 0.98.

    The limit is (1 − 0.98)·40 = 0.8 kW, so the error is 0.2 kW over it.
    """
    t = np.arange(0.0, 120.0, 0.1)
    power = 100 + 20 * np.sin(t / 5)
    speed = 40 + 30 * np.sin(t / 20)
    pd.DataFrame({"t": t, "P": power, "speed": speed}).to_csv(
        pytester.path / "ref.csv", index=False
    )
    pd.DataFrame({"t": t, "P": power + 1.0, "speed": speed}).to_csv(
        pytester.path / "sim.csv", index=False
    )
    text = SPEC.replace("ABS", str(abs_)).replace("MEASUREMENT", measurement)
    pytester.makefile(".hevval.yaml", power=text)


XDIST = [pytest.param([], id="serial"), pytest.param(["-p", "xdist", "-n", "2"], id="xdist")]


@pytest.mark.parametrize("extra", XDIST)
def test_a_miss_within_uncertainty_fails_by_default_and_says_so(
    pytester: pytest.Pytester, extra: list[str]
) -> None:
    _project(pytester, 0.3)
    result = pytester.runpytest("--hevval", "--hevval-no-history", *extra)
    result.assert_outcomes(passed=2, failed=1)
    result.stdout.fnmatch_lines(
        [
            "P missed its thresholds (power.hevval.yaml:7)",
            "  λ4 RMS = 0.9750 < 0.98: RMS 1 kW is 0.2 kW over its limit 0.8 kW; "
            "measurement uncertainty ±0.3 kW (2σ): within measurement uncertainty",
        ]
    )
    result.stdout.fnmatch_lines(["*✗ P [[]P[]] rms 0.9750<0.98 (within measurement uncertainty)*"])


@pytest.mark.parametrize("extra", XDIST)
def test_a_miss_within_uncertainty_passes_when_the_spec_says_so(
    pytester: pytest.Pytester, extra: list[str]
) -> None:
    _project(pytester, 0.3, "measurement: {within_uncertainty: pass}")
    result = pytester.runpytest(
        "--hevval", "--hevval-no-history", "--hevval-report=json", "-rA", *extra
    )
    result.assert_outcomes(passed=3)
    result.stdout.fnmatch_lines(
        [
            "*hevval validation summary*",
            "power: Φ = * PASS*",
            "    ✓ P [[]P[]] rms 0.9750<0.98 (within measurement uncertainty)",
            "        note: λ4 RMS = 0.9750 < 0.98: RMS 1 kW is 0.2 kW over its limit 0.8 kW; "
            "measurement uncertainty ±0.3 kW (2σ): within measurement uncertainty; passes by "
            "measurement.within_uncertainty: pass",
            "  all 2 signals pass",
        ]
    )
    report = json.loads((pytester.path / ".hevval" / "report" / "report.json").read_text())
    (signal,) = [s for s in report["specs"][0]["signals"] if s["path"] == "P"]
    assert signal["passed"] is True
    assert signal["failures"] == []
    (note,) = signal["within_uncertainty"]
    assert note["characteristic"] == "rms"
    assert note["measurement"]["within"] is True
    assert note["measurement"]["margin"] == pytest.approx(0.2, abs=1e-3)
    assert note["measurement"]["uncertainty"] == pytest.approx(0.3)


@pytest.mark.parametrize("extra", XDIST)
def test_a_miss_beyond_uncertainty_fails_even_with_the_pass_setting(
    pytester: pytest.Pytester, extra: list[str]
) -> None:
    _project(pytester, 0.1, "measurement: {within_uncertainty: pass}")
    result = pytester.runpytest("--hevval", "--hevval-no-history", *extra)
    result.assert_outcomes(passed=2, failed=1)
    result.stdout.fnmatch_lines(
        [
            "*RMS 1 kW is 0.2 kW over its limit 0.8 kW; measurement uncertainty ±0.1 kW (2σ): "
            "beyond measurement uncertainty"
        ]
    )


def test_hevval_run_prints_the_note(
    pytester: pytest.Pytester, capsys: pytest.CaptureFixture[str]
) -> None:
    _project(pytester, 0.3, "measurement: {within_uncertainty: pass}")
    from pytest_hevval.cli import main

    code = main(["run", str(pytester.path / "power.hevval.yaml"), "--no-history", "--quiet"])
    assert code == 0
    out = capsys.readouterr().out
    assert "✓ P [P] rms 0.9750<0.98 (within measurement uncertainty)" in out
    assert "note: λ4 RMS = 0.9750 < 0.98: RMS 1 kW is 0.2 kW over its limit 0.8 kW" in out
