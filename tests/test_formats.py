"""Readers for every format, each fed files written by that format's own library."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pytest_hevval.data.readers import FORMATS, detect_format, read_record
from pytest_hevval.data.record import SourceOptions
from pytest_hevval.errors import DataError, HevvalError, MissingExtraError

OPTS = SourceOptions()

I3_HEADER = [
    "Time [s]",
    "Velocity [km/h]",
    "Regenerative Braking Signal ",
    "Battery Temperature [°C]",
    "max. SoC [%)",
]


def _write(path: Path, text: str, encoding: str = "utf-8") -> str:
    path.write_bytes(text.encode(encoding))
    return str(path)


def _signal_frame(n: int = 50) -> pd.DataFrame:
    t = np.arange(n) * 0.1
    frame: pd.DataFrame = pd.DataFrame(
        {
            "t": t,
            "speed": np.sin(t) * 20 + 30,
            "current": np.cos(t) * 100,
            "gear": (np.arange(n) // 10).astype(np.int64),
        }
    )
    return frame


# --------------------------------------------------------------------------------------------
# Dispatch


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("a.csv", "csv"),
        ("a.TXT", "csv"),
        ("a.tsv", "tsv"),
        ("a.tab", "tsv"),
        ("a.parquet", "parquet"),
        ("a.pq", "parquet"),
        ("a.mat", "mat"),
        ("a.h5", "hdf5"),
        ("a.hdf5", "hdf5"),
        ("a.hdf", "hdf5"),
        ("a.mf4", "mdf"),
        ("a.MDF", "mdf"),
    ],
)
def test_format_from_extension(name: str, expected: str) -> None:
    assert detect_format(name, OPTS) == expected


def test_format_option_wins_and_accepts_aliases() -> None:
    assert detect_format("data.bin", SourceOptions(format="parquet")) == "parquet"
    assert detect_format("data.csv", SourceOptions(format="H5")) == "hdf5"
    assert detect_format("data.csv", SourceOptions(format=".mf4")) == "mdf"


def test_unknown_format_option_suggests() -> None:
    with pytest.raises(DataError) as info:
        detect_format("data.bin", SourceOptions(format="parquett"))
    assert str(info.value) == (
        "data.bin: format: unknown format 'parquett'; did you mean 'parquet'? "
        "supported formats: csv, tsv, parquet, mat, hdf5, mdf, can, tdms"
    )


def test_unknown_extension_lists_formats(tmp_path: Path) -> None:
    path = _write(tmp_path / "log.xyz", "t,a\n0,1\n")
    with pytest.raises(DataError) as info:
        read_record(path, None, OPTS)
    message = str(info.value)
    assert message.startswith(f"{path}: cannot tell the file format from the extension '.xyz'")
    assert "set `format:` to one of csv, tsv, parquet, mat, hdf5, mdf" in message
    for exts in FORMATS.values():
        for ext in exts:
            assert ext in message


def test_format_override_reads_odd_extension(tmp_path: Path) -> None:
    path = _write(tmp_path / "log.xyz", "t,a\n0,1\n1,2\n")
    record = read_record(path, None, SourceOptions(format="csv"))
    np.testing.assert_array_equal(record.channels["a"].values, [1.0, 2.0])


# --------------------------------------------------------------------------------------------
# CSV


@pytest.mark.parametrize("engine", ["default", "c"])
def test_csv_reads_only_requested_columns(tmp_path: Path, engine: str) -> None:
    frame = _signal_frame()
    path = str(tmp_path / "run.csv")
    frame.to_csv(path, index=False)
    extra = {"csv_engine": "c"} if engine == "c" else {}
    record = read_record(path, ["current"], SourceOptions(extra=extra))
    assert list(record.channels) == ["current"]
    channel = record.channels["current"]
    assert channel.time.dtype == np.float64
    np.testing.assert_allclose(channel.time, frame["t"])
    np.testing.assert_allclose(channel.values, frame["current"])
    assert record.available == ("t", "speed", "current", "gear")
    assert record.numeric == ("speed", "current", "gear")
    assert record.meta["time_column"] == "t"
    assert record.meta["engine"] == ("c" if engine == "c" else "pyarrow")


def test_csv_all_numeric_columns_when_none_requested(tmp_path: Path) -> None:
    frame = _signal_frame()
    frame["label"] = "x"
    path = str(tmp_path / "run.csv")
    frame.to_csv(path, index=False)
    record = read_record(path, None, OPTS)
    assert list(record.channels) == ["speed", "current", "gear"]
    assert record.channels["gear"].values.dtype == np.float64
    assert "label" in record.available
    assert "label" not in record.numeric
    # One shared time array for a table: alignment can rely on identity.
    assert record.channels["speed"].time is record.channels["gear"].time


def test_csv_semicolon_decimal_comma_latin1(tmp_path: Path) -> None:
    frame = pd.DataFrame(
        {
            "Time [s]": [0.0, 0.1, 0.2],
            "Velocity [km/h]": [1.5, 2.25, 3.0],
            "Regenerative Braking Signal ": [0, 1, 0],
            "Battery Temperature [°C]": [21.5, 21.5, 21.75],
            "max. SoC [%)": [90.0, 90.0, 90.0],
        }
    )
    path = str(tmp_path / "trip.csv")
    frame.to_csv(path, sep=";", decimal=",", encoding="latin-1", index=False)
    assert b"\xb0C" in Path(path).read_bytes()  # the header really is Latin-1
    record = read_record(path, I3_HEADER[1:], SourceOptions(decimal=","))
    assert record.available == tuple(I3_HEADER)
    assert record.meta["sep"] == ";"
    assert record.meta["encoding"] == "latin-1"
    np.testing.assert_allclose(record.channels["Velocity [km/h]"].values, [1.5, 2.25, 3.0])
    np.testing.assert_allclose(record.channels["Battery Temperature [°C]"].values[-1], 21.75)
    assert record.channels["Velocity [km/h]"].unit == "km/h"
    assert record.channels["Regenerative Braking Signal "].unit is None


def test_csv_trailing_space_header_is_suggested(tmp_path: Path) -> None:
    path = _write(tmp_path / "trip.csv", "Time [s];Regenerative Braking Signal \n0;1\n", "latin-1")
    with pytest.raises(DataError) as info:
        read_record(path, ["Regenerative Braking Signal"], OPTS)
    assert str(info.value) == (
        f"{path}: column 'Regenerative Braking Signal': no such column in this file; "
        "did you mean 'Regenerative Braking Signal '?"
    )


def test_csv_explicit_encoding_and_sep(tmp_path: Path) -> None:
    path = _write(tmp_path / "trip.txt", "zeit|Temp [°C]\n0|1\n1|2\n", "cp1252")
    record = read_record(path, ["Temp [°C]"], SourceOptions(sep="|", encoding="cp1252"))
    assert record.meta["time_column"] == "zeit"
    np.testing.assert_allclose(record.channels["Temp [°C]"].values, [1.0, 2.0])


def test_csv_utf8_header_kept(tmp_path: Path) -> None:
    path = _write(tmp_path / "a.csv", "\ufefftime,Temp [°C]\n0,1\n1,2\n")
    record = read_record(path, None, OPTS)
    assert record.available == ("time", "Temp [°C]")


def test_csv_duplicate_headers_are_renamed(tmp_path: Path) -> None:
    path = _write(tmp_path / "b.csv", "t;Vent [°C];Vent [°C]\n0;1;5\n1;2;6\n", "latin-1")
    record = read_record(path, ["Vent [°C]", "Vent [°C].1"], OPTS)
    np.testing.assert_allclose(record.channels["Vent [°C]"].values, [1, 2])
    np.testing.assert_allclose(record.channels["Vent [°C].1"].values, [5, 6])
    assert record.meta["renamed_duplicates"] == {"Vent [°C].1": "Vent [°C]"}


def test_csv_regex_separator(tmp_path: Path) -> None:
    path = _write(tmp_path / "a.txt", "time   speed\n0  1.5\n1 2.5\n")
    record = read_record(path, None, SourceOptions(sep=r"\s+"))
    np.testing.assert_allclose(record.channels["speed"].values, [1.5, 2.5])
    assert record.meta["engine"] == "python"


def test_tsv_and_time_scale(tmp_path: Path) -> None:
    frame = pd.DataFrame({"time_ms": [0, 100, 200, 300], "v": [1.0, 2.0, 3.0, 4.0]})
    path = str(tmp_path / "run.tsv")
    frame.to_csv(path, sep="\t", index=False)
    record = read_record(path, ["v"], SourceOptions(time_scale=0.001))
    np.testing.assert_allclose(record.channels["v"].time, [0.0, 0.1, 0.2, 0.3])


def test_csv_time_option_and_nan_values_kept(tmp_path: Path) -> None:
    path = _write(tmp_path / "a.csv", "x,stamp,y\n5,0,1\n6,1,\n7,2,3\n")
    record = read_record(path, ["x", "y"], SourceOptions(time="stamp"))
    np.testing.assert_allclose(record.channels["y"].values, [1.0, np.nan, 3.0])
    np.testing.assert_allclose(record.channels["x"].time, [0, 1, 2])


def test_csv_without_time_name_uses_first_column(tmp_path: Path) -> None:
    path = _write(tmp_path / "a.csv", "clock,y\n0,1\n1,2\n")
    assert read_record(path, None, OPTS).meta["time_column"] == "clock"


def test_csv_engines_agree(tmp_path: Path) -> None:
    frame = _signal_frame(500)
    path = str(tmp_path / "run.csv")
    frame.to_csv(path, index=False, float_format="%.9g")
    fast = read_record(path, None, OPTS)
    slow = read_record(path, None, SourceOptions(extra={"csv_engine": "c"}))
    assert fast.available == slow.available
    for name, channel in fast.channels.items():
        np.testing.assert_array_equal(channel.values, slow.channels[name].values)
        np.testing.assert_array_equal(channel.time, slow.channels[name].time)


# --------------------------------------------------------------------------------------------
# Parquet


def _write_parquet(path: Path, n: int = 40) -> str:
    import pyarrow as pa
    import pyarrow.parquet as pq

    t = np.arange(n) * 0.01
    table = pa.table(
        {
            "time": pa.array(t),
            "speed": pa.array(np.sin(t), type=pa.float32()),
            "torque": pa.array(np.cos(t)),
            "gear": pa.array(np.arange(n) % 5, type=pa.int16()),
            "flag": pa.array([i % 2 == 0 for i in range(n)]),
            "soc": pa.array([None if i % 7 == 0 else float(i) for i in range(n)]),
            "name": pa.array(["a"] * n),
        }
    )
    pq.write_table(table, path)
    return str(path)


def test_parquet_dtypes_and_subset(tmp_path: Path) -> None:
    path = _write_parquet(tmp_path / "run.parquet")
    record = read_record(path, ["speed", "gear", "soc"], OPTS)
    assert list(record.channels) == ["speed", "gear", "soc"]
    assert record.channels["speed"].values.dtype == np.float32
    assert record.channels["gear"].values.dtype == np.float64
    np.testing.assert_array_equal(record.channels["gear"].values[:6], [0, 1, 2, 3, 4, 0])
    assert np.isnan(record.channels["soc"].values[0])
    assert record.channels["soc"].values[1] == 1.0
    assert record.available == ("time", "speed", "torque", "gear", "flag", "soc", "name")
    assert record.numeric == ("speed", "torque", "gear", "flag", "soc")


def test_parquet_all_numeric(tmp_path: Path) -> None:
    path = _write_parquet(tmp_path / "run.pq")
    record = read_record(path, None, OPTS)
    assert list(record.channels) == ["speed", "torque", "gear", "flag", "soc"]
    np.testing.assert_allclose(record.channels["torque"].time[:3], [0.0, 0.01, 0.02])


@pytest.mark.parametrize("batch_bytes", [1, 8 * 40 * 2, 64 << 20])
def test_parquet_read_a_few_columns_at_a_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, batch_bytes: int
) -> None:
    # Columns are read in batches (one column, two, or all at once) and come back in the
    # order asked, the time column included when a spec asks for it as a signal.
    import pyarrow as pa

    from pytest_hevval.data.readers import parquet

    monkeypatch.setattr(parquet, "_PARQUET_BATCH_BYTES", batch_bytes)
    path = _write_parquet(tmp_path / "run.parquet", n=40)
    pool_before = pa.default_memory_pool().backend_name
    record = read_record(path, ["soc", "time", "gear", "speed", "flag"], OPTS)
    # The read borrows another allocator and gives pyarrow's default back.
    assert pa.default_memory_pool().backend_name == pool_before
    frame = pd.read_parquet(path)
    assert list(record.channels) == ["soc", "time", "gear", "speed", "flag"]
    for name in record.channels:
        np.testing.assert_array_equal(
            record.channels[name].values, frame[name].to_numpy(dtype=np.float64, na_value=np.nan)
        )
    assert record.channels["speed"].values.dtype == np.float32


def test_parquet_reads_in_threads_give_pyarrow_its_pool_back(tmp_path: Path) -> None:
    # The borrowed allocator is process-wide; overlapping reads must not leave it behind.
    from concurrent.futures import ThreadPoolExecutor

    import pyarrow as pa

    path = _write_parquet(tmp_path / "run.parquet", n=2000)
    before = pa.default_memory_pool().backend_name
    with ThreadPoolExecutor(max_workers=4) as pool:
        records = list(pool.map(lambda _: read_record(path, ["torque"], OPTS), range(40)))
    assert pa.default_memory_pool().backend_name == before
    assert all(r.channels["torque"].values.shape == (2000,) for r in records)


def test_parquet_timestamp_time_becomes_seconds(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    stamps = pd.date_range("2024-01-01", periods=4, freq="250ms").as_unit("ns")
    table = pa.table({"time": pa.array(stamps), "v": pa.array([1.0, 2.0, 3.0, 4.0])})
    path = str(tmp_path / "run.parquet")
    pq.write_table(table, path)
    record = read_record(path, ["v"], OPTS)
    np.testing.assert_allclose(record.channels["v"].time, [0.0, 0.25, 0.5, 0.75])


def test_parquet_text_column_rejected(tmp_path: Path) -> None:
    path = _write_parquet(tmp_path / "run.parquet")
    with pytest.raises(DataError) as info:
        read_record(path, ["name"], OPTS)
    assert str(info.value) == (
        f"{path}: column 'name': holds string, not numbers; choose a numeric column"
    )


# --------------------------------------------------------------------------------------------
# HDF5


def test_hdf5_root_and_group(tmp_path: Path) -> None:
    import h5py

    path = str(tmp_path / "run.h5")
    t = np.linspace(0, 1, 11)
    with h5py.File(path, "w") as f:
        f["time"] = t
        f["speed"] = np.sin(t).astype(np.float32)
        f["speed"].attrs["unit"] = "m/s"
        f["count"] = np.arange(11, dtype=np.int32)
        f["image"] = np.zeros((3, 3))
        g = f.create_group("slow")
        g["t"] = t[::2]
        g["temp"] = t[::2] * 10
    record = read_record(path, None, OPTS)
    assert set(record.channels) == {"speed", "count"}
    assert record.channels["speed"].values.dtype == np.float32
    assert record.channels["speed"].unit == "m/s"
    assert record.channels["count"].values.dtype == np.float64
    assert "image" not in record.available

    slow = read_record(path, ["temp"], SourceOptions(group="slow"))
    np.testing.assert_allclose(slow.channels["temp"].time, t[::2])
    assert slow.meta["group"] == "/slow"


def test_hdf5_length_mismatch(tmp_path: Path) -> None:
    import h5py

    path = str(tmp_path / "run.hdf5")
    with h5py.File(path, "w") as f:
        f["time"] = np.arange(5.0)
        f["v"] = np.arange(4.0)
    with pytest.raises(DataError) as info:
        read_record(path, ["v"], OPTS)
    assert str(info.value) == (
        f"{path}: column 'v': has 4 samples but the time column 'time' has 5; channels of a "
        "table must share its time column; store channels with other rates in a group of "
        "their own"
    )


def test_hdf5_missing_group_suggests(tmp_path: Path) -> None:
    import h5py

    path = str(tmp_path / "run.h5")
    with h5py.File(path, "w") as f:
        f.create_group("signals")["time"] = np.arange(3.0)
    with pytest.raises(DataError) as info:
        read_record(path, None, SourceOptions(group="signal"))
    assert str(info.value) == (
        f"{path}: group: no group 'signal' in this file; did you mean 'signals'?"
    )


def test_hdf5_without_vectors_explains_layout(tmp_path: Path) -> None:
    import h5py

    path = str(tmp_path / "store.h5")
    with h5py.File(path, "w") as f:
        f.create_group("df")["block0_values"] = np.zeros((4, 2))
    with pytest.raises(DataError) as info:
        read_record(path, None, OPTS)
    assert str(info.value) == (
        f"{path}: group: no 1-D datasets in the file root; store one 1-D dataset per channel "
        "plus a time dataset, or set `group:` to one of: 'df'; pandas HDFStore files are not "
        "supported: write Parquet instead"
    )


# --------------------------------------------------------------------------------------------
# MAT


def test_mat_v5_variables(tmp_path: Path) -> None:
    from scipy.io import savemat

    path = str(tmp_path / "run.mat")
    t = np.arange(20) * 0.05
    savemat(
        path,
        {
            "t": t.reshape(-1, 1),
            "u": np.sin(t).astype(np.float32),
            "n": np.arange(20, dtype=np.int32),
            "label": "hello",
            "matrix": np.zeros((3, 3)),
            "mass": 1500.0,
            "other_rate": np.arange(7.0),
        },
    )
    record = read_record(path, None, OPTS)
    # Scalars (parameters) and vectors of another length are not channels of this table.
    assert set(record.channels) == {"u", "n"}
    assert set(record.numeric) == {"u", "n"}
    assert {"mass", "other_rate", "label"} <= set(record.available)
    assert record.channels["u"].values.dtype == np.float32
    assert record.channels["n"].values.dtype == np.float64
    np.testing.assert_allclose(record.channels["u"].time, t)
    assert record.meta["mat_version"] == "5"
    with pytest.raises(DataError) as info:
        read_record(path, ["label"], OPTS)
    assert str(info.value) == (
        f"{path}: column 'label': holds a MATLAB char, not numbers; choose a numeric variable"
    )


def test_mat_v5_struct(tmp_path: Path) -> None:
    from scipy.io import savemat

    path = str(tmp_path / "run.mat")
    t = np.arange(10) * 0.1
    savemat(path, {"log": {"inner": {"time": t, "speed": t * 2, "note": "x"}}, "other": 1.0})
    record = read_record(path, ["speed"], SourceOptions(group="log.inner"))
    np.testing.assert_allclose(record.channels["speed"].values, t * 2)
    assert record.available == ("time", "speed")

    with pytest.raises(DataError) as info:
        read_record(path, None, OPTS)
    assert "set `group:` to the struct that holds the channels: 'log'" in str(info.value)


def test_mat_v73_hdf5(tmp_path: Path) -> None:
    import h5py

    path = str(tmp_path / "run.mat")
    t = np.arange(30) * 0.1
    # MATLAB's v7.3 layout: a 512-byte text header, vectors stored as 1xN matrices,
    # class names in attributes and structs as groups.
    with h5py.File(path, "w", userblock_size=512) as f:
        f["t"] = t.reshape(1, -1)
        f["t"].attrs["MATLAB_class"] = np.bytes_(b"double")
        f["v"] = np.cos(t).reshape(-1, 1).astype(np.float32)
        f["name"] = np.array([[104], [105]], dtype=np.uint16)
        f["name"].attrs["MATLAB_class"] = np.bytes_(b"char")
        s = f.create_group("bus")
        s["time"] = t[::3].reshape(1, -1)
        s["torque"] = (t[::3] * 5).reshape(1, -1)
    with open(path, "r+b") as stream:
        stream.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64".ljust(116, b" "))
    record = read_record(path, None, OPTS)
    assert record.meta["mat_version"] == "7.3"
    assert list(record.channels) == ["v"]
    assert record.channels["v"].values.dtype == np.float32
    np.testing.assert_allclose(record.channels["v"].time, t)
    assert "name" in record.available
    assert "name" not in record.numeric

    bus = read_record(path, ["torque"], SourceOptions(group="bus"))
    np.testing.assert_allclose(bus.channels["torque"].values, t[::3] * 5)


# --------------------------------------------------------------------------------------------
# MDF


def _write_mf4(path: Path) -> str:
    from asammdf import MDF, Signal

    fast_t = np.arange(0, 2, 0.01)
    slow_t = np.arange(0, 2, 0.1)
    with MDF(version="4.10") as mdf:
        mdf.append([Signal(np.sin(fast_t).astype(np.float32), fast_t, name="Speed", unit="km/h")])
        mdf.append(
            [
                Signal(np.cos(slow_t), slow_t, name="SoC", unit="%"),
                Signal(np.arange(slow_t.size, dtype=np.int16), slow_t, name="Gear"),
            ]
        )
        mdf.save(str(path), overwrite=True)
    return str(path)


def test_mdf_channels_keep_their_rates(tmp_path: Path) -> None:
    path = _write_mf4(tmp_path / "log.mf4")
    record = read_record(path, ["Speed", "SoC"], SourceOptions(time="ignored"))
    speed, soc = record.channels["Speed"], record.channels["SoC"]
    assert speed.time.size == 200
    assert soc.time.size == 20
    np.testing.assert_allclose(np.diff(speed.time), 0.01, atol=1e-12)
    np.testing.assert_allclose(soc.values, np.cos(np.arange(0, 2, 0.1)))
    assert speed.values.dtype == np.float32
    assert speed.unit == "km/h"
    assert soc.unit == "%"
    assert record.available == ("Speed", "SoC", "Gear")


def test_mdf_all_numeric_and_time_scale(tmp_path: Path) -> None:
    path = _write_mf4(tmp_path / "log.mf4")
    record = read_record(path, None, SourceOptions(time_scale=2.0))
    assert list(record.channels) == ["Speed", "SoC", "Gear"]
    assert record.channels["Gear"].values.dtype == np.float64
    assert record.channels["Gear"].time[-1] == pytest.approx(3.8)


def test_mdf_missing_channel_suggests(tmp_path: Path) -> None:
    path = _write_mf4(tmp_path / "log.mf4")
    with pytest.raises(DataError) as info:
        read_record(path, ["speed"], OPTS)
    assert str(info.value) == (
        f"{path}: column 'speed': no such column in this file; did you mean 'Speed'?"
    )


def _select_all(path: str) -> dict[str, tuple[np.ndarray, np.ndarray, str]]:
    """Every channel as asammdf's own ``select`` returns it (the reference for the streamer)."""
    from asammdf import MDF

    out = {}
    with MDF(path) as mdf:
        for group_index, group in enumerate(mdf.groups):
            master = mdf.masters_db.get(group_index)
            for index, channel in enumerate(group.channels):
                if index != master:
                    (signal,) = mdf.select([(channel.name, group_index, index)])
                    out[channel.name] = (signal.samples, signal.timestamps, signal.unit)
    return out


