"""The pytest plugin end to end, as a user runs it: with and without xdist."""

from __future__ import annotations

import importlib.util
import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from tests.conftest import needs_kernel

pytest_plugins = ["pytester"]

TREE_SPEC = """\
name: pack
reference: {path: data/ref.csv, time: t}
model: {path: data/sim.csv, time: time}
alignment: {max_lag_s: 2}
thresholds: {mae: 0.97, rms: 0.95}
min_phi: 0.5
sets:
  - signal: E
    ref: integrate(V * I) / 3600
    sim: integrate(P) / 3600
    unit: Wh
    children:
      - signal: P
        ref: V * I
        unit: W
        children:
          - {signal: V, unit: V, alpha: 0.5}
          - {signal: I, unit: A, alpha: 0.5}
  - {signal: speed, unit: km/h}
"""


def write_data(root: Path, *, fault: str | None = None, seed: int = 0) -> None:
    """Reference and model output for a pack: E = ∫ V·I, P = V·I, with an optional fault."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 120.0, 0.1)
    voltage = 350 + 10 * np.sin(t / 13)
    current = 60 + 50 * np.sin(t / 5)
    speed = 40 + 30 * np.sin(t / 20)
    sim_voltage = voltage + rng.normal(0, 0.05, t.size)
    sim_current = current + rng.normal(0, 0.05, t.size)
    if fault == "leaf":
        sim_current = sim_current * 1.25 + 8.0
    power = sim_voltage * sim_current
    if fault == "middle":
        power = power + 6000 * np.exp(-(((t - 60) / 15) ** 2))
    (root / "data").mkdir(exist_ok=True)
    pd.DataFrame({"t": t, "V": voltage, "I": current, "speed": speed}).to_csv(
        root / "data" / "ref.csv", index=False
    )
    pd.DataFrame(
        {"time": t, "V": sim_voltage, "I": sim_current, "P": power, "speed": speed + 0.1}
    ).to_csv(root / "data" / "sim.csv", index=False)


@pytest.fixture
def project(pytester: pytest.Pytester) -> pytest.Pytester:
    pytester.makefile(".hevval.yaml", pack=TREE_SPEC)
    return pytester


def _no_plugin_traceback(output: str) -> None:
    assert "Traceback" not in output
    assert "pytest_hevval/" not in output.replace("pytest_hevval/__", "")


def test_inert_without_flag(project: pytest.Pytester) -> None:
    write_data(project.path)
    result = project.runpytest()
    result.assert_outcomes()
    assert result.ret == pytest.ExitCode.NO_TESTS_COLLECTED


def test_passing_spec(project: pytest.Pytester) -> None:
    write_data(project.path)
    result = project.runpytest("--hevval", "-v")
    result.assert_outcomes(passed=6)
    result.stdout.fnmatch_lines(
        [
            "*pack.hevval.yaml::E PASSED*",
            "*pack.hevval.yaml::E/P/V PASSED*",
            "*pack.hevval.yaml::Phi PASSED*",
            "*hevval validation summary*",
            "pack: Φ = 0.9* ≥ min 0.5, PASS*",
        ]
    )


# Loaded by every process of the run, the xdist workers too: the kernel's numpy time made large
# enough for this small project to gain from the kernel (but not to compile mid-run), and a
# stand-in for the compile's
# process that leaves a line in a file instead.
_GAINING_RUN_CONFTEST = """
import os

from pytest_hevval.core import kernel
from pytest_hevval.data import kernel_cache

_saved = {}


def pytest_configure(config):
    _saved.update(
        extra=dict(kernel.NUMPY_EXTRA_S),
        launch=kernel_cache._launch,
        compile=kernel.KERNEL_COMPILE_S,
    )
    kernel.KERNEL_COMPILE_S = float("inf")  # never at once: as the run ends
    kernel.NUMPY_EXTRA_S.update(dict.fromkeys(kernel.NUMPY_EXTRA_S, float(os.environ["EXTRA_S"])))

    def launch(command, **_):
        with open(os.environ["STARTED"], "a") as file:
            file.write(" ".join(command[4:]) + "\\n")

    kernel_cache._launch = launch


def pytest_unconfigure(config):
    kernel.NUMPY_EXTRA_S.update(_saved["extra"])
    kernel_cache._launch = _saved["launch"]
    kernel.KERNEL_COMPILE_S = _saved["compile"]
