"""File-format readers: CSV/TSV, Parquet, MAT (v5 and v7.3), HDF5 and MDF.

:func:`read_record` is the only entry point the engine needs. It picks a reader from
``options.format`` or the file extension, reads only the requested columns (plus time) and
checks the time base, so every :class:`~pytest_hevval.data.record.Record` it returns has
strictly increasing float64 times in seconds.

Every problem a user can fix becomes a :class:`~pytest_hevval.errors.DataError` that names the
file, the column where there is one, and what to change in the spec. The catalogue of messages
is in ``docs/data.md``.
"""

from __future__ import annotations

import csv
import importlib
import io
import os
import re
import struct
import threading
import warnings
import zlib
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import closing, contextmanager
from dataclasses import dataclass
from types import ModuleType
from typing import IO, TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt

from ..errors import DataError, MissingExtraError, did_you_mean
from .record import Channel, Reader, Record, SourceOptions, missing_column
from .remote import is_url, parquet_source, read_url

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "FORMATS",
    "detect_format",
    "read_record",
    "register_reader",
]

FloatArray = npt.NDArray[np.float64]
ValueArray = npt.NDArray[np.floating]

#: Format name → file extensions that select it (lower case, with the dot).
FORMATS: dict[str, tuple[str, ...]] = {
    "csv": (".csv", ".txt"),
    "tsv": (".tsv", ".tab"),
    "parquet": (".parquet", ".pq"),
    "mat": (".mat",),
    "hdf5": (".h5", ".hdf5", ".hdf"),
    "mdf": (".mf4", ".mdf"),
}

# Spellings people write in `format:` that mean one of the formats above.
_ALIASES = {
    "txt": "csv",
    "tab": "tsv",
    "pq": "parquet",
    "matlab": "mat",
    "h5": "hdf5",
    "hdf": "hdf5",
    "mf4": "mdf",
    "mdf4": "mdf",
}

_READERS: dict[str, Reader] = {}

# Names that mark the time column when `time:` is not given (compared after dropping a
# bracketed unit and lower-casing).
_TIME_NAMES = ("time", "t", "timestamp", "timestamps", "zeit", "time_s", "seconds", "sec")

_SEPARATORS = (";", ",", "\t", "|")

# A MATLAB v7.3 file is HDF5 with a 512-byte (or larger power-of-two) user block in front.
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_HDF5_SIGNATURE_OFFSETS = (0, 512, 1024, 2048)

# Rows sampled to tell numeric CSV columns from text ones without reading the whole file.
_SNIFF_ROWS = 200
_SNIFF_BYTES = 65536

_ONE_DAY = 86400.0


def register_reader(name: str, reader: Reader, extensions: Sequence[str] = ()) -> None:
    """Add (or replace) the reader for format ``name``, selected by ``extensions``."""
    key = name.lower()
    _READERS[key] = reader
    exts = tuple(e.lower() if e.startswith(".") else f".{e.lower()}" for e in extensions)
    FORMATS[key] = tuple(dict.fromkeys(FORMATS.get(key, ()) + exts))


def _formats_text() -> str:
    return ", ".join(f"{name} ({', '.join(exts)})" for name, exts in FORMATS.items())


def detect_format(path: str, options: SourceOptions) -> str:
    """The format name for ``path``: ``options.format`` when given, else from the extension."""
    if options.format is not None:
        wanted = options.format.strip().lower().lstrip(".")
        wanted = _ALIASES.get(wanted, wanted)
        if wanted in FORMATS:
            return wanted
        suggestion = did_you_mean(wanted, FORMATS)
        raise DataError(
            f"unknown format {options.format!r}",
            file=path,
            key="format",
            hint=(suggestion + " " if suggestion else "")
            + f"supported formats: {', '.join(FORMATS)}",
        )
    ext = os.path.splitext(path)[1].lower()
    for name, exts in FORMATS.items():
        if ext in exts:
            return name
    shown = repr(ext) if ext else "(none)"
    raise DataError(
        f"cannot tell the file format from the extension {shown}",
        file=path,
        hint=f"set `format:` to one of {', '.join(FORMATS)}; supported: {_formats_text()}",
    )