def _mdf_plans(path: str) -> list[object]:
    from asammdf import MDF

    from pytest_hevval.data.readers.mdf import _plain_mdf_plan

    with MDF(path) as mdf:
        return [
            _plain_mdf_plan(
                mdf,
                str(mdf.version),
                group_index,
                [i for i in range(len(group.channels)) if i != mdf.masters_db.get(group_index)],
            )
            for group_index, group in enumerate(mdf.groups)
        ]


@pytest.mark.parametrize("stream_bytes", [1, 100, 32 << 20])
def test_mdf_records_streamed_equal_asammdf_select(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, stream_bytes: int
) -> None:
    # Plain groups are streamed record by record (a record may straddle the buffer's end);
    # the result must be asammdf's own, value for value, dtype for dtype.
    from asammdf import MDF, Signal

    from pytest_hevval.data.readers import mdf as formats

    monkeypatch.setattr(formats, "_MDF_STREAM_BYTES", stream_bytes)
    t = np.arange(0, 30, 0.01)
    path = tmp_path / "plain.mf4"
    with MDF(version="4.10") as mdf:
        mdf.append(
            [
                Signal(np.sin(t), t, name="v", unit="km/h"),
                Signal(np.cos(t).astype(np.float32), t, name="w"),
                Signal((t * 10).astype(np.int16), t, name="gear"),
                Signal((t * 3).astype(np.uint8), t, name="flag"),
            ]
        )
        slow = t[::7]
        mdf.append([Signal(slow * 2.0, slow, name="soc", unit="%")])
        mdf.save(str(path), overwrite=True)
    assert all(plan is not None for plan in _mdf_plans(str(path)))
    expected = _select_all(str(path))
    record = read_record(str(path), None, OPTS)
    assert list(record.channels) == list(expected)
    for name, (samples, timestamps, unit) in expected.items():
        channel = record.channels[name]
        np.testing.assert_array_equal(channel.values, samples.astype(channel.values.dtype))
        np.testing.assert_array_equal(channel.time, timestamps)
        assert channel.unit == (unit or None)
    assert record.channels["w"].values.dtype == np.float32
    assert record.channels["v"].time is record.channels["gear"].time


