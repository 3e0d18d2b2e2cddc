"""Campaigns: one spec over many recordings, their items, roles, gate and u-pooling."""

from __future__ import annotations

import importlib.util
import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pytest_hevval.core.uncertainty import Interval
from pytest_hevval.core.upooling import (
    U_GRID,
    area_to_uniform,
    pool,
    u_distribution,
    u_distribution_of,
    u_values,
)
from pytest_hevval.errors import SpecError
from pytest_hevval.report.terminal import verdict_lines
from pytest_hevval.results.campaign import (
    CampaignVerdict,
    Distribution,
    RecordingOutcome,
)
from pytest_hevval.scoring.engine import DataCache, Evaluation
from pytest_hevval.scoring.run import RunOptions, run_specs
from pytest_hevval.spec.load import load_specs, parse_spec_text
from tests.recorded_runs import recorded

from .strategies import finite

pytest_plugins = ["pytester"]

MODEL = """\
import pandas as pd


def run(frame, gain=1.0):
    speed = frame["speed"]
    return pd.DataFrame({"time": frame["t"], "speed": speed, "P": 2.0 * speed * gain})
"""

SPEC = """\
name: fleet
reference: {{path: data/Trip*.csv, time: t}}
model: {{callable: "campaign_model:run", driven_by: [speed]}}
recordings:
  - {{id: Trip01, role: calibration}}
  - {{id: Trip03, params: {{gain: {gain}}}}}
campaign: {{min_pass_rate: {rate}, phi_quantile: {{q: 0.25, min: 0.5}}}}
thresholds: {{mae: 0.95}}
min_phi: 0.95
sets:
  - {{signal: P, ref: P, sim: P}}
  - {{signal: speed, ref: speed, sim: speed}}
"""

TRIPS = ("Trip01", "Trip02", "Trip03", "Trip04")


def write_campaign(root: Path, *, gain: float = 1.0, rate: float = 0.6) -> None:
    """Four trips at different speeds; the model is exact unless a recording's gain is off."""
    (root / "data").mkdir(exist_ok=True)
    t = np.arange(0.0, 60.0, 0.1)
    for number, trip in enumerate(TRIPS, start=1):
        speed = 20.0 * number + 10.0 * np.sin(t / (3.0 + number))
        power = 2.0 * speed + np.random.default_rng(number).normal(0.0, 0.1, t.size)
        frame = pd.DataFrame({"t": t, "speed": speed, "P": power})
        frame.to_csv(root / "data" / f"{trip}.csv", index=False)
    (root / "campaign_model.py").write_text(MODEL)
    (root / "fleet.hevval.yaml").write_text(SPEC.format(gain=gain, rate=rate))


@pytest.fixture
def project(pytester: pytest.Pytester) -> pytest.Pytester:
    return pytester


def hevval_run(project: pytest.Pytester, *args: str) -> pytest.RunResult:
    """``hevval run fleet.hevval.yaml --no-history ARGS`` in a child process."""
    return project.run(
        sys.executable, "-m", "pytest_hevval", "run", "fleet.hevval.yaml", "--no-history", *args
    )


# -- memory -----------------------------------------------------------------------------------


