"""ASAM MDF 3 and 4 through asammdf; plain MDF 4 groups streamed out of their records."""

from __future__ import annotations

import io
import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ...errors import DataError
from ..record import Channel, Record, SourceOptions
from ._common import (
    FloatArray,
    _as_values,
    _channel_list,
    _check_time,
    _corrupt,
    _import,
    _is_numeric_dtype,
    _kind_name,
    _not_numbers,
    _start_meta,
)
from .guards.mdf import _MDF3_TEXT_TYPES, _MDF4_NUMERIC_TYPES, _check_mdf_record, _mdf_loop


@contextmanager
def _open_mdf(path: str) -> Iterator[Any]:
    asammdf = _import("asammdf", "reading MDF files", "mdf")
    loop = _mdf_loop(path)
    if loop is not None:
        raise DataError(
            f"cannot read this MDF file (file corrupt?): {loop}",
            file=path,
            hint="write the file again",
        )
    try:
        mdf = asammdf.MDF(path)
    except Exception as exc:
        # asammdf raises MdfException, ValueError, struct.error … for damaged files.
        _disarm_half_open_mdf(exc)
        raise _corrupt(path, "MDF", exc) from None
    try:
        yield mdf
    finally:
        mdf.close()


def _disarm_half_open_mdf(exc: BaseException) -> None:
    """Mark an MDF object whose constructor failed as closed.

    asammdf's ``__del__`` calls ``close()`` on such an object, which then fails on attributes
    the constructor never set; the error surfaces as an unraisable exception (a warning under
    pytest). The object is only reachable through the traceback.

    asammdf's ``MDF.__init__`` also leaves the data file open when the version field of the
    identification block is not ASCII; that stream too is only reachable through the traceback
    and would be reported as an unclosed file when collected.
    """
    traceback = exc.__traceback__
    while traceback is not None:
        frame = traceback.tb_frame
        if str(frame.f_globals.get("__name__", "")).startswith("asammdf"):
            for value in list(frame.f_locals.values()):
                if isinstance(value, io.IOBase) and not value.closed:
                    value.close()
        obj: Any = frame.f_locals.get("self")
        half_open = obj is not None and not getattr(obj, "_closed", True)
        if half_open and type(obj).__module__.startswith("asammdf.blocks.mdf_v"):
            # The MDF 3 reader opens the file as ``_mapped_file`` before it parses anything.
            for attribute in ("_tempfile", "_mapped_file", "_file"):
                stream = getattr(obj, attribute, None)
                if stream is not None and not getattr(stream, "closed", True):
                    stream.close()
            obj._closed = True
        traceback = traceback.tb_next


@dataclass(frozen=True)
class _MdfSamples:
    """One channel's samples and its group's time stamps, however they were read."""

    samples: npt.NDArray[Any]
    timestamps: npt.NDArray[Any]
    unit: str | None


@dataclass(frozen=True)
class _PlainMdfPlan:
    """Where the bytes of some channels of one plain MDF4 channel group lie.

    ``fields`` holds (dtype, byte offset in the record, unit) for the master first, then for
    every channel asked for; ``segments`` the (file offset, size) of each data block in order.
    """

    record_size: int
    cycles: int
    fields: list[tuple[np.dtype[Any], int, str | None]]
    segments: list[tuple[int, int]]


# Plain fixed-size channels: MDF4 channel type 0 (value) or 2 (master), data types 0–5
# (integers and IEEE floats of either byte order).
_PLAIN_MDF_CHANNEL_TYPES = (0, 2)


_PLAIN_MDF_DATA_TYPES = (0, 1, 2, 3, 4, 5)