def test_mdf_groups_that_are_not_plain_go_through_asammdf(tmp_path: Path) -> None:
    # A conversion, or compressed data blocks, leave the reading to asammdf's select.
    from asammdf import MDF, Signal

    t = np.arange(0, 5, 0.01)
    path = tmp_path / "converted.mf4"
    with MDF(version="4.10") as mdf:
        raw = Signal(
            np.arange(t.size, dtype=np.uint16),
            t,
            name="temp",
            conversion={"a": 0.5, "b": -40.0},
        )
        mdf.append([raw])
        mdf.append([Signal(np.sin(t), t, name="v")])
        mdf.save(str(path), overwrite=True)
    plans = _mdf_plans(str(path))
    assert plans[0] is None
    assert plans[1] is not None
    record = read_record(str(path), None, OPTS)
    np.testing.assert_allclose(record.channels["temp"].values, np.arange(t.size) * 0.5 - 40.0)
    np.testing.assert_array_equal(record.channels["v"].values, np.sin(t))

    packed = tmp_path / "packed.mf4"
    with MDF(str(path)) as mdf:
        mdf.save(str(packed), overwrite=True, compression=2)
    assert _mdf_plans(str(packed)) == [None, None]
    again = read_record(str(packed), None, OPTS)
    np.testing.assert_array_equal(again.channels["v"].values, np.sin(t))


