"""The session's data files: each read once with every column the specs need, and hashed.

A file's data are shared by every spec that reads it and let go when the last is done; its
digest (what identifies it in results and history) is computed on a thread of its own while
the spec is scored.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from concurrent.futures import Future, ThreadPoolExecutor

from ..data.digest import DEFAULT_HASH, file_digest
from ..data.record import Record, SourceOptions
from ..errors import DataError
from ..spec.model import SourceSpec, Spec
from .allocator import tune_allocator

__all__ = ["DataCache"]


def _reader() -> Callable[[str, Iterable[str] | None, SourceOptions], Record]:
    from ..data.readers import read_record

    return read_record


def _digest_or_empty(path: str, algorithm: str) -> dict[str, str]:
    try:
        return file_digest(path, algorithm)
    except OSError:
        return {}


class DataCache:
    """Reads each data file once per session, with the union of the columns every spec needs.

    Specs declare their columns at collection time (:meth:`declare`); the first :meth:`read` of
    a file then reads all declared columns in one go. A file's data are let go once every spec
    that declared it is done with it (:meth:`release`), so a campaign holds the data of the
    recordings being scored, not of every recording scored so far.
    """

    def __init__(self, data_hash: str = DEFAULT_HASH) -> None:
        tune_allocator()
        #: How data files are identified in results (see :mod:`pytest_hevval.data.digest`).
        self.data_hash = data_hash
        self._lock = threading.Lock()
        self._records: dict[tuple[str, str], Record] = {}
        #: Every numeric column of a file, for the diagnosis's candidates (:meth:`read_whole`).
        self._whole: dict[tuple[str, str], Record] = {}
        self._declared: dict[tuple[str, str], set[str]] = {}
        #: Declarations not yet released, by file: the record is kept while any is left.
        self._users: dict[tuple[str, str], int] = {}
        self._digests: dict[str, Future[dict[str, str]]] = {}
        self._hasher: ThreadPoolExecutor | None = None
        #: How many times each file was actually read (tests and benchmarks check it).
        self.reads: dict[str, int] = {}

    @staticmethod
    def _key(source: SourceSpec) -> tuple[str, str]:
        options = source.options
        return (
            str(source.path),
            repr(
                (
                    options.time,
                    options.format,
                    options.sep,
                    options.encoding,
                    options.decimal,
                    options.group,
                    options.time_scale,
                    sorted(options.extra.items()),
                )
            ),
        )

    def declare(self, source: SourceSpec, columns: Iterable[str]) -> None:
        if source.kind != "file":
            return
        key = self._key(source)
        with self._lock:
            self._declared.setdefault(key, set()).update(columns)
            self._users[key] = self._users.get(key, 0) + 1

    def release(self, source: SourceSpec) -> None:
        """One declaration of ``source`` is done with it; the last one lets its data go."""
        if source.kind != "file":
            return
        key = self._key(source)
        with self._lock:
            left = self._users.get(key, 0) - 1
            if left > 0:
                self._users[key] = left
            else:
                self._users.pop(key, None)
                self._records.pop(key, None)
                self._whole.pop(key, None)

    def held(self) -> list[str]:
        """The files whose data this cache holds now."""
        with self._lock:
            return sorted(path for path, _ in self._records)

    def declare_spec(self, spec: Spec) -> None:
        """The columns ``spec`` reads from its reference and model files."""
        self.declare(spec.reference, spec.reference_columns())
        self.declare(spec.model, spec.model_columns())

    def release_spec(self, spec: Spec) -> None:
        """``spec`` is scored: its files' data may go (:meth:`release`)."""
        self.release(spec.reference)
        self.release(spec.model)

    def read(self, source: SourceSpec, columns: Iterable[str]) -> Record:
        key = self._key(source)
        wanted = set(columns)
        with self._lock:
            cached = self._records.get(key)
            if cached is not None and wanted <= set(cached.channels):
                return cached
            union = wanted | self._declared.get(key, set())
            if cached is not None:
                union |= set(cached.channels)
            while True:
                try:
                    record = _reader()(str(source.path), sorted(union), source.options)
                    break
                except DataError as exc:
                    # A column another spec declared and the file lacks is that spec's error,
                    # not this one's: read without it, and let that spec's own read say so.
                    if exc.column is None or exc.column in wanted or exc.column not in union:
                        raise
                    union.discard(exc.column)
                    self._declared.get(key, set()).discard(exc.column)
            self.reads[key[0]] = self.reads.get(key[0], 0) + 1
            self._records[key] = record
            self._start_digest(key[0])
            return record

    def read_whole(self, source: SourceSpec) -> Record:
        """Every numeric column of ``source``, read once and let go with its other data."""
        key = self._key(source)
        with self._lock:
            if key not in self._whole:
                self._whole[key] = _reader()(str(source.path), None, source.options)
                self.reads[key[0]] = self.reads.get(key[0], 0) + 1
            return self._whole[key]

    def _start_digest(self, path: str) -> Future[dict[str, str]]:
        # hashlib and xxhash release the GIL, so hashing overlaps with reading and scoring.
        if path not in self._digests:
            if self._hasher is None:
                self._hasher = ThreadPoolExecutor(max_workers=1, thread_name_prefix="hevval-hash")
            self._digests[path] = self._hasher.submit(_digest_or_empty, path, self.data_hash)
        return self._digests[path]

    def digest(self, path: str) -> dict[str, str]:
        """``{"hash": …, "digest": …}`` of a data file (empty if it could not be read)."""
        with self._lock:
            future = self._start_digest(path)
        return future.result()