def test_a_recordings_data_are_let_go_once_it_is_scored(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A campaign of thousands of recordings holds the data of the one being scored, not of
    every recording scored so far; each file is still read once."""
    write_campaign(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    specs = load_specs(tmp_path / "fleet.hevval.yaml")
    cache = DataCache()
    held: list[list[str]] = []
    outcomes = run_specs(
        specs,
        RunOptions(rootdir=tmp_path),
        cache=cache,
        progress=lambda _: held.append(cache.held()),
    )
    assert all(isinstance(outcome, Evaluation) for outcome in outcomes)
    assert held == [[] for _ in TRIPS]
    assert sorted(Path(path).name for path in cache.reads) == [f"{t}.csv" for t in sorted(TRIPS)]
    assert set(cache.reads.values()) == {1}


def test_a_file_two_specs_declare_is_read_once_and_let_go_after_both(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    write_campaign(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    first = load_specs(tmp_path / "fleet.hevval.yaml")
    second = load_specs(tmp_path / "fleet.hevval.yaml")
    cache = DataCache()
    for spec in [*first, *second]:
        cache.declare_spec(spec)
    options = RunOptions(rootdir=tmp_path)
    run_specs(first, options, cache=cache)
    for spec in first:
        cache.release_spec(spec)
    # Every file is still declared by a spec of the second campaign: kept, not read again.
    assert len(cache.held()) == len(TRIPS)
    run_specs(second, options, cache=cache)
    assert set(cache.reads.values()) == {1}
    for spec in second:
        cache.release_spec(spec)
    assert cache.held() == []


# -- pytest items, end to end -----------------------------------------------------------------


def test_items_per_recording_and_a_campaign_item(project: pytest.Pytester) -> None:
    write_campaign(project.path)
    result = project.runpytest("--hevval", "--hevval-no-history", "--collect-only", "-q")
    ids = [line for line in result.stdout.lines if line.startswith("fleet.hevval.yaml::")]
    assert "fleet.hevval.yaml::Trip03::speed" in ids
    assert "fleet.hevval.yaml::Trip04::Phi" in ids
    assert ids[-1] == "fleet.hevval.yaml::campaign"
    assert len(ids) == 4 * 3 + 1


def test_a_recording_that_fails_is_its_own_items_failure(project: pytest.Pytester) -> None:
    # Trip03's model parameters make its power 40 % high; the other recordings pass.
    write_campaign(project.path, gain=1.4)
    result = project.runpytest("--hevval", "--hevval-no-history")
    result.assert_outcomes(passed=11, failed=2)
    result.stdout.fnmatch_lines(
        [
            "campaign fleet.hevval.yaml (fleet): PASS, 2 of 3 validation recordings pass*",
            "  excluded from the gate (calibration): Trip01",
            "  worst recordings: Trip03 Φ * FAIL, *",
            "FAILED fleet.hevval.yaml::Trip03::P*",
            "FAILED fleet.hevval.yaml::Trip03::Phi*",
        ]
    )
    assert "P missed its thresholds (fleet.hevval.yaml:11 (recording Trip03))" in (
        result.stdout.str()
    )


def test_campaign_gate_fails_below_min_pass_rate(project: pytest.Pytester) -> None:
    write_campaign(project.path, gain=1.4, rate=0.9)
    result = project.runpytest("--hevval", "--hevval-no-history")
    result.assert_outcomes(passed=10, failed=3)
    result.stdout.fnmatch_lines(
        [
            "*gate: pass rate 67% < min_pass_rate 90% (2 of 3 validation recordings pass;"
            " failing: Trip03)",
            "FAILED fleet.hevval.yaml::campaign*",
        ]
    )


def test_calibration_recording_never_counts(project: pytest.Pytester) -> None:
    write_campaign(project.path, rate=1.0)
    spec = project.path / "fleet.hevval.yaml"
    # The fitted-on trip is the one the model misses: it fails its own items, but it is
    # excluded from the gate, so the campaign passes.
    spec.write_text(
        spec.read_text().replace(
            "{id: Trip01, role: calibration}",
            "{id: Trip01, role: calibration, params: {gain: 1.4}}",
        )
    )
    result = project.runpytest("--hevval", "--hevval-no-history")
    result.assert_outcomes(passed=11, failed=2)
    result.stdout.fnmatch_lines(["campaign fleet.hevval.yaml (fleet): PASS, 3 of 3*"])
    assert "FAILED fleet.hevval.yaml::Trip01::P" in result.stdout.str()


def test_same_outcomes_under_xdist_and_selection(project: pytest.Pytester) -> None:
    write_campaign(project.path, gain=1.4, rate=0.9)
    serial = project.runpytest("--hevval", "--hevval-no-history")
    parallel = project.runpytest("--hevval", "--hevval-no-history", "-p", "xdist", "-n", "2")
    assert serial.parseoutcomes() == parallel.parseoutcomes()
    parallel.stdout.fnmatch_lines(["campaign fleet.hevval.yaml (fleet): FAIL, 2 of 3*"])
    selected = project.runpytest("--hevval", "--hevval-no-history", "-k", "Trip03")
    selected.assert_outcomes(passed=1, failed=2)
    selected.stdout.fnmatch_lines(
        ["campaign fleet.hevval.yaml (fleet): FAIL (1 of 4 recordings scored)*"]
    )
    # --lf reruns the failed recording's items and the failed campaign item, nothing else.
    rerun = project.runpytest("--hevval", "--hevval-no-history", "--lf")
    rerun.assert_outcomes(failed=3)
    # A gate deselected with -k is not judged under xdist either (its recordings unscored).
    selected_parallel = project.runpytest(
        "--hevval", "--hevval-no-history", "-k", "Trip03", "-p", "xdist", "-n", "2"
    )
    selected_parallel.assert_outcomes(passed=1, failed=2)  # xdist does not count deselected
    assert "fleet.hevval.yaml::campaign" not in selected_parallel.stdout.str()


#: JUnit properties that time the model's calls.
TIMED_PROPERTIES = frozenset({"model_wall_s", "model_cpu_s", "realtime_factor"})


def test_recordings_spread_over_workers_and_the_gate_judges_them_all(
    project: pytest.Pytester,
) -> None:
    """Under -n 2 each worker scores whole recordings (a recording's items stay together, so
    its file is read once) and the campaign item, judged once every recording is in, fails
    the run as it does serially, in the terminal and in JUnit XML."""
    write_campaign(project.path, gain=1.4, rate=0.9)
    result = project.runpytest(
        "--hevval", "--hevval-no-history", "-p", "xdist", "-n", "2", "-v", "--junitxml=out.xml"
    )
    result.assert_outcomes(passed=10, failed=3)
    workers: dict[str, set[str]] = {}
    for line in result.stdout.lines:
        if line.startswith("[gw") and "::Trip" in line:
            worker, _, rest = line.partition("]")
            recording = rest.split("::")[1]
            workers.setdefault(recording, set()).add(worker)
    assert set(workers) == set(TRIPS)
    assert all(len(found) == 1 for found in workers.values()), workers
    assert len(set().union(*workers.values())) == 2
    result.stdout.fnmatch_lines(["FAILED fleet.hevval.yaml::campaign*"])
    xml = (project.path / "out.xml").read_text()
    assert 'name="campaign"' in xml
    assert "pass_rate" in xml
    # Each recording's items are judged by one of them on its worker and reported by the
    # controller: the same items, outcomes, texts and properties as a serial run.
    project.runpytest("--hevval", "--hevval-no-history", "--junitxml=serial.xml")

    def cases(name: str) -> dict[str, dict[str, str | None]]:
        tree = ET.parse(project.path / name)
        return {
            f"{c.get('classname')}::{c.get('name')}": {
                **{
                    p.get("name", ""): p.get("value")
                    for p in c.iter("property")
                    # What the model's calls cost differs between any two runs.
                    if p.get("name") not in TIMED_PROPERTIES
                },
                "failure": next((f.get("message") for f in c.iter("failure")), None),
            }
            for c in tree.iter("testcase")
        }

    assert len(cases("serial.xml")) == 13
    assert cases("serial.xml") == cases("out.xml")


def test_one_count_in_pytest_the_summary_and_the_reports(project: pytest.Pytester) -> None:
    write_campaign(project.path, gain=1.4, rate=0.9)
    result = project.runpytest("--hevval", "--hevval-no-history", "--hevval-report=md,json")
    outcomes = result.parseoutcomes()
    line = "1 spec file, 0 pass; 13 items, 3 fail: 1 of 8 signals, 1 of 4 Φ, 1 of 1 campaign gate"
    assert outcomes == {"passed": 10, "failed": 3}
    result.stdout.fnmatch_lines([line])
    report = project.path / ".hevval" / "report"
    assert (report / "report.md").read_text().startswith(f"### ❌ hevval: {line}\n")
    assert json.loads((report / "report.json").read_text())["summary"]["outcome"] == line


def test_cli_run_gives_the_campaign_verdict(project: pytest.Pytester) -> None:
    write_campaign(project.path, gain=1.4, rate=0.9)
    result = hevval_run(project, "--json", "out.json")
    assert result.ret == 1
    payload = json.loads((project.path / "out.json").read_text())
    (campaign,) = payload["campaigns"]
    assert campaign["excluded"] == ["Trip01"]
    assert campaign["pass_rate"] == pytest.approx(2 / 3)
    assert [r["id"] for r in campaign["recordings"]] == list(TRIPS)
    # Each recording's file is identified (xxh3_128 with the fast extra, else sampled BLAKE2b).
    assert all(r["hash"] and len(r["digest"]) >= 32 for r in campaign["recordings"])
    assert {s["spec"] for s in payload["specs"]} == {f"fleet.hevval.yaml::{t}" for t in TRIPS}


# -- the spec ---------------------------------------------------------------------------------


def _spec(tmp_path: Path, head: str) -> str:
    (tmp_path / "data").mkdir(exist_ok=True)
    for trip in ("TripA", "TripB"):
        (tmp_path / "data" / f"{trip}.csv").write_text("t,x\n0,1\n1,2\n")
    return head + "sets:\n  - {signal: x}\n"


GLOB_HEAD = "reference: {path: data/Trip*.csv, time: t}\nmodel: {callable: 'm:run'}\n"


def test_pattern_expands_to_one_spec_per_recording(tmp_path: Path) -> None:
    text = _spec(tmp_path, GLOB_HEAD + "recordings:\n  - {id: TripB, role: calibration}\n")
    (tmp_path / "c.hevval.yaml").write_text(text)
    specs = load_specs(tmp_path / "c.hevval.yaml")
    assert [(s.recording, s.role) for s in specs] == [
        ("TripA", "validation"),
        ("TripB", "calibration"),
    ]
    assert specs[1].reference.path == str((tmp_path / "data" / "TripB.csv").resolve())
    assert specs[0].key.endswith("c.hevval.yaml::TripA")
    (only,) = load_specs(f"{tmp_path / 'c.hevval.yaml'}::TripB")
    assert only.recording == "TripB"


def test_table_of_recordings_passes_parameters(tmp_path: Path) -> None:
    text = _spec(
        tmp_path,
        "reference: {time: t}\n"
        "model: {callable: 'm:run', params: {version: 2}}\n"
        "recordings:\n"
        "  - {path: data/TripA.csv, params: {ambient_c: 31}}\n"
        "  - {id: cold, path: data/TripB.csv, params: {ambient_c: -5, version: 1}}\n",
    )
    specs = parse_spec_text(text, tmp_path / "c.hevval.yaml").per_recording()
    assert [s.recording for s in specs] == ["TripA", "cold"]
    assert dict(specs[1].model.params) == {"version": 1, "ambient_c": -5}
    assert dict(specs[0].model.params) == {"version": 2, "ambient_c": 31}


@pytest.mark.parametrize(
    ("head", "line", "key", "message"),
    [
        (
            "reference: {path: data/Nothing*.csv, time: t}\nmodel: {callable: 'm:run'}\n",
            1,
            "reference.path",
            "the pattern matches no file (got 'data/Nothing*.csv')",
        ),
        (
            GLOB_HEAD + "recordings:\n  - {id: TripA, role: calibraton}\n",
            4,
            "recordings[0].role",
            "must be one of validation, calibration",
        ),
        (
            GLOB_HEAD + "recordings:\n  - {id: TripA}\n  - {id: TripA, role: calibration}\n",
            5,
            "recordings[1].id",
            "duplicate recording id 'TripA' (first listed at line 4)",
        ),
        (
            GLOB_HEAD + "recordings:\n  - {id: TripC}\n",
            4,
            "recordings[0].id",
            "no file matched by reference.path has this id",
        ),
        (
            "reference: {path: data/TripA.csv, time: t}\nmodel: {callable: 'm:run'}\n"
            "campaign: {min_pass_rate: 0.8}\n",
            3,
            "campaign",
            "gates a campaign, but the spec names a single recording",
        ),
        (
            "reference: {path: data/Trip*.csv, time: t}\nmodel: {path: data/TripA.csv}\n",
            2,
            "model.path",
            "names one file, but a campaign needs the model's output for each recording "
            "(recording 'TripA' has none)",
        ),
        (
            "reference: {path: data/TripA.csv, time: t}\nmodel: {path: 'sim/{id}.csv'}\n",
            2,
            "model.path",
            "has {id}, which each recording of a campaign fills in",
        ),
        (
            GLOB_HEAD + "recordings:\n  - {id: TripA, model: sim/a.csv}\n",
            4,
            "recordings.model",
            "names a model output file, but the spec's model is a callable",
        ),
        (
            "reference: {time: t}\nmodel: {path: sim/one.csv}\nrecordings:\n"
            "  - {path: data/TripA.csv, model: sim/a.csv}\n  - {path: data/TripB.csv}\n",
            2,
            "model.path",
            "(recording 'TripB' has none)",
        ),
        (
            "reference: {time: t}\nmodel: {callable: 'm:run'}\nrecordings:\n"
            "  - {path: data/TripA.csv}\n  - {path: data/TripA.csv}\n",
            5,
            "recordings[1].id",
            "duplicate recording id 'TripA'",
        ),
        (
            GLOB_HEAD + "campaign: {phi_quantile: {q: 0.1}}\n",
            3,
            "campaign.phi_quantile.min",
            "is required",
        ),
    ],
)
def test_bad_campaigns_are_spec_errors(
    tmp_path: Path, head: str, line: int, key: str, message: str
) -> None:
    path = tmp_path / "c.hevval.yaml"
    with pytest.raises(SpecError) as caught:
        parse_spec_text(_spec(tmp_path, head), path)
    error = caught.value
    assert (error.file, error.line, error.key) == (str(path), line, key)
    assert message in str(error)


def write_exported(root: Path, *, gain: float = 1.0, extra: str | None = "Trip99") -> None:
    """The campaign of :func:`write_campaign` with the model's runs exported to files, one per
    recording (as a Simulink or Dymola batch writes them), instead of a callable."""
    write_campaign(root, gain=gain)
    (root / "sim").mkdir(exist_ok=True)
    for trip in TRIPS:
        measured = pd.read_csv(root / "data" / f"{trip}.csv")
        scale = gain if trip == "Trip03" else 1.0
        exported = pd.DataFrame(
            {"time_s": measured["t"], "speed": measured["speed"]}
            | {"P": 2.0 * measured["speed"] * scale}
        )
        exported.to_csv(root / "sim" / f"{trip}.csv", index=False)
    if extra:
        exported.to_csv(root / "sim" / f"{extra}.csv", index=False)
    spec = SPEC.format(gain=gain, rate=0.6).replace(
        'model: {callable: "campaign_model:run", driven_by: [speed]}',
        "model: {path: 'sim/{id}.csv', time: time_s}",
    )
    spec = spec.replace(f"  - {{id: Trip03, params: {{gain: {gain}}}}}\n", "")
    (root / "fleet.hevval.yaml").write_text(spec)


def test_exported_model_files_score_like_the_callable(project: pytest.Pytester) -> None:
    """The same campaign, once with the model run in-process and once from exported files,
    gives the same items, outcomes and verdict; a file no recording uses is named."""
    write_campaign(project.path, gain=1.4)
    from_callable = project.runpytest("--hevval", "--hevval-no-history")
    write_exported(project.path, gain=1.4)
    from_files = project.runpytest("--hevval", "--hevval-no-history")
    assert (
        from_files.parseoutcomes()
        == from_callable.parseoutcomes()
        == {
            "passed": 11,
            "failed": 2,
        }
    )
    from_files.stdout.fnmatch_lines(
        [
            "campaign fleet.hevval.yaml (fleet): PASS, 2 of 3*",
            "  model output files no recording uses: sim/Trip99.csv",
        ]
    )
    assert "FAILED fleet.hevval.yaml::Trip03::P" in from_files.stdout.str()


def test_a_recording_without_its_model_file_names_both(project: pytest.Pytester) -> None:
    write_exported(project.path, extra=None)
    (project.path / "sim" / "Trip02.csv").unlink()
    result = project.runpytest("--hevval", "--hevval-no-history")
    # The gate fails too: a recording without a result cannot be judged.
    result.assert_outcomes(passed=9, failed=1, errors=3)
    text = result.stdout.str()
    assert "recording 'Trip02' has no model output: the file does not exist" in text
    assert "sim/Trip02.csv" in text
    assert "data/Trip02.csv" in text
    assert "model output files no recording uses" not in text
    result.stdout.fnmatch_lines(
        ["campaign fleet.hevval.yaml (fleet): FAIL (3 of 4 recordings scored)*"]
    )


def test_cli_run_scores_the_others_and_names_the_recording_it_could_not(
    project: pytest.Pytester,
) -> None:
    write_exported(project.path, extra=None)
    (project.path / "sim" / "Trip04.csv").unlink()
    result = hevval_run(project, "--json", "out.json")
    assert result.ret == 2
    errors = [line for line in result.stderr.lines if line.startswith("hevval run: error:")]
    assert len(errors) == 1
    assert "recording 'Trip04' has no model output" in errors[0]
    payload = json.loads((project.path / "out.json").read_text())
    assert payload["passed"] is False
    assert [e["spec"] for e in payload["errors"]] == ["fleet.hevval.yaml::Trip04"]
    assert payload["errors"][0]["file"].endswith("sim/Trip04.csv")
    assert {s["spec"] for s in payload["specs"]} == {
        f"fleet.hevval.yaml::{t}" for t in TRIPS if t != "Trip04"
    }
    assert payload["campaigns"][0]["missing"] == ["Trip04"]


def test_exported_model_files_on_dask(project: pytest.Pytester) -> None:
    """Each recording is its own task, its files read where the task runs; the items, the
    gate and the JSON agree with a run on this machine."""
    if importlib.util.find_spec("distributed") is None:
        pytest.skip("distributed is not installed (the dask extra)")
    write_exported(project.path, gain=1.4)
    serial = project.runpytest("--hevval", "--hevval-no-history")
    # In a subprocess: importing distributed inside an in-process run would leave state
    # (tblib's pickling hooks) pointing at modules pytester removes afterwards.
    remote = project.runpytest_subprocess("--hevval", "--hevval-no-history", "--hevval-dask=local")
    assert serial.parseoutcomes() == remote.parseoutcomes() == {"passed": 11, "failed": 2}
    remote.stdout.fnmatch_lines(["  model output files no recording uses: sim/Trip99.csv"])
    runs = {}
    for name, extra in (("here", []), ("dask", ["--dask", "local"])):
        done = hevval_run(project, "--json", f"{name}.json", *extra)
        assert done.ret == 1, done.stderr.str()
        runs[name] = json.loads((project.path / f"{name}.json").read_text())
    assert runs["here"]["campaigns"] == runs["dask"]["campaigns"]
    assert [s["phi"] for s in runs["here"]["specs"]] == [s["phi"] for s in runs["dask"]["specs"]]


def test_each_row_may_name_its_model_file(tmp_path: Path) -> None:
    text = _spec(
        tmp_path,
        "reference: {time: t}\n"
        "model: {time: time_s}\n"
        "recordings:\n"
        "  - {path: data/TripA.csv, model: sim/a_run.parquet}\n"
        "  - {id: cold, path: data/TripB.csv, model: sim/b_run.parquet}\n",
    )
    specs = parse_spec_text(text, tmp_path / "c.hevval.yaml").per_recording()
    assert [(s.recording, s.model.kind, s.model.options.time) for s in specs] == [
        ("TripA", "file", "time_s"),
        ("cold", "file", "time_s"),
    ]
    assert specs[1].model.path == str((tmp_path / "sim" / "b_run.parquet").resolve())


def test_cli_run_lists_unused_model_files_in_the_json(project: pytest.Pytester) -> None:
    write_exported(project.path)
    result = hevval_run(project, "--json", "out.json")
    assert result.ret == 0, result.stdout.str()
    (campaign,) = json.loads((project.path / "out.json").read_text())["campaigns"]
    assert campaign["unused_models"] == ["sim/Trip99.csv"]
    assert campaign["passed"] is True


def test_unknown_recording_on_the_command_line(tmp_path: Path) -> None:
    (tmp_path / "c.hevval.yaml").write_text(_spec(tmp_path, GLOB_HEAD))
    with pytest.raises(SpecError, match=r"no recording 'TripC'.*did you mean"):
        load_specs(f"{tmp_path / 'c.hevval.yaml'}::TripC")


# -- u-pooling --------------------------------------------------------------------------------


def test_golden_areas() -> None:
    observed = np.linspace(0.0, 1.0, 20001)
    # Predicted U(0, 2), observed U(0, 1): u = y / 2 is uniform on [0, 0.5], its distribution
    # min(2u, 1), and the area to the uniform one ∫0^.5 u du + ∫.5^1 (1 − u) du = 1/4.
    half = area_to_uniform(u_distribution(u_values(observed, np.linspace(0.0, 2.0, 20001))))
    assert half == pytest.approx(0.25, abs=1e-3)
    # Every observation below everything predicted: u = 0, the largest area, 1/2.
    assert area_to_uniform(u_distribution(u_values(observed, observed + 5.0))) == pytest.approx(
        0.5, abs=1e-3
    )
    # The model's distribution is the observed one: u is uniform, the area 0.
    assert area_to_uniform(u_distribution(u_values(observed, observed))) == pytest.approx(
        0.0, abs=1e-3
    )


def test_pooling_over_operating_points() -> None:
    # Two recordings far apart in physical units, each matched in distribution: pooled area 0.
    low = np.linspace(0.0, 1.0, 5001)
    high = np.linspace(100.0, 300.0, 5001)
    pooled = pool([u_distribution(u_values(x, x)) for x in (low, high)])
    assert area_to_uniform(pooled) == pytest.approx(0.0, abs=1e-3)
    # One matched, one wholly below its prediction (area 0.5): the pool lies between.
    pooled = pool([u_distribution(u_values(low, low)), u_distribution(u_values(high, high + 500))])
    assert area_to_uniform(pooled) == pytest.approx(0.25, abs=2e-3)


samples = hnp.arrays(np.float64, st.integers(1, 200), elements=finite)


@settings(max_examples=60, deadline=None)
@given(samples, samples, samples, samples)
def test_u_pooling_properties(
    observed_a: np.ndarray, predicted_a: np.ndarray, observed_b: np.ndarray, predicted_b: np.ndarray
) -> None:
    a = u_distribution(u_values(observed_a, predicted_a))
    b = u_distribution(u_values(observed_b, predicted_b))
    for distribution in (a, b):
        assert np.all(np.diff(distribution) >= 0)
        assert distribution[-1] == 1.0
        assert 0.0 <= area_to_uniform(distribution) <= 0.5 + 1e-12
    assert np.array_equal(pool([a, a]), a)
    # The area is convex in the distribution: a pool is never worse than its recordings' mean.
    assert area_to_uniform(pool([a, b])) <= (area_to_uniform(a) + area_to_uniform(b)) / 2 + 1e-12
    # u depends only on ranks: scaling both sides alike (exactly, by 2) changes nothing.
    shifted = u_values(2.0 * observed_a, 2.0 * predicted_a)
    assert np.allclose(shifted, u_values(observed_a, predicted_a))


few_values = hnp.arrays(
    np.float64, st.integers(1, 60), elements=st.sampled_from([-1.5, 0.0, 2.0, 7.0])
)


@settings(max_examples=200, deadline=None)
@given(st.one_of(samples, few_values), st.one_of(samples, few_values))
def test_fast_distribution_is_the_definition(observed: np.ndarray, predicted: np.ndarray) -> None:
    """The engine's shortcut gives, bit for bit, the distribution of u sample by sample."""
    expected = u_distribution(u_values(observed, predicted))
    assert np.array_equal(u_distribution_of(observed, predicted), expected)


def test_pool_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="nothing to pool"):
        pool([])
    with pytest.raises(ValueError, match="points on U_GRID"):
        pool([np.zeros(3)])
    with pytest.raises(ValueError, match="weights"):
        pool([U_GRID], weights=[0.0])


