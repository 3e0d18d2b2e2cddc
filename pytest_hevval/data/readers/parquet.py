"""Parquet through pyarrow, a few columns at a time."""

from __future__ import annotations

import threading
from collections.abc import Iterable, Iterator
from contextlib import closing, contextmanager
from typing import Any

import numpy as np
import numpy.typing as npt

from ...errors import DataError
from ..record import Record, SourceOptions
from ..remote import parquet_source
from ._common import (
    _SECONDS_PER,
    ValueArray,
    _as_values,
    _channel_list,
    _check_time,
    _clock_options,
    _corrupt,
    _import,
    _no_rows,
    _not_numbers,
    _pick_time,
    _start_meta,
    _table_record,
    _time_base,
    _unit_from_name,
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
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise DataError(
                f"the file has {names.count(repeated[0])} columns named {repeated[0]!r}",
                file=path,
                column=repeated[0],
                hint="give each column its own name when the file is written",
            )
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
        if time_column.null_count:
            missing = np.flatnonzero(time_column.is_null().to_numpy(zero_copy_only=False))
            raise DataError(
                f"time is missing at index {int(missing[0])} "
                f"({time_column.null_count} missing in all)",
                file=path,
                column=time_name,
                hint="remove those rows or fill in their time",
            )
        start_meta: dict[str, Any] = {}
        if types.is_timestamp(time_column.type) or types.is_duration(time_column.type):
            # Absolute or elapsed time stamps become seconds since the first sample.
            # Subtract in int64: epoch nanoseconds exceed float64's exact integer range.
            stamps = np.asarray(time_column.cast(pa.int64()).to_numpy(), dtype=np.int64)
            unit = time_column.type.unit
            time_raw: npt.NDArray[Any] = (stamps - stamps[0]).astype(np.float64) * _SECONDS_PER[
                unit
            ]
            if types.is_timestamp(time_column.type) and stamps.size:
                # Arrow keeps time-zone-aware stamps in UTC; naive ones are taken as UTC.
                start_meta = _start_meta(float(stamps[0]) * _SECONDS_PER[unit])
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
        if start_meta:
            time = _check_time(path, time_name, time_raw, _clock_options(options))
        else:
            time, start_meta = _time_base(path, time_name, time_raw, options)
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
        path,
        time_name,
        time,
        values,
        available=names,
        numeric=numeric,
        units=units,
        meta=start_meta,
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
