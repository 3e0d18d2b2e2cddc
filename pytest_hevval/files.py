"""The one way hevval reads an input file and writes an output: inputs are regular files of a
bounded size, outputs are written atomically, durably, with the usual permissions.

A spec, its sidecar, a data file, a history record or a compared run is opened only when it is
a regular file: a named pipe would block the run until its time limit, a device could be read
forever. The small inputs (specs, sidecars, records, runs) are read whole only under a limit
on their size, so that a mistaken or hostile file cannot exhaust memory.

History records, reports, ratchet sidecars and JSON output all go through here. A reader sees
the old file or the new one, never half of one; a failure leaves the old file as it was and no
temporary file behind. Temporary files are created with mode 0o666 before the umask rather than by
:func:`tempfile.mkstemp`, so the result gets the mode the user's umask gives (0644 usually),
not 0600: ratchet sidecars and reports are files users commit and share.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import secrets
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from .errors import OutputError

__all__ = [
    "MAX_DOCUMENT_BYTES",
    "MAX_JSON_DEPTH",
    "InputRefused",
    "check_input",
    "forget_temporary",
    "output_error",
    "publish",
    "read_input",
    "read_json",
    "remove_temporaries_on_signals",
    "write_atomic",
    "write_temporary",
]

#: The largest spec, sidecar, history record or run JSON read (a run of 600 signals with its
#: intervals and windows writes about 10 MB).
MAX_DOCUMENT_BYTES = 256 * 1024 * 1024
#: The deepest nesting of a JSON document read (a history record nests about eight levels).
MAX_JSON_DEPTH = 64


class InputRefused(OSError):
    """An input that is not a regular file, or too large to read whole; ``strerror`` says
    which, so callers that name an unreadable file by its OSError need nothing new."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.strerror = message


def check_input(path: Path | str) -> int:
    """The size of ``path`` when it is a regular file (symbolic links followed); raises
    :class:`InputRefused` for a folder, a named pipe, a socket or a device, and the usual
    OSError (FileNotFoundError, PermissionError) when it cannot be looked at."""
    info = os.stat(path)
    if stat.S_ISREG(info.st_mode):
        return info.st_size
    if stat.S_ISDIR(info.st_mode):
        kind = "a folder"
    elif stat.S_ISFIFO(info.st_mode):
        kind = "a named pipe"
    elif stat.S_ISSOCK(info.st_mode):
        kind = "a socket"
    else:
        kind = "a device"
    raise InputRefused(f"{kind}, not a regular file")


def unreadable(path: Path | str, exc: OSError) -> str:
    """Why ``path`` could not be opened, in words: a dangling link or a loop of links says
    so, where the system's reason ("No such file or directory") would mislead."""
    if exc.errno == errno.ELOOP:
        return "a loop of symbolic links"
    if exc.errno == errno.ENOENT and os.path.islink(path):
        with contextlib.suppress(OSError):
            return f"a symbolic link to {os.readlink(path)!r}, which does not exist"
    return exc.strerror or str(exc)


def read_input(path: Path | str, limit: int = MAX_DOCUMENT_BYTES) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (see :func:`check_input`)."""
    size = check_input(path)
    if size > limit:
        raise InputRefused(f"{size:,} bytes, over the {limit:,}-byte limit for this kind of file")
    with open(path, "rb") as stream:
        data = stream.read(limit + 1)
    if len(data) > limit:  # grew while being read
        raise InputRefused(f"over the {limit:,}-byte limit for this kind of file")
    return data


def read_json(path: Path | str, limit: int = MAX_DOCUMENT_BYTES) -> Any:
    """The JSON document in ``path``: OSError when it cannot be read (:func:`read_input`),
    ValueError when it is not UTF-8 JSON (``json.JSONDecodeError`` with its line) or nests
    deeper than :data:`MAX_JSON_DEPTH`."""
    text = read_input(path, limit).decode("utf-8")
    try:
        document = json.loads(text)
    except RecursionError:
        raise ValueError(f"nested deeper than {MAX_JSON_DEPTH} levels") from None
    pending: list[tuple[Any, int]] = [(document, 1)]
    while pending:
        value, depth = pending.pop()
        if depth > MAX_JSON_DEPTH:
            raise ValueError(f"nested deeper than {MAX_JSON_DEPTH} levels")
        if isinstance(value, dict):
            pending.extend((item, depth + 1) for item in value.values())
        elif isinstance(value, list):
            pending.extend((item, depth + 1) for item in value)
    return document


#: Temporary files being written or not yet removed, which a termination signal removes.
_IN_FLIGHT: set[Path] = set()
#: The signals after which no temporary file may stay: a CI job cancelled, a terminal closed.
_TERMINATING = ("SIGTERM", "SIGHUP")


def remove_temporaries_on_signals() -> None:
    """Make a termination signal remove the temporary files in flight before the process
    ends as the signal ends it (its exit status unchanged). Front ends call this once, from
    the main thread; a handler someone else installed is left alone."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return
    for name in _TERMINATING:
        number = getattr(signal, name, None)
        if number is not None and signal.getsignal(number) is signal.SIG_DFL:
            signal.signal(number, _remove_and_die)