# -- reports and comparison -------------------------------------------------------------------


def test_reports_have_a_campaign_section(project: pytest.Pytester) -> None:
    write_campaign(project.path, gain=1.4, rate=0.9)
    project.runpytest("--hevval", "--hevval-no-history", "--hevval-report=html,json,md")
    folder = next(project.path.glob("**/report.json")).parent
    (campaign,) = json.loads((folder / "report.json").read_text())["campaigns"]
    assert campaign["excluded"] == ["Trip01"]
    assert campaign["failures"][0].startswith("pass rate 67% < min_pass_rate 90%")
    assert 0.0 <= campaign["pooled_area"]["P"] <= 0.5
    markdown = (folder / "report.md").read_text()
    assert "**❌ campaign fleet** (`fleet.hevval.yaml`)" in markdown
    assert "Excluded from the gate (calibration): `Trip01`" in markdown
    assert '<section class="card" id="campaign-1">' in (folder / "report.html").read_text()
    # Every recording's Φ carries its 95 % interval, in JSON and in the Markdown table.
    for recording in campaign["recordings"]:
        interval = recording["phi_interval"]
        assert interval["low"] <= recording["phi"] <= interval["high"]
        assert f"{recording['phi']:.4f} [{interval['low']:.4f}, {interval['high']:.4f}]" in markdown


