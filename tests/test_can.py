"""CAN logs: frames written by python-can (and asammdf), decoded against cantools itself."""

from __future__ import annotations

import math
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

can = pytest.importorskip("can")
cantools = pytest.importorskip("cantools")

from pytest_hevval.data.readers import detect_format, read_record  # noqa: E402
from pytest_hevval.data.readers.can import SignalLayout, decode_signal  # noqa: E402
from pytest_hevval.data.record import SourceOptions  # noqa: E402
from pytest_hevval.errors import DataError, SpecError  # noqa: E402
from pytest_hevval.spec.load import parse_spec_text  # noqa: E402

pytest_plugins = ["pytester"]

# Intel and Motorola signals, signed, odd lengths, an IEEE float and a double, a multiplexed
# message, an extended identifier, a 61-bit signal and 64-bit signals spanning nine bytes of a
# CAN FD payload; `temp` is defined by two messages.
DBC = """\
VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 256 Engine: 8 ECU
 SG_ speed : 0|16@1+ (0.01,0) [0|655.35] "km/h" ECU
 SG_ torque : 16|12@1- (0.5,-10) [-1034|1013.5] "Nm" ECU
 SG_ temp : 39|11@0+ (1,-40) [-40|2007] "degC" ECU
 SG_ current : 52|13@0- (0.1,0) [-409.6|409.5] "A" ECU

BO_ 512 Battery: 8 ECU
 SG_ voltage : 0|32@1- (1,0) [0|0] "V" ECU
 SG_ soc : 32|7@1+ (1,0) [0|100] "%" ECU
 SG_ temp : 47|9@0+ (0.5,-40) [-40|215.5] "degC" ECU

BO_ 768 Modes: 8 ECU
 SG_ sel M : 0|8@1+ (1,0) [0|255] "" ECU
 SG_ a m0 : 8|16@1+ (1,0) [0|65535] "" ECU
 SG_ b m1 : 15|16@0- (0.25,0) [-8192|8191.75] "rpm" ECU
 SG_ c : 56|8@1+ (1,0) [0|255] "" ECU

BO_ 2566844926 Body: 8 ECU
 SG_ odo : 3|61@1+ (0.001,0) [0|0] "km" ECU

BO_ 1024 Wide: 24 ECU
 SG_ longbe : 2|64@0- (1,0) [0|0] "" ECU
 SG_ longle : 69|64@1+ (1,0) [0|0] "" ECU
 SG_ frac : 140|20@1+ (0.001,5) [0|0] "" ECU
 SG_ dbl : 0|64@1- (1,0) [0|0] "" ECU

VAL_ 768 sel 0 "first" 1 "second" ;
SIG_VALTYPE_ 512 voltage : 1;
SIG_VALTYPE_ 1024 dbl : 2;
"""

START = 1_700_000_000.25  # epoch seconds of the first frame


@pytest.fixture(scope="module")
def database_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("db") / "powertrain.dbc"
    path.write_text(DBC)
    return path


@pytest.fixture(scope="module")
def database(database_file: Path) -> Any:
    return cantools.database.load_file(str(database_file), strict=False)


