"""Inputs that used to be read silently wrong: each now gives the right result or a clear error."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pytest_hevval import cli
from pytest_hevval.data.readers import read_record
from pytest_hevval.data.record import SourceOptions
from pytest_hevval.errors import DataError

T = np.arange(0.0, 60.0, 0.01)
V = np.sin(T) + 2.0


def _spec(folder: Path, ref: str, sim: str, *, signal: str = "{signal: v}") -> Path:
    path = folder / "trust.hevval.yaml"
    path.write_text(
        f"name: trust\nreference: {{{ref}}}\nmodel: {{{sim}}}\nalignment: {{max_lag_s: 2}}\n"
        f"sets:\n  - {signal}\n",
        encoding="utf-8",
    )
    return path


def _run(spec: Path, tmp_path: Path) -> dict:
    out = tmp_path / "out.json"
    cli.main(["run", str(spec), "--no-history", "--quiet", "--json", str(out)])
    return json.loads(out.read_text("utf-8"))


def test_a_time_header_in_milliseconds_is_read_as_milliseconds(tmp_path: Path) -> None:
    """`Time [ms]` with no time_scale: a 0.5 s lag is 0.5 s, the grid 100 Hz (it was read as
    seconds: a lag of 0 and 0.1 Hz)."""
    pd.DataFrame({"Time [ms]": np.round(T * 1000, 3), "v": V}).to_csv(
        tmp_path / "ref.csv", index=False
    )
    pd.DataFrame({"Time [ms]": np.round((T + 0.5) * 1000, 3), "v": V}).to_csv(
        tmp_path / "sim.csv", index=False
    )
    found = _run(_spec(tmp_path, "path: ref.csv", "path: sim.csv"), tmp_path)
    (signal,) = found["signals"]
    assert signal["dt"] == pytest.approx(0.01)
    assert abs(signal["lag_s"]) == pytest.approx(0.5)


@pytest.mark.parametrize(
    ("header", "scale", "message"),
    [
        ("Time [s]", 0.001, "header says s, 1 s per unit, but `time_scale` is 0.001"),
        ("Time [samples]", None, "names the unit 'samples', which is not a unit of time"),
    ],
)
def test_a_time_unit_is_honoured_or_refused_never_ignored(
    tmp_path: Path, header: str, scale: float | None, message: str
) -> None:
    path = tmp_path / "a.csv"
    pd.DataFrame({header: T, "v": V}).to_csv(path, index=False)
    with pytest.raises(DataError, match=message) as error:
        read_record(str(path), ["v"], SourceOptions(time_scale=scale))
    assert error.value.column == header
    assert error.value.file == str(path)


def test_a_unit_the_header_does_not_know_can_be_stated_in_the_spec(tmp_path: Path) -> None:
    path = tmp_path / "a.csv"
    pd.DataFrame({"Time [ticks]": np.arange(T.size), "v": V}).to_csv(path, index=False)
    record = read_record(str(path), ["v"], SourceOptions(time_scale=0.01))
    assert record.channels["v"].time[1] == pytest.approx(0.01)


def test_the_exact_time_name_wins_over_a_name_that_starts_like_it(tmp_path: Path) -> None:
    path = tmp_path / "a.csv"
    pd.DataFrame({"timer_ticks": np.arange(T.size) * 7, "time": T, "v": V}).to_csv(
        path, index=False
    )
    record = read_record(str(path), ["v"], SourceOptions())
    assert record.meta["time_column"] == "time"
    assert float(record.channels["v"].time[1]) == pytest.approx(0.01)


def test_time_stamps_in_epoch_seconds_give_the_grid_they_were_logged_at(
    tmp_path: Path,
) -> None:
    """Epoch seconds at 10 Hz as floats: steps of 0.1 s, not 0.1000000238 s, so a model equal to
    the reference scores exactly."""
    stamps = 1.7e9 + np.arange(0.0, 600.0, 0.1)
    frame = pd.DataFrame({"time": stamps, "v": np.sin(np.arange(stamps.size) / 10)})
    frame.to_csv(tmp_path / "ref.csv", index=False)
    frame.to_csv(tmp_path / "sim.csv", index=False)
    found = _run(_spec(tmp_path, "path: ref.csv", "path: sim.csv"), tmp_path)
    (signal,) = found["signals"]
    assert signal["dt"] == 0.1
    assert signal["lag_s"] == 0.0
    assert signal["mae"] == 0.0


def test_a_side_unit_given_without_unit_still_converts(tmp_path: Path) -> None:
    """`ref_unit: m/s`, `sim_unit: km/h` and no `unit`: the model is converted to m/s (it was
    compared as is, 3.6× off)."""
    pytest.importorskip("pint")
    pd.DataFrame({"t": T, "v": V}).to_csv(tmp_path / "ref.csv", index=False)
    pd.DataFrame({"t": T, "v": V * 3.6}).to_csv(tmp_path / "sim.csv", index=False)
    spec = _spec(
        tmp_path,
        "path: ref.csv",
        "path: sim.csv",
        signal="{signal: v, ref_unit: m/s, sim_unit: km/h}",
    )
    found = _run(spec, tmp_path)
    (signal,) = found["signals"]
    assert signal["unit"] == "m/s"
    assert signal["mae"] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize(
    ("field", "text"),
    [
        ("signal", '"v\\nFAKE PASSED"'),
        ("signal", '"v\\rx"'),
        ("name", '"trust\\n::FAKE PASSED"'),
    ],
)
def test_a_name_that_would_print_a_forged_line_is_refused(field: str, text: str) -> None:
    from pytest_hevval.errors import SpecError
    from pytest_hevval.spec.load import parse_spec_text

    signal = text if field == "signal" else "v"
    name = text if field == "name" else "trust"
    spec = (
        f"name: {name}\nreference: {{path: ref.csv}}\nmodel: {{path: sim.csv}}\n"
        f"sets:\n  - {{signal: {signal}}}\n"
    )
    with pytest.raises(SpecError, match="printable") as error:
        parse_spec_text(spec, Path("/nowhere/trust.hevval.yaml"))
    assert error.value.line is not None


def test_a_model_that_calls_sys_exit_fails_the_run_with_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`sys.exit(0)` inside a model ended `hevval run` with exit code 0 and nothing scored."""
    pd.DataFrame({"t": T, "v": V}).to_csv(tmp_path / "ref.csv", index=False)
    (tmp_path / "quitter.py").write_text(
        "import sys\n\ndef model(frame):\n    sys.exit(0)\n", encoding="utf-8"
    )
    spec = _spec(tmp_path, "path: ref.csv", "callable: 'quitter:model'")
    code = cli.main(["run", str(spec), "--no-history", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert "the model called sys.exit(0) instead of returning its output" in err
    assert "model.callable" in err


def test_a_parquet_time_stamp_that_is_null_is_named_by_its_row(tmp_path: Path) -> None:
    """It was reported as "time is not increasing: t=-9.2e+09", with a RuntimeWarning."""
    pytest.importorskip("pyarrow")
    stamps = pd.Series(pd.date_range("2024-06-01", periods=50, freq="100ms", tz="UTC"))
    stamps[7] = pd.NaT
    path = tmp_path / "a.parquet"
    pd.DataFrame({"time": stamps, "v": np.arange(50.0)}).to_parquet(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning leaks either
        with pytest.raises(DataError, match="time is missing at index 7") as error:
            read_record(str(path), ["v"], SourceOptions())
    assert error.value.column == "time"


def test_a_column_one_spec_lacks_is_that_specs_error_only(tmp_path: Path) -> None:
    """Two specs read one file; the second names a column the file does not hold. The first is
    scored (every item of it errored too, since the file is read once for both)."""
    from pytest_hevval.scoring.engine import Evaluation
    from pytest_hevval.scoring.run import RunOptions, run_specs
    from pytest_hevval.spec.load import load_spec

    pd.DataFrame({"t": T, "v": V}).to_csv(tmp_path / "data.csv", index=False)
    good = tmp_path / "a.hevval.yaml"
    bad = tmp_path / "b.hevval.yaml"
    for path, signal in ((good, "{signal: v}"), (bad, "{signal: w, ref: missing, sim: v}")):
        path.write_text(
            f"reference: {{path: data.csv}}\nmodel: {{path: data.csv}}\nsets:\n  - {signal}\n",
            encoding="utf-8",
        )
    first, second = run_specs(
        [load_spec(good), load_spec(bad)], RunOptions(rootdir=tmp_path, intervals=False)
    )
    assert isinstance(first, Evaluation)
    assert first.result.passed
    assert isinstance(second, DataError)
    assert second.column == "missing"


@pytest.mark.parametrize("kind", ["external link", "external storage", "virtual dataset"])
def test_hdf5_data_in_another_file_is_refused(tmp_path: Path, kind: str) -> None:
    """A spec and its data come from the change the gate judges: an HDF5 file must not make
    hevval read, score and publish the bytes of a file the spec does not name."""
    h5py = pytest.importorskip("h5py")
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.txt").write_bytes(b"SECRET!!" * 100)
    with h5py.File(outside / "other.h5", "w") as other:
        other["v"] = np.arange(10.0)
    folder = tmp_path / "data"
    folder.mkdir()
    path = folder / "a.h5"
    with h5py.File(path, "w") as handle:
        handle["time"] = np.arange(10.0)
        if kind == "external link":
            handle["v"] = h5py.ExternalLink("../outside/other.h5", "/v")
        elif kind == "external storage":
            handle.create_dataset(
                "v", shape=(10,), dtype="f8", external=[("../outside/secret.txt", 0, 80)]
            )
        else:
            layout = h5py.VirtualLayout(shape=(10,), dtype="f8")
            layout[:] = h5py.VirtualSource(str(outside / "other.h5"), "v", shape=(10,))
            handle.create_virtual_dataset("v", layout)
    with pytest.raises(DataError, match="hevval reads only the data file the spec names") as error:
        read_record(str(path), None, SourceOptions())
    assert error.value.column == "v"
    assert "other.h5" in str(error.value) or "secret.txt" in str(error.value)


@pytest.mark.parametrize("suffix", ["h5", "mat"])
@pytest.mark.parametrize("time_scale", [None, 0.001])
def test_epoch_milliseconds_in_hdf5_and_mat_become_seconds_from_the_start(
    tmp_path: Path, suffix: str, time_scale: float | None
) -> None:
    """These readers took epoch numbers as a relative time base: milliseconds read as seconds
    (undetected under a day) or, with time_scale, absolute seconds at 1.7e9."""
    stamps = np.round((1.7e9 + np.arange(0.0, 60.0, 0.01)) * 1000)
    path = tmp_path / f"a.{suffix}"
    if suffix == "h5":
        h5py = pytest.importorskip("h5py")
        with h5py.File(path, "w") as handle:
            handle["time"] = stamps
            handle["v"] = V
    else:
        scipy_io = pytest.importorskip("scipy.io")
        scipy_io.savemat(path, {"time": stamps, "v": V})
    record = read_record(str(path), ["v"], SourceOptions(time_scale=time_scale))
    time = record.channels["v"].time
    assert time[0] == 0.0
    assert time[1] == pytest.approx(0.01)
    assert record.meta["start_epoch_s"] == pytest.approx(1.7e9)


def test_a_full_disk_is_an_error_naming_the_output_and_leaves_the_old_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import errno

    from pytest_hevval import files
    from pytest_hevval.errors import OutputError

    target = tmp_path / "out.json"
    target.write_text("old", encoding="utf-8")

    def full(*args: object, **kwargs: object) -> Path:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(files, "write_temporary", full)
    with pytest.raises(OutputError, match="cannot write it: No space left on device") as error:
        files.write_atomic(target, "new")
    assert error.value.file == str(target)
    assert "free some disk space" in str(error.value)
    assert target.read_text("utf-8") == "old"


def test_an_expression_error_names_the_side_it_is_on(tmp_path: Path) -> None:
    """An overflowing `ref:` expression was reported at `sim`."""
    from pytest_hevval.errors import ExpressionError

    pd.DataFrame({"t": T, "v": V}).to_csv(tmp_path / "ref.csv", index=False)
    pd.DataFrame({"t": T, "v": V}).to_csv(tmp_path / "sim.csv", index=False)
    spec = _spec(
        tmp_path, "path: ref.csv", "path: sim.csv", signal="{signal: w, ref: 'v ** 1e5', sim: v}"
    )
    from pytest_hevval.scoring.run import RunOptions, run_specs
    from pytest_hevval.spec.load import load_spec

    (outcome,) = run_specs([load_spec(spec)], RunOptions(rootdir=tmp_path, intervals=False))
    assert isinstance(outcome, ExpressionError)
    assert outcome.key == "sets[0].ref"


def test_an_hdf5_group_reached_through_a_link_into_another_file_is_refused(
    tmp_path: Path,
) -> None:
    """`group:` naming an external link, and the group listing of an error message, must not
    open the other file either (a named pipe there would hang the run)."""
    h5py = pytest.importorskip("h5py")
    with h5py.File(tmp_path / "other.h5", "w") as other:
        other["g/time"] = np.arange(10.0)
        other["g/v"] = np.arange(10.0)
    path = tmp_path / "a.h5"
    with h5py.File(path, "w") as handle:
        handle["time"] = np.arange(10.0)
        handle["elsewhere"] = h5py.ExternalLink(str(tmp_path / "other.h5"), "/g")
    with pytest.raises(DataError, match="leads through a link to '/g' in the file") as error:
        read_record(str(path), None, SourceOptions(group="elsewhere"))
    assert error.value.key == "group"
    with pytest.raises(DataError, match="no group 'nowhere'") as missing:
        read_record(str(path), None, SourceOptions(group="nowhere"))
    assert "elsewhere" not in str(missing.value)
