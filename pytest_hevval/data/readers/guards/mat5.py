"""Byte-level checks of MAT v5 files before scipy reads them.

scipy segfaults on some damaged element tags and allocates gigabytes for damaged dimensions;
:func:`_mat5_problem` walks the elements on plain bytes and names what is wrong first.
"""

from __future__ import annotations

import mmap
import struct
import zlib

# MAT v5 data types: miINT8 … miUINT32, miSINGLE, miDOUBLE, miINT64, miUINT64 hold numbers;
# miMATRIX and miCOMPRESSED hold variables; miUTF8 … miUTF32 hold text. 0, 8, 10, 11 and
# anything above 18 are not defined.
_MAT5_NUMBERS = frozenset({1, 2, 3, 4, 5, 6, 7, 9, 12, 13})


_MAT5_MATRIX = 14


_MAT5_COMPRESSED = 15


_MAT5_TEXT = frozenset({16, 17, 18})


# Array classes (mxClass) by what follows flags, dimensions and name: cell, struct and object
# hold variables; char, sparse and the numeric classes 6–15 hold number (or text) elements.
_MAT5_CONTAINERS = frozenset({1, 2, 3})


_MAT5_CHAR = 4


_MAT5_SPARSE = 5


_MAT5_COMPLEX_FLAG = 0x800


def _mat5_elements(
    buffer: bytes, start: int, end: int, order: str, padded: bool
) -> list[tuple[int, int, int, int]]:
    """(position, type, body start, body size) of each element tag between start and end.

    A tag whose body runs past ``end`` ends the list, with a size of -1: scipy still reads
    what there is of it before it notices. A small element claiming more than 4 bytes ends it
    with a size of ``_MAT5_OVERSIZED``.
    """
    found = []
    position = start
    while position + 8 <= end:
        first, second = struct.unpack_from(order + "II", buffer, position)
        if first >> 16:
            # A small element packs its size into the upper half of the first word.
            kind, size, body, following = first & 0xFFFF, first >> 16, position + 4, position + 8
            if size > 4:
                # Cannot be: scipy would copy that many bytes out of a 4-byte slot.
                found.append((position, kind, body, _MAT5_OVERSIZED))
                break
        else:
            kind, size, body = first, second, position + 8
            following = body + size + ((-size) % 8 if padded else 0)
        if body + size > end:
            found.append((position, kind, body, -1))
            break
        found.append((position, kind, body, size))
        position = following
    return found


_MAT5_OVERSIZED = -2


# Element types scipy knows at the top level (and inside compressed variables), and inside
# an array.
_MAT5_IN_ARRAY = _MAT5_NUMBERS | _MAT5_TEXT | {_MAT5_MATRIX}


_MAT5_TOP_LEVEL = _MAT5_IN_ARRAY | {_MAT5_COMPRESSED}


def _mat5_count(buffer: bytes, dims: tuple[int, int, int, int], order: str) -> int | None:
    """The number of elements an array's dimensions element declares, if it is readable."""
    _, kind, body, size = dims
    if kind not in (5, 6) or size < 0 or size % 4:  # int32 or uint32 dimensions
        return None
    count = 1
    for value in struct.unpack_from(f"{order}{size // 4}{'i' if kind == 5 else 'I'}", buffer, body):
        count *= max(0, int(value))
    return count


def _mat5_tag_problem(
    elements: list[tuple[int, int, int, int]], known: frozenset[int]
) -> str | None:
    """A small element claiming more than 4 bytes, else the first type scipy does not know."""
    for position, _, _, size in elements:
        if size == _MAT5_OVERSIZED:
            return f"a small data element at byte {position} claims more than 4 bytes"
    for position, kind, _, _ in elements:
        if kind not in known:
            return f"undefined data type {kind} at byte {position}"
    return None