def _frames(database: Any, seed: int = 0) -> list[Any]:
    """Classic frames of Engine (100 Hz), Battery (10 Hz), Modes (50 Hz, mux alternating),
    Body (extended id) and an id the database does not know, over two seconds."""
    rng = np.random.default_rng(seed)
    engine = database.get_message_by_name("Engine")
    battery = database.get_message_by_name("Battery")
    modes = database.get_message_by_name("Modes")
    body = database.get_message_by_name("Body")
    messages = []
    for i in range(200):
        t = START + i * 0.01
        messages.append(
            can.Message(
                timestamp=t,
                arbitration_id=engine.frame_id,
                is_extended_id=False,
                data=engine.encode(
                    {
                        "speed": round(50 + 30 * math.sin(i / 20), 2),
                        "torque": float(rng.integers(-500, 500)) * 0.5 - 10,
                        "temp": 20 + i % 50,
                        "current": round(float(rng.normal(0, 50)), 1),
                    }
                ),
            )
        )
        if i % 10 == 3:
            messages.append(
                can.Message(
                    timestamp=t + 0.002,
                    arbitration_id=battery.frame_id,
                    is_extended_id=False,
                    data=battery.encode({"voltage": 350.5 + i, "soc": i % 100, "temp": 25.5}),
                )
            )
        if i % 2 == 1:
            sel = (i // 2) % 2
            values = {
                "sel": sel,
                "c": i % 256,
                "a" if sel == 0 else "b": i * (1 if sel == 0 else -0.25),
            }
            messages.append(
                can.Message(
                    timestamp=t + 0.004,
                    arbitration_id=modes.frame_id,
                    is_extended_id=False,
                    data=modes.encode(values),
                )
            )
        if i % 20 == 7:
            messages.append(
                can.Message(
                    timestamp=t + 0.006,
                    arbitration_id=body.frame_id,
                    is_extended_id=True,
                    data=body.encode({"odo": 12345.678 + i}),
                )
            )
        if i % 25 == 0:
            messages.append(
                can.Message(
                    timestamp=t + 0.008,
                    arbitration_id=0x7DF,
                    is_extended_id=False,
                    data=bytes(8),
                )
            )
    return messages


def _write_log(path: Path, messages: Sequence[Any]) -> Path:
    writer = {".blf": can.BLFWriter, ".asc": can.ASCWriter, ".log": can.CanutilsLogWriter}[
        path.suffix
    ]
    with writer(str(path)) as log:
        for message in messages:
            log.on_message_received(message)
    return path


def _options(database_file: Path | str) -> SourceOptions:
    return SourceOptions(extra={"dbc": str(database_file)})


def _expected(database: Any, messages: Sequence[Any]) -> dict[str, tuple[list[float], list[float]]]:
    """cantools' decode_message frame by frame: signal → (times from first frame, values)."""
    first = min(m.timestamp for m in messages)
    out: dict[str, tuple[list[float], list[float]]] = {}
    for message in messages:
        try:
            spec = database.get_message_by_frame_id(message.arbitration_id)
        except KeyError:
            continue
        decoded = database.decode_message(
            message.arbitration_id, message.data, decode_choices=False
        )
        for name, value in decoded.items():
            column = f"{spec.name}.{name}" if name == "temp" else name
            times, values = out.setdefault(column, ([], []))
            # Epoch seconds as floats carry about 0.24 µs: times from the first frame are
            # known to the microsecond, and the reader keeps them so (10 ms, not 9.99999 ms).
            times.append(float(np.round((message.timestamp - first) / 1e-6) * 1e-6))
            values.append(float(value))
    return out


# --------------------------------------------------------------------------------------------
# Reading logs


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".log"])
def test_log_decodes_as_cantools(
    tmp_path: Path, database: Any, database_file: Path, suffix: str
) -> None:
    messages = _frames(database)
    path = _write_log(tmp_path / f"trip{suffix}", messages)
    assert detect_format(str(path), SourceOptions()) == "can"
    record = read_record(str(path), None, _options(database_file))
    expected = _expected(database, messages)
    assert set(record.channels) == set(expected)
    for name, (times, values) in expected.items():
        channel = record.channels[name]
        # ASC stores times in microseconds relative to the start; BLF and candump absolute.
        np.testing.assert_allclose(channel.time, times, rtol=0, atol=2e-6, err_msg=name)
        np.testing.assert_array_equal(channel.values, values, err_msg=name)
    assert record.meta["interpolation"] == "previous"
    assert record.meta["format"] == "can"
    # Every signal keeps the frame times of its own message.
    assert record.channels["speed"].time.size == 200
    assert record.channels["soc"].time.size == 20
    assert record.channels["a"].time.size == 50  # multiplexer 0 on half the Modes frames
    assert record.channels["b"].time.size == 50
    assert record.channels["c"].time.size == 100
    assert record.channels["odo"].time.size == 10
    np.testing.assert_allclose(record.channels["soc"].time[:2], [0.032, 0.132], atol=2e-6)
    assert record.channels["speed"].unit == "km/h"
    assert record.channels["b"].unit == "rpm"
    assert record.meta["can"] == {
        "frames": len(messages),
        "decoded_frames": len(messages) - 8,
        "unknown_ids": {"0x7DF": 8},
    }


