"""Byte-level checks of MDF files before asammdf reads them.

Block lists that link back on themselves make asammdf loop forever, and damaged record counts
make it allocate tens of gigabytes; these checks walk the blocks on plain bytes first.
"""

from __future__ import annotations

import os
import struct
from typing import IO, Any

from ....errors import DataError
from .._common import _read_at

# asammdf data-type codes for numbers: MDF4 codes 0-5 are integers and reals; MDF3 codes
# 7 and 8 are strings and byte arrays, everything else numeric.
_MDF4_NUMERIC_TYPES = range(6)


_MDF3_TEXT_TYPES = (7, 8)


# Where the links of the block lists asammdf follows while opening a file sit: the first data
# group in the header, and in each block its next sibling and first child.
_MDF_LINKS = {
    # version: (address size, header's first data group, next block, first child)
    "3": (4, 68, 4, 8),
    "4": (8, 88, 24, 32),
}


def _mdf_loop(path: str) -> str | None:
    """Describe a loop in the data group, channel group or channel lists, or None.

    asammdf walks these linked lists while opening a file and never remembers where it has
    been; one damaged link that points back makes it loop forever, so the lists are walked
    here first, each address visited at most once.
    """
    try:
        with open(path, "rb") as stream:
            return mdf_loop_in(stream, os.fstat(stream.fileno()).st_size)
    except OSError:
        return None


def mdf_loop_in(stream: IO[bytes], size: int) -> str | None:
    """:func:`_mdf_loop` on an open binary stream of ``size`` bytes (a file, or bytes)."""
    head = stream.read(64 + 32)
    if len(head) < 64 or not head.startswith(b"MDF"):
        return None  # not an MDF file asammdf can open; it says why itself
    major = chr(head[8]) if head[8:9].isdigit() else ""
    if major not in _MDF_LINKS:
        return None
    width, first, next_at, child_at = _MDF_LINKS[major]
    # MDF 3 declares its byte order in the identification block; MDF 4 is little-endian.
    big = major == "3" and int.from_bytes(head[24:26], "little") != 0
    order = ">" if big else "<"
    code = "Q" if width == 8 else "I"

    def link(address: int) -> int:
        if address <= 0 or address + width > size:
            return 0
        return int(struct.unpack(order + code, _read_at(stream, address, width))[0])

    seen: set[int] = set()
    # Each list: data groups (children: channel groups), channel groups (children:
    # channels), channels (no children followed here).
    pending = [(link(first), 0)]
    while pending:
        address, depth = pending.pop()
        while address:
            if address in seen:
                return f"the block at byte {address} is linked to twice (a loop)"
            if address >= size:
                break  # asammdf reports addresses past the end itself
            seen.add(address)
            if depth < 2:
                pending.append((link(address + child_at), depth + 1))
            address = link(address + next_at)
    return None


# MDF4 channel types whose samples sit in the group's records (value, VLSD offset, master,
# sync, VLSC offset); virtual and MLSD channels have no bytes of their own there.
_MDF4_RECORD_TYPES = (0, 1, 2, 4, 7)


def _check_mdf_record(path: str, version: str, group: Any) -> None:
    """Refuse a channel group whose channels reach past the end of its record.

    asammdf copies each channel out of the records in C without checking the channel's byte
    range against the record size; a damaged channel block (or record size) then corrupts the
    heap and the process aborts, so the file is refused before anything is read.
    """
    size = int(group.channel_group.samples_byte_nr)
    if version.startswith("4"):
        size += int(group.channel_group.invalidation_bytes_nr)
    # asammdf sizes its buffers by the record size and the record count, so one damaged
    # field (4 GB of invalidation bytes, or 10^9 records, in a 2 kB file) would exhaust the
    # memory before anything is read. Complete records never need more than the stored data
    # (decompressed sizes, so compressed files pass).
    stored = sum(int(getattr(block, "original_size", 0) or 0) for block in group.data_blocks)
    cycles = int(group.channel_group.cycles_nr)
    if size > stored and (stored or cycles):
        raise DataError(
            f"a record of {size} bytes is larger than the {stored} bytes of data holding it "
            "(file truncated or corrupt?)",
            file=path,
            hint="write the file again",
        )
    if size * cycles > stored:
        raise DataError(
            f"{cycles} records of {size} bytes need {size * cycles} bytes, but the file holds "
            f"{stored} bytes of data for them (file truncated or corrupt?)",
            file=path,
            hint="write the file again",
        )
    # MDF 3 has no block sizes: asammdf derives them from the record count, so a damaged count
    # (10^9 records in a 2 kB file) passed the check above and asked for tens of gigabytes.
    # Every block's stored bytes must lie inside the file.
    file_size = os.path.getsize(path)
    for block in group.data_blocks:
        stored_size = block.compressed_size if block.block_type else block.original_size
        end = int(block.address or 0) + int(stored_size or 0)
        if end > file_size:
            raise DataError(
                f"a data block ends at byte {end}, past the end of the {file_size}-byte file "
                "(file truncated or corrupt?)",
                file=path,
                hint="write the file again",
            )
    for channel in group.channels:
        bits = int(channel.bit_count)
        if version.startswith("4"):
            if int(channel.channel_type) not in _MDF4_RECORD_TYPES:
                continue
            start = 8 * int(channel.byte_offset) + int(channel.bit_offset)
        else:
            if getattr(channel, "component_addr", 0):
                continue
            start = int(channel.start_offset) + 8 * int(
                getattr(channel, "additional_byte_offset", 0)
            )
        # asammdf reads at least one byte even for a channel of 0 bits.
        end = -(-(start + max(bits, 1)) // 8)
        if end > size:
            raise DataError(
                f"channel {str(channel.name)!r} ends at byte {end} of a {size}-byte record "
                "(file truncated or corrupt?)",
                file=path,
                hint="write the file again",
            )