def test_mdf_data_block_cut_short_is_a_data_error(tmp_path: Path) -> None:
    from asammdf import MDF, Signal

    from pytest_hevval.data.readers import mdf as formats

    t = np.arange(0, 30, 0.01)
    path = tmp_path / "log.mf4"
    with MDF(version="4.10") as mdf:
        mdf.append([Signal(np.sin(t), t, name="v")])
        mdf.save(str(path), overwrite=True)
    with MDF(str(path)) as mdf:
        plan = formats._plain_mdf_plan(mdf, "4.10", 0, [1])
    assert plan is not None
    address, size = plan.segments[0]
    cut = tmp_path / "cut.mf4"
    cut.write_bytes(path.read_bytes()[: address + size // 2])
    with pytest.raises(DataError, match="ends past the end of the file"):
        formats._read_plain_mdf(str(cut), plan)


# --------------------------------------------------------------------------------------------
# The bad-data corpus: every error a user can cause, with the exact message.

Builder = Callable[[Path], tuple[str, list[str] | None, SourceOptions]]


def _csv(name: str, text: str, columns: list[str] | None = None, **opts: object) -> Builder:
    def build(tmp: Path) -> tuple[str, list[str] | None, SourceOptions]:
        return _write(tmp / name, text), columns, SourceOptions(**opts)  # type: ignore[arg-type]

    return build


def _missing(tmp: Path) -> tuple[str, list[str] | None, SourceOptions]:
    return str(tmp / "nope.csv"), None, OPTS


def _truncated_parquet(tmp: Path) -> tuple[str, list[str] | None, SourceOptions]:
    full = Path(_write_parquet(tmp / "full.parquet")).read_bytes()
    path = tmp / "cut.parquet"
    path.write_bytes(full[: len(full) // 2])
    (tmp / "full.parquet").unlink()
    return str(path), None, OPTS


def _truncated_mf4(tmp: Path) -> tuple[str, list[str] | None, SourceOptions]:
    full = Path(_write_mf4(tmp / "full.mf4")).read_bytes()
    path = tmp / "cut.mf4"
    path.write_bytes(full[: len(full) // 2])
    (tmp / "full.mf4").unlink()
    return str(path), None, OPTS


def _garbage_mat(tmp: Path) -> tuple[str, list[str] | None, SourceOptions]:
    path = tmp / "bad.mat"
    path.write_bytes(b"MATLAB 5.0 MAT-file" + bytes(200))
    return str(path), None, OPTS


def _garbage_hdf5(tmp: Path) -> tuple[str, list[str] | None, SourceOptions]:
    path = tmp / "bad.h5"
    path.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(100))
    return str(path), None, OPTS


MS_ROWS = "".join(f"{i * 100},{i}\n" for i in range(1000))

# (id, builder, expected message with {path} for the file, column named or None)
CORPUS: list[tuple[str, Builder, str, str | None]] = [
    (
        "missing-file",
        _missing,
        "{path}: file not found; check the path (the current directory is {cwd})",
        None,
    ),
    (
        "empty-file",
        _csv("empty.csv", ""),
        "{path}: the file is empty (0 bytes); export the data again as csv",
        None,
    ),
    (
        "blank-file",
        _csv("blank.csv", "\n\n  \n"),
        "{path}: the file holds no header line, only blank space; check that the export finished",
        None,
    ),
    (
        "header-only",
        _csv("head.csv", "t,a\n", ["a"]),
        "{path}: the file has a header but no data rows; check that the export finished",
        None,
    ),
    (
        "wrong-separator",
        _csv("semi.csv", "t;a;b\n0;1;2\n", ["a"], sep=","),
        "{path}: found 1 column 't;a;b' using separator ',' (the header looks ';'-separated); "
        "set `sep:` to the file's separator",
        None,
    ),
    (
        "missing-column",
        _csv("a.csv", "time,speed,torque\n0,1,2\n1,2,3\n", ["sped"]),
        "{path}: column 'sped': no such column in this file; did you mean 'speed'?",
        "sped",
    ),
    (
        "missing-column-no-near-name",
        _csv("a.csv", "time,speed\n0,1\n1,2\n", ["zzz"]),
        "{path}: column 'zzz': no such column in this file; the file has 2 columns: "
        "'time', 'speed'",
        "zzz",
    ),
    (
        "missing-time-column",
        _csv("a.csv", "time,speed\n0,1\n1,2\n", ["speed"], time="Time"),
        "{path}: column 'Time': no time column with this name; did you mean 'time'? set "
        "`time:` to the name of the time column",
        "Time",
    ),
    (
        "non-numeric-cell",
        _csv("a.csv", "t,v\n0,1\n1,2\n2,oops\n", ["v"]),
        "{path}:4: column 'v': non-numeric value 'oops' at index 2; fix or remove that cell",
        "v",
    ),
    (
        "decimal-comma",
        _csv("a.csv", "t;v\n0;1,5\n1;2,5\n", ["v"]),
        "{path}:2: column 'v': non-numeric value '1,5' at index 0; the file seems to use ',' "
        'as decimal mark: set `decimal: ","`',
        "v",
    ),
    (
        "non-numeric-time",
        _csv("a.csv", "t,v\n0,1\nnoon,2\n", ["v"]),
        "{path}:3: column 't': non-numeric value 'noon' at index 1; fix or remove that cell",
        "t",
    ),
    (
        "time-backwards",
        _csv("a.csv", "t,v\n0,1\n2,2\n1,3\n", ["v"]),
        "{path}:4: column 't': time is not increasing: t=1 at index 2 follows t=2 at index 1; "
        "sort the data by time and drop repeated rows",
        "t",
    ),
    (
        "time-duplicate",
        _csv("a.csv", "t,v\n0,1\n0.5,2\n0.5,3\n", ["v"]),
        "{path}:4: column 't': duplicate timestamp t=0.5 at index 1 and 2; sort the data by "
        "time and drop repeated rows",
        "t",
    ),
    (
        "time-nan",
        _csv("a.csv", "t,v\n0,1\n,2\n2,3\n", ["v"]),
        "{path}:3: column 't': time is missing or not finite at index 1 (value nan); remove "
        "that row or fill in its time",
        "t",
    ),
    (
        "time-in-ms",
        _csv("a.csv", "time,v\n" + MS_ROWS, ["v"]),
        "{path}: column 'time': time looks like milliseconds, not seconds: whole numbers with a "
        "median step of 100 and a span of 99900 s (1.2 days); set `time_scale: 0.001` (or "
        "`check_time_unit: false` if the data really are seconds)",
        "time",
    ),
    (
        "latin1-declared-utf8",
        _csv("a.csv", "t,v\n0,1\n", ["v"], encoding="utf-8"),
        "",  # replaced below: needs bytes that are not UTF-8
        None,
    ),
    (
        "truncated-parquet",
        _truncated_parquet,
        "{path}: cannot read this Parquet file (file truncated or corrupt?); write the file "
        "again; the reader said: ",
        None,
    ),
    (
        "truncated-mf4",
        _truncated_mf4,
        "{path}: cannot read this MDF file (file truncated or corrupt?); write the file again; "
        "the reader said: ",
        None,
    ),
    (
        "corrupt-mat",
        _garbage_mat,
        "{path}: cannot read this MAT file (file truncated or corrupt?); write the file again; "
        "the reader said: ",
        None,
    ),
    (
        "corrupt-hdf5",
        _garbage_hdf5,
        "{path}: cannot read this HDF5 file (file truncated or corrupt?); write the file again; "
        "the reader said: ",
        None,
    ),
]


def _latin1_declared_utf8(tmp: Path) -> tuple[str, list[str] | None, SourceOptions]:
    path = _write(tmp / "a.csv", "t,Temp [°C]\n0,1\n1,2\n", "latin-1")
    return path, ["Temp [°C]"], SourceOptions(encoding="utf-8")


CORPUS[[c[0] for c in CORPUS].index("latin1-declared-utf8")] = (
    "latin1-declared-utf8",
    _latin1_declared_utf8,
    "{path}: cannot decode the file as utf-8 (invalid start byte); set `encoding:` "
    "(for example latin-1 or cp1252)",
    None,
)

# Messages that end in the library's own words: only the prefix is ours to pin.
_PREFIX_ONLY = {"truncated-parquet", "truncated-mf4", "corrupt-mat", "corrupt-hdf5"}


@pytest.mark.parametrize(
    ("builder", "expected", "column"),
    [pytest.param(b, e, c, id=i) for i, b, e, c in CORPUS],
)
def test_bad_data_corpus(
    tmp_path: Path, builder: Builder, expected: str, column: str | None
) -> None:
    path, columns, options = builder(tmp_path)
    before = sorted(os.listdir(tmp_path))
    with pytest.raises(DataError) as info:
        read_record(path, columns, options)
    error = info.value
    message = str(error)
    want = expected.format(path=path, cwd=os.getcwd())
    if want.endswith("the reader said: "):
        assert message.startswith(want)
        assert len(message) > len(want)
    else:
        assert message == want
    assert error.file == path
    assert error.column == column
    assert sorted(os.listdir(tmp_path)) == before, "reading must not write files"
    assert isinstance(error, HevvalError)
    assert "Traceback" not in message


def test_corpus_covers_every_prefix_only_case() -> None:
    ids = {c[0] for c in CORPUS}
    assert ids >= _PREFIX_ONLY


def test_time_unit_check_can_be_disabled(tmp_path: Path) -> None:
    path = _write(tmp_path / "a.csv", "time,v\n" + MS_ROWS)
    record = read_record(path, ["v"], SourceOptions(extra={"check_time_unit": False}))
    assert record.channels["v"].time[-1] == 99900.0
    scaled = read_record(path, ["v"], SourceOptions(time_scale=0.001))
    assert scaled.channels["v"].time[-1] == pytest.approx(99.9)


def test_seconds_files_pass_the_unit_check(tmp_path: Path) -> None:
    # A 1 Hz dyno log with whole-second stamps, like the ANL files: under a day, accepted.
    rows = "".join(f"{float(i)},{i % 7}\n" for i in range(1, 3600))
    path = _write(tmp_path / "dyno.txt", "Time[s],Dyno_Spd[mph]\n-0.0,0\n" + rows)
    record = read_record(path, None, OPTS)
    assert record.channels["Dyno_Spd[mph]"].unit == "mph"
    assert record.channels["Dyno_Spd[mph]"].time[-1] == 3599.0


def test_errors_pickle(tmp_path: Path) -> None:
    import pickle

    path, columns, options = _csv("a.csv", "t,v\n0,1\n1,x\n", ["v"])(tmp_path)
    with pytest.raises(DataError) as info:
        read_record(path, columns, options)
    clone = pickle.loads(pickle.dumps(info.value))
    assert str(clone) == str(info.value)


@pytest.mark.parametrize(
    ("name", "module", "extra"),
    [
        ("run.parquet", "pyarrow", "parquet"),
        ("run.h5", "h5py", "hdf5"),
        ("run.mf4", "asammdf", "mdf"),
    ],
)
def test_missing_library_names_the_extra(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, module: str, extra: str
) -> None:
    path = tmp_path / name
    path.write_bytes(b"not empty")
    monkeypatch.setitem(sys.modules, module, None)
    with pytest.raises(MissingExtraError) as info:
        read_record(str(path), None, OPTS)
    message = str(info.value)
    assert message.startswith(f"{path}: ")
    assert f"needs the optional package {module!r}" in message
    assert message.endswith(f"install it with: pip install 'pytest-hevval[{extra}]'")


def test_a_header_with_nul_bytes_is_a_data_error(tmp_path: Path) -> None:
    # UTF-16 text without a declared encoding: Python 3.10's csv module raises on the NUL bytes.
    path = tmp_path / "utf16.csv"
    path.write_bytes(b"\xff\xfet\x00i\x00m\x00e\x00")
    with pytest.raises(DataError) as caught:
        read_record(str(path), None, SourceOptions())
    assert str(path) in str(caught.value)
