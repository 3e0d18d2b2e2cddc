"""Results to JSON data and back: the one place numbers cross into and out of JSON.

JSON has no NaN or infinity, and hevval writes strict JSON (``allow_nan=False``) so that every
parser reads its files: a value that is not a finite number is stored as ``null`` and read back
as NaN where a number is expected. numpy scalars and arrays become plain Python numbers.
"""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Mapping, Sequence
from pathlib import PurePath
from typing import Any, TypeGuard

from ..core.registry import PAPER_CHARACTERISTICS
from ..errors import HevvalError

__all__ = [
    "checked_number",
    "data_identity",
    "dumps",
    "finite_bounds",
    "interval_bounds",
    "interval_table",
    "is_finite_number",
    "json_number",
    "json_numbers",
    "keyed_lambdas",
    "lambdas_or_none",
    "number_or_nan",
    "plain_json",
]


def _is_numpy_number(value: Any) -> bool:
    # numpy scalars arrive straight from the core; accept them without importing numpy here.
    # An array has a shape of its own (a 0-d array is taken as its one number).
    return type(value).__module__ == "numpy" and getattr(value, "shape", None) == ()


def json_number(value: Any) -> float | None:
    """A finite number as a float; ``None`` for NaN, ±inf, ``None``, a bool or a non-number."""
    if value is None or isinstance(value, bool):
        return None
    if isinstance(value, (int, float)) or _is_numpy_number(value):
        number = float(value)
        return number if math.isfinite(number) else None
    return None


def json_numbers(values: Any) -> list[float | None]:
    """:func:`json_number` of every value of an array or sequence, in one vectorised step (a
    spec's window and cell tables hold hundreds of thousands of values)."""
    import numpy as np

    array = np.asarray(values, dtype=np.float64).ravel()
    out: list[float | None] = array.tolist()
    for index in np.flatnonzero(~np.isfinite(array)).tolist():
        out[index] = None
    return out


def is_finite_number(value: object) -> TypeGuard[float]:
    """A real, finite number (numpy scalars included, booleans not)."""
    if isinstance(value, float):
        return math.isfinite(value)
    return (
        isinstance(value, numbers.Real)
        and not isinstance(value, bool)
        and math.isfinite(float(value))
    )


def checked_number(
    value: Any, *, where: str, file: str | None = None, error: type[HevvalError] = HevvalError
) -> float | None:
    """``value`` read from a file that must hold a number or null: a finite float, or ``None``
    for null and NaN; anything else raises ``error`` naming the file and the key."""
    if value is None:
        return None
    if isinstance(value, bool) or not (isinstance(value, (int, float)) or _is_numpy_number(value)):
        raise error(
            f"expected a number or null (got {value!r})",
            file=file,
            key=where,
            hint="the file was not written by pytest-hevval or was edited by hand; "
            "restore it from version control or delete it",
        )
    return json_number(value)


def keyed_lambdas(raw: Any) -> dict[str, float | None]:
    """λ values keyed by name from plain data: a mapping, or a list in paper order (old files)."""
    if isinstance(raw, Mapping):
        return {str(k): _lenient_number(v) for k, v in raw.items()}
    if isinstance(raw, Sequence) and not isinstance(raw, str):
        if len(raw) > len(PAPER_CHARACTERISTICS):
            raise ValueError(
                f"expected at most {len(PAPER_CHARACTERISTICS)} values (got {len(raw)})"
            )
        return {
            name: _lenient_number(v) for name, v in zip(PAPER_CHARACTERISTICS, raw, strict=False)
        }
    return {}


def lambdas_or_none(raw: Any) -> dict[str, float | None]:
    """:func:`keyed_lambdas` for a reader that takes what it can: values it cannot place (a
    list longer than the paper's seven) read as none."""
    try:
        return keyed_lambdas(raw)
    except ValueError:
        return {}


def finite_bounds(low: Any, high: Any) -> tuple[float, float] | None:
    """(low, high) as floats; ``None`` where either is not a finite number (unknown)."""
    low, high = json_number(low), json_number(high)
    return None if low is None or high is None else (low, high)


def interval_bounds(raw: Any) -> tuple[float, float] | None:
    """(low, high) of a result's ``{"low": …, "high": …}`` interval; ``None`` where it is
    missing or either bound is not a finite number (``null``: unknown)."""
    if not isinstance(raw, Mapping):
        return None
    return finite_bounds(raw.get("low"), raw.get("high"))


def interval_table(raw: Any) -> dict[str, tuple[float, float]]:
    """The intervals of a mapping of name → ``{"low", "high"}`` that :func:`interval_bounds`
    reads, by name (a signal's λ intervals); empty where ``raw`` is no mapping."""
    if not isinstance(raw, Mapping):
        return {}
    return {
        str(name): bounds
        for name, raw_bounds in raw.items()
        if (bounds := interval_bounds(raw_bounds)) is not None
    }


def _lenient_number(value: Any) -> float | None:
    # Hand-edited old files may hold a number as text.
    if value is None or isinstance(value, bool):
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def number_or_nan(value: Any) -> float:
    """A number read from JSON: ``null`` (and anything not a finite number) is NaN."""
    number = json_number(value)
    return math.nan if number is None else number