def _remove_and_die(number: int, _frame: object) -> None:
    import shutil
    import signal

    for temp in list(_IN_FLIGHT):
        with contextlib.suppress(OSError):
            if temp.is_dir() and not temp.is_symlink():
                shutil.rmtree(temp, ignore_errors=True)
            else:
                os.unlink(temp)
    signal.signal(number, signal.SIG_DFL)
    os.kill(os.getpid(), number)


@contextlib.contextmanager
def temporary_folder(prefix: str = "hevval-") -> Iterator[Path]:
    """A new temporary folder, removed afterwards, and by a termination signal before that
    (see :func:`remove_temporaries_on_signals`)."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix=prefix) as folder:
        path = Path(folder)
        _IN_FLIGHT.add(path)
        try:
            yield path
        finally:
            _IN_FLIGHT.discard(path)


def forget_temporary(temp: Path) -> None:
    """Remove ``temp`` if it is still there, and stop tracking it."""
    with contextlib.suppress(FileNotFoundError):
        temp.unlink()
    _IN_FLIGHT.discard(temp)


def write_temporary(directory: Path, payload: bytes, *, stem: str = "hevval") -> Path:
    """Write ``payload`` to a new hidden file in ``directory``, flushed to disk; its path.
    Until :func:`forget_temporary` a termination signal removes it (see
    :func:`remove_temporaries_on_signals`)."""
    temp = directory / f".tmp-{stem}.{os.getpid()}.{secrets.token_hex(4)}.part"
    _IN_FLIGHT.add(temp)
    # 0o666 before the umask: the mode a plain open() would give, not mkstemp's 0600.
    fd = os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        try:
            handle = os.fdopen(fd, "wb")
        except BaseException:
            os.close(fd)
            raise
        with handle:
            handle.write(payload)
            handle.flush()
            os.fsync(handle.fileno())
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        _IN_FLIGHT.discard(temp)
        raise
    return temp


def publish(temp: Path, final: Path, *, replace: bool) -> bool:
    """Give ``temp`` the name ``final``.

    With ``replace`` an existing ``final`` is swapped out at once. Without it an existing
    ``final`` is left alone and the answer is False: a hard link refuses to overwrite, and
    where the filesystem has no hard links an exclusively created placeholder reserves the name.
    ``temp`` still exists afterwards unless it was renamed; callers remove it.
    """
    if replace:
        os.replace(temp, final)
        return True
    try:
        os.link(temp, final)
        return True
    except FileExistsError:
        return False
    except OSError:
        pass  # a filesystem without hard links
    try:
        fd = os.open(final, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        return False
    os.close(fd)
    try:
        os.replace(temp, final)
    except OSError:
        # Left behind, the empty placeholder would look like a damaged file to every reader.
        with contextlib.suppress(OSError):
            os.unlink(final)
        raise
    return True


def fsync_directory(directory: Path) -> None:
    """Make a new directory entry durable (a no-op where directories cannot be opened)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_atomic(path: Path | str, content: str | bytes, *, replace: bool = True) -> bool:
    """Write ``content`` (text is UTF-8 with ``\\n`` line ends) to ``path`` atomically.

    Creates the parent folder. Returns False only when ``replace`` is False and ``path``
    already exists (nothing is written then). Raises :class:`~pytest_hevval.errors.OutputError`
    (an OSError) naming the path when it cannot be written: a folder in its place, a file where
    a folder should be, no permission, a full disk. The old file is then left as it was.
    """
    target = Path(path)
    payload = content.encode("utf-8") if isinstance(content, str) else content
    try:
        if target.is_dir():
            raise IsADirectoryError(errno.EISDIR, "it is a folder")
        if str(path).endswith(("/", os.sep)):
            # Path() drops the slash that says the user meant a folder.
            raise IsADirectoryError(errno.EISDIR, "the path ends in a slash, so it names a folder")
        target.parent.mkdir(parents=True, exist_ok=True)
        temp = write_temporary(target.parent, payload, stem=target.name)
        try:
            written = publish(temp, target, replace=replace)
            if written:
                fsync_directory(target.parent)
            return written
        finally:
            forget_temporary(temp)
    except OutputError:
        raise
    except OSError as exc:
        raise output_error(target, exc) from None


def output_error(path: Path | str, exc: OSError) -> OutputError:
    """The clear error for an output that could not be written, from the OSError that said so."""
    reason = exc.strerror or str(exc)
    if exc.errno == errno.EISDIR:
        hint = "name a file, not a folder"
    elif exc.errno == errno.ENOSPC:
        hint = "free some disk space, or write somewhere else"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        hint = "make the folder writable, or write somewhere else"
    elif isinstance(exc, (FileExistsError, NotADirectoryError)):
        hint = "a file stands where a folder is needed: remove it, or write somewhere else"
    else:
        hint = "choose another path"
    return OutputError(f"cannot write it: {reason}", file=str(path), hint=hint)
