"""TDMS files (npTDMS): waveform and table channels, groups, units, absolute start, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pytest_hevval.data.readers import read_record
from pytest_hevval.data.record import SourceOptions
from pytest_hevval.errors import DataError

nptdms = pytest.importorskip("nptdms")
START = np.datetime64("2024-03-05T08:15:30.250000")


def _write(path: Path, *groups: tuple[str, list[object]]) -> Path:
    objects: list[object] = []
    for name, channels in groups:
        objects.append(nptdms.GroupObject(name))
        objects.extend(channels)
    with nptdms.TdmsWriter(str(path)) as writer:
        writer.write_segment(objects)
    return path


def _waveform(group: str, name: str, values: np.ndarray, step: float, unit: str) -> object:
    properties = {
        "wf_increment": step,
        "wf_start_offset": 0.5,
        "wf_start_time": START,
        "unit_string": unit,
    }
    return nptdms.ChannelObject(group, name, values, properties=properties)


def test_waveform_channels_keep_their_own_time_base(tmp_path: Path) -> None:
    fast = np.sin(np.arange(100) / 10.0)
    slow = np.arange(10, dtype=np.float64)
    path = _write(
        tmp_path / "bench.tdms",
        (
            "Bench",
            [
                _waveform("Bench", "torque", fast, 0.01, "N·m"),
                _waveform("Bench", "temp", slow, 0.1, "degC"),
            ],
        ),
    )
    record = read_record(str(path), ["torque", "temp"], SourceOptions())
    torque = record.channels["torque"]
    np.testing.assert_array_equal(torque.values, fast)
    np.testing.assert_allclose(torque.time, 0.5 + 0.01 * np.arange(100), rtol=0, atol=1e-12)
    assert torque.unit == "N·m"
    assert record.channels["temp"].time[-1] == pytest.approx(0.5 + 0.9)
    assert record.meta["format"] == "tdms"
    assert record.meta["absolute_start"] == "2024-03-05T08:15:30.250000+00:00"
    assert record.meta["start_epoch_s"] == pytest.approx(1709626530.25)


def test_table_channels_share_the_group_time_channel(tmp_path: Path) -> None:
    t = np.arange(50) * 0.02
    path = _write(
        tmp_path / "log.tdms",
        (
            "Log",
            [
                nptdms.ChannelObject("Log", "Time", t),
                nptdms.ChannelObject("Log", "speed", 3.0 * t, properties={"unit_string": "km/h"}),
            ],
        ),
    )
    record = read_record(str(path), ["speed"], SourceOptions())
    np.testing.assert_array_equal(record.channels["speed"].time, t)
    np.testing.assert_array_equal(record.channels["speed"].values, 3.0 * t)
    assert "start_epoch_s" not in record.meta


def test_groups_are_chosen_by_name(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "two.tdms",
        ("A", [_waveform("A", "x", np.zeros(5), 0.1, "V")]),
        ("B", [_waveform("B", "x", np.ones(5), 0.1, "V")]),
    )
    with pytest.raises(DataError) as caught:
        read_record(str(path), ["x"], SourceOptions())
    assert str(caught.value) == (
        f"{path}: group: the TDMS file holds 2 groups of channels; set `group:` to one of A, B"
    )
    assert read_record(str(path), ["x"], SourceOptions(group="B")).channels["x"].values[0] == 1.0
    with pytest.raises(DataError, match="no group 'b' in this TDMS file; did you mean 'B'"):
        read_record(str(path), ["x"], SourceOptions(group="b"))


def test_a_missing_channel_gets_a_suggestion(tmp_path: Path) -> None:
    path = _write(tmp_path / "a.tdms", ("G", [_waveform("G", "torque", np.zeros(5), 0.1, "")]))
    with pytest.raises(DataError, match=r"column 'torqe'.*did you mean 'torque'"):
        read_record(str(path), ["torqe"], SourceOptions())


def test_a_damaged_file_is_a_data_error(tmp_path: Path) -> None:
    path = _write(tmp_path / "a.tdms", ("G", [_waveform("G", "x", np.zeros(50), 0.1, "")]))
    data = path.read_bytes()
    path.write_bytes(data[:20] + b"\xff" * 8 + data[28:])
    with pytest.raises(DataError, match="TDMS"):
        read_record(str(path), ["x"], SourceOptions())
