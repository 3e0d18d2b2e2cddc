"""Checks and building blocks every reader shares: the time base, numeric columns, errors."""

from __future__ import annotations

import importlib
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from types import ModuleType
from typing import IO, Any

import numpy as np
import numpy.typing as npt

from ...errors import DataError, MissingExtraError, did_you_mean
from ..record import Channel, Record, SourceOptions, missing_column

FloatArray = npt.NDArray[np.float64]


ValueArray = npt.NDArray[np.floating]


# Names that mark the time column when `time:` is not given (compared after dropping a
# bracketed unit and lower-casing).
_TIME_NAMES = ("time", "t", "timestamp", "timestamps", "zeit", "time_s", "seconds", "sec")


_ONE_DAY = 86400.0

#: Seconds in one unit of a time column, by the unit its header names (``Time [ms]``).
TIME_UNITS: dict[str, float] = {
    "s": 1.0,
    "sec": 1.0,
    "secs": 1.0,
    "second": 1.0,
    "seconds": 1.0,
    "ms": 1e-3,
    "msec": 1e-3,
    "us": 1e-6,
    "µs": 1e-6,
    "μs": 1e-6,
    "ns": 1e-9,
    "min": 60.0,
    "h": 3600.0,
}


def _import(module: str, feature: str, extra: str) -> ModuleType:
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError.for_extra(feature, extra, module.split(".")[0]) from None


#: First time stamps in these ranges are Unix epoch times (1980–2100) in that unit; a relative
#: time base starts near zero and never reaches them.
_EPOCH_UNITS: tuple[tuple[str, float], ...] = (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9))
_EPOCH_SECONDS = (3.15e8, 4.1e9)


def _clock_seconds(
    raw: npt.NDArray[Any], unit_scale: float | None = None
) -> tuple[npt.NDArray[Any], float] | None:
    """Absolute time stamps as (seconds since the first stamp, the first as Unix seconds).

    Absolute means: datetime64 values (naive ones are taken as UTC), ISO-8601 text, or numbers
    whose first value is a Unix time in s, ms, µs or ns between 1980 and 2100 (in the unit the
    column's header names, when it names one). None for a relative time base (seconds from some
    start), which is returned as it is by the caller.

    Stamps stored as floats cannot hold more than their magnitude allows (an epoch second
    carries about 0.24 µs); the times from the first stamp are rounded to that resolution, so
    that 10 Hz stamps give steps of 0.1 s and not 0.1000000238 s.
    """
    values = np.asarray(raw)
    if values.ndim != 1 or values.size == 0:
        return None
    if np.issubdtype(values.dtype, np.datetime64):
        stamps = values.astype("datetime64[ns]").astype(np.int64)
    elif values.dtype.kind in "OUS":
        import pandas as pd

        try:
            parsed = pd.to_datetime(pd.Series(values), utc=True, format="ISO8601")
        except (ValueError, TypeError, OverflowError):
            return None
        if parsed.isna().any():
            return None
        stamps = parsed.to_numpy(dtype="datetime64[ns]").astype(np.int64)
    elif values.dtype.kind in "iuf":
        first = float(values[0])
        scales = [unit_scale] if unit_scale is not None else [s for _, s in _EPOCH_UNITS]
        for scale in scales:
            if _EPOCH_SECONDS[0] <= first * scale <= _EPOCH_SECONDS[1]:
                if values.dtype.kind in "iu":
                    # Subtract in integers: epoch nanoseconds exceed float64's exact range.
                    relative = (values.astype(np.int64) - int(values[0])).astype(np.float64)
                else:
                    relative = _at_resolution(values.astype(np.float64) - first, first)
                return relative * scale, first * scale
        return None
    else:
        return None
    return (stamps - stamps[0]).astype(np.float64) * 1e-9, float(stamps[0]) * 1e-9


