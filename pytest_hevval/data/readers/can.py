"""CAN bus logs decoded with a signal database: BLF, ASC, candump and MDF4 bus logging.

A source ``{path: trip.blf, dbc: powertrain.dbc}`` reads the frames of the log and decodes
every signal the spec uses with the database (DBC, ARXML or KCD, loaded by cantools). Each
signal becomes a channel with its own time stamps: the times of the frames of its message, in
seconds from the log's first frame.

Frames are read with python-can (BLF, ASC, candump ``.log``) or asammdf (MDF4 files with
``CAN_DataFrame`` bus logging) and gathered into numpy arrays per frame identifier. Signals are
then decoded vectorised from cantools' signal definitions (bit position, length, byte order,
signedness, IEEE floats, scale and offset, multiplexing), which gives cantools'
``decode_message`` values (``decode_choices=False``) a frame at a time would, orders of
magnitude faster.
"""

from __future__ import annotations

import os
from array import array
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import IO, Any

import numpy as np
import numpy.typing as npt

from ...errors import DataError, did_you_mean
from ...files import check_input
from ..record import Channel, Record, SourceOptions
from ._common import _at_resolution, _corrupt, _import
from .mdf import _open_mdf

__all__ = ["CAN_EXTENSIONS", "DATABASE_KEY", "SignalLayout", "decode_signal", "read_can"]

#: File extensions read as CAN logs (MDF4 bus logging keeps the ``mdf`` extensions and is
#: read as a CAN log when the source names a database).
CAN_EXTENSIONS = (".blf", ".asc", ".log")

#: The source option naming the signal database.
DATABASE_KEY = "dbc"

# Bit 31 marks an extended (29-bit) identifier in the frame keys; CAN identifiers use 29 bits.
_EXTENDED_BIT = 1 << 31
_EXTENDED = np.uint32(_EXTENDED_BIT)
_ID_MASK = 0x1FFFFFFF

# Epoch seconds before 1990 are a logger's relative clock, not a date.
_EARLIEST_ABSOLUTE_S = 631152000.0

_MDF_SIGNATURE = b"MDF     "
_BLF_SIGNATURE = b"LOGG"

FloatArray = npt.NDArray[np.float64]
U64Array = npt.NDArray[np.uint64]


# --------------------------------------------------------------------------------------------
# Signal layout and vectorised decoding


