"""Clock time: ISO-8601 text, datetimes, Unix epoch numbers and MDF start times; by: clock."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pytest_hevval.data.readers import read_record
from pytest_hevval.data.record import SourceOptions
from pytest_hevval.errors import DataError
from pytest_hevval.scoring.engine import evaluate_spec
from pytest_hevval.spec.load import parse_spec_text

START = pd.Timestamp("2024-06-01T08:00:00Z")
N = 200


def _signal() -> np.ndarray:
    return np.sin(np.arange(N) / 7.0) * 10.0 + np.arange(N) * 0.05


def _stamps(offset_s: float = 0.0) -> pd.DatetimeIndex:
    return START + pd.to_timedelta(np.arange(N) * 0.1 + offset_s, unit="s")


@pytest.mark.parametrize(
    ("form", "column"),
    [
        ("iso text", lambda s: [t.isoformat() for t in s]),
        ("iso text, no zone", lambda s: [t.tz_localize(None).isoformat() for t in s]),
        ("epoch s", lambda s: s.asi8 / 1e9),
        ("epoch ms", lambda s: s.asi8 // 1_000_000),
        ("epoch us", lambda s: s.asi8 // 1_000),
        ("epoch ns", lambda s: s.asi8),
    ],
)
def test_csv_clock_columns_become_seconds_from_the_start(
    tmp_path: Path, form: str, column: object
) -> None:
    path = tmp_path / "log.csv"
    pd.DataFrame({"time": column(_stamps()), "v": _signal()}).to_csv(path, index=False)  # type: ignore[operator]
    record = read_record(str(path), ["v"], SourceOptions())
    time = record.channels["v"].time
    np.testing.assert_allclose(time, np.arange(N) * 0.1, atol=1e-6)
    assert record.meta["absolute_start"] == "2024-06-01T08:00:00+00:00"
    assert record.meta["start_epoch_s"] == pytest.approx(START.timestamp())


@pytest.mark.parametrize("zone", [None, "Europe/Berlin"])
def test_parquet_datetime_columns(tmp_path: Path, zone: str | None) -> None:
    pytest.importorskip("pyarrow")
    stamps = _stamps().tz_convert(zone) if zone else _stamps().tz_localize(None)
    path = tmp_path / "log.parquet"
    pd.DataFrame({"time": stamps, "v": _signal()}).to_parquet(path)
    record = read_record(str(path), ["v"], SourceOptions())
    np.testing.assert_allclose(record.channels["v"].time, np.arange(N) * 0.1, atol=1e-9)
    assert record.meta["absolute_start"] == "2024-06-01T08:00:00+00:00"


def test_mdf_start_time(tmp_path: Path) -> None:
    asammdf = pytest.importorskip("asammdf")
    path = tmp_path / "log.mf4"
    with asammdf.MDF(version="4.10") as mdf:
        mdf.start_time = START.to_pydatetime()
        mdf.append([asammdf.Signal(_signal(), np.arange(N) * 0.1, name="v")])
        mdf.save(path, overwrite=True)
    record = read_record(str(path), ["v"], SourceOptions())
    assert record.meta["absolute_start"] == "2024-06-01T08:00:00+00:00"


def test_relative_time_has_no_clock(tmp_path: Path) -> None:
    path = tmp_path / "log.csv"
    pd.DataFrame({"time": np.arange(N) * 0.1, "v": _signal()}).to_csv(path, index=False)
    assert "start_epoch_s" not in read_record(str(path), ["v"], SourceOptions()).meta


SPEC = """\
reference: {path: ref.csv}
model: {path: sim.csv}
alignment: {by: clock}
sets:
  - {signal: v}
"""


def test_by_clock_lines_up_records_that_start_at_different_times(tmp_path: Path) -> None:
    # The model log starts 5 s after the measurement and counts its own seconds from 0.
    signal = np.sin(np.arange(N + 50) / 7.0) * 10.0
    measured = pd.DataFrame({"time": [t.isoformat() for t in _stamps()], "v": signal[:N]})
    measured.to_csv(tmp_path / "ref.csv", index=False)
    later = _stamps(5.0).asi8 // 1_000_000  # epoch milliseconds
    simulated = pd.DataFrame({"time": later, "v": signal[50 : 50 + N]})
    simulated.to_csv(tmp_path / "sim.csv", index=False)
    result = evaluate_spec(parse_spec_text(SPEC, tmp_path / "t.hevval.yaml")).result
    assert result.alignment.by == "clock"
    assert result.alignment.clock_offset_s == pytest.approx(5.0)
    assert result.alignment.absolute_start == "2024-06-01T08:00:05+00:00"
    assert result.signals[0].lambdas["mae"] == pytest.approx(1.0, abs=1e-9)


def test_by_clock_without_absolute_time_names_the_file(tmp_path: Path) -> None:
    frame = pd.DataFrame({"time": np.arange(N) * 0.1, "v": _signal()})
    frame.to_csv(tmp_path / "ref.csv", index=False)
    frame.to_csv(tmp_path / "sim.csv", index=False)
    with pytest.raises(DataError) as caught:
        evaluate_spec(parse_spec_text(SPEC, tmp_path / "t.hevval.yaml"))
    message = str(caught.value)
    assert "ref.csv: alignment.by is clock, but this record has no absolute time" in message
    assert "ISO 8601" in message


def test_the_html_report_shows_the_absolute_start(tmp_path: Path) -> None:
    pytest.importorskip("jinja2")
    from pytest_hevval.report.html import render_html

    signal = np.sin(np.arange(N + 50) / 7.0) * 10.0
    measured = pd.DataFrame({"time": [t.isoformat() for t in _stamps()], "v": signal[:N]})
    measured.to_csv(tmp_path / "ref.csv", index=False)
    simulated = pd.DataFrame({"time": _stamps(5.0).asi8 // 1_000_000, "v": signal[50 : 50 + N]})
    simulated.to_csv(tmp_path / "sim.csv", index=False)
    result = evaluate_spec(parse_spec_text(SPEC, tmp_path / "t.hevval.yaml")).result
    page = render_html([result], title="t", generated_utc="now")
    assert "2024-06-01T08:00:05+00:00" in page
    assert "lined up by clock, model 5 s later" in page