def _outcome(name: str, phi: float, low: float, high: float, **kwargs: object) -> RecordingOutcome:
    defaults: dict[str, object] = {"role": "validation", "passed": phi >= 0.9, "min_phi": 0.9}
    defaults.update(kwargs)
    return RecordingOutcome(
        id=name,
        phi=phi,
        hash="",
        digest="",
        failed_signals=(),
        phi_interval=Interval(phi, low, high),
        **defaults,  # type: ignore[arg-type]
    )


def test_recordings_whose_interval_holds_min_phi_are_within_noise() -> None:
    clear_fail = _outcome("A", 0.80, 0.78, 0.82)
    noisy_fail = _outcome("B", 0.89, 0.87, 0.91)
    noisy_pass = _outcome("C", 0.91, 0.89, 0.93)
    clear_pass = _outcome("D", 0.95, 0.93, 0.97)
    at_bound = _outcome("E", 0.92, 0.90, 0.94)  # low == min_phi: noise cannot take it below
    calibration = _outcome("F", 0.89, 0.87, 0.91, role="calibration")
    no_gate = _outcome("G", 0.89, 0.87, 0.91, min_phi=None)
    no_interval = RecordingOutcome("H", "validation", 0.89, False, "", "", (), None, 0.9)
    outcomes = [clear_fail, noisy_fail, noisy_pass, clear_pass, at_bound, calibration]
    outcomes += [no_gate, no_interval]
    assert [o.id for o in outcomes if o.within_noise] == ["B", "C", "F"]
    found = CampaignVerdict(
        spec="fleet.hevval.yaml",
        name="fleet",
        recordings=outcomes,
        missing=[],
        min_pass_rate=None,
        phi_quantile=None,
        phi=Distribution.of([o.phi for o in outcomes]),
        lambdas={},
        signal_pass_rates={},
        pooled_area={},
    )
    # A calibration recording never counts, so it is not named either.
    assert [o.id for o in found.within_noise] == ["B", "C"]
    assert found.to_dict()["within_noise"] == ["B", "C"]
    assert (
        "  Φ within noise of min_phi (the 95 % interval holds it): "
        "B Φ 0.8900 [0.8700, 0.9100], C Φ 0.9100 [0.8900, 0.9300]"
    ) in verdict_lines(found)
    assert "worst recordings: A Φ 0.8000 [0.7800, 0.8200] FAIL" in "\n".join(verdict_lines(found))