def read_record(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    """Read ``columns`` (all numeric ones when None) and the time column of ``path``.

    Parameters
    ----------
    path
        The data file.
    columns
        Channel names to read. The time column is always read and is not returned as a
        channel unless it is listed here too.
    options
        How to read the file (format, separator, encoding, time column, group, time scale).

    Raises
    ------
    DataError
        For anything wrong with the file: missing, empty, unreadable, a column that is not
        there or not numeric, or a time base that is not strictly increasing seconds.
    MissingExtraError
        When the format needs an optional package that is not installed.
    """
    path = os.fspath(path)
    fmt = detect_format(path, options)
    if is_url(path):
        return read_url(path, columns, options, fmt, _READERS[fmt])
    if not os.path.exists(path):
        raise DataError(
            "file not found",
            file=path,
            hint=f"check the path (the current directory is {os.getcwd()})",
        )
    if os.path.isdir(path):
        raise DataError("this is a directory, not a data file", file=path, hint="name a file")
    if os.path.getsize(path) == 0:
        raise DataError("the file is empty (0 bytes)", file=path, hint=_rewrite_hint(fmt))
    wanted = None if columns is None else list(dict.fromkeys(columns))
    reader = _READERS[fmt]
    try:
        record = reader(path, wanted, options)
    except MissingExtraError as exc:
        raise exc.with_context(file=path) from None
    record.meta.setdefault("format", fmt)
    return record


def _rewrite_hint(fmt: str) -> str:
    return f"export the data again as {fmt}"


# --------------------------------------------------------------------------------------------
# Shared checks


def _import(module: str, feature: str, extra: str) -> ModuleType:
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError.for_extra(feature, extra, module.split(".")[0]) from None


def _check_time(
    source: str,
    column: str,
    raw: npt.NDArray[Any],
    options: SourceOptions,
    *,
    first_line: int | None = None,
) -> FloatArray:
    """Return ``raw`` as float64 seconds, or raise if it is not a usable time base.

    ``first_line`` is the file line of index 0 (text formats), so errors can point at a line.
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
    bad = np.flatnonzero(step <= 0)
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
    if options.time_scale == 1.0 and options.extra.get("check_time_unit", True):
        _check_time_unit(source, column, time)
    if options.time_scale != 1.0:
        time = time * float(options.time_scale)
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
    for name in names:
        bare = re.sub(r"\s*[\[(].*$", "", name).strip().lower()
        if bare in _TIME_NAMES or bare.startswith("time"):
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


# --------------------------------------------------------------------------------------------
# CSV / TSV


def _read_head(path: str) -> bytes:
    with open(path, "rb") as stream:
        return stream.read(_SNIFF_BYTES)


def _sniff_encoding(head: bytes) -> str:
    if head.startswith(b"\xef\xbb\xbf"):
        return "utf-8-sig"
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        # A multi-byte character cut by the sniff window is not evidence against UTF-8.
        if exc.start < len(head) - 3:
            return "latin-1"
    return "utf-8"


def _check_encoding(path: str, encoding: str) -> None:
    """Reject an `encoding:` Python does not know, or one that does not decode bytes to text."""
    try:
        # Empty input would skip the codec lookup. The header is decoded with "replace", which
        # some codecs (idna) refuse.
        b"\x00\x00\x00\x00".decode(encoding, errors="replace")
    except (LookupError, UnicodeError):
        raise DataError(
            f"{encoding!r} is not a text encoding Python can read files in",
            file=path,
            key="encoding",
            hint="set `encoding:` to a text encoding such as utf-8, latin-1 or cp1252",
        ) from None


def _header_line(head: bytes, encoding: str) -> str:
    text = head.decode(encoding, errors="replace")
    for line in text.splitlines():
        if line.strip():
            return line
    return ""


def _sniff_sep(header: str) -> str:
    counts = {sep: header.count(sep) for sep in _SEPARATORS}
    best = max(_SEPARATORS, key=lambda sep: counts[sep])
    return best if counts[best] else ","


def _sep_name(sep: str) -> str:
    return {"\t": "'\\t' (tab)"}.get(sep, repr(sep))


def _engine(sep: str) -> Literal["c", "python"]:
    # A multi-character separator is a regular expression, which only the python engine
    # reads; asking the C engine would fall back with a warning.
    return "c" if len(sep) == 1 else "python"


def _pyarrow_available() -> bool:
    try:
        importlib.import_module("pyarrow")
    except ImportError:
        return False
    return True


def _read_csv(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    return _read_delimited(path, _as_list(columns), options, default_sep=None)


def _read_tsv(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    return _read_delimited(path, _as_list(columns), options, default_sep="\t")


def _read_delimited(
    path: str,
    columns: list[str] | None,
    options: SourceOptions,
    *,
    default_sep: str | None,
) -> Record:
    import pandas as pd

    head = _read_head(path)
    if options.encoding is not None:
        _check_encoding(path, options.encoding)
    encoding = options.encoding or _sniff_encoding(head)
    header = _header_line(head, encoding)
    if not header:
        raise DataError(
            "the file holds no header line, only blank space",
            file=path,
            hint="check that the export finished",
        )
    sep = options.sep or default_sep or _sniff_sep(header)
    decimal = options.decimal or "."

    sample, encoding = _with_latin1_fallback(
        path,
        encoding,
        options.encoding is None,
        lambda enc: pd.read_csv(
            path, sep=sep, encoding=enc, decimal=decimal, nrows=_SNIFF_ROWS, engine=_engine(sep)
        ),
    )
    names = [str(c) for c in sample.columns]
    header = _header_line(head, encoding)
    raw_names = next(csv.reader([header], delimiter=sep)) if len(sep) == 1 else names
    renamed = {new: old for new, old in zip(names, raw_names, strict=False) if new != old}

    if len(names) == 1:
        needs_more = columns is None or any(c != names[0] for c in columns)
        if needs_more:
            guess = _sniff_sep(header)
            looks = (
                f" (the header looks {_sep_name(guess)}-separated)"
                if guess != sep and header.count(guess)
                else ""
            )
            raise DataError(
                f"found 1 column {names[0]!r} using separator {_sep_name(sep)}{looks}",
                file=path,
                hint="set `sep:` to the file's separator",
            )

    time_name = _pick_time(path, names, options)
    numeric = [
        n
        for n in names
        if pd.api.types.is_numeric_dtype(sample[n]) or pd.api.types.is_bool_dtype(sample[n])
    ]
    wanted = _channel_list(path, columns, names, [n for n in numeric if n != time_name])
    needed = list(dict.fromkeys([time_name, *wanted]))

    use_arrow = (
        _pyarrow_available()
        and not renamed
        and len(sep) == 1
        and options.extra.get("csv_engine") != "c"
    )
    positions = sorted(names.index(n) for n in needed)
    frame, engine = _read_csv_frame(
        path,
        needed=needed,
        positions=positions,
        names=names,
        sep=sep,
        encoding=encoding,
        decimal=decimal,
        use_arrow=use_arrow,
        retry_latin1=options.encoding is None,
    )
    if len(frame) == 0:
        raise _no_rows(path)

    time_raw = _numeric_column(path, frame, time_name, decimal)
    time = _check_time(path, time_name, time_raw, options, first_line=2)
    values = {
        name: _as_values(path, name, _numeric_column(path, frame, name, decimal)) for name in wanted
    }
    meta: dict[str, Any] = {"sep": sep, "encoding": encoding, "decimal": decimal, "engine": engine}
    if renamed:
        meta["renamed_duplicates"] = renamed
    return _table_record(
        path,
        time_name,
        time,
        values,
        available=names,
        numeric=numeric,
        units={n: _unit_from_name(n) for n in needed},
        meta=meta,
    )


def _with_latin1_fallback(
    path: str, encoding: str, may_retry: bool, read: Callable[[str], pd.DataFrame]
) -> tuple[pd.DataFrame, str]:
    """Run ``read(encoding)``; on a decoding error retry with Latin-1 when it was guessed."""
    import pandas as pd

    try:
        return read(encoding), encoding
    except UnicodeDecodeError as exc:
        if not may_retry or encoding == "latin-1":
            raise DataError(
                f"cannot decode the file as {encoding} ({exc.reason})",
                file=path,
                hint="set `encoding:` (for example latin-1 or cp1252)",
            ) from None
    except pd.errors.EmptyDataError:
        raise DataError(
            "the file holds no columns", file=path, hint="check that the export finished"
        ) from None
    except (pd.errors.ParserError, ValueError) as exc:
        raise DataError(
            f"cannot parse the file ({_first_line(exc)})",
            file=path,
            hint="check `sep:`, `decimal:` and `encoding:`",
        ) from None
    return _with_latin1_fallback(path, "latin-1", False, read)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    if isinstance(exc, LookupError) and text:
        # A bare "0" or "'cn'" says nothing without the kind of lookup that failed.
        return f"{type(exc).__name__}: {text[0]}"
    return text[0] if text else type(exc).__name__


def _read_csv_frame(
    path: str,
    *,
    needed: list[str],
    positions: list[int],
    names: list[str],
    sep: str,
    encoding: str,
    decimal: str,
    use_arrow: bool,
    retry_latin1: bool,
) -> tuple[pd.DataFrame, str]:
    import pandas as pd

    if use_arrow:
        try:
            frame = pd.read_csv(
                path,
                sep=sep,
                encoding=encoding,
                decimal=decimal,
                usecols=needed,
                engine="pyarrow",
            )
        except Exception:
            # The pyarrow engine rejects some files the C engine reads (ragged rows, odd
            # encodings); the C engine's answer, success or error, is the one reported.
            pass
        else:
            return frame, "pyarrow"

    def read(enc: str) -> pd.DataFrame:
        frame = pd.read_csv(
            path, sep=sep, encoding=enc, decimal=decimal, usecols=positions, engine=_engine(sep)
        )
        # Positions keep duplicate headers apart; name them as the header read did.
        frame.columns = pd.Index([names[p] for p in positions])
        return frame

    frame, _ = _with_latin1_fallback(path, encoding, retry_latin1, read)
    return frame, _engine(sep)


def _numeric_column(path: str, frame: pd.DataFrame, name: str, decimal: str) -> npt.NDArray[Any]:
    """The column as a numpy array, or a DataError naming the first cell that is not a number."""
    import pandas as pd

    series = frame[name]
    if pd.api.types.is_bool_dtype(series):
        return series.to_numpy(dtype=np.float64)
    if pd.api.types.is_numeric_dtype(series):
        return series.to_numpy()
    coerced = pd.to_numeric(series, errors="coerce")
    bad = series.notna() & coerced.isna()
    index = int(np.flatnonzero(bad.to_numpy())[0]) if bool(bad.any()) else 0
    value = series.iloc[index]
    hint = "fix or remove that cell"
    if isinstance(value, str) and decimal == "." and re.fullmatch(r"\s*[-+]?\d*,\d+\s*", value):
        hint = "the file seems to use ',' as decimal mark: set `decimal: \",\"`"
    raise DataError(
        f"non-numeric value {value!r} at index {index}",
        file=path,
        line=2 + index,
        column=name,
        hint=hint,
    )


# --------------------------------------------------------------------------------------------
# Parquet


def _corrupt(path: str, kind: str, exc: BaseException) -> DataError:
    return DataError(
        f"cannot read this {kind} file (file truncated or corrupt?)",
        file=path,
        hint=f"write the file again; the reader said: {_first_line(exc)}",
    )


def _read_parquet(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    pa = _import("pyarrow", "reading Parquet files", "parquet")
    pq = _import("pyarrow.parquet", "reading Parquet files", "parquet")
    with _returning_arrow_pool(pa):
        return _read_parquet_columns(path, columns, options, pa, pq)


def _read_parquet_columns(
    path: str, columns: Iterable[str] | None, options: SourceOptions, pa: Any, pq: Any
) -> Record:
    try:
        source, filesystem = parquet_source(path)
        # Pre-buffering coalesces reads for object stores; on a local file it keeps a second
        # copy of every column chunk alive during the read (about 2x the loaded columns).
        parquet_file = pq.ParquetFile(
            source, filesystem=filesystem, pre_buffer=filesystem is not None
        )
        schema = parquet_file.schema_arrow
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise _corrupt(path, "Parquet", exc) from None
    with closing(parquet_file):
        names = [str(n) for n in schema.names]
        types = pa.types

        def is_numeric(name: str) -> bool:
            kind = schema.field(name).type
            return bool(types.is_integer(kind) or types.is_floating(kind) or types.is_boolean(kind))

        numeric = [n for n in names if is_numeric(n)]
        time_name = _pick_time(path, names, options)
        wanted = _channel_list(path, columns, names, [n for n in numeric if n != time_name])
        needed = list(dict.fromkeys([time_name, *wanted]))
        try:
            time_table = parquet_file.read(columns=[time_name])
        except (pa.ArrowException, OSError, ValueError) as exc:
            raise _corrupt(path, "Parquet", exc) from None
        if time_table.num_rows == 0:
            raise _no_rows(path)
        time_column = time_table.column(0)
        if types.is_timestamp(time_column.type) or types.is_duration(time_column.type):
            # Absolute or elapsed time stamps become seconds since the first sample.
            # Subtract in int64: epoch nanoseconds exceed float64's exact integer range.
            stamps = np.asarray(time_column.cast(pa.int64()).to_numpy(), dtype=np.int64)
            unit = time_column.type.unit
            time_raw: npt.NDArray[Any] = (stamps - stamps[0]).astype(np.float64) * _SECONDS_PER[
                unit
            ]
        elif is_numeric(time_name):
            time_raw = _arrow_to_numpy(time_column)
        else:
            raise DataError(
                f"the time column holds {time_column.type}, not numbers",
                file=path,
                column=time_name,
                hint="set `time:` to the numeric time column",
            )
        del time_table, time_column
        time = _check_time(path, time_name, time_raw, options)
        for name in wanted:
            if not is_numeric(name):
                raise _not_numbers(path, name, str(schema.field(name).type))
        loaded: dict[str, ValueArray] = {}
        # A few columns per read: the decoder's buffers then hold a batch, not the whole
        # table, beside the arrays already made (peak memory near the loaded columns).
        column_bytes = 8 * max(1, time.shape[0])
        # At most an eighth of what is loaded, so that a few columns of a wide file keep
        # the same small overhead as all of them.
        batch_bytes = min(_PARQUET_BATCH_BYTES, column_bytes * len(wanted) // 8)
        per_read = max(1, batch_bytes // column_bytes)
        for first in range(0, len(wanted), per_read):
            batch = [n for n in wanted[first : first + per_read] if n != time_name]
            if not batch:
                continue
            try:
                table = parquet_file.read(columns=batch)
            except (pa.ArrowException, OSError, ValueError) as exc:
                raise _corrupt(path, "Parquet", exc) from None
            for name in batch:
                loaded[name] = _as_values(path, name, _arrow_to_numpy(table.column(name)))
            del table
        if time_name in wanted:
            loaded[time_name] = _as_values(path, time_name, np.asarray(time_raw))
        values = {name: loaded[name] for name in wanted}
    units = {n: _field_unit(schema.field(n)) for n in needed}
    return _table_record(
        path, time_name, time, values, available=names, numeric=numeric, units=units
    )


_ARROW_POOL_LOCK = threading.Lock()
# [readers inside, pyarrow's pool before the first of them entered]
_ARROW_POOL_STATE: list[Any] = [0, None]


@contextmanager
def _returning_arrow_pool(pa: Any) -> Iterator[None]:
    """Decode with an allocator that hands freed memory back while the read goes on.

    pyarrow's default pool (mimalloc) keeps the decoder's freed buffers as resident memory, so
    peak memory reached about 1.5x the loaded columns; jemalloc (or the system allocator)
    returns them and the peak stays near the columns themselves. Each buffer remembers the
    pool it came from, so switching back afterwards is safe. The pool is process-wide: with
    several reads in threads, the last one out puts pyarrow's own pool back.
    """
    with _ARROW_POOL_LOCK:
        if _ARROW_POOL_STATE[0] == 0:
            _ARROW_POOL_STATE[1] = pa.default_memory_pool()
            try:
                pool = pa.jemalloc_memory_pool()
            except (NotImplementedError, pa.ArrowException):
                pool = pa.system_memory_pool()
            pa.set_memory_pool(pool)
        _ARROW_POOL_STATE[0] += 1
    try:
        yield
    finally:
        with _ARROW_POOL_LOCK:
            _ARROW_POOL_STATE[0] -= 1
            if _ARROW_POOL_STATE[0] == 0:
                pa.set_memory_pool(_ARROW_POOL_STATE[1])
                _ARROW_POOL_STATE[1] = None


# Decoded bytes per Parquet read call (see _read_parquet).
_PARQUET_BATCH_BYTES = 64 << 20

_SECONDS_PER = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}


def _arrow_to_numpy(column: Any) -> npt.NDArray[Any]:
    """A numeric Arrow column as numpy; nulls become NaN (integers are widened to float)."""
    if column.null_count:
        return np.asarray(column.to_numpy(), dtype=np.float64)
    result: npt.NDArray[Any] = column.to_numpy()
    return result


def _field_unit(field: Any) -> str | None:
    metadata = field.metadata or {}
    unit = metadata.get(b"unit") or metadata.get(b"units")
    if isinstance(unit, bytes):
        return unit.decode("utf-8", errors="replace")
    return _unit_from_name(str(field.name))


# --------------------------------------------------------------------------------------------
# HDF5 and MATLAB v7.3 (which is HDF5)


@contextmanager
def _open_hdf5(path: str, kind: str) -> Iterator[Any]:
    h5py = _import("h5py", f"reading {kind} files", "hdf5" if kind == "HDF5" else "mat")
    try:
        handle = h5py.File(path, "r")
    except (OSError, ValueError) as exc:
        raise _corrupt(path, kind, exc) from None
    with handle:
        try:
            yield handle
        except DataError:
            raise
        except (RuntimeError, OSError, KeyError, ValueError) as exc:
            # A damaged object header or heap surfaces only when the group is walked, as
            # RuntimeError ("Object visitation failed") or OSError from the HDF5 library.
            raise _corrupt(path, kind, exc) from None


def _read_hdf5(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    with _open_hdf5(path, "HDF5") as handle:
        return _read_hdf5_group(
            path, handle, options.group, _as_list(columns), options, matlab=False
        )


def _hdf5_name(name: str | bytes) -> str:
    # h5py hands out a link name it cannot decode as UTF-8 (a damaged or foreign file) as bytes.
    return name.decode("utf-8", errors="replace") if isinstance(name, bytes) else name


_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
# End of a local heap's free-space list (H5HL_FREE_NULL).
_HDF5_FREE_NULL = 1
_HDF5_SYMBOL_TABLE_MESSAGE = 0x11


def _hdf5_name_heap_problem(path: str, group: Any) -> str | None:
    """Describe a loop in the free-space list of an old-style group's name heap, or None.

    Groups written with HDF5's earliest file format keep their member names in a local heap
    whose free blocks form a linked list. libhdf5 walks that list when it loads the heap and
    never remembers where it has been: one damaged offset that points back makes listing the
    group loop forever inside the library, where nothing can interrupt it. The list is walked
    here first. Other layouts, or anything unexpected, are left to the library.
    """

    try:
        # H5Gget_objinfo gives the address without loading the heap (H5Oget_info loads it).
        header_at = _hdf5_address(group)
        with open(path, "rb") as stream:
            base = next(
                (
                    at
                    for at in (0, 512, 1024, 2048, 4096)
                    if _read_at(stream, at, 8) == _HDF5_SIGNATURE
                ),
                None,
            )
            superblock = _read_at(stream, base, 16) if base is not None else b""
            if base is None or superblock[8] > 1 or superblock[13:15] != b"\x08\x08":
                return None  # newer superblocks, or 32-bit addresses: not checked
            header = _read_at(stream, base + header_at, 16)
            if len(header) < 16 or header[0] != 1:
                return None  # version-2 object headers hold new-style groups
            messages, size = (
                struct.unpack_from("<H", header, 2)[0],
                struct.unpack_from("<I", header, 8)[0],
            )
            body = _read_at(stream, base + header_at + 16, min(size, 1 << 16))
            heap_at = None
            position = 0
            for _ in range(messages):
                if position + 8 > len(body):
                    break
                kind, length = struct.unpack_from("<HH", body, position)
                if (
                    kind == _HDF5_SYMBOL_TABLE_MESSAGE
                    and length >= 16
                    and position + 24 <= len(body)
                ):
                    heap_at = struct.unpack_from("<Q", body, position + 16)[0]
                    break
                position += 8 + length
            if heap_at is None:
                return None
            heap = _read_at(stream, base + heap_at, 32)
            if len(heap) < 32 or heap[:4] != b"HEAP":
                return None  # the library reports a missing heap itself
            data_size, free, data_at = struct.unpack_from("<QQQ", heap, 8)
            seen: set[int] = set()
            while free != _HDF5_FREE_NULL:
                if free in seen or free + 16 > data_size:
                    where = "a second time (a loop)" if free in seen else "outside the heap"
                    return f"name heap at byte {base + heap_at} lists free space {where}"
                seen.add(free)
                link = _read_at(stream, base + data_at + free, 8)
                if len(link) < 8:
                    return None
                free = struct.unpack("<Q", link)[0]
    except (OSError, ValueError, struct.error, RuntimeError, KeyError, TypeError, IndexError):
        return None
    return None


def _hdf5_address(obj: Any) -> int:
    import h5py

    return int(h5py.h5g.get_objinfo(obj.id).objno[0])


def _read_at(stream: IO[bytes], position: int, count: int) -> bytes:
    stream.seek(position)
    return bytes(stream.read(count))


def _check_hdf5_group(path: str, group: Any) -> None:
    problem = _hdf5_name_heap_problem(path, group)
    if problem is not None:
        raise DataError(
            f"cannot read this file (file corrupt?): its HDF5 {problem}",
            file=path,
            hint="write the file again",
        )


def _hdf5_get_checked(path: str, handle: Any, key: str) -> Any:
    """``handle.get(key)``, checking every group on the way, and a group found, before a name
    is looked up in it."""
    import h5py

    node = handle
    for part in [p for p in key.split("/") if p]:
        if not isinstance(node, h5py.Group):
            return None
        _check_hdf5_group(path, node)
        node = node.get(part)
        if node is None:
            return None
    if isinstance(node, h5py.Group):
        _check_hdf5_group(path, node)
    return node


def _hdf5_groups(path: str, handle: Any) -> list[str]:
    """Every group's path, walked one group at a time so that each is checked before listing."""
    import h5py

    found: list[str] = []
    pending: list[tuple[str, Any]] = [("", handle)]
    seen: set[int] = set()
    while pending:
        prefix, group = pending.pop()
        _check_hdf5_group(path, group)
        for raw_name, obj in group.items():
            name = _hdf5_name(raw_name)
            if not isinstance(obj, h5py.Group) or name.startswith("#"):
                continue
            address = _hdf5_address(obj)
            if address in seen:
                continue  # hard links to a group already listed (or a loop of them)
            seen.add(address)
            full = f"{prefix}/{name}" if prefix else name
            found.append(full)
            pending.append((full, obj))
    return sorted(found)


def _read_hdf5_group(
    path: str,
    handle: Any,
    group: str | None,
    columns: list[str] | None,
    options: SourceOptions,
    *,
    matlab: bool,
) -> Record:
    import h5py

    key = "/" if not group else "/" + group.replace(".", "/").strip("/")
    node = _hdf5_get_checked(path, handle, key)
    if node is None or not isinstance(node, h5py.Group):
        groups = _hdf5_groups(path, handle)
        what = "struct" if matlab else "group"
        problem = (
            f"no {what} {group!r} in this file"
            if node is None
            else f"{group!r} is a dataset, not a {what}"
        )
        suggestion = did_you_mean(str(group), groups)
        listing = ", ".join(repr(g) for g in groups[:12]) if groups else "none"
        raise DataError(
            problem,
            file=path,
            key="group",
            hint=suggestion or f"set `group:` to one of: {listing}",
        )
    datasets: dict[str, Any] = {}
    for raw_name, obj in node.items():
        name = _hdf5_name(raw_name)
        if name.startswith("#") or not isinstance(obj, h5py.Dataset):
            continue
        if _vector_length(obj.shape) is not None:
            datasets[name] = obj
    names = list(datasets)
    if not names:
        where = "the file root" if key == "/" else f"group {key!r}"
        subgroups = [g for g in _hdf5_groups(path, handle) if g]
        hint = (
            "store one 1-D dataset per channel plus a time dataset"
            + (
                f", or set `group:` to one of: {', '.join(repr(g) for g in subgroups[:12])}"
                if subgroups
                else ""
            )
            + "; pandas HDFStore files are not supported: write Parquet instead"
        )
        raise DataError(f"no 1-D datasets in {where}", file=path, key="group", hint=hint)

    def is_numeric(name: str) -> bool:
        dataset = datasets[name]
        matlab_class = _attr_text(dataset.attrs.get("MATLAB_class"))
        return _is_numeric_dtype(dataset.dtype) and matlab_class != "char"

    numeric = [n for n in names if is_numeric(n)]
    lengths = {n: _vector_length(datasets[n].shape) or 0 for n in names}
    time_name, wanted, numeric = _vector_plan(path, lengths, numeric, columns, options)
    if not is_numeric(time_name):
        raise DataError(
            f"the time column holds {_kind_name(datasets[time_name].dtype)}, not numbers",
            file=path,
            column=time_name,
            hint="set `time:` to the numeric time dataset",
        )
    try:
        time_raw = np.asarray(datasets[time_name][()]).reshape(-1)
        raw = {n: np.asarray(datasets[n][()]).reshape(-1) for n in wanted}
    except (OSError, ValueError, KeyError) as exc:
        raise _corrupt(path, "MAT" if matlab else "HDF5", exc) from None
    if time_raw.size == 0:
        raise _no_rows(path)
    time = _check_time(path, time_name, time_raw, options)
    values: dict[str, ValueArray] = {}
    for name in wanted:
        if not is_numeric(name):
            kind = (
                "text" if _is_numeric_dtype(datasets[name].dtype) else _kind_name(raw[name].dtype)
            )
            raise _not_numbers(path, name, str(kind))
        values[name] = _as_values(path, name, raw[name])
    units = {
        n: _attr_text(datasets[n].attrs.get("unit", datasets[n].attrs.get("units")))
        for n in [time_name, *wanted]
    }
    meta = {"group": key}
    return _table_record(
        path, time_name, time, values, available=names, numeric=numeric, units=units, meta=meta
    )


def _vector_length(shape: tuple[int, ...]) -> int | None:
    """Length of a 1-D array, also written as a row or column matrix (MATLAB's habit)."""
    if len(shape) == 1:
        return shape[0]
    if len(shape) == 2 and 1 in shape:
        return max(shape)
    return None


def _attr_text(value: Any) -> str | None:
    if value is None:
        return None
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray) and value.size == 1:
        return _attr_text(value.reshape(-1)[0])
    if isinstance(value, np.bytes_):
        return bytes(value).decode("utf-8", errors="replace")
    return str(value)