@pytest.mark.parametrize("suffix", [".blf", ".log"])
def test_absolute_start_is_recorded(
    tmp_path: Path, database: Any, database_file: Path, suffix: str
) -> None:
    path = _write_log(tmp_path / f"trip{suffix}", _frames(database))
    record = read_record(str(path), ["speed"], _options(database_file))
    assert record.meta["start_epoch_s"] == pytest.approx(START, abs=1e-6)
    assert record.meta["absolute_start"] == "2023-11-14T22:13:20.250000+00:00"
    assert datetime.fromisoformat(record.meta["absolute_start"]).timestamp() == pytest.approx(
        START, abs=1e-6
    )


def test_asc_start_comes_from_its_triggerblock_date(
    tmp_path: Path, database: Any, database_file: Path
) -> None:
    # python-can writes the ASC date in local time at millisecond resolution.
    path = _write_log(tmp_path / "trip.asc", _frames(database))
    record = read_record(str(path), ["speed"], _options(database_file))
    assert record.meta["start_epoch_s"] == pytest.approx(START, abs=1e-3)


def test_relative_log_has_no_absolute_start(
    tmp_path: Path, database: Any, database_file: Path
) -> None:
    messages = _frames(database)
    for message in messages:
        message.timestamp -= START - 5.0
    path = _write_log(tmp_path / "trip.log", messages)
    record = read_record(str(path), ["speed"], _options(database_file))
    assert "start_epoch_s" not in record.meta
    assert "absolute_start" not in record.meta
    assert record.channels["speed"].time[0] == 0.0


def test_frames_out_of_order_are_sorted_and_same_time_frames_counted(
    tmp_path: Path, database: Any, database_file: Path
) -> None:
    engine = database.get_message_by_name("Engine")

    def frame(t: float, speed: float) -> Any:
        return can.Message(
            timestamp=START + t,
            arbitration_id=engine.frame_id,
            is_extended_id=False,
            data=engine.encode({"speed": speed, "torque": 0, "temp": 0, "current": 0}),
        )

    # candump keeps the order it is given; a frame repeated at one instant (two channels)
    # keeps the later.
    path = _write_log(
        tmp_path / "trip.log",
        [frame(0.0, 1.0), frame(0.2, 3.0), frame(0.1, 2.0), frame(0.2, 4.0), frame(0.3, 5.0)],
    )
    record = read_record(str(path), ["speed"], _options(database_file))
    np.testing.assert_allclose(record.channels["speed"].time, [0.0, 0.1, 0.2, 0.3], atol=1e-6)
    np.testing.assert_array_equal(record.channels["speed"].values, [1.0, 2.0, 4.0, 5.0])
    assert record.meta["can"]["same_time_frames_dropped"] == 1


def test_short_frames_lack_the_signals_they_cut(
    tmp_path: Path, database: Any, database_file: Path
) -> None:
    engine = database.get_message_by_name("Engine")
    full = engine.encode({"speed": 12.5, "torque": 4.0, "temp": 30, "current": 1.5})
    messages = [
        can.Message(timestamp=START, arbitration_id=0x100, is_extended_id=False, data=full),
        can.Message(
            timestamp=START + 0.1, arbitration_id=0x100, is_extended_id=False, data=full[:3]
        ),
    ]
    path = _write_log(tmp_path / "trip.blf", messages)
    record = read_record(str(path), ["speed", "current"], _options(database_file))
    assert record.channels["speed"].values.tolist() == [12.5, 12.5]
    assert record.channels["current"].values.tolist() == [1.5]
    expected = database.decode_message(0x100, full[:3], decode_choices=False, allow_truncated=True)
    assert set(expected) == {"speed"}


def test_can_fd_frames_decode_as_cantools(
    tmp_path: Path, database: Any, database_file: Path
) -> None:
    wide = database.get_message_by_name("Wide")
    rng = np.random.default_rng(3)
    messages = [
        can.Message(
            timestamp=START + i * 0.01,
            arbitration_id=wide.frame_id,
            is_extended_id=False,
            is_fd=True,
            data=rng.integers(0, 256, 24, dtype=np.uint8).tobytes(),
        )
        for i in range(50)
    ]
    path = _write_log(tmp_path / "fd.blf", messages)
    record = read_record(str(path), None, _options(database_file))
    expected = _expected(database, messages)
    assert set(record.channels) == {"longbe", "longle", "frac", "dbl"}
    for name, (_, values) in expected.items():
        np.testing.assert_array_equal(record.channels[name].values, values, err_msg=name)


