"""The model's runtime: measured where a callable runs, shown, recorded, gated from the spec
and compared across runs with the noise rule."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pytest_hevval.cli import main
from pytest_hevval.errors import SpecError
from pytest_hevval.history.runtime_changes import runtime_change_lines, runtime_changes
from pytest_hevval.results.runtime import (
    RUNTIME_MIN_GROWTH_S,
    RUNTIME_SLOWDOWN,
    ModelRuntime,
    RuntimeGate,
)
from pytest_hevval.spec.load import parse_spec_text
from tests.recorded_runs import recorded
from tests.strategies import call_times
from tests.test_plugin import write_data

pytest_plugins = ["pytester"]

#: A model that computes for ``seconds`` of CPU time per call, then returns the measured
#: voltage, current and speed as they are.
MODEL = """\
import time


def simulate(frame, seconds=0.0):
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass
    return frame.rename(columns={"t": "time"})
"""

SPEC = """\
name: timed
reference: {path: data/ref.csv, time: t}
model:
  callable: "slow_model:simulate"
  params: {seconds: SECONDS}
  driven_by: [V, I, speed]
thresholds: {mae: 0.9}
RUNTIME
sets:
  - {signal: V}
  - {signal: I}
  - {signal: speed}
"""


def _spec(seconds: float, runtime: str = "") -> str:
    return SPEC.replace("SECONDS", str(seconds)).replace("RUNTIME", runtime)


@pytest.fixture
def timed(pytester: pytest.Pytester) -> pytest.Pytester:
    write_data(pytester.path)
    (pytester.path / "slow_model.py").write_text(MODEL)
    return pytester


def test_runtime_keys_are_read_and_checked() -> None:
    spec = parse_spec_text(
        _spec(0, "runtime: {min_realtime_factor: 50, max_s: 2, repeat: 3}"), Path("t.hevval.yaml")
    )
    assert (spec.runtime.min_realtime_factor, spec.runtime.max_s, spec.runtime.repeat) == (50, 2, 3)
    assert spec.runtime.gated
    assert spec.runtime.line == 8
    with pytest.raises(SpecError, match=r"t.hevval.yaml:8: runtime.repeat: must be a whole"):
        parse_spec_text(_spec(0, "runtime: {repeat: 2.5}"), Path("t.hevval.yaml"))
    with pytest.raises(SpecError, match=r"t.hevval.yaml:8: runtime.max_s: must be greater than 0"):
        parse_spec_text(_spec(0, "runtime: {max_s: 0}"), Path("t.hevval.yaml"))
    exported = _spec(0, "runtime: {max_s: 1}").replace(
        'callable: "slow_model:simulate"\n  params: {seconds: 0}\n  driven_by: [V, I, speed]',
        "path: data/sim.csv",
    )
    with pytest.raises(SpecError) as raised:
        parse_spec_text(exported, Path("t.hevval.yaml"))
    assert str(raised.value).startswith(
        "t.hevval.yaml:6: runtime: the model is exported files, which ran elsewhere and carry "
        "no runtime to measure"
    )


def test_runtime_is_measured_reported_recorded_and_gated(timed: pytest.Pytester) -> None:
    # 120 s of record in 0.2 s of CPU a call: a real-time factor of about 600, far below 10⁵.
    timed.makefile(
        ".hevval.yaml",
        timed=_spec(0.2, "runtime: {min_realtime_factor: 100000, max_s: 60, repeat: 2}"),
    )
    result = timed.runpytest(
        "--hevval", "--hevval-history", "--hevval-report=json,md,html", "--junitxml=out.xml"
    )
    result.assert_outcomes(passed=4, failed=1)
    result.stdout.fnmatch_lines(
        [
            "*the model's runtime missed its gate (timed.hevval.yaml:8)",
            "*real-time factor (cpu) * < 100000 (119.9 s simulated in 0.2* s of CPU time, the "
            "fastest of 2 calls)",
        ]
    )
    assert "1 of 1 runtime gate" in result.stdout.str()
    report = timed.path / ".hevval" / "report"
    runtime = json.loads((report / "report.json").read_text())["specs"][0]["runtime"]
    assert len(runtime["wall_s"]) == 2
    assert min(runtime["cpu_s"]) >= 0.2
    # The model computes for 0.2 s on one thread, so its wall time holds at least that; the
    # process's CPU time can exceed the wall clock by what other threads (BLAS) add meanwhile.
    assert min(runtime["wall_s"]) >= 0.2
    assert runtime["simulated_s"] == pytest.approx(119.9)
    assert runtime["passed"] is False
    assert "real-time factor" in (report / "report.md").read_text()
    assert "gate: real-time factor" in (report / "report.html").read_text()
    [record] = (timed.path / ".hevval" / "history").glob("*.json")
    assert json.loads(record.read_text())["specs"][0]["runtime"]["wall_s"] == runtime["wall_s"]
    case = next(
        c for c in ET.parse(timed.path / "out.xml").iter("testcase") if c.get("name") == "runtime"
    )
    properties = {p.get("name"): p.get("value") for p in case.iter("property")}
    assert float(properties["realtime_factor"]) < 1000
    phi = next(
        c for c in ET.parse(timed.path / "out.xml").iter("testcase") if c.get("name") == "Phi"
    )
    assert (
        float(next(p.get("value") for p in phi.iter("property") if p.get("name") == "model_cpu_s"))
        >= 0.2
    )
    assert case.find("failure") is not None


def test_a_model_three_times_slower_is_a_runtime_regression(
    timed: pytest.Pytester, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    timed.makefile(".hevval.yaml", timed=_spec(0.1, "runtime: {repeat: 3}"))
    timed.runpytest("--hevval", "--hevval-history", "--hevval-model-version=v1")
    timed.makefile(".hevval.yaml", timed=_spec(0.3, "runtime: {repeat: 3}"))
    timed.runpytest("--hevval", "--hevval-history", "--hevval-model-version=v2")
    monkeypatch.chdir(timed.path)
    capsys.readouterr()
    assert main(["compare", "history:v1", "history:v2"]) == 0
    out = capsys.readouterr().out
    assert "model runtime timed.hevval.yaml (v1 → v2):" in out
    assert "RUNTIME REGRESSION" in out
    assert main(["compare", "history:v1", "history:v2", "--compare-fail", "phi:0.5"]) == 1
    capsys.readouterr()
    assert main(["compare", "history:v1", "history:v2", "--format", "json"]) == 0
    [change] = json.loads(capsys.readouterr().out)["runtime"]
    assert change["regression"] is True
    assert change["ratio"] > 2


def test_exported_files_say_they_carry_no_runtime(pytester: pytest.Pytester) -> None:
    from tests.test_plugin import TREE_SPEC

    pytester.makefile(".hevval.yaml", pack=TREE_SPEC)
    write_data(pytester.path)
    pytester.runpytest("--hevval", "--hevval-report=json,md")
    report = pytester.path / ".hevval" / "report"
    assert "runtime" not in json.loads((report / "report.json").read_text())["specs"][0]
    assert (
        "none (the model is exported files: it ran elsewhere)" in (report / "report.md").read_text()
    )


def _runtime(walls: list[float], simulated: float = 100.0) -> ModelRuntime:
    return ModelRuntime(
        kind="callable", simulated_s=simulated, wall_s=tuple(walls), cpu_s=tuple(walls)
    )


def _result(spec: str, runtime: ModelRuntime) -> dict[str, object]:
    return {"spec": spec, "runtime": runtime.to_dict()}


@given(call_times, call_times, st.floats(0.5, 3.0))
def test_the_rule_judges_the_fastest_calls_cpu_and_not_the_wall_clock(
    before: list[float], wall: list[float], work: float
) -> None:
    # The new model does `work` times the CPU work; its wall times are anything at all (load).
    after = ModelRuntime(
        kind="callable",
        simulated_s=100.0,
        wall_s=tuple(wall),
        cpu_s=tuple(c * work for c in before),
    )
    [change] = runtime_changes(
        recorded([_result("a.hevval.yaml", _runtime(before))]),
        recorded([_result("a.hevval.yaml", after)]),
    )
    assert change.ratio == pytest.approx(work)
    grown = min(before) * work - min(before)
    assert change.regression == (
        min(before) * work > RUNTIME_SLOWDOWN * min(before) and grown >= RUNTIME_MIN_GROWTH_S
    )


def test_a_few_hundredths_of_a_second_more_is_not_a_runtime_regression() -> None:
    """A 25 ms model timed at 48 ms under load is the machine's noise, said so."""
    [change] = runtime_changes(
        recorded([_result("a.hevval.yaml", _runtime([0.025]))]),
        recorded([_result("a.hevval.yaml", _runtime([0.048]))]),
    )
    assert change.ratio > RUNTIME_SLOWDOWN
    assert not change.regression
    (line,) = runtime_change_lines([change], "v1", "v2")
    assert "within the machine's noise; not a regression" in line