def test_compare_names_the_recordings_that_changed(project: pytest.Pytester) -> None:
    write_campaign(project.path, gain=1.4)
    project.runpytest("--hevval", "--hevval-history", "--hevval-model-version=v1")
    write_campaign(project.path, gain=1.0)
    result = project.runpytest("--hevval", "--hevval-model-version=v2", "--hevval-compare=latest")
    result.stdout.fnmatch_lines(
        [
            "campaign fleet.hevval.yaml (v1 → v2): Φ better on Trip03 (+0.1*); worse on none;"
            " unchanged on Trip01, Trip02, Trip04"
        ]
    )


def test_a_recording_is_scored_alone_as_file_and_id(project: pytest.Pytester) -> None:
    """The form a Dask worker receives a campaign recording in."""
    from pytest_hevval.scoring.cluster import evaluate_spec_file

    write_campaign(project.path)
    payload = evaluate_spec_file(
        str(project.path / "fleet.hevval.yaml") + "::Trip02", str(project.path)
    )
    assert (payload["recording"], payload["role"]) == ("Trip02", "validation")
    assert payload["campaign"]["recordings"] == list(TRIPS)
    assert len(payload["signals"][0]["u_distribution"]) == U_GRID.size


def _recording(trip: str, phi: float, low: float | None = None, high: float | None = None) -> dict:
    spec: dict = {"spec": f"fleet.hevval.yaml::{trip}", "name": "fleet", "phi": phi, "signals": []}
    if low is not None:
        spec["phi_interval"] = {"low": low, "high": high}
    return spec


