"""Byte-level checks of HDF5 groups before libhdf5 walks them.

A damaged name heap whose free list points back at itself makes libhdf5 loop forever, where
Python cannot interrupt it; these checks refuse such a group first.
"""

from __future__ import annotations

import struct
from typing import Any

from ....errors import DataError
from .._common import _read_at

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _hdf5_name(name: str | bytes) -> str:
    # h5py hands out a link name it cannot decode as UTF-8 (a damaged or foreign file) as bytes.
    return name.decode("utf-8", errors="replace") if isinstance(name, bytes) else name


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


def _check_hdf5_group(path: str, group: Any) -> None:
    problem = _hdf5_name_heap_problem(path, group)
    if problem is not None:
        raise DataError(
            f"cannot read this file (file corrupt?): its HDF5 {problem}",
            file=path,
            hint="write the file again",
        )


def hdf5_external_links(group: Any) -> dict[bytes, tuple[str, str]]:
    """The group's links into other files, by name as the file stores it: (file, path) each.

    Read at the library's level: looking a link up through h5py follows it, opening the other
    file (a named pipe there would block), and h5py cannot look up names that are not UTF-8.
    """
    import h5py

    found: dict[bytes, tuple[str, str]] = {}
    for raw_name in group.id.__iter__():
        if group.id.links.get_info(raw_name).type == h5py.h5l.TYPE_EXTERNAL:
            file_name, target = group.id.links.get_val(raw_name)
            found[raw_name] = (_hdf5_name(file_name), _hdf5_name(target))
    return found


def _hdf5_get_checked(path: str, handle: Any, key: str) -> Any:
    """``handle.get(key)``, checking every group on the way, and a group found, before a name
    is looked up in it; a link into another file on the way is refused."""
    import h5py

    node = handle
    for part in [p for p in key.split("/") if p]:
        if not isinstance(node, h5py.Group):
            return None
        _check_hdf5_group(path, node)
        external = hdf5_external_links(node).get(part.encode("utf-8", "surrogateescape"))
        if external is not None:
            raise DataError(
                f"{key!r} leads through a link to {external[1]!r} in the file {external[0]!r}: "
                "hevval reads only the data file the spec names",
                file=path,
                key="group",
                hint="copy the data into this file, or name the file that holds them",
            )
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
        external = hdf5_external_links(group)
        for raw_name in group.id.__iter__():
            if raw_name in external:
                continue  # another file's groups are not this file's
            obj = group.get(raw_name)
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