@dataclass(frozen=True)
class SignalLayout:
    """What the decoder needs from a cantools signal, as plain numbers."""

    name: str
    #: Start bit as cantools gives it (DBC numbering: LSB for Intel, MSB for Motorola).
    start: int
    length: int
    big_endian: bool
    signed: bool
    is_float: bool
    scale: float
    offset: float
    unit: str | None = None
    #: Name of the multiplexer signal selecting this one, and the values that select it.
    multiplexer: str | None = None
    multiplexer_ids: tuple[int, ...] = ()

    @classmethod
    def of(cls, signal: Any) -> SignalLayout:
        return cls(
            name=str(signal.name),
            start=int(signal.start),
            length=int(signal.length),
            big_endian=signal.byte_order == "big_endian",
            signed=bool(signal.is_signed),
            is_float=bool(signal.is_float),
            scale=float(signal.scale),
            offset=float(signal.offset),
            unit=str(signal.unit) if signal.unit else None,
            multiplexer=signal.multiplexer_signal,
            multiplexer_ids=tuple(int(i) for i in signal.multiplexer_ids or ()),
        )

    @property
    def bytes_needed(self) -> int:
        """Payload bytes a frame must hold for this signal to be in it."""
        if self.big_endian:
            msb0 = 8 * (self.start // 8) + 7 - self.start % 8
            return (msb0 + self.length - 1) // 8 + 1
        return (self.start + self.length - 1) // 8 + 1


def _byte_column(payload: npt.NDArray[np.uint8], index: int) -> U64Array:
    return payload[:, index].astype(np.uint64)


def _raw_bits(payload: npt.NDArray[np.uint8], layout: SignalLayout) -> U64Array:
    """The signal's raw bits as unsigned integers, one per frame (payload rows)."""
    length = layout.length
    if layout.big_endian:
        # cantools: Motorola bits counted MSB-first over the whole payload ("network order").
        msb0 = 8 * (layout.start // 8) + 7 - layout.start % 8
        first, last = msb0 // 8, (msb0 + length - 1) // 8
        right = 8 * (last + 1) - (msb0 + length)
        if payload.shape[1] == 8:
            shift = 64 - msb0 - length
            value = payload.view(">u8")[:, 0].astype(np.uint64) >> np.uint64(shift)
        else:
            value = np.zeros(payload.shape[0], dtype=np.uint64)
            for index in range(first, min(last, first + 7) + 1):
                value = (value << np.uint64(8)) | _byte_column(payload, index)
            if last - first == 8:
                # 9 bytes: shift the first eight down before the ninth's bits join.
                value = (value << np.uint64(8 - right)) | (
                    _byte_column(payload, last) >> np.uint64(right)
                )
            else:
                value >>= np.uint64(right)
    else:
        first, last = layout.start // 8, (layout.start + length - 1) // 8
        shift = layout.start % 8
        if payload.shape[1] == 8:
            value = payload.view("<u8")[:, 0].astype(np.uint64) >> np.uint64(layout.start)
        else:
            value = np.zeros(payload.shape[0], dtype=np.uint64)
            for index in range(first, min(last, first + 7) + 1):
                value |= _byte_column(payload, index) << np.uint64(8 * (index - first))
            value >>= np.uint64(shift)
            if last - first == 8:
                value |= _byte_column(payload, last) << np.uint64(64 - shift)
    if length < 64:
        value &= np.uint64((1 << length) - 1)
    return np.asarray(value, dtype=np.uint64)


def decode_signal(payload: npt.NDArray[np.uint8], layout: SignalLayout) -> FloatArray:
    """Physical values of one signal in every row of ``payload`` (frames × bytes).

    ``payload`` must have at least ``layout.bytes_needed`` columns; choices stay numbers.
    """
    raw = _raw_bits(payload, layout)
    length = layout.length
    number: npt.NDArray[Any]
    if layout.is_float:
        float_type = {16: np.float16, 32: np.float32, 64: np.float64}[length]
        unsigned = {16: np.uint16, 32: np.uint32, 64: np.uint64}[length]
        # Random or damaged payloads hold signalling NaNs, which warn when widened.
        with np.errstate(invalid="ignore"):
            number = raw.astype(unsigned).view(float_type).astype(np.float64)
    elif layout.signed:
        if length == 64:
            number = raw.view(np.int64)
        else:
            sign = np.int64(1 << (length - 1))
            number = (raw ^ np.uint64(1 << (length - 1))).astype(np.int64) - sign
    else:
        number = raw
    values = number.astype(np.float64)
    if layout.scale != 1.0:
        values *= layout.scale
    if layout.offset != 0.0:
        values += layout.offset
    return values


# --------------------------------------------------------------------------------------------
# Frames


@dataclass
class _Frames:
    """Data frames of a log in time order: absolute or relative seconds, keys, payloads."""

    time: FloatArray
    #: Arbitration id, with bit 31 set for extended identifiers.
    key: npt.NDArray[np.uint32]
    length: npt.NDArray[np.uint8]
    #: Payload bytes padded with zeros to at least 8 columns.
    payload: npt.NDArray[np.uint8]
    absolute: bool


def _payload_matrix(
    flat: npt.NDArray[np.uint8], lengths: npt.NDArray[np.uint8]
) -> npt.NDArray[np.uint8]:
    """Variable-length payloads laid end to end → one zero-padded row per frame."""
    count = lengths.shape[0]
    width = max(8, int(lengths.max()) if count else 0)
    if count and int(lengths.min()) == width:
        return flat.reshape(count, width)
    out = np.zeros((count, width), dtype=np.uint8)
    if flat.size:
        rows = np.repeat(np.arange(count), lengths)
        starts = np.cumsum(lengths, dtype=np.int64) - lengths
        columns = np.arange(flat.size, dtype=np.int64) - np.repeat(starts, lengths)
        out[rows, columns] = flat
    return out


def _collect(messages: Iterable[Any]) -> tuple[array[float], array[int], array[int], bytearray]:
    times: array[float] = array("d")
    keys: array[int] = array("L")
    lengths: array[int] = array("B")
    data = bytearray()
    add_time, add_key, add_length, add_data = (
        times.append,
        keys.append,
        lengths.append,
        data.extend,
    )
    extended = _EXTENDED_BIT
    for message in messages:
        if message.is_error_frame or message.is_remote_frame:
            continue
        payload = message.data
        add_time(message.timestamp)
        add_key(
            message.arbitration_id | extended if message.is_extended_id else message.arbitration_id
        )
        add_length(len(payload))
        add_data(payload)
    return times, keys, lengths, data


def _python_can_reader(stream: IO[Any], kind: str) -> Any:
    can = _import("can", "reading CAN logs", "can")
    if kind == "blf":
        return can.BLFReader(stream)
    if kind == "asc":
        # Absolute times come from the file's `date` line; without one they stay relative.
        return can.ASCReader(stream, relative_timestamp=False)
    return can.CanutilsLogReader(stream)


def _log_kind(path: str) -> str:
    """blf, asc, candump or mdf: from the file's first bytes, else from its extension."""
    with open(path, "rb") as stream:
        head = stream.read(4096)
    if head.startswith(_MDF_SIGNATURE):
        return "mdf"
    if head.startswith(_BLF_SIGNATURE):
        return "blf"
    text = head.decode("latin-1").lstrip()
    if text.startswith("("):
        return "candump"
    lowered = text.lower()
    if lowered.startswith(("date ", "base ", "begin triggerblock", "//")):
        return "asc"
    ext = os.path.splitext(path)[1].lower()
    known = {".blf": "blf", ".asc": "asc", ".log": "candump", ".mf4": "mdf", ".mdf": "mdf"}
    if ext in known:
        return known[ext]
    raise DataError(
        "cannot tell which kind of CAN log this is",
        file=path,
        hint="CAN logs are read from Vector BLF (.blf), Vector ASC (.asc), candump -l (.log) "
        "or MDF4 bus logging (.mf4)",
    )


def _read_frames(path: str) -> _Frames:
    kind = _log_kind(path)
    if kind == "mdf":
        return _mdf_frames(path)
    # The file is opened here, not by python-can, so that it is closed even when a reader's
    # constructor fails on a damaged header.
    stream: IO[Any] = (
        open(path, "rb") if kind == "blf" else open(path, encoding="latin-1", newline=None)  # noqa: SIM115
    )
    try:
        with stream:
            reader = _python_can_reader(stream, kind)
            _check_blf_size(path, reader)
            times, keys, lengths, data = _collect(reader)
    except DataError:
        raise
    except Exception as exc:
        # python-can raises BLFParseError, struct.error, ValueError, … for damaged logs.
        raise _corrupt(path, f"CAN log ({kind})", exc) from None
    length = np.frombuffer(lengths, dtype=np.uint8) if lengths else np.zeros(0, np.uint8)
    time = np.frombuffer(times, dtype=np.float64) if times else np.zeros(0)
    key = np.asarray(keys, dtype=np.uint32)
    first = float(time[0]) if time.size else 0.0
    return _Frames(
        time=time,
        key=key,
        length=length,
        payload=_payload_matrix(np.frombuffer(data, dtype=np.uint8), length),
        absolute=first >= _EARLIEST_ABSOLUTE_S,
    )


def _check_blf_size(path: str, reader: Any) -> None:
    """Refuse a BLF file shorter than its header says: python-can would read part of it."""
    declared = int(getattr(reader, "file_size", 0) or 0)
    actual = os.path.getsize(path)
    if declared > actual:
        raise DataError(
            f"the BLF header declares {declared} bytes but the file has {actual} (file truncated?)",
            file=path,
            hint="copy the log again from the logger",
        )


def _mdf_frames(path: str) -> _Frames:
    """The ``CAN_DataFrame`` records of an MDF4 bus logging file, read a group at a time."""
    parts: list[tuple[FloatArray, Any, Any, Any, Any]] = []
    with _open_mdf(path) as mdf:
        try:
            start = mdf.header.start_time
            offset = start.timestamp() if start is not None else 0.0
            for group_index, group in enumerate(mdf.groups):
                if not any(str(channel.name) == "CAN_DataFrame" for channel in group.channels):
                    continue
                if int(group.channel_group.cycles_nr) == 0:
                    continue
                signal = mdf.get("CAN_DataFrame", group_index, raw=True)
                samples = signal.samples
                names = samples.dtype.names or ()
                data_bytes = np.asarray(samples["CAN_DataFrame.DataBytes"], dtype=np.uint8)
                if data_bytes.ndim == 1:
                    data_bytes = data_bytes.reshape(-1, 1)
                if "CAN_DataFrame.DataLength" in names:
                    length = np.asarray(samples["CAN_DataFrame.DataLength"], dtype=np.uint8)
                else:
                    length = np.asarray(samples["CAN_DataFrame.DLC"], dtype=np.uint8)
                ide = (
                    np.asarray(samples["CAN_DataFrame.IDE"], dtype=bool)
                    if "CAN_DataFrame.IDE" in names
                    else np.zeros(len(samples), dtype=bool)
                )
                raw_id = np.asarray(samples["CAN_DataFrame.ID"]).astype(np.uint32)
                parts.append(
                    (
                        np.asarray(signal.timestamps, dtype=np.float64) + offset,
                        raw_id,
                        ide,
                        np.minimum(length, data_bytes.shape[1]),
                        data_bytes,
                    )
                )
        except DataError:
            raise
        except Exception as exc:
            raise _corrupt(path, "MDF", exc) from None
    if not parts:
        raise DataError(
            "the MDF file holds no CAN bus logging (no CAN_DataFrame channel)",
            file=path,
            hint="drop `dbc:` to read it as plain MDF channels, or log the CAN bus to MDF4",
        )
    width = max(8, *(p[4].shape[1] for p in parts))
    payload = np.zeros((sum(p[0].shape[0] for p in parts), width), dtype=np.uint8)
    row = 0
    for part in parts:
        payload[row : row + part[4].shape[0], : part[4].shape[1]] = part[4]
        row += part[4].shape[0]
    # Bit 31 of a logged ID is the extended flag in some loggers, as IDE is in others.
    raw_ids = np.concatenate([p[1] for p in parts])
    extended = np.concatenate([p[2] for p in parts]) | (raw_ids & _EXTENDED).astype(bool)
    key = (raw_ids & np.uint32(_ID_MASK)) | np.where(extended, _EXTENDED, np.uint32(0))
    time = np.concatenate([p[0] for p in parts])
    return _Frames(
        time=time,
        key=key.astype(np.uint32),
        length=np.concatenate([p[3] for p in parts]).astype(np.uint8),
        payload=payload,
        absolute=bool(time.size) and float(time.min()) >= _EARLIEST_ABSOLUTE_S,
    )


def _id_text(key: int) -> str:
    if key & _EXTENDED_BIT:
        return f"0x{key & _ID_MASK:08X}"
    return f"0x{key:03X}"


# --------------------------------------------------------------------------------------------
# Database


def _load_database(database_path: str) -> Any:
    cantools = _import("cantools", "reading CAN logs", "can")
    try:
        check_input(database_path)
    except OSError as exc:
        problem = "not found" if isinstance(exc, FileNotFoundError) else (exc.strerror or str(exc))
        raise DataError(
            f"CAN database {problem}",
            file=database_path,
            key=DATABASE_KEY,
            hint="check the `dbc:` path (relative paths start at the spec file)",
        ) from None
    try:
        # strict=False: real databases often overlap multiplexed signals cantools would refuse.
        database = cantools.database.load_file(database_path, strict=False)
    except Exception as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise DataError(
            "cannot read this CAN database",
            file=database_path,
            key=DATABASE_KEY,
            hint=f"give a DBC, ARXML or KCD file; the parser said: {first}",
        ) from None
    if not hasattr(database, "messages"):
        raise DataError(
            "this is a diagnostics database (CDD), not a CAN signal database",
            file=database_path,
            key=DATABASE_KEY,
            hint="give a DBC, ARXML or KCD file",
        )
    if not database.messages:
        raise DataError(
            "the CAN database defines no messages",
            file=database_path,
            key=DATABASE_KEY,
            hint="check that this is the database of the logged bus",
        )
    return database


@dataclass(frozen=True)
class _SignalRef:
    column: str
    message: Any
    layout: SignalLayout


class _Catalogue:
    """Column names of a database: bare signal names where unique, ``Message.Signal`` always."""

    def __init__(self, database: Any, database_path: str) -> None:
        self.database_path = database_path
        self.by_key: dict[int, Any] = {}
        self.qualified: dict[str, tuple[Any, Any]] = {}
        owners: dict[str, list[str]] = {}
        for message in database.messages:
            self.by_key.setdefault(_message_key(message), message)
            for signal in message.signals:
                qualified = f"{message.name}.{signal.name}"
                self.qualified[qualified] = (message, signal)
                owners.setdefault(str(signal.name), []).append(qualified)
        self.bare = {name: q[0] for name, q in owners.items() if len(q) == 1}
        self.ambiguous = {name: q for name, q in owners.items() if len(q) > 1}

    @property
    def columns(self) -> list[str]:
        """The names to choose from: unique bare names, then every ``Message.Signal``."""
        return [*self.bare, *self.qualified]

    @property
    def default_columns(self) -> list[str]:
        """One name per signal: the bare one where unique."""
        qualified_of_bare = set(self.bare.values())
        return [*self.bare, *(q for q in self.qualified if q not in qualified_of_bare)]

    def resolve(self, source: str, column: str) -> _SignalRef:
        qualified = self.bare.get(column, column)
        if qualified in self.qualified:
            message, signal = self.qualified[qualified]
            return _SignalRef(column, message, SignalLayout.of(signal))
        if column in self.ambiguous:
            names = self.ambiguous[column]
            raise DataError(
                f"signal {column!r} is defined by {len(names)} messages of the CAN database "
                f"{os.path.basename(self.database_path)}: {', '.join(map(repr, names))}",
                file=source,
                column=column,
                hint=f"name it with its message, e.g. {names[0]!r}",
            )
        suggestion = did_you_mean(column, self.columns)
        names = self.default_columns
        raise DataError(
            f"no such signal in the CAN database {os.path.basename(self.database_path)}",
            file=source,
            column=column,
            hint=suggestion
            or f"the database has {len(names)} signals: "
            + ", ".join(repr(n) for n in names[:12])
            + (", …" if len(names) > 12 else ""),
        )


# --------------------------------------------------------------------------------------------
# Reader


def read_can(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    """Read a CAN log and decode ``columns`` (every signal when None) with the database."""
    database_path = options.extra.get(DATABASE_KEY)
    if not database_path:
        raise DataError(
            "a CAN log needs a signal database to decode it",
            file=path,
            key=DATABASE_KEY,
            hint="add `dbc: <file>` (DBC, ARXML or KCD) to the source; "
            "for a text table with the .log extension set `format: csv`",
        )
    catalogue = _Catalogue(_load_database(str(database_path)), str(database_path))
    wanted = catalogue.default_columns if columns is None else list(dict.fromkeys(columns))
    refs = [catalogue.resolve(path, column) for column in wanted]
    frames = _read_frames(path)
    if frames.time.size == 0:
        raise DataError(
            "the log holds no CAN data frames",
            file=path,
            hint="check that the logger recorded the bus",
        )
    return _decode(path, frames, catalogue, refs, strict=columns is not None)


def _time_order(time: FloatArray) -> npt.NDArray[np.intp] | None:
    """The stable sort order of ``time``, or None when it is already in order."""
    if time.size < 2 or bool(np.all(time[1:] >= time[:-1])):
        return None
    return np.argsort(time, kind="stable")


@dataclass
class _MessageFrames:
    time: FloatArray
    length: npt.NDArray[np.uint8]
    payload: npt.NDArray[np.uint8]
    same_time_dropped: int


def _group(frames: _Frames, origin: float) -> dict[int, _MessageFrames]:
    """Frames per key in time order; of frames of one key at the same instant, the last."""
    order = np.argsort(frames.key, kind="stable")
    keys = frames.key[order]
    starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    ends = np.r_[starts[1:], keys.size]
    groups = {}
    for start, end in zip(starts, ends, strict=True):
        rows = order[start:end]
        time = frames.time[rows] - origin
        if frames.absolute:
            # Epoch seconds as floats carry about 0.24 µs: keep what they carry, not rounding.
            time = _at_resolution(time, origin)
        later = np.r_[time[1:] > time[:-1], True]
        kept = rows[later]
        groups[int(keys[start])] = _MessageFrames(
            time=time[later],
            length=frames.length[kept],
            payload=frames.payload[kept],
            same_time_dropped=int(rows.size - kept.size),
        )
    return groups


def _decode(
    path: str, frames: _Frames, catalogue: _Catalogue, refs: Sequence[_SignalRef], *, strict: bool
) -> Record:
    order = _time_order(frames.time)
    if order is not None:
        frames = _Frames(
            frames.time[order],
            frames.key[order],
            frames.length[order],
            frames.payload[order],
            frames.absolute,
        )
    origin = float(frames.time[0])
    groups = _group(frames, origin)
    unknown = {
        _id_text(key): int(group.time.size + group.same_time_dropped)
        for key, group in sorted(groups.items())
        if key not in catalogue.by_key
    }
    decoded_frames = sum(
        group.time.size + group.same_time_dropped
        for key, group in groups.items()
        if key in catalogue.by_key
    )
    channels: dict[str, Channel] = {}
    # Decoded values and presence per (message key, signal): multiplexers are shared.
    cache: dict[tuple[int, str], tuple[FloatArray, npt.NDArray[np.bool_]]] = {}
    for ref in refs:
        key = _message_key(ref.message)
        group = groups.get(key)
        if group is None:
            if strict:
                raise DataError(
                    f"message {ref.message.name!r} ({_id_text(key)}) of signal "
                    f"{ref.layout.name!r} has no frames in this log",
                    file=path,
                    column=ref.column,
                    hint="check that the log and the database belong to the same bus",
                )
            continue
        values, present = _signal_values(ref.message, ref.layout, group, cache)
        if not present.any():
            if strict:
                raise DataError(
                    f"signal {ref.layout.name!r} is multiplexed and its multiplexer never "
                    f"selects it in the {group.time.size} frames of message "
                    f"{ref.message.name!r}",
                    file=path,
                    column=ref.column,
                    hint="choose a signal that was sent",
                )
            continue
        time = group.time if present.all() else group.time[present]
        channels[ref.column] = Channel(
            time=time,
            values=values if present.all() else values[present],
            unit=ref.layout.unit,
        )
    meta: dict[str, Any] = {
        "interpolation": "previous",
        "can": {
            "frames": int(frames.time.size),
            "decoded_frames": int(decoded_frames),
            "unknown_ids": unknown,
        },
    }
    dropped = sum(group.same_time_dropped for group in groups.values())
    if dropped:
        meta["can"]["same_time_frames_dropped"] = dropped
    if frames.absolute:
        meta["start_epoch_s"] = origin
        meta["absolute_start"] = datetime.fromtimestamp(origin, tz=timezone.utc).isoformat()
    return Record(
        source=path,
        channels=channels,
        available=tuple(catalogue.columns),
        # Candidates for diagnosis: signals of the messages the log holds.
        numeric=tuple(
            name
            for name in catalogue.default_columns
            if _message_key(catalogue.resolve(path, name).message) in groups
        ),
        meta=meta,
    )


def _message_key(message: Any) -> int:
    """The frame key of a database message: its identifier, bit 31 set when extended."""
    return int(message.frame_id) | (_EXTENDED_BIT if message.is_extended_frame else 0)


def _signal_values(
    message: Any,
    layout: SignalLayout,
    group: _MessageFrames,
    cache: dict[tuple[int, str], tuple[FloatArray, npt.NDArray[np.bool_]]],
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Values of ``layout`` in every frame of its message, and where the signal is present."""
    key = (_message_key(message), layout.name)
    if key in cache:
        return cache[key]
    needed = layout.bytes_needed
    present = group.length >= needed
    payload = group.payload
    if payload.shape[1] < needed:
        payload = np.pad(payload, ((0, 0), (0, needed - payload.shape[1])))
    values = decode_signal(payload, layout)
    if layout.multiplexer is not None:
        selector = SignalLayout.of(message.get_signal_by_name(layout.multiplexer))
        selector_values, selector_present = _signal_values(message, selector, group, cache)
        # cantools selects a branch by int() of the multiplexer's physical value.
        with np.errstate(invalid="ignore"):
            chosen = np.isin(np.trunc(selector_values), np.asarray(layout.multiplexer_ids))
        present = present & selector_present & chosen
    cache[key] = (values, present)
    return values, present