# --------------------------------------------------------------------------------------------
# MAT


def _is_hdf5(path: str) -> bool:
    with open(path, "rb") as stream:
        head = stream.read(max(_HDF5_SIGNATURE_OFFSETS) + len(_HDF5_SIGNATURE))
    return any(
        head[o : o + len(_HDF5_SIGNATURE)] == _HDF5_SIGNATURE for o in _HDF5_SIGNATURE_OFFSETS
    )


_MAT_NUMERIC = {
    "double",
    "single",
    "logical",
    "int8",
    "uint8",
    "int16",
    "uint16",
    "int32",
    "uint32",
    "int64",
    "uint64",
}


def _read_mat(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    if _is_hdf5(path):
        with _open_hdf5(path, "MAT") as handle:
            record = _read_hdf5_group(
                path, handle, options.group, _as_list(columns), options, matlab=True
            )
        record.meta["mat_version"] = "7.3"
        return record
    return _read_mat5(path, _as_list(columns), options)


# MAT v5 data types: miINT8 … miUINT32, miSINGLE, miDOUBLE, miINT64, miUINT64 hold numbers;
# miMATRIX and miCOMPRESSED hold variables; miUTF8 … miUTF32 hold text. 0, 8, 10, 11 and
# anything above 18 are not defined.
_MAT5_NUMBERS = frozenset({1, 2, 3, 4, 5, 6, 7, 9, 12, 13})
_MAT5_MATRIX = 14
_MAT5_COMPRESSED = 15
_MAT5_TEXT = frozenset({16, 17, 18})
# Array classes (mxClass) by what follows flags, dimensions and name: cell, struct and object
# hold variables; char, sparse and the numeric classes 6–15 hold number (or text) elements.
_MAT5_CONTAINERS = frozenset({1, 2, 3})
_MAT5_CHAR = 4
_MAT5_SPARSE = 5
_MAT5_COMPLEX_FLAG = 0x800


def _mat5_elements(
    buffer: bytes, start: int, end: int, order: str, padded: bool
) -> list[tuple[int, int, int, int]]:
    """(position, type, body start, body size) of each element tag between start and end.

    A tag whose body runs past ``end`` ends the list, with a size of -1: scipy still reads
    what there is of it before it notices. A small element claiming more than 4 bytes ends it
    with a size of ``_MAT5_OVERSIZED``.
    """
    found = []
    position = start
    while position + 8 <= end:
        first, second = struct.unpack_from(order + "II", buffer, position)
        if first >> 16:
            # A small element packs its size into the upper half of the first word.
            kind, size, body, following = first & 0xFFFF, first >> 16, position + 4, position + 8
            if size > 4:
                # Cannot be: scipy would copy that many bytes out of a 4-byte slot.
                found.append((position, kind, body, _MAT5_OVERSIZED))
                break
        else:
            kind, size, body = first, second, position + 8
            following = body + size + ((-size) % 8 if padded else 0)
        if body + size > end:
            found.append((position, kind, body, -1))
            break
        found.append((position, kind, body, size))
        position = following
    return found


_MAT5_OVERSIZED = -2
# Element types scipy knows at the top level (and inside compressed variables), and inside
# an array.
_MAT5_IN_ARRAY = _MAT5_NUMBERS | _MAT5_TEXT | {_MAT5_MATRIX}
_MAT5_TOP_LEVEL = _MAT5_IN_ARRAY | {_MAT5_COMPRESSED}


def _mat5_count(buffer: bytes, dims: tuple[int, int, int, int], order: str) -> int | None:
    """The number of elements an array's dimensions element declares, if it is readable."""
    _, kind, body, size = dims
    if kind not in (5, 6) or size < 0 or size % 4:  # int32 or uint32 dimensions
        return None
    count = 1
    for value in struct.unpack_from(f"{order}{size // 4}{'i' if kind == 5 else 'I'}", buffer, body):
        count *= max(0, int(value))
    return count


def _mat5_tag_problem(
    elements: list[tuple[int, int, int, int]], known: frozenset[int]
) -> str | None:
    """A small element claiming more than 4 bytes, else the first type scipy does not know."""
    for position, _, _, size in elements:
        if size == _MAT5_OVERSIZED:
            return f"a small data element at byte {position} claims more than 4 bytes"
    for position, kind, _, _ in elements:
        if kind not in known:
            return f"undefined data type {kind} at byte {position}"
    return None


def _mat5_problem(path: str) -> str | None:
    """Describe the first element scipy.io.loadmat would read as numbers but cannot, if any.

    scipy looks element types up in a table without a bounds check and reads an array's parts
    one after the other without checking that they lie inside the array. An undefined type,
    or a variable where numbers should be (a complex flag on an array without an imaginary
    part makes scipy read the next variable's tag as one), then crashes the process with a
    segmentation fault instead of an exception. One damaged byte is enough for either.
    """
    with open(path, "rb") as stream:
        data = stream.read()
    if data[126:128] not in (b"IM", b"MI"):
        return None  # MAT v4, or not a MAT file: scipy tells
    order = ">" if data[126:128] == b"MI" else "<"
    # (buffer, start, end): the file's top level, or the body of a compressed variable.
    levels: list[tuple[bytes, int, int]] = [(data, 128, len(data))]
    # (buffer, body start, body end) of each matrix still to check
    matrices: list[tuple[bytes, int, int]] = []
    while levels or matrices:
        if levels:
            buffer, start, end = levels.pop()
            elements = _mat5_elements(buffer, start, end, order, False)
            problem = _mat5_tag_problem(elements, _MAT5_TOP_LEVEL)
            if problem:
                return problem
            for _, kind, body, size in elements:
                if kind == _MAT5_MATRIX:
                    matrices.append((buffer, body, body + size if size >= 0 else end))
                elif kind == _MAT5_COMPRESSED and size >= 0:
                    try:
                        inner = zlib.decompress(buffer[body : body + size])
                    except zlib.error:
                        continue  # scipy cannot decompress it either, and says so
                    levels.append((inner, 0, len(inner)))
                if size < 0:
                    break
            continue
        buffer, start, end = matrices.pop()
        parts = _mat5_elements(buffer, start, end, order, True)
        problem = _mat5_tag_problem(parts, _MAT5_IN_ARRAY)
        if problem:
            return problem
        if len(parts) < 3 or parts[0][1] != 6 or parts[0][3] < 4:
            continue  # no usable array flags: scipy rejects the variable itself
        flags = struct.unpack_from(order + "I", buffer, parts[0][2])[0]
        mx_class = flags & 0xFF
        if mx_class in _MAT5_CONTAINERS:
            # scipy makes the object array the dimensions ask for before reading its elements:
            # one damaged dimension asked for 8 GB in a 1 kB file. Every element needs a tag
            # of 8 bytes at least, so more elements than that cannot be there.
            count = _mat5_count(buffer, parts[1], order)
            if count is not None and count * 8 > end - start:
                return (
                    f"the cell or struct array at byte {parts[0][0] - 8} claims {count} "
                    f"elements in {end - start} bytes"
                )
            for _, kind, body, size in parts[3:]:
                if kind == _MAT5_MATRIX:
                    matrices.append((buffer, body, body + size if size >= 0 else end))
            continue
        if mx_class == _MAT5_SPARSE:
            needed = 6  # flags, dims, name, row indices, column indices, values
        elif mx_class == _MAT5_CHAR or 6 <= mx_class <= 15:
            needed = 4  # flags, dims, name, values
        else:
            continue  # function handles and opaque objects: scipy reads them differently
        if flags & _MAT5_COMPLEX_FLAG and mx_class != _MAT5_CHAR:
            needed += 1
        allowed = _MAT5_NUMBERS | (_MAT5_TEXT if mx_class == _MAT5_CHAR else frozenset())
        for position, kind, _, _ in parts[3:needed]:
            if kind not in allowed:
                return f"data type {kind} where numbers should be, at byte {position}"
        if len(parts) < needed or parts[needed - 1][3] < 0:
            position = parts[0][0]
            return f"the array at byte {position - 8} ends before all its parts"
    return None


def _read_mat5(path: str, columns: list[str] | None, options: SourceOptions) -> Record:
    sio = _import("scipy.io", "reading MAT files", "mat")
    problem = _mat5_problem(path)
    if problem is not None:
        raise _corrupt(path, "MAT", ValueError(problem))
    try:
        with _mat_warnings_as_errors():
            variables = sio.whosmat(path)
    except Exception as exc:
        # scipy raises a mix of ValueError, TypeError, OSError and its own MatReadError for
        # damaged files; all mean the same to the user.
        raise _corrupt(path, "MAT", exc) from None
    group = options.group
    if group:
        top = group.split(".")[0]
        structs = [name for name, _, cls in variables if cls == "struct"]
        if top not in {name for name, _, _ in variables}:
            suggestion = did_you_mean(top, structs)
            listing = ", ".join(repr(s) for s in structs[:12]) or "none"
            raise DataError(
                f"no struct {group!r} in this file",
                file=path,
                key="group",
                hint=suggestion or f"set `group:` to one of the structs: {listing}",
            )
        loaded = _loadmat(sio, path, [top])
        node: Any = loaded[top]
        for part in group.split(".")[1:]:
            if not isinstance(node, dict) or part not in node:
                raise DataError(
                    f"no struct {group!r} in this file",
                    file=path,
                    key="group",
                    hint=did_you_mean(part, node if isinstance(node, dict) else [])
                    or "check the struct path (fields are separated by '.')",
                )
            node = node[part]
        if not isinstance(node, dict):
            raise DataError(
                f"{group!r} is not a struct",
                file=path,
                key="group",
                hint="set `group:` to a struct whose fields are the channels",
            )
        arrays = {
            str(k): np.atleast_1d(np.asarray(v))
            for k, v in node.items()
            if isinstance(v, np.ndarray | float | int)
        }
        lengths = {n: a.shape[0] for n, a in arrays.items() if a.ndim == 1}
        numeric = [n for n in lengths if _is_numeric_dtype(arrays[n].dtype)]
        names = list(lengths)
        time_name, wanted, numeric = _vector_plan(path, lengths, numeric, columns, options)
        data = {n: arrays[n] for n in [time_name, *wanted]}
    else:
        vectors: dict[str, str] = {}
        lengths = {}
        for name, shape, cls in variables:
            length = _vector_length(tuple(shape))
            if length is not None:
                vectors[name] = cls
                lengths[name] = length
        names = list(vectors)
        numeric = [n for n, cls in vectors.items() if cls in _MAT_NUMERIC]
        if not any(lengths[n] >= 2 for n in numeric):
            structs = [name for name, _, cls in variables if cls == "struct"]
            hint = (
                f"set `group:` to the struct that holds the channels: "
                f"{', '.join(repr(s) for s in structs[:12])}"
                if structs
                else "save one vector per channel plus a time vector"
            )
            raise DataError("no numeric vectors in this file", file=path, key="group", hint=hint)
        time_name, wanted, numeric = _vector_plan(path, lengths, numeric, columns, options)
        for name in [time_name, *wanted]:
            if vectors[name] not in _MAT_NUMERIC:
                raise DataError(
                    f"holds a MATLAB {vectors[name]}, not numbers",
                    file=path,
                    column=name,
                    hint="choose a numeric variable",
                )
        loaded = _loadmat(sio, path, list(dict.fromkeys([time_name, *wanted])))
        data = {n: np.atleast_1d(np.asarray(loaded[n])).reshape(-1) for n in [time_name, *wanted]}

    time_raw = data[time_name]
    if not _is_numeric_dtype(time_raw.dtype):
        raise DataError(
            f"the time column holds {_kind_name(time_raw.dtype)}, not numbers",
            file=path,
            column=time_name,
            hint="set `time:` to the numeric time variable",
        )
    if time_raw.size == 0:
        raise _no_rows(path)
    time = _check_time(path, time_name, time_raw, options)
    values = {n: _as_values(path, n, data[n]) for n in wanted}
    meta: dict[str, Any] = {"mat_version": "5"}
    if group:
        meta["group"] = group
    return _table_record(path, time_name, time, values, available=names, numeric=numeric, meta=meta)


@contextmanager
def _mat_warnings_as_errors() -> Iterator[None]:
    """Raise scipy's warnings while reading a MAT file instead of letting them through.

    They all describe a damaged file ("We do not support byte ordering 'VAX D-float';
    returned data may be corrupt", duplicate or unreadable variables), so the data must not be
    used; and under ``-W error`` a warning would escape as an exception of its own.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def _loadmat(sio: ModuleType, path: str, names: list[str]) -> dict[str, Any]:
    try:
        with _mat_warnings_as_errors():
            loaded: dict[str, Any] = sio.loadmat(path, variable_names=names, simplify_cells=True)
    except Exception as exc:
        # See _read_mat5: scipy's errors for damaged files have no common base class.
        raise _corrupt(path, "MAT", exc) from None
    return loaded


# --------------------------------------------------------------------------------------------
# MDF (ASAM MDF 3 and 4)

# asammdf data-type codes for numbers: MDF4 codes 0-5 are integers and reals; MDF3 codes
# 7 and 8 are strings and byte arrays, everything else numeric.
_MDF4_NUMERIC_TYPES = range(6)
_MDF3_TEXT_TYPES = (7, 8)


# Where the links of the block lists asammdf follows while opening a file sit: the first data
# group in the header, and in each block its next sibling and first child.
_MDF_LINKS = {
    # version: (address size, header's first data group, next block, first child)
    "3": (4, 68, 4, 8),
    "4": (8, 88, 24, 32),
}


def _mdf_loop(path: str) -> str | None:
    """Describe a loop in the data group, channel group or channel lists, or None.

    asammdf walks these linked lists while opening a file and never remembers where it has
    been; one damaged link that points back makes it loop forever, so the lists are walked
    here first, each address visited at most once.
    """
    try:
        with open(path, "rb") as stream:
            head = stream.read(64 + 32)
            size = os.fstat(stream.fileno()).st_size
            if len(head) < 64 or not head.startswith(b"MDF"):
                return None  # not an MDF file asammdf can open; it says why itself
            major = chr(head[8]) if head[8:9].isdigit() else ""
            if major not in _MDF_LINKS:
                return None
            width, first, next_at, child_at = _MDF_LINKS[major]
            # MDF 3 declares its byte order in the identification block; MDF 4 is little-endian.
            big = major == "3" and int.from_bytes(head[24:26], "little") != 0
            order = ">" if big else "<"
            code = "Q" if width == 8 else "I"

            def link(address: int) -> int:
                if address <= 0 or address + width > size:
                    return 0
                return int(struct.unpack(order + code, _read_at(stream, address, width))[0])

            seen: set[int] = set()
            # Each list: data groups (children: channel groups), channel groups (children:
            # channels), channels (no children followed here).
            pending = [(link(first), 0)]
            while pending:
                address, depth = pending.pop()
                while address:
                    if address in seen:
                        return f"the block at byte {address} is linked to twice (a loop)"
                    if address >= size:
                        break  # asammdf reports addresses past the end itself
                    seen.add(address)
                    if depth < 2:
                        pending.append((link(address + child_at), depth + 1))
                    address = link(address + next_at)
    except OSError:
        return None
    return None


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


# MDF4 channel types whose samples sit in the group's records (value, VLSD offset, master,
# sync, VLSC offset); virtual and MLSD channels have no bytes of their own there.
_MDF4_RECORD_TYPES = (0, 1, 2, 4, 7)


def _check_mdf_record(path: str, version: str, group: Any) -> None:
    """Refuse a channel group whose channels reach past the end of its record.

    asammdf copies each channel out of the records in C without checking the channel's byte
    range against the record size; a damaged channel block (or record size) then corrupts the
    heap and the process aborts, so the file is refused before anything is read.
    """
    size = int(group.channel_group.samples_byte_nr)
    if version.startswith("4"):
        size += int(group.channel_group.invalidation_bytes_nr)
    # asammdf sizes its buffers by the record size and the record count, so one damaged
    # field (4 GB of invalidation bytes, or 10^9 records, in a 2 kB file) would exhaust the
    # memory before anything is read. Complete records never need more than the stored data
    # (decompressed sizes, so compressed files pass).
    stored = sum(int(getattr(block, "original_size", 0) or 0) for block in group.data_blocks)
    cycles = int(group.channel_group.cycles_nr)
    if size > stored and (stored or cycles):
        raise DataError(
            f"a record of {size} bytes is larger than the {stored} bytes of data holding it "
            "(file truncated or corrupt?)",
            file=path,
            hint="write the file again",
        )
    if size * cycles > stored:
        raise DataError(
            f"{cycles} records of {size} bytes need {size * cycles} bytes, but the file holds "
            f"{stored} bytes of data for them (file truncated or corrupt?)",
            file=path,
            hint="write the file again",
        )
    # MDF 3 has no block sizes: asammdf derives them from the record count, so a damaged count
    # (10^9 records in a 2 kB file) passed the check above and asked for tens of gigabytes.
    # Every block's stored bytes must lie inside the file.
    file_size = os.path.getsize(path)
    for block in group.data_blocks:
        stored_size = block.compressed_size if block.block_type else block.original_size
        end = int(block.address or 0) + int(stored_size or 0)
        if end > file_size:
            raise DataError(
                f"a data block ends at byte {end}, past the end of the {file_size}-byte file "
                "(file truncated or corrupt?)",
                file=path,
                hint="write the file again",
            )
    for channel in group.channels:
        bits = int(channel.bit_count)
        if version.startswith("4"):
            if int(channel.channel_type) not in _MDF4_RECORD_TYPES:
                continue
            start = 8 * int(channel.byte_offset) + int(channel.bit_offset)
        else:
            if getattr(channel, "component_addr", 0):
                continue
            start = int(channel.start_offset) + 8 * int(
                getattr(channel, "additional_byte_offset", 0)
            )
        # asammdf reads at least one byte even for a channel of 0 bits.
        end = -(-(start + max(bits, 1)) // 8)
        if end > size:
            raise DataError(
                f"channel {str(channel.name)!r} ends at byte {end} of a {size}-byte record "
                "(file truncated or corrupt?)",
                file=path,
                hint="write the file again",
            )


def _mdf_numeric(version: str, data_type: int) -> bool:
    if version.startswith("4"):
        return data_type in _MDF4_NUMERIC_TYPES
    return data_type not in _MDF3_TEXT_TYPES


register_reader("csv", _read_csv)
register_reader("tsv", _read_tsv)
register_reader("parquet", _read_parquet)
register_reader("mat", _read_mat)
register_reader("hdf5", _read_hdf5)
register_reader("mdf", _read_mdf)
register_reader(
    "can",
    lambda path, columns, options: importlib.import_module(".can", __package__).read_can(
        path, columns, options
    ),
    (".blf", ".asc", ".log"),
)