def _at_resolution(relative: FloatArray, magnitude: float) -> FloatArray:
    """Times from the first stamp rounded to the power of ten at or above the spacing of
    floats at the stamps' ``magnitude``: what lies below it is rounding, not measurement."""
    spacing = float(np.spacing(abs(magnitude)))
    if spacing <= 0.0:
        return relative
    quantum = 10.0 ** math.ceil(math.log10(spacing))
    return np.asarray(np.round(relative / quantum) * quantum, dtype=np.float64)


def _start_meta(start_epoch_s: float) -> dict[str, Any]:
    """The record's absolute start, as Record.meta keys (read by clock-time alignment)."""
    from datetime import datetime, timezone

    start = datetime.fromtimestamp(start_epoch_s, tz=timezone.utc)
    return {"start_epoch_s": start_epoch_s, "absolute_start": start.isoformat()}


def _time_base(
    source: str,
    column: str,
    raw: npt.NDArray[Any],
    options: SourceOptions,
    *,
    first_line: int | None = None,
) -> tuple[FloatArray, dict[str, Any]]:
    """:func:`_check_time` for relative or absolute (clock) time; the meta of a clock start."""
    scale, stated = time_scale(source, column, options) if _numeric(raw) else (1.0, False)
    clock = _clock_seconds(raw, scale if stated else None)
    events = bool(options.extra.get("events"))
    if clock is None:
        if np.asarray(raw).dtype.kind in "OUS":
            raw = text_time_numbers(source, column, raw, first_line=first_line)
        checked = _check_time(source, column, raw, options, first_line=first_line, events=events)
        meta: dict[str, Any] = {}
    else:
        relative, start = clock
        checked = _check_time(
            source, column, relative, _clock_options(options), first_line=first_line, events=events
        )
        meta = _start_meta(start)
    if events:
        checked, meta["events"] = _separate_events(checked)
    return checked, meta


