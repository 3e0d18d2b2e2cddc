"""Readers of measured and simulated data: one module per format, one registry.

:func:`read_record` is the only entry point the engine needs. It picks a reader from
``options.format`` or the file extension, reads only the requested columns (plus time) and
checks the time base, so every :class:`~pytest_hevval.data.record.Record` it returns has
strictly increasing float64 times in seconds.

Every problem a user can fix becomes a :class:`~pytest_hevval.errors.DataError` that names the
file, the column where there is one, and what to change in the spec. The catalogue of messages
is in ``docs/data.md``. Adding a format: ``docs/extending.md``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from typing import cast

from ...errors import DataError, HevvalError, MissingExtraError, did_you_mean
from ...files import check_input
from ...lazy import import_own
from ..record import Reader, Record, SourceOptions
from ..remote import is_url, read_url

__all__ = [
    "ENTRY_POINT_GROUP",
    "FORMATS",
    "detect_format",
    "format_names",
    "read_record",
    "register_reader",
]

#: Third-party readers register through this entry point group: the entry point names a
#: module that calls :func:`register_reader` when imported, or a function that does when
#: called with no arguments.
ENTRY_POINT_GROUP = "pytest_hevval.readers"

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


def register_reader(name: str, reader: Reader, extensions: Sequence[str] = ()) -> None:
    """Add (or replace) the reader for format ``name``, selected by ``extensions``."""
    key = name.lower()
    _READERS[key] = reader
    exts = tuple(e.lower() if e.startswith(".") else f".{e.lower()}" for e in extensions)
    FORMATS[key] = tuple(dict.fromkeys(FORMATS.get(key, ()) + exts))


_ENTRY_POINTS_LOADED = False


def _load_entry_points() -> None:
    """Import the readers other packages declare, once per process."""
    global _ENTRY_POINTS_LOADED
    if _ENTRY_POINTS_LOADED:
        return
    _ENTRY_POINTS_LOADED = True
    from importlib.metadata import entry_points

    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            loaded = entry.load()
            if callable(loaded):
                loaded()
        except Exception as exc:
            raise HevvalError(
                f"the reader entry point {entry.name!r} ({entry.value}) failed to load: "
                f"{type(exc).__name__}: {exc}",
                hint=f"fix or uninstall the package that declares it in {ENTRY_POINT_GROUP!r}",
            ) from None


def format_names() -> tuple[str, ...]:
    """Every name ``format:`` accepts: the registered readers, then their aliases."""
    _load_entry_points()
    return (*FORMATS, *(alias for alias in _ALIASES if alias not in FORMATS))


def _formats_text() -> str:
    return ", ".join(f"{name} ({', '.join(exts)})" for name, exts in FORMATS.items())


def detect_format(path: str, options: SourceOptions) -> str:
    """The format name for ``path``: ``options.format`` when given, else from the extension."""
    _load_entry_points()
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
    try:
        check_input(path)
    except OSError as exc:
        raise DataError(
            f"cannot read it: {exc.strerror or exc}", file=path, hint="name a regular data file"
        ) from None
    if os.path.getsize(path) == 0:
        raise DataError("the file is empty (0 bytes)", file=path, hint=_rewrite_hint(fmt))
    wanted = None if columns is None else list(dict.fromkeys(columns))
    reader = _READERS[fmt]
    try:
        record = reader(path, wanted, options)
    except MissingExtraError as exc:
        raise exc.with_context(file=path) from None
    except OSError as exc:  # no permission, a read error of the disk, a file gone meanwhile
        raise DataError(
            f"cannot read it: {exc.strerror or exc}",
            file=path,
            hint="check the file's permissions and that it is complete",
        ) from None
    record.meta.setdefault("format", fmt)
    return record


def _rewrite_hint(fmt: str) -> str:
    return f"export the data again as {fmt}"


def _deferred(module: str, function: str) -> Reader:
    """A reader whose module is imported on first use, so the registry itself stays light."""

    def read(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
        reader = getattr(import_own(f".{module}", __name__), function)
        return cast(Record, reader(path, columns, options))

    read.__name__ = f"{module}.{function}"
    return read


register_reader("csv", _deferred("delimited", "_read_csv"))
register_reader("tsv", _deferred("delimited", "_read_tsv"))
register_reader("parquet", _deferred("parquet", "_read_parquet"))
register_reader("mat", _deferred("mat", "_read_mat"))
register_reader("hdf5", _deferred("hdf5", "_read_hdf5"))
register_reader("mdf", _deferred("mdf", "_read_mdf"))
register_reader("can", _deferred("can", "read_can"), (".blf", ".asc", ".log"))
register_reader("tdms", _deferred("tdms", "read_tdms"), (".tdms",))
