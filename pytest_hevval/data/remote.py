"""Data that lives elsewhere: fsspec URLs such as ``s3://``, ``gs://``, ``abfs://``, ``https://``.

A spec's ``reference.path`` or ``model.path`` containing ``://`` is kept as written (see
:mod:`pytest_hevval.spec.sources`) and read here, on the machine that evaluates the spec, so a Dask
worker next to the data reads it directly instead of receiving it through the client.

Two ways of reading, chosen per format:

* **Parquet is streamed.** pyarrow reads through the fsspec file system and fetches only the
  footer and the column chunks of the requested channels, so a spec that uses 20 of a file's
  600 columns moves about 20/600 of its bytes.
* **Every other format is copied to a temporary file first** and read from there. A CSV file
  has to be read whole anyway, and its reader opens it up to three times (encoding sniff,
  header sniff, full read), which over a network would be three transfers. MAT, HDF5 and MDF
  libraries want a seekable local file.

fsspec is optional (``pip install 'pytest-hevval[dask]'``); the protocol's own package
(s3fs, gcsfs, adlfs …) must be installed where the data is read.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
from collections.abc import Iterable, Iterator
from contextlib import AbstractContextManager, contextmanager
from typing import IO, Any, cast

from ..errors import DataError, HevvalError, MissingExtraError
from ..files import temporary_folder
from .record import Reader, Record, SourceOptions

__all__ = [
    "STREAMED_FORMATS",
    "is_url",
    "local_copy",
    "open_url",
    "parquet_source",
    "read_url",
    "relative_to",
    "url_digest",
    "url_filesystem",
]

#: Formats whose readers accept a URL themselves and read only what they need.
STREAMED_FORMATS = frozenset({"parquet"})

# A URL is a scheme followed by "://", optionally behind fsspec's chaining syntax
# ("simplecache::s3://bucket/key"). A Windows drive ("C:\\data") has no "//" after its colon.
_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*(?:::[A-Za-z][A-Za-z0-9+.\-]*)*://")

_COPY_BLOCK = 1 << 22


def is_url(path: str | os.PathLike[str]) -> bool:
    """True for ``scheme://…`` paths, which fsspec reads; False for local paths."""
    return bool(_URL.match(os.fspath(path)))


def relative_to(rootdir: str | os.PathLike[str], path: str) -> str:
    """``path`` relative to ``rootdir`` (URLs and paths on another drive unchanged)."""
    if is_url(path):
        return path
    try:
        return os.path.relpath(path, rootdir)
    except ValueError:
        return path


def _fsspec() -> Any:
    try:
        import fsspec
    except ImportError:
        raise MissingExtraError.for_extra("reading data from a URL", "dask", "fsspec") from None
    return fsspec


def url_filesystem(url: str) -> tuple[Any, str]:
    """The fsspec file system for ``url`` and the path within it.

    Raises
    ------
    DataError
        When the protocol is unknown or its package (s3fs, gcsfs …) is not installed.
    """
    fsspec = _fsspec()
    try:
        filesystem, path = fsspec.core.url_to_fs(url)
    except ImportError as exc:
        # fsspec names the package to install for the protocol ("Install s3fs to access S3").
        raise DataError(
            f"cannot open this URL: {exc}",
            file=url,
            hint="install the fsspec package for its protocol where the data is read",
        ) from None
    except ValueError as exc:
        raise DataError(
            f"cannot open this URL: {exc}",
            file=url,
            hint="use a protocol fsspec knows (s3://, gs://, abfs://, https://, file:// …)",
        ) from None
    return filesystem, str(path)


def open_url(url: str) -> AbstractContextManager[IO[bytes]]:
    """``url`` opened for binary reading, as a context manager."""
    fsspec = _fsspec()
    return cast("AbstractContextManager[IO[bytes]]", fsspec.open(url, "rb"))


def _check_file(url: str) -> tuple[Any, str]:
    """The file system and path of ``url`` after checking it is a non-empty file."""
    filesystem, path = url_filesystem(url)
    try:
        info = filesystem.info(path)
    except FileNotFoundError:
        raise DataError(
            "file not found", file=url, hint="check the URL and that this machine may read it"
        ) from None
    except OSError as exc:
        raise DataError(
            f"cannot read this URL ({exc})",
            file=url,
            hint="check the credentials of the machine that reads the data",
        ) from None
    if info.get("type") == "directory":
        raise DataError("this is a directory, not a data file", file=url, hint="name a file")
    if info.get("size") == 0:
        raise DataError("the file is empty (0 bytes)", file=url, hint="export the data again")
    return filesystem, path


@contextmanager
def local_copy(url: str) -> Iterator[str]:
    """Copy ``url`` into a temporary folder and yield the local path; delete it afterwards.

    The copy keeps the file's name, so readers that pick a format by extension still can.
    """
    filesystem, path = _check_file(url)
    name = os.path.basename(path.rstrip("/")) or "data"
    with temporary_folder() as folder:
        local = os.path.join(folder, name)
        try:
            with filesystem.open(path, "rb") as source, open(local, "wb") as target:
                shutil.copyfileobj(source, target, _COPY_BLOCK)
        except OSError as exc:
            raise DataError(
                f"cannot download this URL ({exc})",
                file=url,
                hint="check the connection and the credentials of the machine that reads it",
            ) from None
        yield local


def parquet_source(path: str) -> tuple[str, Any | None]:
    """``(source, filesystem)`` for ``pyarrow.parquet.ParquetFile``: a URL goes through fsspec.

    A local path comes back unchanged with no file system, so pyarrow behaves as before.
    """
    if not is_url(path):
        return path, None
    filesystem, inner = url_filesystem(path)
    return inner, filesystem


def read_url(
    url: str,
    columns: Iterable[str] | None,
    options: SourceOptions,
    fmt: str,
    reader: Reader,
) -> Record:
    """What :func:`~pytest_hevval.data.readers.read_record` does for a URL.

    Streamed formats get the URL; others a local copy. Either way, errors and the record name
    the URL, never a temporary file.
    """
    wanted = None if columns is None else list(dict.fromkeys(columns))
    if fmt in STREAMED_FORMATS:
        _check_file(url)
        try:
            record = reader(url, wanted, options)
        except MissingExtraError as exc:
            raise exc.with_context(file=url) from None
    else:
        with local_copy(url) as local:
            try:
                record = reader(local, wanted, options)
            except HevvalError as exc:
                raise _renamed(exc, local, url) from None
        record.source = url
    record.meta.setdefault("format", fmt)
    record.meta.setdefault("url", url)
    return record


def _renamed(exc: HevvalError, local: str, url: str) -> HevvalError:
    """``exc`` with the temporary file's path replaced by the URL in every field."""

    def swap(text: str | None) -> str | None:
        return None if text is None else text.replace(local, url)

    file = url if exc.file in (None, local) else exc.file
    return type(exc)(
        swap(exc.problem) or "",
        file=file,
        line=exc.line,
        key=exc.key,
        column=exc.column,
        hint=swap(exc.hint),
    )


def url_digest(url: str) -> str:
    """SHA-256 of the data behind ``url`` (hex), streamed; ``""`` when it cannot be read.

    This transfers the whole file, which for a streamed Parquet file is more than the columns
    a spec reads; it is what keeps history able to tell when remote measurements changed.
    """
    digest = hashlib.sha256()
    try:
        with open_url(url) as handle:
            for block in iter(lambda: handle.read(_COPY_BLOCK), b""):
                digest.update(block)
    except (OSError, ValueError, ImportError, HevvalError):
        return ""
    return digest.hexdigest()
