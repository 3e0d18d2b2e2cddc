"""How data files are identified in results and history records."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from pytest_hevval.data import digest
from pytest_hevval.results.codec import data_identity


def _file(tmp_path: Path, size: int, seed: int = 0) -> Path:
    path = tmp_path / f"data{seed}.bin"
    path.write_bytes(bytes((i * 31 + seed) % 251 for i in range(size)))
    return path


def test_sha256_is_the_whole_file_sha256(tmp_path: Path) -> None:
    path = _file(tmp_path, 100_000)
    got = digest.file_digest(str(path), "sha256")
    assert got == {"hash": "sha256", "digest": hashlib.sha256(path.read_bytes()).hexdigest()}


def test_fast_hash_is_xxh3_128_of_the_whole_file(tmp_path: Path) -> None:
    xxhash = pytest.importorskip("xxhash")
    path = _file(tmp_path, 100_000)
    got = digest.file_digest(str(path))
    assert got == {"hash": "xxh3_128", "digest": xxhash.xxh3_128(path.read_bytes()).hexdigest()}


@pytest.mark.parametrize("size", [10, 64 * 65_536, 64 * 65_536 + 1, 20_000_000])
def test_sampled_fallback_sees_size_and_sampled_changes(
    tmp_path: Path, size: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(digest, "_xxhash", lambda: None)
    path = _file(tmp_path, size)
    first = digest.file_digest(str(path))
    assert first["hash"] == "sampled-blake2b"
    assert digest.file_digest(str(path)) == first
    data = bytearray(path.read_bytes())
    data[-1] ^= 0xFF  # the last block is always sampled
    path.write_bytes(bytes(data))
    assert digest.file_digest(str(path)) != first
    path.write_bytes(bytes(data) + b"\0")
    assert digest.file_digest(str(path))["digest"] != first["digest"]


def test_unknown_algorithm_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="fast, sha256"):
        digest.file_digest(str(_file(tmp_path, 10)), "md5")


@pytest.mark.parametrize(
    ("entry", "expected"),
    [
        ({"path": "a", "sha256": "ab"}, ("sha256", "ab")),
        ({"path": "a", "hash": "xxh3_128", "digest": "cd"}, ("xxh3_128", "cd")),
        ({"path": "a", "kind": "callable"}, None),
        ({"path": "a", "sha256": ""}, None),
    ],
)
def test_identity_reads_old_and_new_records(
    entry: dict[str, str], expected: tuple[str, str] | None
) -> None:
    assert data_identity(entry) == expected
