"""The identity of a data file in results and history records: a hash, and which one.

History tells "the measurements changed" from "the model changed" by comparing these. A run
must not wait for them, so the default is a fast hash: xxHash's XXH3-128 of the whole file
when ``xxhash`` is installed (the ``fast`` extra; it hashes at memory speed), else BLAKE2b of
the file's size and of evenly spaced blocks, which reads at most 4 MiB of any file.
``--hevval-hash=sha256`` asks for SHA-256 of the whole file instead.

Two digests mean the same only under the same algorithm: a record states its algorithm
(``hash``) beside the digest, and records written before that carry ``sha256`` alone.
"""

from __future__ import annotations

import hashlib
import importlib
import os
from typing import Any

__all__ = ["DEFAULT_HASH", "HASH_CHOICES", "file_digest"]

#: What ``--hevval-hash`` accepts: ``fast`` (xxh3_128, else sampled) or ``sha256``.
HASH_CHOICES = ("fast", "sha256")
DEFAULT_HASH = "fast"

_BLOCK = 1 << 22
# The sampled fallback reads this many blocks of _SAMPLE bytes: the first, the last and
# evenly spaced ones between (the whole file when it is no larger).
_SAMPLES = 64
_SAMPLE = 1 << 16


def _xxhash() -> Any | None:
    try:
        return importlib.import_module("xxhash")
    except ImportError:
        return None


def _whole(path: str, digest: Any) -> str:
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(_BLOCK), b""):
            digest.update(block)
    hexdigest: str = digest.hexdigest()
    return hexdigest


def _sampled(path: str) -> str:
    """BLAKE2b of the size and of _SAMPLES blocks: a change that keeps the size and falls
    between the blocks goes unseen (use sha256 where that matters)."""
    digest = hashlib.blake2b(digest_size=16)
    with open(path, "rb") as handle:
        size = os.fstat(handle.fileno()).st_size
        digest.update(size.to_bytes(8, "little"))
        if size <= _SAMPLES * _SAMPLE:
            digest.update(handle.read())
        else:
            step = (size - _SAMPLE) / (_SAMPLES - 1)
            for i in range(_SAMPLES):
                handle.seek(round(i * step))
                digest.update(handle.read(_SAMPLE))
    return digest.hexdigest()


def file_digest(path: str, algorithm: str = DEFAULT_HASH) -> dict[str, str]:
    """``{"hash": name, "digest": hex}`` of a data file, for results and history records."""
    if algorithm == "sha256":
        return {"hash": "sha256", "digest": _whole(path, hashlib.sha256())}
    if algorithm != "fast":
        raise ValueError(f"unknown hash {algorithm!r}: use one of {', '.join(HASH_CHOICES)}")
    xxhash = _xxhash()
    if xxhash is not None:
        return {"hash": "xxh3_128", "digest": _whole(path, xxhash.xxh3_128())}
    return {"hash": "sampled-blake2b", "digest": _sampled(path)}
