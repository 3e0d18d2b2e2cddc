"""Odd and hostile inputs, each run in a child process with a time and a memory limit, so that
a hang or a memory bomb fails its test instead of the CI job. Every case must end, within
seconds, in a result or in one clear error naming the file (and the key or column), with no
traceback from inside the plugin."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

#: Seconds and bytes a child may take; every case here needs a fraction of either.
TIME_LIMIT_S = 60
MEMORY_LIMIT = 3 * 1024**3

SPEC = """\
name: hostile
reference: {path: ref.csv}
model: {path: sim.csv}
sets:
  - {signal: v}
"""


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def hevval(folder: Path, *argv: str) -> subprocess.CompletedProcess[str]:
    """``hevval ARGV`` in ``folder``, bounded in time and memory."""
    try:
        return subprocess.run(
            [sys.executable, "-m", "pytest_hevval", *argv],
            cwd=folder,
            capture_output=True,
            text=True,
            timeout=TIME_LIMIT_S,
            preexec_fn=_limits,
            stdin=subprocess.DEVNULL,
            env={**os.environ, "PYTHONWARNINGS": "error::RuntimeWarning"},
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"hevval {' '.join(argv)} did not end within {TIME_LIMIT_S} s")


def _clear_error(done: subprocess.CompletedProcess[str], *expected: str) -> None:
    output = done.stdout + done.stderr
    assert done.returncode == 2, output
    assert "Traceback" not in output, output
    for text in expected:
        assert text in output, output
    assert len(done.stderr) < 2000, "one short message, not a dump of the input"


@pytest.fixture
def project(tmp_path: Path) -> Path:
    t = np.arange(0.0, 30.0, 0.1)
    pd.DataFrame({"t": t, "v": np.sin(t)}).to_csv(tmp_path / "ref.csv", index=False)
    pd.DataFrame({"t": t, "v": np.sin(t) + 0.01}).to_csv(tmp_path / "sim.csv", index=False)
    (tmp_path / "hostile.hevval.yaml").write_text(SPEC, encoding="utf-8")
    return tmp_path


def _pipe(path: Path) -> None:
    if path.exists():
        path.unlink()
    os.mkfifo(path)


needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes need POSIX")


# -- hangs: a named pipe where a file is expected ------------------------------------------------


@needs_fifo
def test_a_named_pipe_as_the_spec(project: Path) -> None:
    _pipe(project / "pipe.hevval.yaml")
    done = hevval(project, "run", "pipe.hevval.yaml", "--no-history")
    _clear_error(done, "pipe.hevval.yaml", "a named pipe, not a regular file")


@needs_fifo
def test_a_named_pipe_as_the_data(project: Path) -> None:
    _pipe(project / "sim.csv")
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "sim.csv", "a named pipe, not a regular file")


@needs_fifo
def test_a_named_pipe_as_the_threshold_sidecar(project: Path) -> None:
    _pipe(project / "hostile.hevval.thresholds.yaml")
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "hostile.hevval.thresholds.yaml", "a named pipe, not a regular file")


@needs_fifo
def test_a_named_pipe_among_the_history_records(project: Path) -> None:
    """The run is scored and recorded; the pipe is skipped and named."""
    history = project / ".hevval" / "history"
    history.mkdir(parents=True)
    _pipe(history / "20260101T000000Z_v0_00000000.json")
    done = hevval(project, "history")
    assert "a named pipe, not a regular file" in done.stderr, done.stderr
    assert "Traceback" not in done.stdout + done.stderr


@needs_fifo
def test_a_named_pipe_to_compare(project: Path) -> None:
    _pipe(project / "before.json")
    (project / "after.json").write_text('{"specs": []}', encoding="utf-8")
    done = hevval(project, "compare", "before.json", "after.json")
    _clear_error(done, "before.json", "a named pipe, not a regular file")


# -- unbounded input ---------------------------------------------------------------------------


def test_a_compare_input_nested_100000_deep(project: Path) -> None:
    (project / "deep.json").write_text("[" * 100_000 + "]" * 100_000, encoding="utf-8")
    (project / "after.json").write_text('{"specs": []}', encoding="utf-8")
    done = hevval(project, "compare", "deep.json", "after.json")
    _clear_error(done, "deep.json", "nested deeper than")


def test_a_history_record_nested_100000_deep_is_skipped(project: Path) -> None:
    history = project / ".hevval" / "history"
    history.mkdir(parents=True)
    record = {"schema_version": 1, "model_version": "v0", "nest": None}
    text = json.dumps(record).replace("null", "[" * 100_000 + "]" * 100_000)
    (history / "20260101T000000Z_v0_00000000.json").write_text(text, encoding="utf-8")
    done = hevval(project, "history")
    assert "nested deeper than" in done.stderr, done.stderr
    assert "Traceback" not in done.stdout + done.stderr


# -- bad spec values that size the work, and texts that used to be misread -------------------------

BOMB_LEVELS = 7


def _alias_bomb() -> str:
    """Each level holds eight aliases of the level below: 8**7 values once expanded."""
    lines = ["  - signal: v0", "    children: &l0 [" + ", ".join(["{signal: w}"] * 8) + "]"]
    for level in range(1, BOMB_LEVELS):
        below = f"{{signal: n{level}, children: *l{level - 1}}}"
        lines += [
            f"  - signal: v{level}",
            f"    children: &l{level} [" + ", ".join([below] * 8) + "]",
        ]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("sets", "expected"),
    [
        ("  - {signal: v, unit: 'm/((', sim_unit: m}\n", ["sets[0].unit", "unbalanced"]),
        ("  - {signal: v, unit: m, sim_unit: 'm * 9**9**9'}\n", ["sets[0].sim_unit", "power"]),
        ("  - {signal: v, alpha: 1.0e308}\n", ["sets[0].alpha", "at most"]),
        (_alias_bomb(), ["invalid YAML", "aliases expand to over"]),
    ],
    ids=["unbalanced unit", "unit power tower", "huge weight", "alias bomb"],
)
def test_a_spec_value_that_would_hang_or_crash_is_refused(
    project: Path, sets: str, expected: list[str]
) -> None:
    text = SPEC.split("sets:\n")[0] + "sets:\n" + sets
    (project / "hostile.hevval.yaml").write_text(text, encoding="utf-8")
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "hostile.hevval.yaml", *expected)


def test_a_rate_so_high_its_grid_would_not_fit_in_memory(project: Path) -> None:
    text = SPEC.replace("sets:", "alignment: {rate_hz: 1.0e12}\nsets:")
    (project / "hostile.hevval.yaml").write_text(text, encoding="utf-8")
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "hostile.hevval.yaml", "alignment.rate_hz", "the grid would hold")


def test_a_number_yaml_reads_as_text_is_read_as_the_number_meant(project: Path) -> None:
    """`rate_hz: 1e3` is text to YAML 1.1; it was refused as "must be a number (got '1e3')"."""
    text = SPEC.replace("sets:", "alignment: {rate_hz: 1e3}\nsets:")
    (project / "hostile.hevval.yaml").write_text(text, encoding="utf-8")
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history", "--json", "out.json")
    assert done.returncode == 0, done.stderr
    (signal,) = json.loads((project / "out.json").read_text("utf-8"))["signals"]
    assert signal["dt"] == pytest.approx(1e-3)


def test_a_merge_key_may_be_overridden(project: Path) -> None:
    """YAML's merge key: the mapping's own keys override the merged ones (it was refused as a
    duplicate key)."""
    text = SPEC.replace(
        "  - {signal: v}\n",
        "  - &base {signal: v, alpha: 1.0}\n"
        "  - {<<: *base, signal: w, ref: v, sim: v, alpha: 0.5}\n",
    )
    (project / "hostile.hevval.yaml").write_text(text, encoding="utf-8")
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history", "--json", "out.json")
    assert done.returncode == 0, done.stderr
    alphas = [s["alpha"] for s in json.loads((project / "out.json").read_text("utf-8"))["signals"]]
    assert alphas == [1.0, 0.5]


# -- data that used to crash, or to be answered unclearly ----------------------------------------


def test_a_megabyte_of_nul_bytes_as_data(project: Path) -> None:
    (project / "sim.csv").write_bytes(b"\0" * (1 << 20))
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "sim.csv", "NUL byte", "not a text CSV")


def test_a_parquet_file_with_a_repeated_column(project: Path) -> None:
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    t = np.arange(0.0, 30.0, 0.1)
    table = pa.table([pa.array(t), pa.array(np.sin(t)), pa.array(np.cos(t))], names=["t", "v", "v"])
    pq.write_table(table, project / "sim.parquet")
    text = SPEC.replace("sim.csv", "sim.parquet")
    (project / "hostile.hevval.yaml").write_text(text, encoding="utf-8")
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "sim.parquet", "column 'v'", "2 columns named 'v'")


def test_a_two_dimensional_hdf5_dataset(project: Path) -> None:
    h5py = pytest.importorskip("h5py")
    t = np.arange(0.0, 30.0, 0.1)
    with h5py.File(project / "sim.h5", "w") as handle:
        handle["t"] = t
        handle["v"] = np.ones((t.size, 3))
    (project / "hostile.hevval.yaml").write_text(SPEC.replace("sim.csv", "sim.h5"), "utf-8")
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "sim.h5", "column 'v'", "shape (300, 3), not one channel")


def test_the_html_report_of_a_model_off_by_a_constant(project: Path) -> None:
    """The residual is a constant up to rounding: the error histogram could not be binned."""
    t = np.arange(0.0, 30.0, 0.1)
    pd.DataFrame({"t": t, "v": np.sin(t) + 2.5}).to_csv(project / "sim.csv", index=False)
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history", "--report", "html")
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    assert (project / ".hevval" / "report" / "report.html").is_file()


# -- outputs that cannot be written ----------------------------------------------------------------


def test_json_output_naming_a_folder(project: Path) -> None:
    (project / "out").mkdir()
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history", "--json", "out")
    _clear_error(done, "out: cannot write it: it is a folder")


def test_a_report_folder_that_is_a_file(project: Path) -> None:
    """The run is scored and judged; the report step says why it wrote nothing."""
    (project / "reports").write_text("not a folder", encoding="utf-8")
    done = hevval(
        project,
        "run",
        "hostile.hevval.yaml",
        "--no-history",
        "--report",
        "html",
        "--report-dir",
        "reports",
    )
    assert done.returncode == 1, done.stdout + done.stderr
    assert "report: error: " in done.stdout, done.stdout
    assert "reports: cannot write it" in done.stdout, done.stdout
    assert "Traceback" not in done.stdout + done.stderr
    assert (project / "reports").read_text("utf-8") == "not a folder"


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files without permission")
def test_a_data_file_without_read_permission(project: Path) -> None:
    (project / "sim.csv").chmod(0)
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "sim.csv", "cannot read it")


def test_region_bins_that_would_make_millions_of_cells(project: Path) -> None:
    text = SPEC.replace("sets:", "regions: {by: [v, v], bins: [5000, 5000]}\nsets:")
    (project / "hostile.hevval.yaml").write_text(text, encoding="utf-8")
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "hostile.hevval.yaml", "regions.bins", "region cells")


@pytest.mark.parametrize("suffix", ["csv", "parquet", "mat", "h5", "mf4", "tdms"])
def test_a_ten_gigabyte_file_of_nul_bytes_as_data(project: Path, suffix: str) -> None:
    """A sparse file: no disk used, but a reader that loads it whole runs out of memory."""
    path = project / f"sim.{suffix}"
    with open(path, "wb") as stream:
        stream.truncate(10 * 1024**3)
    (project / "hostile.hevval.yaml").write_text(SPEC.replace("sim.csv", path.name), "utf-8")
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, path.name)