"""


@needs_kernel
@pytest.mark.parametrize("workers", [[], ["-n", "2"]], ids=["serial", "xdist"])
def test_a_cold_kernel_cache_is_compiled_in_the_background_as_the_run_ends_and_said_once(
    project: pytest.Pytester, monkeypatch: pytest.MonkeyPatch, tmp_path: Path, workers: list[str]
) -> None:
    """A run that would gain from the kernel starts one compile as it ends (its lock file keeps
    the xdist workers from starting more) and says so once; a run too short to gain, or on
    the numpy path, starts and says nothing."""
    from pytest_hevval.core import kernel
    from pytest_hevval.data import kernel_cache

    write_data(project.path)
    project.makeconftest(_GAINING_RUN_CONFTEST)
    started = tmp_path / "started.txt"
    cache = tmp_path / "empty-cache"
    monkeypatch.setenv("STARTED", str(started))
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    monkeypatch.setenv("HEVVAL_KERNEL", "auto")
    monkeypatch.delenv(kernel_cache.BACKGROUND_COMPILE_ENV)
    note = "hevval: numba's cache did not hold the compiled kernel, so this run scored on numpy"
    runs = (("auto", "1e-9", False), ("numpy", "1.0", False), ("auto", "1.0", True))
    for path, extra_s, compiles in runs:
        monkeypatch.setattr(kernel_cache, "_background", {})
        monkeypatch.setattr(kernel, "_would_save", [0.0])
        monkeypatch.setenv("HEVVAL_KERNEL", path)
        monkeypatch.setenv("EXTRA_S", extra_s)
        result = project.runpytest("--hevval", "-q", *workers)
        result.assert_outcomes(passed=6)
        assert result.stdout.str().count(note) == int(compiles), (path, extra_s)
        assert started.exists() == compiles
    result.stdout.fnmatch_lines(["*hevval validation summary*", note + "*"])
    assert started.read_text().split() == [
        *kernel_cache.FIRST_COMPILED,
        *(n for n in kernel.COMPILED if n not in kernel_cache.FIRST_COMPILED),
    ]
    assert list(cache.rglob(".hevval-compiling"))


def test_ini_switch_and_custom_glob(pytester: pytest.Pytester) -> None:
    pytester.makefile(".yaml", custom=TREE_SPEC)
    pytester.makeini("[pytest]\nhevval = true\nhevval_files = custom.yaml\n")
    write_data(pytester.path)
    result = pytester.runpytest()
    result.assert_outcomes(passed=6)


def test_error_at_leaf_is_localised(project: pytest.Pytester) -> None:
    write_data(project.path, fault="leaf")
    result = project.runpytest("--hevval")
    result.assert_outcomes(passed=3, failed=3)
    output = result.stdout.str()
    _no_plugin_traceback(output)
    result.stdout.fnmatch_lines(
        [
            "*_ hevval pack: E _*",
            "E missed its thresholds (pack.hevval.yaml:8)",
            "  set 1, level 1, position 1, α = 1",
            "  λ3 MAE = 0.* < 0.97 (MAE * Wh over a * Wh range)",
            "  where the error appears:",
            "    E/P/I (level 3, line 18): mae 0.*",
            "  next: hevval diagnose pack.hevval.yaml --signal E/P/I *",
        ]
    )
    result.stdout.fnmatch_lines(
        [
            "*_ hevval pack: E/P/I _*",
            "E/P/I missed its thresholds (pack.hevval.yaml:18)",
            "  set 1, level 3, position 2, α = 0.5",
            "  λ3 MAE = * < 0.97 (MAE * A over a * A range)",
            "  lag *s, where the mean-removed correlation peaks: * (* at zero lag)",
            "  where the error appears: here, at level 3 (a leaf)",
        ]
    )
    result.stdout.fnmatch_lines(["*✗ I ?E/P/I? mae*← error appears here*"])


def test_error_at_middle_node_is_localised(project: pytest.Pytester) -> None:
    write_data(project.path, fault="middle")
    result = project.runpytest("--hevval")
    result.assert_outcomes(passed=4, failed=2)
    result.stdout.fnmatch_lines(
        [
            "E missed its thresholds*",
            "*where the error appears:",
            "    E/P (level 2, line 13)*",
        ]
    )
    result.stdout.fnmatch_lines(
        [
            "E/P missed its thresholds (pack.hevval.yaml:13)",
            "*where the error appears: here, at level 2: the signals below it pass, so the error "
            "emerges where they combine",
        ]
    )


def test_phi_item_reports_against_min_phi(pytester: pytest.Pytester) -> None:
    pytester.makefile(".hevval.yaml", pack=TREE_SPEC.replace("min_phi: 0.5", "min_phi: 0.999"))
    write_data(pytester.path, fault="leaf")
    result = pytester.runpytest("--hevval", "-k", "Phi")
    result.assert_outcomes(failed=1, deselected=5)
    result.stdout.fnmatch_lines(
        [
            "Φ = 0.* < min_phi 0.999 (pack.hevval.yaml:6)",
            "  signals that pull Φ down most (share of 1 − Φ):",
            "    E/P/I: * % (weakest *",
        ]
    )


def test_keyword_selection(project: pytest.Pytester) -> None:
    write_data(project.path, fault="leaf")
    # Keywords match any part of the node id, so pick names unique to the items.
    result = project.runpytest("--hevval", "-k", "speed or Phi")
    result.assert_outcomes(passed=2, deselected=4)


def test_last_failed_and_exitfirst(project: pytest.Pytester) -> None:
    write_data(project.path, fault="leaf")
    project.runpytest("--hevval").assert_outcomes(passed=3, failed=3)
    rerun = project.runpytest("--hevval", "--lf", "-v")
    rerun.assert_outcomes(failed=3)
    assert "PASSED" not in rerun.stdout.str()
    first = project.runpytest("--hevval", "-x", "-p", "no:cacheprovider")
    first.assert_outcomes(failed=1)


def test_junit_properties(project: pytest.Pytester) -> None:
    write_data(project.path)
    project.runpytest("--hevval", "--junitxml=out.xml").assert_outcomes(passed=6)
    tree = ET.parse(project.path / "out.xml")
    case = next(c for c in tree.iter("testcase") if c.get("name") == "E/P/I")
    properties = {p.get("name"): p.get("value") for p in case.iter("property")}
    assert set(properties) == {
        "phi",
        "lambda1_lag_correlation",
        "lambda2_derivative_match",
        "lambda3_mae",
        "lambda4_rms",
        "lambda5_anomaly",
        "lambda6_error_std",
        "lambda7_emergent",
        "lag_s",
    }
    assert 0.9 < float(properties["phi"]) <= 1.0
    assert float(properties["lambda7_emergent"]) == 1.0  # a leaf


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            TREE_SPEC.replace("min_phi: 0.5", "min_phy: 0.5"),
            "pack.hevval.yaml:6: min_phy: unknown key; did you mean 'min_phi'?",
        ),
        (
            TREE_SPEC.replace("{mae: 0.97, rms: 0.95}", "{mae: 1.97, rms: 0.95}"),
            "pack.hevval.yaml:5: thresholds.mae: must lie between 0 and 1 (got 1.97)",
        ),
    ],
)
def test_bad_spec_is_a_collection_error(
    pytester: pytest.Pytester, text: str, expected: str
) -> None:
    pytester.makefile(".hevval.yaml", pack=text)
    write_data(pytester.path)
    result = pytester.runpytest("--hevval")
    result.assert_outcomes(errors=1)
    output = result.stdout.str()
    assert "ERROR collecting pack.hevval.yaml" in output
    assert expected in output
    _no_plugin_traceback(output)


def test_missing_column_is_an_error_naming_file_and_column(project: pytest.Pytester) -> None:
    write_data(project.path)
    frame = pd.read_csv(project.path / "data" / "sim.csv").rename(columns={"P": "Power"})
    frame.to_csv(project.path / "data" / "sim.csv", index=False)
    result = project.runpytest("--hevval")
    result.assert_outcomes(errors=6)
    output = result.stdout.str()
    assert "sim.csv: column 'P': no such column in this file" in output
    _no_plugin_traceback(output)


def test_missing_file_is_an_error(project: pytest.Pytester) -> None:
    write_data(project.path)
    (project.path / "data" / "ref.csv").unlink()
    result = project.runpytest("--hevval")
    result.assert_outcomes(errors=6)
    assert "ref.csv" in result.stdout.str()
    _no_plugin_traceback(result.stdout.str())


@pytest.mark.parametrize("fault", [None, "leaf", "middle"])
def test_same_outcomes_under_xdist(project: pytest.Pytester, fault: str | None) -> None:
    write_data(project.path, fault=fault)
    serial = project.runpytest("--hevval", "--junitxml=serial.xml")
    parallel = project.runpytest("--hevval", "-p", "xdist", "-n", "2", "--junitxml=par.xml")
    assert serial.parseoutcomes() == parallel.parseoutcomes()

    def cases(name: str) -> dict[str, dict[str, str | None]]:
        tree = ET.parse(project.path / name)
        return {
            c.get("name", ""): {
                **{p.get("name", ""): p.get("value") for p in c.iter("property")},
                "failure": next((f.get("message") for f in c.iter("failure")), None),
            }
            for c in tree.iter("testcase")
        }

    # Under xdist one item of the spec judges the others and the controller reports them
    # (items.carry_spec_items): every item still has its own outcome, text and properties.
    assert cases("serial.xml") == cases("par.xml")
    parallel.stdout.fnmatch_lines(["*hevval validation summary*", "pack: Φ = *"])


def test_a_data_error_under_xdist_is_every_items_error_said_once(
    project: pytest.Pytester,
) -> None:
    write_data(project.path)
    (project.path / "data" / "ref.csv").unlink()
    serial = project.runpytest("--hevval").stdout.str()
    result = project.runpytest("--hevval", "-p", "xdist", "-n", "2")
    result.assert_outcomes(errors=6)
    output = result.stdout.str()
    assert output.count("ref.csv: file not found") == serial.count("ref.csv: file not found") == 1
    assert output.count("not scored: the error of") == serial.count("not scored: the error of")
    _no_plugin_traceback(output)


def test_cli_run_json(project: pytest.Pytester) -> None:
    write_data(project.path, fault="leaf")
    result = project.run(
        sys.executable, "-m", "pytest_hevval", "run", "pack.hevval.yaml", "--json", "out.json"
    )
    assert result.ret == 1
    payload = json.loads((project.path / "out.json").read_text())
    assert {"phi", "min_phi", "passed", "signals"} <= set(payload)
    assert payload["passed"] is False
    by_path = {s["path"]: s for s in payload["signals"]}
    leaf = by_path["E/P/I"]
    assert {
        "path",
        "set",
        "level",
        "alpha",
        "lambdas",
        "lag_s",
        "peak_correlation",
        "mae",
        "rms",
        "passed",
        "failures",
        "origin",
    } <= set(leaf)
    assert len(leaf["lambdas"]) == 7
    assert leaf["origin"] is True
    assert by_path["E"]["origin"] is False
    assert by_path["E"]["origins"] == ["E/P/I"]


def test_cli_run_bad_spec_exit_code(pytester: pytest.Pytester) -> None:
    pytester.makefile(".hevval.yaml", bad="sets: 3\n")
    result = pytester.run(sys.executable, "-m", "pytest_hevval", "run", "bad.hevval.yaml")
    assert result.ret == 2
    assert "bad.hevval.yaml:1: reference: is required" in result.stderr.str()


def test_reports_are_written_once_with_diagnosis(project: pytest.Pytester) -> None:
    write_data(project.path, fault="leaf")
    result = project.runpytest(
        "--hevval", "-p", "xdist", "-n", "2", "--hevval-report=html,json,md", "--hevval-no-history"
    )
    result.assert_outcomes(passed=3, failed=3)
    folder = project.path / ".hevval" / "report"
    assert sorted(p.name for p in folder.iterdir()) == ["report.html", "report.json", "report.md"]
    document = json.loads((folder / "report.json").read_text())
    specs = document["specs"] if isinstance(document, dict) else document
    signal = next(s for s in specs[0]["signals"] if s["path"] == "E/P/I")
    assert signal["figures"]["overlay"]
    assert "summary" in signal["diagnosis"]
    assert "E/P/I" in (folder / "report.md").read_text()
    html = (folder / "report.html").read_text()
    assert "https://" not in html
    assert "<script src" not in html


def test_exitfirst_under_xdist_stops_on_a_failure_its_worker_judged_with_another_item(
    project: pytest.Pytester,
) -> None:
    """A failing item judged on the worker by another item of its spec counts for -x and
    --maxfail as a failure the worker reports itself: the run stops, as a serial one does."""
    write_data(project.path, fault="leaf")
    for index in range(6):
        project.makefile(".hevval.yaml", **{f"more{index}": TREE_SPEC})
    result = project.runpytest("--hevval", "--hevval-no-history", "-p", "xdist", "-n", "1", "-x")
    assert result.ret == pytest.ExitCode.INTERRUPTED
    result.stdout.fnmatch_lines(["*stopping after 1 failures*"])
    # Not every spec ran: the worker was told to stop with work left in its queue.
    outcomes = result.parseoutcomes()
    assert outcomes.get("failed", 0) + outcomes.get("passed", 0) < 7 * 6


def test_reports_and_history_under_xdist_hold_what_a_serial_run_writes(
    project: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The controller publishes the results its workers sent as they came (their JSON data):
    the JSON report and the history record hold what a serial run writes, bit for bit.

    On one kernel path: the auto path may take the compiled kernel in one process and numpy
    in another (this test process has loaded the kernel already), and the two agree only to
    the last bits. Both runs compute in fresh processes: run inline, the serial run inherits
    whatever an earlier test left in this process (the BLAS thread pool among it), and the
    diagnosis's least-squares sums then differ from the workers' in the ninth digit."""
    monkeypatch.setenv("HEVVAL_KERNEL", "numpy")
    write_data(project.path, fault="leaf")
    written: dict[str, tuple[Any, Any]] = {}
    for name, extra in (("serial", []), ("xdist", ["-p", "xdist", "-n", "2"])):
        history = project.path / f"history-{name}"
        project.runpytest_subprocess(
            "--hevval",
            *extra,
            "--hevval-report=json",
            "--hevval-history",
            f"--hevval-history-dir={history}",
        ).assert_outcomes(passed=3, failed=3)
        report = json.loads((project.path / ".hevval" / "report" / "report.json").read_text())
        (record,) = [json.loads(path.read_text()) for path in history.glob("*.json")]
        written[name] = (report, record)

    def specs(document: Any) -> Any:
        return document["specs"] if isinstance(document, dict) else document

    assert specs(written["xdist"][0]) == specs(written["serial"][0])
    assert written["xdist"][1]["specs"] == written["serial"][1]["specs"]
    assert specs(written["xdist"][0])[0]["signals"][0]["failures"]