def _mat5_problem(path: str) -> str | None:
    """Describe the first element scipy.io.loadmat would read as numbers but cannot, if any.

    scipy looks element types up in a table without a bounds check and reads an array's parts
    one after the other without checking that they lie inside the array. An undefined type,
    or a variable where numbers should be (a complex flag on an array without an imaginary
    part makes scipy read the next variable's tag as one), then crashes the process with a
    segmentation fault instead of an exception. One damaged byte is enough for either.
    """
    with open(path, "rb") as stream:
        head = stream.read(128)
        if head and not head.strip(b"\x00"):
            # No MAT header of any version is NUL bytes; scipy would read a v4 file of empty
            # variables from them, as far as the file goes.
            return "the file starts with NUL bytes where a MAT header should be"
        if head[126:128] not in (b"IM", b"MI"):
            return None  # MAT v4, or not a MAT file: scipy tells
        # Mapped, not read: the walk touches the element tags, not the whole file.
        with mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return mat5_problem_in(data)  # type: ignore[arg-type]


def mat5_problem_in(data: bytes) -> str | None:
    """:func:`_mat5_problem` on the bytes of a MAT file."""
    if data[126:128] not in (b"IM", b"MI"):
        return None  # MAT v4, or not a MAT file: scipy tells
    order = ">" if data[126:128] == b"MI" else "<"
    # (buffer, start, end): the file's top level, or the body of a compressed variable.
    levels: list[tuple[bytes, int, int]] = [(data, 128, len(data))]
    # (buffer, body start, body end) of each matrix still to check
    matrices: list[tuple[bytes, int, int]] = []
    while levels or matrices:
        if levels:
            buffer, start, end = levels.pop()
            elements = _mat5_elements(buffer, start, end, order, False)
            problem = _mat5_tag_problem(elements, _MAT5_TOP_LEVEL)
            if problem:
                return problem
            for _, kind, body, size in elements:
                if kind == _MAT5_MATRIX:
                    matrices.append((buffer, body, body + size if size >= 0 else end))
                elif kind == _MAT5_COMPRESSED and size >= 0:
                    try:
                        inner = zlib.decompress(buffer[body : body + size])
                    except zlib.error:
                        continue  # scipy cannot decompress it either, and says so
                    levels.append((inner, 0, len(inner)))
                if size < 0:
                    break
            continue
        buffer, start, end = matrices.pop()
        parts = _mat5_elements(buffer, start, end, order, True)
        problem = _mat5_tag_problem(parts, _MAT5_IN_ARRAY)
        if problem:
            return problem
        if len(parts) < 3 or parts[0][1] != 6 or parts[0][3] < 4:
            continue  # no usable array flags: scipy rejects the variable itself
        flags = struct.unpack_from(order + "I", buffer, parts[0][2])[0]
        mx_class = flags & 0xFF
        if mx_class in _MAT5_CONTAINERS:
            # scipy makes the object array the dimensions ask for before reading its elements:
            # one damaged dimension asked for 8 GB in a 1 kB file. Every element needs a tag
            # of 8 bytes at least, so more elements than that cannot be there.
            count = _mat5_count(buffer, parts[1], order)
            if count is not None and count * 8 > end - start:
                return (
                    f"the cell or struct array at byte {parts[0][0] - 8} claims {count} "
                    f"elements in {end - start} bytes"
                )
            for _, kind, body, size in parts[3:]:
                if kind == _MAT5_MATRIX:
                    matrices.append((buffer, body, body + size if size >= 0 else end))
            continue
        if mx_class == _MAT5_SPARSE:
            needed = 6  # flags, dims, name, row indices, column indices, values
        elif mx_class == _MAT5_CHAR or 6 <= mx_class <= 15:
            needed = 4  # flags, dims, name, values
        else:
            continue  # function handles and opaque objects: scipy reads them differently
        if flags & _MAT5_COMPLEX_FLAG and mx_class != _MAT5_CHAR:
            needed += 1
        allowed = _MAT5_NUMBERS | (_MAT5_TEXT if mx_class == _MAT5_CHAR else frozenset())
        for position, kind, _, _ in parts[3:needed]:
            if kind not in allowed:
                return f"data type {kind} where numbers should be, at byte {position}"
        if len(parts) < needed or parts[needed - 1][3] < 0:
            position = parts[0][0]
            return f"the array at byte {position - 8} ends before all its parts"
    return None