# --------------------------------------------------------------------------------------------
# MDF4 bus logging


def _write_bus_mdf(path: Path, messages: Sequence[Any], database_file: Path) -> Path:
    """An MDF4 bus logging file as asammdf writes one: a CAN_DataFrame channel group."""
    asammdf = pytest.importorskip("asammdf")
    from asammdf.blocks.source_utils import Source
    from asammdf.blocks.v4_constants import BUS_TYPE_CAN, SOURCE_BUS

    dtype = np.dtype(
        [
            ("CAN_DataFrame.BusChannel", "<u1"),
            ("CAN_DataFrame.ID", "<u4"),
            ("CAN_DataFrame.IDE", "<u1"),
            ("CAN_DataFrame.DLC", "<u1"),
            ("CAN_DataFrame.DataLength", "<u1"),
            ("CAN_DataFrame.DataBytes", "(8,)u1"),
            ("CAN_DataFrame.Dir", "<u1"),
        ]
    )
    records = np.zeros(len(messages), dtype=dtype)
    for row, message in zip(records, messages, strict=True):
        row["CAN_DataFrame.BusChannel"] = 1
        row["CAN_DataFrame.ID"] = message.arbitration_id
        row["CAN_DataFrame.IDE"] = int(message.is_extended_id)
        row["CAN_DataFrame.DLC"] = len(message.data)
        row["CAN_DataFrame.DataLength"] = len(message.data)
        row["CAN_DataFrame.DataBytes"][: len(message.data)] = np.frombuffer(
            bytes(message.data), dtype=np.uint8
        )
    first = messages[0].timestamp
    mdf = asammdf.MDF(version="4.10")
    mdf.header.start_time = datetime.fromtimestamp(first).astimezone()
    mdf.append(
        asammdf.Signal(
            name="CAN_DataFrame",
            samples=records,
            timestamps=np.array([m.timestamp - first for m in messages]),
            source=Source(
                name="CAN1",
                path="CAN1",
                comment="",
                source_type=SOURCE_BUS,
                bus_type=BUS_TYPE_CAN,
            ),
        )
    )
    mdf.save(str(path), overwrite=True)
    mdf.close()
    return path


def test_mdf_bus_logging_decodes_like_logs_and_asammdf(
    tmp_path: Path, database: Any, database_file: Path
) -> None:
    asammdf = pytest.importorskip("asammdf")
    messages = _frames(database)
    path = _write_bus_mdf(tmp_path / "trip.mf4", messages, database_file)
    record = read_record(
        str(path), None, SourceOptions(format="can", extra={"dbc": str(database_file)})
    )
    expected = _expected(database, messages)
    assert set(record.channels) == set(expected)
    for name, (times, values) in expected.items():
        np.testing.assert_allclose(record.channels[name].time, times, atol=1e-9, err_msg=name)
        np.testing.assert_array_equal(record.channels[name].values, values, err_msg=name)
    assert record.meta["can"]["unknown_ids"] == {"0x7DF": 8}
    assert record.meta["start_epoch_s"] == pytest.approx(START, abs=1e-6)
    # asammdf's own bus logging extraction agrees.
    with asammdf.MDF(str(path)) as mdf:
        decoded = mdf.extract_bus_logging({"CAN": [(str(database_file), 0)]})
        for name in ("speed", "current", "b", "odo"):
            signal = decoded.get(name)
            np.testing.assert_allclose(
                record.channels[name].values, np.asarray(signal.samples, dtype=float), err_msg=name
            )
        decoded.close()


def test_mdf_without_bus_logging_is_explained(tmp_path: Path, database_file: Path) -> None:
    asammdf = pytest.importorskip("asammdf")
    path = tmp_path / "plain.mf4"
    mdf = asammdf.MDF(version="4.10")
    mdf.append(asammdf.Signal(np.arange(5.0), np.arange(5.0), name="speed"))
    mdf.save(str(path), overwrite=True)
    mdf.close()
    with pytest.raises(DataError) as info:
        read_record(
            str(path), ["speed"], SourceOptions(format="can", extra={"dbc": str(database_file)})
        )
    assert str(info.value) == (
        f"{path}: the MDF file holds no CAN bus logging (no CAN_DataFrame channel); drop "
        "`dbc:` to read it as plain MDF channels, or log the CAN bus to MDF4"
    )