def test_campaign_compare_separates_real_changes_from_noise() -> None:
    from pytest_hevval.history.compare import campaign_change_lines, compare
    from pytest_hevval.results.changes import campaign_changes

    before = [
        _recording("Trip01", 0.90, 0.89, 0.91),
        _recording("Trip02", 0.90, 0.89, 0.91),
        _recording("Trip03", 0.90, 0.89, 0.91),
        _recording("Trip04", 0.90),  # recorded without intervals
        _recording("Trip05", 0.90, 0.89, 0.91),
    ]
    after = [
        _recording("Trip01", 0.95, 0.94, 0.96),  # disjoint: better
        _recording("Trip02", 0.905, 0.895, 0.915),  # overlapping: noise
        _recording("Trip03", 0.85, 0.84, 0.86),  # disjoint: worse
        _recording("Trip04", 0.901, 0.89, 0.91),  # no interval before: the point value decides
        _recording("Trip05", 0.90, 0.89, 0.91),
    ]
    comparison = compare(recorded(after), recorded(before), before_label="v1", after_label="v2")
    (change,) = campaign_changes(comparison)
    assert [r for r, _ in change.better] == ["Trip01", "Trip04"]
    assert [r for r, _ in change.worse] == ["Trip03"]
    assert [r for r, _ in change.within_noise] == ["Trip02"]
    assert change.unchanged == ("Trip05",)
    assert change.to_dict()["within_noise"] == [
        {"recording": "Trip02", "phi_delta": pytest.approx(0.005)}
    ]
    (line,) = campaign_change_lines(comparison)
    assert line == (
        "campaign fleet.hevval.yaml (v1 → v2): Φ better on Trip01 (+0.0500), Trip04 (+0.0010);"
        " worse on Trip03 (-0.0500); within noise on Trip02 (+0.0050); unchanged on Trip05"
    )
