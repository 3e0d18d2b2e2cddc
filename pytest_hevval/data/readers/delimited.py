"""CSV and TSV: separator, encoding and decimal mark sniffed; read with pandas."""

from __future__ import annotations

import csv
import importlib
import re
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt

from ...errors import DataError
from ..record import Record, SourceOptions

if TYPE_CHECKING:
    import pandas as pd
from ._common import (
    _as_list,
    _as_values,
    _channel_list,
    _clock_seconds,
    _first_line,
    _no_rows,
    _pick_time,
    _table_record,
    _time_base,
    _unit_from_name,
    check_stamps,
)

_SEPARATORS = (";", ",", "\t", "|")


# Rows sampled to tell numeric CSV columns from text ones without reading the whole file.
_SNIFF_ROWS = 200


_SNIFF_BYTES = 65536


def _read_head(path: str) -> bytes:
    with open(path, "rb") as stream:
        return stream.read(_SNIFF_BYTES)


def _check_text(path: str, head: bytes) -> None:
    """A delimited file is text: NUL bytes say it is binary (or a file still being written)."""
    at = head.find(b"\x00")
    if at >= 0:
        raise DataError(
            f"byte {at} is a NUL byte: this is not a text CSV or TSV file",
            file=path,
            hint="name the data file itself (an export may still be in progress), or set "
            "`format:` when it is another format",
        )


#: Byte-order marks and the encodings they announce; UTF-32's before UTF-16's, which they
#: begin with.
_BOMS = (
    (b"\xef\xbb\xbf", "utf-8-sig"),
    (b"\xff\xfe\x00\x00", "utf-32"),
    (b"\x00\x00\xfe\xff", "utf-32"),
    (b"\xff\xfe", "utf-16"),
    (b"\xfe\xff", "utf-16"),
)


def _sniff_encoding(head: bytes) -> str:
    for bom, encoding in _BOMS:
        if head.startswith(bom):
            return encoding
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
    elif not any(head.startswith(bom) for bom, _ in _BOMS):
        # A declared or announced encoding (UTF-16, UTF-32) has NUL bytes of its own.
        _check_text(path, head)
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
    try:
        raw_names = next(csv.reader([header], delimiter=sep)) if len(sep) == 1 else names
    except (csv.Error, TypeError) as exc:
        # Python 3.10's csv module refuses NUL bytes, in the text (UTF-16 read as 8-bit, for
        # one) or as the separator.
        raise DataError(
            f"cannot read the header line with separator {sep!r}: {exc}",
            file=path,
            hint="save the file as UTF-8 text, or set `encoding:` and `sep:` to the file's",
        ) from None
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

    time_raw = frame[time_name].to_numpy()
    if time_raw.dtype.kind not in "OUSM" or _clock_seconds(time_raw) is None:
        # A column of stamps with one that cannot be read is named by that stamp.
        check_stamps(path, time_name, time_raw, first_line=2)
        time_raw = _numeric_column(path, frame, time_name, decimal)
    time, start_meta = _time_base(path, time_name, time_raw, options, first_line=2)
    values = {
        name: _as_values(path, name, _numeric_column(path, frame, name, decimal)) for name in wanted
    }
    meta: dict[str, Any] = {"sep": sep, "encoding": encoding, "decimal": decimal, "engine": engine}
    meta.update(start_meta)
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
