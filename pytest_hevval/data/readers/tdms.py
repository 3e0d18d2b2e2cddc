"""NI TDMS files (LabVIEW, common on test benches) through npTDMS.

A TDMS file holds groups of channels. ``group:`` picks one; a file with a single group needs
none. A channel's time comes from its waveform properties when it has them
(``wf_start_offset`` + k·``wf_increment``, each channel on its own time base), otherwise from a
time channel of the group, found like a table's time column (``time:``, or a time-like name).
A waveform's ``wf_start_time`` gives the record's absolute start (``start_epoch_s``,
``absolute_start``) for clock-time alignment. Units come from ``unit_string``.
"""

from __future__ import annotations

from collections.abc import Iterable
from datetime import datetime, timezone
from typing import Any

import numpy as np

from ...errors import DataError, did_you_mean
from ..record import Channel, Record, SourceOptions, missing_column
from ._common import _check_time, _corrupt, _import, _is_numeric_dtype, _pick_time

__all__ = ["read_tdms"]

#: Waveform properties that make a channel its own time base.
_WAVEFORM_STEP = "wf_increment"
_WAVEFORM_OFFSET = "wf_start_offset"
_WAVEFORM_START = "wf_start_time"


def read_tdms(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    nptdms = _import("nptdms", "reading TDMS files", "tdms")
    try:
        tdms = nptdms.TdmsFile.read(path)
        groups = {group.name: group for group in tdms.groups()}
    except Exception as exc:  # npTDMS raises ValueError, KeyError, struct.error … when damaged
        raise _corrupt(path, "TDMS", exc) from None
    group = _group(path, groups, options.group)
    by_name = {channel.name: channel for channel in group.channels()}
    numeric = [n for n, c in by_name.items() if _is_numeric_dtype(np.asarray(c[:0]).dtype)]
    wanted = list(dict.fromkeys(columns)) if columns is not None else numeric
    for name in wanted:
        if name not in by_name:
            raise missing_column(path, name, by_name)
    shared_time: np.ndarray | None = None
    time_name: str | None = None
    if not all(_is_waveform(by_name[n]) for n in wanted):
        candidates = [n for n in numeric if not _is_waveform(by_name[n])]
        time_name = _pick_time(path, list(by_name), options, candidates)
        raw = np.asarray(by_name[time_name][:])
        shared_time = _check_time(path, time_name, raw, options)
    channels: dict[str, Channel] = {}
    start: datetime | None = None
    for name in wanted:
        channel = by_name[name]
        values = np.asarray(channel[:])
        if not _is_numeric_dtype(values.dtype):
            raise DataError(
                f"holds {values.dtype} values, not numbers",
                file=path,
                column=name,
                hint="score a numeric channel",
            )
        if _is_waveform(channel):
            properties = channel.properties
            step = float(properties[_WAVEFORM_STEP])
            offset = float(properties.get(_WAVEFORM_OFFSET, 0.0))
            time = offset + step * np.arange(values.shape[0], dtype=np.float64)
            time = _check_time(path, name, time, options)
            start = start or _absolute(properties.get(_WAVEFORM_START))
        else:
            assert shared_time is not None
            time = shared_time
            if values.shape[0] != time.shape[0]:
                raise DataError(
                    f"has {values.shape[0]} samples but the time channel {time_name!r} has "
                    f"{time.shape[0]}",
                    file=path,
                    column=name,
                    hint="give the channel waveform properties (wf_increment) or a time "
                    "channel of its own length",
                )
        unit = channel.properties.get("unit_string") or None
        channels[name] = Channel(time=time, values=values, unit=str(unit) if unit else None)
    meta: dict[str, Any] = {"group": group.name}
    if start is not None:
        meta["start_epoch_s"] = start.timestamp()
        meta["absolute_start"] = start.isoformat()
    return Record(
        source=path,
        channels=channels,
        available=tuple(by_name),
        numeric=tuple(n for n in numeric if n != time_name),
        meta=meta,
    )


def _group(path: str, groups: dict[str, Any], wanted: str | None) -> Any:
    populated = {name: g for name, g in groups.items() if g.channels()}
    if wanted is not None:
        if wanted in groups:
            return groups[wanted]
        suggestion = did_you_mean(wanted, groups)
        raise DataError(
            f"no group {wanted!r} in this TDMS file",
            file=path,
            key="group",
            hint=(suggestion + " " if suggestion else "")
            + f"the groups are: {', '.join(groups) or '(none)'}",
        )
    if len(populated) == 1:
        return next(iter(populated.values()))
    if not populated:
        raise DataError("the TDMS file holds no channels", file=path, hint="check the file")
    raise DataError(
        f"the TDMS file holds {len(populated)} groups of channels",
        file=path,
        key="group",
        hint=f"set `group:` to one of {', '.join(populated)}",
    )


def _is_waveform(channel: Any) -> bool:
    return _WAVEFORM_STEP in channel.properties


def _absolute(value: Any) -> datetime | None:
    """A waveform's start time (numpy datetime64 in UTC, as npTDMS returns it) as a datetime."""
    if value is None:
        return None
    try:
        stamp = np.datetime64(value, "us").astype("datetime64[us]").astype(object)
    except (TypeError, ValueError):
        return None
    if not isinstance(stamp, datetime):
        return None
    return stamp.replace(tzinfo=timezone.utc)