@given(call_times)
def test_runtime_round_trips_through_json(calls: list[float]) -> None:
    runtime = ModelRuntime(
        kind="fmu",
        simulated_s=10.0,
        wall_s=tuple(calls),
        cpu_s=tuple(calls),
        peak_memory_bytes=1024,
        steps=7,
        events=2,
        gate=RuntimeGate(min_realtime_factor=2.0, max_s=None),
    )
    again = ModelRuntime.from_dict(json.loads(json.dumps(runtime.to_dict())))
    assert again == runtime
    assert again.passed == (10.0 / min(calls) >= 2.0)
    wall_gate = ModelRuntime(
        kind="callable",
        simulated_s=10.0,
        wall_s=(5.0,),
        cpu_s=(1.0,),
        gate=RuntimeGate(max_s=2.0, clock="wall"),
    )
    assert wall_gate.failures() == ["model call 5 s of wall time > max 2 s (the fastest of 1 call)"]


def test_an_fmu_run_reports_its_cost_steps_and_guid(tmp_path: Path) -> None:
    from pytest_hevval.data.fmu import run_fmu
    from tests.test_fmu import GAIN, _build, _reference

    record = run_fmu(
        _build(tmp_path, "Gain", GAIN),
        _reference(),
        inputs={"u": "throttle"},
        outputs={"y_sim": "y"},
        start_time=0.0,
        stop_time=2.0,
        step_size=0.01,
    )
    assert record.meta["cost"].wall_s > 0
    # Two seconds in communication steps of 0.01 s; a co-simulation FMU reports no events.
    assert record.meta["steps"] == 200
    assert "events" not in record.meta
    assert len(record.meta["guid"]) > 8


def test_the_runtime_item_under_xdist(timed: pytest.Pytester) -> None:
    timed.makefile(".hevval.yaml", timed=_spec(0.05, "runtime: {min_realtime_factor: 100000}"))
    result = timed.runpytest("--hevval", "-p", "xdist", "-n", "2")
    result.assert_outcomes(passed=4, failed=1)
    result.stdout.fnmatch_lines(["*FAILED timed.hevval.yaml::runtime*"])