def _plain_mdf_plan(
    mdf: Any, version: str, group_index: int, channel_indices: list[int]
) -> _PlainMdfPlan | None:
    """A plan to copy these channels straight out of the records, or None to ask asammdf.

    asammdf reads a whole channel group into memory before it extracts any channel (as much
    memory again as a group's channels), so for the common layout — uncompressed data blocks
    of fixed records, byte-aligned numbers without conversions or invalidation bits — the
    records are streamed instead. asammdf still parses the file and describes the layout
    (``group.record``); anything else goes through ``MDF.select``.
    """
    if not version.startswith("4"):
        return None
    try:
        group = mdf.groups[group_index]
        master = mdf.masters_db.get(group_index)
        channel_group = group.channel_group
        if master is None or group.uses_ld or int(group.data_location) != 0:
            return None
        if int(group.data_group.record_id_len) or int(channel_group.invalidation_bytes_nr):
            return None
        record_size = int(channel_group.samples_byte_nr)
        cycles = int(channel_group.cycles_nr)
        fields = []
        for index in [master, *channel_indices]:
            channel = group.channels[index]
            layout = group.record[index]
            if (
                layout is None
                or group.signal_data[index]
                or group.channel_dependencies[index]
                or channel.conversion is not None
                or not channel.standard_C_size
                or int(channel.channel_type) not in _PLAIN_MDF_CHANNEL_TYPES
                or int(channel.data_type) not in _PLAIN_MDF_DATA_TYPES
                or int(channel.flags) & 0b11  # all values invalid, or invalidation bits
            ):
                return None
            dtype, byte_size, byte_offset, bit_offset = layout
            dtype = np.dtype(dtype)
            if bit_offset or dtype.itemsize != int(byte_size) or dtype.kind not in "fiu":
                return None
            if byte_offset + dtype.itemsize > record_size:
                return None
            fields.append((dtype, int(byte_offset), str(channel.unit) or None))
        segments = []
        for block in group.data_blocks:
            if int(block.block_type) != 0:
                return None
            size = int(block.original_size)
            if block.block_limit is not None:
                size = min(size, int(block.block_limit))
            segments.append((int(block.address), size))
    except (AttributeError, IndexError, KeyError, TypeError, ValueError):
        return None
    if record_size <= 0 or sum(size for _, size in segments) < cycles * record_size:
        return None
    return _PlainMdfPlan(record_size, cycles, fields, segments)


# Bytes of records held at once while streaming a plain MDF group.
_MDF_STREAM_BYTES = 32 << 20