def test_bad_report_format_is_a_usage_error(project: pytest.Pytester) -> None:
    result = project.runpytest("--hevval", "--hevval-report=pdf")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert "--hevval-report" in result.stderr.str()


def test_github_annotations_point_at_the_spec_line(
    project: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GITHUB_ACTIONS", "true")
    write_data(project.path, fault="leaf")
    result = project.runpytest("--hevval", "--hevval-no-history")
    result.stdout.fnmatch_lines(
        ["::error file=pack.hevval.yaml,line=18,title=hevval::pack: E/P/I:*"]
    )


def test_dask_gives_the_same_outcomes(project: pytest.Pytester) -> None:
    # Only whether it is installed: the test process itself never needs distributed.
    if importlib.util.find_spec("distributed") is None:
        pytest.skip("distributed is not installed (the dask extra)")
    write_data(project.path, fault="leaf")
    serial = project.runpytest("--hevval", "--hevval-no-history", "--junitxml=serial.xml")
    project.makeconftest(
        "def pytest_runtest_setup(item):\n"
        "    with open('setups.txt', 'a') as f:\n"
        "        f.write(item.nodeid + '\\n')\n"
    )
    # In a subprocess: importing distributed inside an in-process run would leave state
    # (tblib's pickling hooks) pointing at modules pytester removes afterwards.
    remote = project.runpytest_subprocess(
        "--hevval", "--hevval-no-history", "--hevval-dask=local", "--junitxml=dask.xml"
    )
    assert serial.parseoutcomes() == remote.parseoutcomes()
    # Scored on the cluster, the spec's items are judged here by one of them.
    assert len((project.path / "setups.txt").read_text().splitlines()) == 1

    def cases(name: str) -> dict[str, dict[str, str | None]]:
        tree = ET.parse(project.path / name)
        return {
            c.get("name", ""): {
                **{p.get("name", ""): p.get("value") for p in c.iter("property")},
                # Its first lines: a spec scored on Dask comes back without its traces, so
                # its failures have no diagnosis.
                "failure": next(
                    ("\n".join(f.get("message", "").splitlines()[:5]) for f in c.iter("failure")),
                    None,
                ),
            }
            for c in tree.iter("testcase")
        }

    # One item per spec judges the others in the pytest process; each is still its own case.
    assert len(cases("dask.xml")) == 6
    assert cases("serial.xml") == cases("dask.xml")
    remote.stdout.fnmatch_lines(["E/P/I missed its thresholds (pack.hevval.yaml:18)"])