def _separate_events(time: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Time with each event's first row (the value before it) one float64 step earlier, so
    that time increases strictly; and the events' times.

    Scoring then sees a step at the event (the value before it up to the event's instant, the
    value after it from there), and an FMU's input gets the two rows back at one time stamp
    (:func:`pytest_hevval.data.fmu.run_fmu`).
    """
    before = np.flatnonzero(np.diff(time) == 0)
    if not before.size:
        return time, before.astype(np.float64)
    separated = time.copy()
    separated[before] = np.nextafter(time[before], -np.inf)
    return separated, time[before + 1]


def text_time_numbers(
    source: str, column: str, raw: npt.NDArray[Any], *, first_line: int | None = None
) -> FloatArray:
    """A time column of text that is not all ISO-8601 stamps, as numbers; else the error that
    names its first cell that is neither a stamp (where the column holds stamps) nor a
    number."""
    import pandas as pd

    check_stamps(source, column, raw, first_line=first_line)
    cells = pd.Series(np.asarray(raw, dtype=object))
    numbers = pd.to_numeric(cells, errors="coerce")
    bad = np.flatnonzero((numbers.isna() & cells.notna()).to_numpy())
    if bad.size:
        index = int(bad[0])
        raise DataError(
            f"non-numeric value {cells.iloc[index]!r} at index {index}",
            file=source,
            line=None if first_line is None else first_line + index,
            column=column,
            hint="give time as seconds or as ISO-8601 stamps",
        )
    return np.asarray(numbers, dtype=np.float64)


def check_stamps(
    source: str, column: str, raw: npt.NDArray[Any], *, first_line: int | None = None
) -> None:
    """Where a text time column holds ISO-8601 stamps, the error naming its first cell that
    is not one (a leap second, ``…T23:59:60Z``, says so)."""
    import pandas as pd

    values = np.asarray(raw)
    if values.dtype.kind not in "OUS" or values.size == 0:
        return
    if not re.match(r"\s*[+-]?\d{4}-\d\d-\d\d", str(values[0])):
        return
    cells = pd.Series(values.astype(object))
    stamps = pd.to_datetime(cells, utc=True, format="ISO8601", errors="coerce")
    if stamps.notna().any():
        bad = np.flatnonzero((stamps.isna() & cells.notna()).to_numpy())
        if bad.size:
            index = int(bad[0])
            value = cells.iloc[index]
            leap = isinstance(value, str) and re.search(r":60(\.\d*)?\s*(Z|[+-]\d|$)", value)
            raise DataError(
                f"{value!r} at index {index} is not a time stamp"
                + (" (a leap second, which no time stamp type here can hold)" if leap else ""),
                file=source,
                line=None if first_line is None else first_line + index,
                column=column,
                hint="write that stamp as the second before it (…:59.999) or give time as seconds"
                if leap
                else "fix or remove that cell",
            )


def _numeric(raw: npt.NDArray[Any]) -> bool:
    return np.asarray(raw).dtype.kind in "iuf"


def _clock_options(options: SourceOptions) -> SourceOptions:
    """Clock time is seconds already: no time_scale, no milliseconds check."""
    return SourceOptions(
        time=options.time,
        format=options.format,
        time_scale=None,
        extra={**options.extra, "check_time_unit": False, "clock_seconds": True},
    )


def time_scale(source: str, column: str, options: SourceOptions) -> tuple[float, bool]:
    """Seconds per unit of a time column, and whether its unit is stated.

    One rule for every reader: a unit in the header (``Time [ms]``) is honoured; the spec's
    ``time_scale`` says it where the header does not, and must agree where it does; a header
    unit that is not a unit of time is refused rather than ignored.
    """
    given = options.time_scale
    if options.extra.get("clock_seconds"):
        return 1.0, True
    header = _unit_from_name(column)
    if header is None:
        return (1.0, False) if given is None else (float(given), True)
    scale = TIME_UNITS.get(header.lower()) or TIME_UNITS.get(header)
    if scale is None:
        if given is not None:
            return float(given), True  # the spec says what the header's unit is
        raise DataError(
            f"the time column's header names the unit {header!r}, which is not a unit of time",
            file=source,
            column=column,
            hint="set `time_scale:` to the seconds in one of its units (0.001 for milliseconds),"
            " or rename the column",
        )
    if given is not None and not math.isclose(float(given), scale, rel_tol=1e-9):
        raise DataError(
            f"the time column's header says {header}, {scale:g} s per unit, but `time_scale` "
            f"is {float(given):g}",
            file=source,
            column=column,
            hint="remove `time_scale:` (the header's unit is used) or correct it",
        )
    return scale, True


def _check_time(
    source: str,
    column: str,
    raw: npt.NDArray[Any],
    options: SourceOptions,
    *,
    first_line: int | None = None,
    events: bool = False,
) -> FloatArray:
    """Return ``raw`` as float64 seconds, or raise if it is not a usable time base.

    ``first_line`` is the file line of index 0 (text formats), so errors can point at a line.
    With ``events``, two rows at one time stamp (an event in the FMI convention: the values
    before and after it) are allowed; three are not.
    """

    def line(index: int) -> int | None:
        return None if first_line is None else first_line + index

    time = np.asarray(raw, dtype=np.float64)
    if time.ndim != 1:
        raise DataError(
            f"the time column has shape {time.shape}, expected one dimension",
            file=source,
            column=column,
            hint="store time as a 1-D array",
        )
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"time is missing or not finite at index {i} (value {time[i]})",
            file=source,
            line=line(i),
            column=column,
            hint="remove that row or fill in its time",
        )
    step = np.diff(time)
    # Only with events may two rows share a time stamp.
    repeated = step == 0 if events else np.zeros(step.shape, dtype=bool)
    if events:
        third = np.flatnonzero(repeated[:-1] & repeated[1:])
        if third.size:
            i = int(third[0])
            raise DataError(
                f"three rows at t={time[i]:g} (index {i} to {i + 2}); an event has two, "
                "the values before and after it",
                file=source,
                line=line(i + 2),
                column=column,
                hint="keep two rows per time stamp at most",
            )
    bad = np.flatnonzero((step <= 0) & ~repeated)
    if bad.size:
        i = int(bad[0])
        if step[i] == 0:
            problem = f"duplicate timestamp t={time[i]:g} at index {i} and {i + 1}"
        else:
            problem = (
                f"time is not increasing: t={time[i + 1]:g} at index {i + 1} "
                f"follows t={time[i]:g} at index {i}"
            )
        raise DataError(
            problem,
            file=source,
            line=line(i + 1),
            column=column,
            hint="sort the data by time and drop repeated rows",
        )
    scale, stated = time_scale(source, column, options)
    if not stated and options.extra.get("check_time_unit", True):
        _check_time_unit(source, column, time)
    if scale != 1.0:
        with np.errstate(over="ignore", under="ignore"):
            scaled = time * scale
        if not (np.all(np.isfinite(scaled)) and np.all(np.diff(scaled) > 0)):
            raise DataError(
                f"`time_scale: {scale:g}` takes the time outside what float64 holds "
                f"(from t = {time[0]:g} to {time[-1]:g} become {scaled[0]:g} to {scaled[-1]:g} s)",
                file=source,
                column=column,
                key="time_scale",
                hint="set `time_scale:` to the seconds in one unit of this column "
                "(0.001 for milliseconds)",
            )
        time = scaled
    return time


def _check_time_unit(source: str, column: str, time: FloatArray) -> None:
    """Reject a time column that is evidently milliseconds read as seconds.

    Whole-number times whose median step is at least 1 and whose span exceeds a day are what
    a logger writing integer milliseconds produces; a vehicle test in seconds at that
    resolution would have to last over a day, which the spec can still allow explicitly.
    """
    if time.size < 3:
        return
    span = float(time[-1] - time[0])
    median_step = float(np.median(np.diff(time)))
    if span <= _ONE_DAY or median_step < 1.0 or not np.all(time == np.round(time)):
        return
    raise DataError(
        f"time looks like milliseconds, not seconds: whole numbers with a median step of "
        f"{median_step:g} and a span of {span:g} s ({span / _ONE_DAY:.1f} days)",
        file=source,
        column=column,
        hint="set `time_scale: 0.001` (or `check_time_unit: false` if the data really are seconds)",
    )


def _as_values(
    source: str, column: str, raw: npt.NDArray[Any], *, line_of: int | None = None
) -> ValueArray:
    """Return channel values: float32 stays float32, other numbers become float64."""
    arr = np.asarray(raw)
    if arr.dtype == np.float32 or arr.dtype == np.float64:
        return arr
    if arr.dtype.kind in "biuf":
        return arr.astype(np.float64)
    raise _not_numbers(source, column, _kind_name(arr.dtype), line=line_of)


def _not_numbers(
    source: str, column: str, holds: str, *, line: int | None = None, noun: str = "column"
) -> DataError:
    return DataError(
        f"holds {holds}, not numbers",
        file=source,
        line=line,
        column=column,
        hint=f"choose a numeric {noun}",
    )


def _kind_name(dtype: np.dtype[Any]) -> str:
    return {
        "U": "text",
        "S": "bytes",
        "O": "objects (text or mixed)",
        "M": "dates",
        "m": "durations",
        "V": "records",
        "c": "complex numbers",
    }.get(dtype.kind, f"values of type {dtype}")


def _is_numeric_dtype(dtype: np.dtype[Any]) -> bool:
    return dtype.kind in "biuf"


def _pick_time(
    source: str,
    names: Sequence[str],
    options: SourceOptions,
    fallback: Sequence[str] | None = None,
) -> str:
    """The time column: ``options.time`` when given, else a time-like name, else the first.

    ``fallback`` narrows "the first" to columns that can be a time base at all.
    """
    if options.time is not None:
        if options.time in names:
            return options.time
        suggestion = did_you_mean(options.time, names)
        raise DataError(
            "no time column with this name",
            file=source,
            column=options.time,
            hint=(suggestion + " " if suggestion else "")
            + "set `time:` to the name of the time column",
        )
    bare = [re.sub(r"\s*[\[(].*$", "", name).strip().lower() for name in names]
    # An exact time name wins over a name that merely starts like one (`time` over
    # `timer_ticks`); a prefix counts only when no letter follows it (`time_s`, `Time.1`).
    for name, stem in zip(names, bare, strict=True):
        if stem in _TIME_NAMES:
            return name
    for name, stem in zip(names, bare, strict=True):
        if stem.startswith("time") and not stem[4:5].isalpha():
            return name
    candidates = list(fallback) if fallback else list(names)
    if not candidates:
        raise DataError("the file has no columns", file=source, hint="check the file's content")
    return candidates[0]


def _vector_plan(
    source: str,
    lengths: Mapping[str, int],
    numeric: Sequence[str],
    columns: Iterable[str] | None,
    options: SourceOptions,
) -> tuple[str, list[str], list[str]]:
    """Time column, channels to read and numeric channels for a file of named vectors.

    Such files (MAT, HDF5) also hold scalars and vectors of other lengths (parameters,
    other rates); only numeric vectors as long as the time vector count as its channels.
    """
    names = list(lengths)
    series = [n for n in numeric if lengths[n] >= 2]
    time_name = _pick_time(source, names, options, fallback=series)
    same = [n for n in numeric if lengths[n] == lengths[time_name] and n != time_name]
    return time_name, _channel_list(source, columns, names, same), same


def _as_list(columns: Iterable[str] | None) -> list[str] | None:
    return None if columns is None else list(dict.fromkeys(columns))


def _channel_list(
    source: str,
    wanted: Iterable[str] | None,
    available: Sequence[str],
    numeric: Sequence[str],
) -> list[str]:
    """The channels to read: ``wanted`` (checked against ``available``) or all numeric ones."""
    if wanted is None:
        return list(numeric)
    names = list(dict.fromkeys(wanted))
    for name in names:
        if name not in available:
            raise missing_column(source, name, available)
    return names


def _unit_from_name(name: str) -> str | None:
    """``'Velocity [km/h]'`` → ``'km/h'``: a unit written in brackets at the end of a header."""
    match = re.search(r"\[([^\[\]]+)\]\s*$", name)
    return match.group(1).strip() if match else None


def _table_record(
    source: str,
    time_name: str,
    time: FloatArray,
    values: Mapping[str, ValueArray],
    *,
    available: Sequence[str],
    numeric: Sequence[str],
    units: Mapping[str, str | None] | None = None,
    meta: dict[str, Any] | None = None,
) -> Record:
    """A record whose channels all share one time array."""
    units = units or {}
    channels = {}
    for name, vals in values.items():
        if vals.shape[0] != time.shape[0]:
            raise DataError(
                f"has {vals.shape[0]} samples but the time column {time_name!r} has "
                f"{time.shape[0]}",
                file=source,
                column=name,
                hint="channels of a table must share its time column; store channels with "
                "other rates in a group of their own",
            )
        channels[name] = Channel(time=time, values=vals, unit=units.get(name))
    full_meta = {"time_column": time_name}
    full_meta.update(meta or {})
    return Record(
        source=source,
        channels=channels,
        available=tuple(available),
        numeric=tuple(n for n in numeric if n != time_name),
        meta=full_meta,
    )


def _no_rows(source: str) -> DataError:
    return DataError(
        "the file has a header but no data rows",
        file=source,
        hint="check that the export finished",
    )


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    if isinstance(exc, LookupError) and text:
        # A bare "0" or "'cn'" says nothing without the kind of lookup that failed.
        return f"{type(exc).__name__}: {text[0]}"
    return text[0] if text else type(exc).__name__


def _corrupt(path: str, kind: str, exc: BaseException) -> DataError:
    return DataError(
        f"cannot read this {kind} file (file truncated or corrupt?)",
        file=path,
        hint=f"write the file again; the reader said: {_first_line(exc)}",
    )


_SECONDS_PER = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}


def _read_at(stream: IO[bytes], position: int, count: int) -> bytes:
    stream.seek(position)
    return bytes(stream.read(count))