# --------------------------------------------------------------------------------------------
# Vectorised decoding against cantools


def _layouts(database: Any) -> list[tuple[Any, list[SignalLayout]]]:
    return [(m, [SignalLayout.of(s) for s in m.signals]) for m in database.messages]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(1, 40))
def test_vectorised_decode_equals_cantools(database: Any, seed: int, rows: int) -> None:
    rng = np.random.default_rng(seed)
    for message, layouts in _layouts(database):
        payload = rng.integers(0, 256, (rows, message.length), dtype=np.uint8)
        if message.name == "Modes":
            payload[:, 0] = rng.integers(0, 2, rows)  # a multiplexer value the database knows
        ours = {layout.name: decode_signal(payload, layout) for layout in layouts}
        for row in range(rows):
            expected = message.decode(payload[row].tobytes(), decode_choices=False)
            for layout in layouts:
                if layout.name not in expected:
                    continue
                want = float(expected[layout.name])
                got = float(ours[layout.name][row])
                if math.isnan(want):
                    assert math.isnan(got), layout.name
                else:
                    # cantools scales integer raws in exact integer arithmetic; above 2**53
                    # a float is only as exact as its last bit.
                    assert got == pytest.approx(want, rel=2**-52, abs=0), layout.name


@settings(max_examples=300, deadline=None)
@given(
    size=st.sampled_from([8, 16]),
    start=st.integers(0, 127),
    length=st.integers(1, 64),
    big_endian=st.booleans(),
    signed=st.booleans(),
    data=st.data(),
)
def test_any_integer_layout_equals_cantools(
    size: int, start: int, length: int, big_endian: bool, signed: bool, data: st.DataObject
) -> None:
    """Every start bit and length, both byte orders, in classic (8) and FD (16) payloads."""
    msb0 = 8 * (start // 8) + 7 - start % 8
    assume((msb0 if big_endian else start) + length <= 8 * size)
    signal = cantools.database.can.Signal(
        name="x",
        start=start,
        length=length,
        byte_order="big_endian" if big_endian else "little_endian",
        is_signed=signed,
    )
    message = cantools.database.can.Message(
        frame_id=1, name="m", length=size, signals=[signal], strict=False
    )
    payloads = data.draw(st.lists(st.binary(min_size=size, max_size=size), min_size=1, max_size=8))
    matrix = np.frombuffer(b"".join(payloads), dtype=np.uint8).reshape(len(payloads), size)
    ours = decode_signal(matrix, SignalLayout.of(signal))
    for row, payload in enumerate(payloads):
        want = message.decode(payload, decode_choices=False)["x"]
        assert ours[row] == pytest.approx(float(want), rel=2**-52, abs=0)


def test_unknown_multiplexer_value_leaves_the_branch_out(
    tmp_path: Path, database: Any, database_file: Path
) -> None:
    modes = database.get_message_by_name("Modes")
    data = bytearray(modes.encode({"sel": 0, "a": 7, "c": 9}))
    other = bytearray(data)
    other[0] = 5  # no branch for 5: cantools refuses the frame, its plain signals remain
    messages = [
        can.Message(timestamp=START, arbitration_id=0x300, is_extended_id=False, data=data),
        can.Message(timestamp=START + 1, arbitration_id=0x300, is_extended_id=False, data=other),
    ]
    path = _write_log(tmp_path / "trip.blf", messages)
    record = read_record(str(path), ["sel", "a", "c"], _options(database_file))
    assert record.channels["a"].values.tolist() == [7.0]
    assert record.channels["sel"].values.tolist() == [0.0, 5.0]
    assert record.channels["c"].values.tolist() == [9.0, 9.0]
    with pytest.raises(cantools.database.DecodeError):
        database.decode_message(0x300, bytes(other))


# --------------------------------------------------------------------------------------------
# Errors


@pytest.fixture
def blf(tmp_path: Path, database: Any) -> Path:
    return _write_log(tmp_path / "trip.blf", _frames(database))


def test_missing_signal_suggests_names(blf: Path, database_file: Path) -> None:
    with pytest.raises(DataError) as info:
        read_record(str(blf), ["sped"], _options(database_file))
    assert str(info.value) == (
        f"{blf}: column 'sped': no such signal in the CAN database powertrain.dbc; "
        "did you mean 'speed'?"
    )


def test_missing_signal_without_near_name_lists_signals(blf: Path, database_file: Path) -> None:
    with pytest.raises(
        DataError, match=r"the database has 16 signals: 'speed', 'torque', 'current'"
    ):
        read_record(str(blf), ["zzzzzz"], _options(database_file))


def test_signal_of_two_messages_is_ambiguous(blf: Path, database_file: Path) -> None:
    with pytest.raises(DataError) as info:
        read_record(str(blf), ["temp"], _options(database_file))
    assert str(info.value) == (
        f"{blf}: column 'temp': signal 'temp' is defined by 2 messages of the CAN database "
        "powertrain.dbc: 'Engine.temp', 'Battery.temp'; name it with its message, e.g. "
        "'Engine.temp'"
    )
    record = read_record(
        str(blf), ["Engine.temp", "Battery.temp", "Engine.speed"], _options(database_file)
    )
    assert record.channels["Engine.temp"].time.size == 200
    assert record.channels["Battery.temp"].values[0] == 25.5
    assert record.channels["Engine.speed"].time.size == 200


def test_bad_database_is_named(blf: Path, tmp_path: Path) -> None:
    bad = tmp_path / "broken.dbc"
    bad.write_text("BO_ this is not a database\n")
    with pytest.raises(DataError) as info:
        read_record(str(blf), ["speed"], _options(bad))
    message = str(info.value)
    assert message.startswith(
        f"{bad}: dbc: cannot read this CAN database; give a DBC, ARXML or KCD file; "
        "the parser said: "
    )


def test_missing_database_is_named(blf: Path, tmp_path: Path) -> None:
    with pytest.raises(DataError) as info:
        read_record(str(blf), ["speed"], _options(tmp_path / "nope.dbc"))
    assert str(info.value) == (
        f"{tmp_path / 'nope.dbc'}: dbc: CAN database not found; check the `dbc:` path "
        "(relative paths start at the spec file)"
    )


def test_log_without_database(blf: Path) -> None:
    with pytest.raises(DataError) as info:
        read_record(str(blf), ["speed"], SourceOptions())
    assert str(info.value) == (
        f"{blf}: dbc: a CAN log needs a signal database to decode it; add `dbc: <file>` "
        "(DBC, ARXML or KCD) to the source; for a text table with the .log extension set "
        "`format: csv`"
    )


def test_empty_log(tmp_path: Path, database_file: Path) -> None:
    path = _write_log(tmp_path / "empty.blf", [])
    with pytest.raises(DataError) as info:
        read_record(str(path), ["speed"], _options(database_file))
    assert str(info.value) == (
        f"{path}: the log holds no CAN data frames; check that the logger recorded the bus"
    )


def test_message_absent_from_log(tmp_path: Path, database: Any, database_file: Path) -> None:
    messages = [m for m in _frames(database) if m.arbitration_id != 0x200]
    path = _write_log(tmp_path / "trip.blf", messages)
    with pytest.raises(DataError) as info:
        read_record(str(path), ["soc"], _options(database_file))
    assert str(info.value) == (
        f"{path}: column 'soc': message 'Battery' (0x200) of signal 'soc' has no frames in this "
        "log; check that the log and the database belong to the same bus"
    )
    # Reading every signal skips the ones never sent.
    record = read_record(str(path), None, _options(database_file))
    assert "soc" not in record.channels
    assert "speed" in record.channels
    assert "soc" not in record.numeric
    assert "soc" in record.available


def test_multiplexed_signal_never_selected(
    tmp_path: Path, database: Any, database_file: Path
) -> None:
    modes = database.get_message_by_name("Modes")
    messages = [
        can.Message(
            timestamp=START + i * 0.1,
            arbitration_id=modes.frame_id,
            is_extended_id=False,
            data=modes.encode({"sel": 0, "a": i, "c": 1}),
        )
        for i in range(40)
    ]
    path = _write_log(tmp_path / "trip.blf", messages)
    with pytest.raises(DataError) as info:
        read_record(str(path), ["b"], _options(database_file))
    assert str(info.value) == (
        f"{path}: column 'b': signal 'b' is multiplexed and its multiplexer never selects it "
        "in the 40 frames of message 'Modes'; choose a signal that was sent"
    )


@pytest.mark.parametrize("cut", [1000, 4000])
def test_truncated_blf(blf: Path, tmp_path: Path, database_file: Path, cut: int) -> None:
    path = tmp_path / "cut.blf"
    size = blf.stat().st_size
    path.write_bytes(blf.read_bytes()[:cut])
    with pytest.raises(DataError) as info:
        read_record(str(path), None, _options(database_file))
    assert str(info.value) == (
        f"{path}: the BLF header declares {size} bytes but the file has {cut} (file "
        "truncated?); copy the log again from the logger"
    )


def test_damaged_blf_object(blf: Path, tmp_path: Path, database_file: Path) -> None:
    path = tmp_path / "damaged.blf"
    content = bytearray(blf.read_bytes())
    content[144:148] = b"JUNK"  # the first object's signature
    path.write_bytes(bytes(content))
    with pytest.raises(DataError) as info:
        read_record(str(path), ["speed"], _options(database_file))
    assert str(info.value).startswith(
        f"{path}: cannot read this CAN log (blf) file (file truncated or corrupt?); write the "
        "file again; the reader said: "
    )


# --------------------------------------------------------------------------------------------
# Spec and end to end


def test_spec_resolves_dbc_and_selects_can(tmp_path: Path) -> None:
    spec = parse_spec_text(
        "reference: {path: logs/trip.mf4, dbc: db/powertrain.dbc}\n"
        "model: {path: sim.csv}\n"
        "sets: [{signal: speed}]\n",
        tmp_path / "a.hevval.yaml",
    )
    assert spec.reference.options.format == "can"
    assert spec.reference.options.extra == {"dbc": str(tmp_path / "db" / "powertrain.dbc")}
    assert spec.model.options.extra == {}


def test_spec_refuses_dbc_on_other_formats(tmp_path: Path) -> None:
    with pytest.raises(SpecError) as info:
        parse_spec_text(
            "reference: {path: trip.csv, format: csv, dbc: p.dbc}\n"
            "model: {path: sim.csv}\n"
            "sets: [{signal: speed}]\n",
            tmp_path / "a.hevval.yaml",
        )
    assert str(info.value) == (
        f"{tmp_path / 'a.hevval.yaml'}:1: reference.dbc: a signal database decodes CAN logs, "
        "not csv files; remove `dbc:`, or set `format: can` for a BLF, ASC, candump or MDF4 bus log"
    )


def test_spec_refuses_dbc_on_a_callable_model(tmp_path: Path) -> None:
    with pytest.raises(SpecError) as info:
        parse_spec_text(
            "reference: trip.blf\n"
            "model: {callable: 'pkg.mod:run', dbc: p.dbc}\n"
            "sets: [{signal: speed}]\n",
            tmp_path / "a.hevval.yaml",
        )
    assert str(info.value) == (
        f"{tmp_path / 'a.hevval.yaml'}:2: model.dbc: a signal database decodes a CAN log "
        "file, not a callable model; remove `dbc:`"
    )


def test_spec_with_can_reference_runs_end_to_end(
    pytester: pytest.Pytester, database: Any, database_file: Path
) -> None:
    messages = _frames(database)
    (pytester.path / "logs").mkdir()
    (pytester.path / "db").mkdir()
    (pytester.path / "db" / "powertrain.dbc").write_text(DBC)
    _write_log(pytester.path / "logs" / "trip.blf", messages)
    expected = _expected(database, messages)
    t = np.arange(0.0, 1.98, 0.02)
    speed_t, speed = expected["speed"]
    sim = pd.DataFrame(
        {
            "time": t,
            "speed": np.interp(t, speed_t, speed) + 0.05,
            "c": np.interp(t, *expected["c"]),
        }
    )
    sim.to_csv(pytester.path / "sim.csv", index=False)
    pytester.makefile(
        ".hevval.yaml",
        trip="""\
reference: {path: logs/trip.blf, dbc: db/powertrain.dbc}
model: {path: sim.csv}
alignment: {max_lag_s: 0.2}
thresholds: {mae: 0.5}
sets:
  - {signal: speed, unit: km/h}
  - {signal: c, interpolation: previous}
""",
    )
    result = pytester.runpytest("--hevval", "-v")
    result.assert_outcomes(passed=3)
    result.stdout.fnmatch_lines(["*trip.hevval.yaml::speed PASSED*"])

    pytester.makefile(
        ".hevval.yaml",
        trip="""\
reference: {path: logs/trip.blf, dbc: db/powertrain.dbc}
model: {path: sim.csv}
sets:
  - {signal: sped}
""",
    )
    result = pytester.runpytest("--hevval")
    result.stdout.fnmatch_lines(
        [
            "*trip.blf: column 'sped': no such signal in the CAN database powertrain.dbc; "
            "did you mean 'speed'?*"
        ]
    )


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".log"])
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_damaged_logs_read_or_raise_data_error(
    tmp_path_factory: pytest.TempPathFactory,
    database: Any,
    database_file: Path,
    suffix: str,
    data: st.DataObject,
) -> None:
    """Bytes overwritten or the file cut anywhere: a record or a DataError, never a crash."""
    folder = tmp_path_factory.mktemp("damaged")
    original = _write_log(folder / f"good{suffix}", _frames(database)[:120]).read_bytes()
    content = bytearray(original)
    for _ in range(data.draw(st.integers(1, 4))):
        # Positions modulo the size: an ASC header holds the writing time, so sizes vary.
        at = data.draw(st.integers(0, 1 << 20)) % len(content)
        content[at] = data.draw(st.integers(0, 255))
    cut = 1 + data.draw(st.integers(0, 1 << 20)) % len(content)
    path = folder / f"bad{suffix}"
    path.write_bytes(bytes(content[:cut]))
    problem = ""
    try:
        record = read_record(str(path), None, _options(database_file))
    except DataError as exc:
        problem = str(exc)
    if problem:
        assert problem.startswith(f"{path}: ")
    else:
        assert record.meta["can"]["frames"] > 0


