"""The one way hevval writes a file: atomically, durably, with the usual permissions.

History records, reports, ratchet sidecars and JSON output all go through here. A reader sees
the old file or the new one, never half of one; a failure leaves the old file as it was and no
temporary file behind. Temporary files are created with mode 0o666 before the umask rather than by
:func:`tempfile.mkstemp`, so the result gets the mode the user's umask gives (0644 usually),
not 0600: ratchet sidecars and reports are files users commit and share.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path

__all__ = ["publish", "write_atomic", "write_temporary"]


def write_temporary(directory: Path, payload: bytes, *, stem: str = "hevval") -> Path:
    """Write ``payload`` to a new hidden file in ``directory``, flushed to disk; its path."""
    temp = directory / f".tmp-{stem}.{os.getpid()}.{secrets.token_hex(4)}.part"
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
    already exists (nothing is written then). OSError propagates for the caller to word.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    payload = content.encode("utf-8") if isinstance(content, str) else content
    temp = write_temporary(target.parent, payload, stem=target.name)
    try:
        written = publish(temp, target, replace=replace)
        if written:
            fsync_directory(target.parent)
        return written
    finally:
        with contextlib.suppress(FileNotFoundError):
            temp.unlink()