#: Where a value sits in the data, built as the copy descends: (parent, key), None at the top.
_Location = tuple[Any, str | int] | None


def plain_json(
    value: Any, *, strict: bool = False, where: str = "", error: type[HevvalError] = HevvalError
) -> Any:
    """A deep copy of ``value`` in plain JSON types; non-finite floats become ``None``.

    Lenient (the default) for outputs: keys become text, paths POSIX text, numpy arrays lists,
    anything else its text. ``strict`` for records that are read back: a key that is not text,
    or a value that is not plain data, raises ``error`` naming its place (``where`` is the
    name of the top).
    """
    return _copy(value, (None, where) if where else None, strict, error)


def _copy(value: Any, location: _Location, strict: bool, error: type[HevvalError]) -> Any:
    # A run's record holds tens of thousands of numbers: the exact types come first, and a
    # value's key path is kept as linked pairs, joined into text only to name a bad value.
    kind = type(value)
    if kind is float:
        return value if math.isfinite(value) else None
    if kind is str or kind is int or kind is bool or value is None:
        return value
    if isinstance(value, Mapping):
        out: dict[str, Any] = {}
        for key, item in value.items():
            if not isinstance(key, str):
                if strict:
                    raise error(
                        f"mapping keys must be strings (got {key!r})",
                        key=_key_text(location),
                        hint="convert the result to plain JSON data before recording it",
                    )
                key = str(key)
            out[key] = _copy(item, (location, key), strict, error)
        return out
    if isinstance(value, (list, tuple)):
        return [_copy(item, (location, i), strict, error) for i, item in enumerate(value)]
    if isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):  # numpy's float64
        return value if math.isfinite(value) else None
    if _is_numpy_number(value):
        return _copy(value.item(), location, strict, error)
    if not strict:
        if isinstance(value, PurePath):
            return value.as_posix()
        tolist = getattr(value, "tolist", None)  # numpy arrays
        if callable(tolist):
            return _copy(tolist(), location, strict, error)
        return str(value)
    raise error(
        f"cannot store a value of type {type(value).__name__} (got {value!r})",
        key=_key_text(location),
        hint="results must be plain JSON data: numbers, strings, lists and mappings",
    )


def _key_text(location: _Location) -> str | None:
    """``specs[0].signals[2].x`` from the linked pairs, or None at the top."""
    keys: list[str | int] = []
    while location is not None:
        location, key = location
        keys.append(key)
    text = ""
    for key in reversed(keys):
        text = f"{text}[{key}]" if isinstance(key, int) else (f"{text}.{key}" if text else key)
    return text or None


def dumps(payload: Any, *, indent: int | None = 2) -> str:
    """Strict JSON text of plain data, keys sorted, ending in a newline.

    With ``indent``, mappings and lists of mappings take a line per item, and a list of
    numbers or text (or of short lists of them, as spans are) stays on one line: a spec's
    window and cell tables are columns of hundreds of thousands of numbers, which the standard
    library's indenting encoder (written in Python) took seconds to lay out one per line,
    where its C encoder writes each column at once.
    """
    if indent is None:
        return json.dumps(payload, sort_keys=True, allow_nan=False) + "\n"
    parts: list[str] = []
    _layout(payload, indent, 0, parts)
    parts.append("\n")
    return "".join(parts)


def _nested(items: Sequence[Any]) -> bool:
    """Whether a list takes a line per item: its first item is a mapping, or a list that holds
    containers (a list of spans stays on one line). The first item stands for the rest: the
    lists of a result hold one kind each, and the layout never changes what the text means."""
    if not items:
        return False
    first = items[0]
    if isinstance(first, (list, tuple)):
        return bool(first) and isinstance(first[0], (Mapping, list, tuple))
    return isinstance(first, Mapping)


def _layout(value: Any, indent: int, depth: int, out: list[str]) -> None:
    inner = "\n" + " " * (indent * (depth + 1))
    if isinstance(value, Mapping) and value and all(isinstance(k, str) for k in value):
        out.append("{")
        for i, key in enumerate(sorted(value)):
            out.append(("," if i else "") + inner + json.dumps(key) + ": ")
            _layout(value[key], indent, depth + 1, out)
        out.append("\n" + " " * (indent * depth) + "}")
    elif isinstance(value, (list, tuple)) and _nested(value):
        out.append("[")
        for i, item in enumerate(value):
            out.append(("," if i else "") + inner)
            _layout(item, indent, depth + 1, out)
        out.append("\n" + " " * (indent * depth) + "]")
    else:
        out.append(json.dumps(value, sort_keys=True, allow_nan=False))


def data_identity(entry: Mapping[str, Any]) -> tuple[str, str] | None:
    """(algorithm, digest) of a record's data entry, old (``sha256`` only) or new; None when
    the entry has no digest (a callable model, or an unreadable file)."""
    digest = entry.get("digest")
    if isinstance(digest, str) and digest:
        return str(entry.get("hash", "sha256")), digest
    old = entry.get("sha256")
    if isinstance(old, str) and old:
        return "sha256", old
    return None