def test_kcd_database_decodes_as_dbc(tmp_path: Path, database: Any, database_file: Path) -> None:
    kcd = tmp_path / "powertrain.kcd"
    kcd.write_text(database.as_kcd_string())
    path = _write_log(tmp_path / "trip.blf", _frames(database))
    from_dbc = read_record(str(path), ["speed", "current", "b"], _options(database_file))
    from_kcd = read_record(str(path), ["speed", "current", "b"], _options(kcd))
    for name in ("speed", "current", "b"):
        np.testing.assert_array_equal(
            from_kcd.channels[name].values, from_dbc.channels[name].values
        )


def test_can_signals_are_held_between_frames_unless_the_spec_says_otherwise(
    tmp_path: Path, database: Any
) -> None:
    from pytest_hevval.scoring.engine import evaluate_spec
    from pytest_hevval.spec.load import parse_spec_text

    messages = _frames(database)
    (tmp_path / "powertrain.dbc").write_text(DBC)
    _write_log(tmp_path / "trip.blf", messages)
    times, values = _expected(database, messages)["c"]
    expected_t, expected = np.asarray(times), np.asarray(values)
    t = np.arange(0.0, 1.98, 0.01)
    pd.DataFrame({"time": t, "c": np.zeros_like(t)}).to_csv(tmp_path / "sim.csv", index=False)
    base = "reference: {path: trip.blf, dbc: powertrain.dbc}\nmodel: {path: sim.csv}\nsets:\n"
    for node, method in (
        ("{signal: c}", "previous"),
        ("{signal: c, interpolation: linear}", "linear"),
    ):
        spec = parse_spec_text(base + f"  - {node}\n", tmp_path / "t.hevval.yaml")
        evaluation = evaluate_spec(spec, keep_arrays=True)
        ref, _ = evaluation.arrays["c"]
        grid = evaluation.aligned.time if evaluation.aligned is not None else t
        if method == "previous":
            held = expected[np.clip(np.searchsorted(expected_t, grid, side="right") - 1, 0, None)]
            np.testing.assert_array_equal(ref, held)
        else:
            np.testing.assert_allclose(ref, np.interp(grid, expected_t, expected), rtol=1e-12)