def _read_plain_mdf(path: str, plan: _PlainMdfPlan) -> list[_MdfSamples]:
    """Stream the records of a plain group, copying each field into its own array."""
    size = plan.record_size
    # Checked before anything is allocated: a damaged record count must not size arrays.
    # (_check_mdf_record has put every data block inside the file; a short read is caught
    # below.)
    if plan.cycles * size > os.path.getsize(path):
        raise DataError(
            "a data block ends past the end of the file (file truncated?)",
            file=path,
            hint="write the file again",
        )
    # The buffer stays small beside the arrays it fills, so a spec that reads a few channels
    # of a wide group does not pay for the whole record width in memory.
    wanted_bytes = plan.cycles * sum(dtype.itemsize for dtype, _, _ in plan.fields)
    per_pass = max(1, min(_MDF_STREAM_BYTES, wanted_bytes // 8) // size)
    buffer = bytearray(per_pass * size)
    view = memoryview(buffer)
    outputs = [np.empty(plan.cycles, dtype=dtype) for dtype, _, _ in plan.fields]
    done = 0  # records copied out
    filled = 0  # bytes waiting in the buffer

    def drain(count: int) -> None:
        nonlocal done
        records = np.frombuffer(buffer, dtype=np.uint8, count=count * size).reshape(count, size)
        for (dtype, offset, _), out in zip(plan.fields, outputs, strict=True):
            field = records[:, offset : offset + dtype.itemsize].view(dtype)[:, 0]
            out[done : done + count] = field
        done += count

    try:
        with open(path, "rb") as stream:
            for address, length in plan.segments:
                stream.seek(address)
                while length > 0 and done < plan.cycles:
                    got = stream.readinto(view[filled : filled + min(length, len(buffer) - filled)])
                    if not got:
                        raise DataError(
                            "a data block ends past the end of the file (file truncated?)",
                            file=path,
                            hint="write the file again",
                        )
                    filled += got
                    length -= got
                    whole = min(filled // size, plan.cycles - done)
                    if whole and (filled == len(buffer) or length == 0):
                        drain(whole)
                        leftover = filled - whole * size
                        buffer[:leftover] = buffer[whole * size : filled]
                        filled = leftover
    except OSError as exc:
        raise _corrupt(path, "MDF", exc) from None
    finally:
        view.release()
    if done < plan.cycles:
        raise DataError(
            f"the data blocks hold {done} of the {plan.cycles} records the channel group "
            "declares (file truncated or corrupt?)",
            file=path,
            hint="write the file again",
        )
    time = outputs[0]
    return [
        _MdfSamples(values, time, unit)
        for values, (_, _, unit) in zip(outputs[1:], plan.fields[1:], strict=True)
    ]


def _read_mdf(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    with _open_mdf(path) as mdf:
        version = str(mdf.version)
        started = _mdf_start(mdf)
        first: dict[str, tuple[int, int]] = {}
        numeric_flag: dict[str, bool] = {}
        repeated: set[str] = set()
        for group_index, group in enumerate(mdf.groups):
            master = mdf.masters_db.get(group_index)
            for channel_index, channel in enumerate(group.channels):
                if channel_index == master:
                    continue
                name = str(channel.name)
                if name in first:
                    repeated.add(name)
                    continue
                first[name] = (group_index, channel_index)
                numeric_flag[name] = _mdf_numeric(version, int(channel.data_type))
        names = list(first)
        numeric = [n for n in names if numeric_flag[n]]
        wanted = _channel_list(path, columns, names, numeric)
        for group_index in sorted({first[n][0] for n in wanted}):
            _check_mdf_record(path, version, mdf.groups[group_index])
        by_group: dict[int, list[str]] = {}
        for name in wanted:
            by_group.setdefault(first[name][0], []).append(name)
        loaded: dict[str, _MdfSamples] = {}
        rest: list[str] = []
        for group_index, names_in_group in by_group.items():
            plan = _plain_mdf_plan(mdf, version, group_index, [first[n][1] for n in names_in_group])
            if plan is None:
                rest.extend(names_in_group)
                continue
            loaded.update(zip(names_in_group, _read_plain_mdf(path, plan), strict=True))
        try:
            # copy_master=False: the channels of a group share one time array instead of
            # one copy each, which for a 600-channel group doubled the memory and the time.
            selected = (
                mdf.select([(n, *first[n]) for n in rest], raw=False, copy_master=False)
                if rest
                else []
            )
        except Exception as exc:
            # Same as opening: a damaged data block fails with assorted exception types.
            raise _corrupt(path, "MDF", exc) from None
        for name, signal in zip(rest, selected, strict=True):
            loaded[name] = _MdfSamples(
                np.asarray(signal.samples), np.asarray(signal.timestamps), signal.unit
            )
        signals = [loaded[name] for name in wanted]

    channels: dict[str, Channel] = {}
    # Channels of one MDF group share its master time: check it once and keep one array,
    # instead of one copy per channel (as much memory again as the values).
    group_times: dict[int, FloatArray] = {}
    for name, signal in zip(wanted, signals, strict=True):
        samples = np.asarray(signal.samples)
        if samples.ndim != 1 or not _is_numeric_dtype(samples.dtype):
            raise _not_numbers(path, name, _kind_name(samples.dtype), noun="channel")
        if samples.size == 0:
            raise DataError(
                "the channel has no samples",
                file=path,
                column=name,
                hint="choose a channel that was recorded",
            )
        group = first[name][0]
        time = group_times.get(group)
        if time is None or time.shape[0] != samples.shape[0]:
            time = _check_time(path, name, np.asarray(signal.timestamps), options)
            group_times.setdefault(group, time)
        unit = str(signal.unit) if signal.unit else None
        channels[name] = Channel(time=time, values=_as_values(path, name, samples), unit=unit)
    meta: dict[str, Any] = {"mdf_version": version}
    if started is not None:
        meta.update(_start_meta(started))
    if repeated:
        # The first occurrence wins; the others are reachable only by renaming at export.
        meta["repeated_channel_names"] = sorted(repeated)
    return Record(
        source=path,
        channels=channels,
        available=tuple(names),
        numeric=tuple(numeric),
        meta=meta,
    )


def _mdf_numeric(version: str, data_type: int) -> bool:
    if version.startswith("4"):
        return data_type in _MDF4_NUMERIC_TYPES
    return data_type not in _MDF3_TEXT_TYPES


def _mdf_start(mdf: Any) -> float | None:
    """The measurement's absolute start (MDF header), as Unix seconds; naive times are UTC."""
    from datetime import datetime, timezone

    start = getattr(mdf, "start_time", None)
    if not isinstance(start, datetime):
        return None
    if start.tzinfo is None:
        start = start.replace(tzinfo=timezone.utc)
    seconds = start.timestamp()
    # asammdf reports a header without a date as the epoch itself.
    return seconds if seconds > 0 else None
