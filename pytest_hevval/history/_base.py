"""Shared vocabulary of the history package: its error class, field names and JSON helpers."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ..core.characteristics import CHARACTERISTICS
from ..errors import HevvalError

__all__ = [
    "CHARACTERISTICS",
    "ERROR_FIELDS",
    "HistoryError",
    "json_safe",
    "optional_float",
    "spec_key",
]

#: Physical error quantities carried by every signal result, in the signal's unit (``lag_s`` in
#: seconds). Lower magnitude is better for all of them.
ERROR_FIELDS: tuple[str, ...] = ("lag_s", "mae", "rms", "delta_e", "error_std", "mean_error")


class HistoryError(HevvalError, ValueError):
    """A history record, history folder, comparison rule or threshold sidecar is unusable."""


def optional_float(value: Any, *, where: str, file: str | None = None) -> float | None:
    """Return ``value`` as a finite float, or ``None`` for null/NaN (JSON has no NaN)."""
    if value is None:
        return None
    numeric = isinstance(value, (int, float)) or _is_np_number(value)
    if isinstance(value, bool) or not numeric:
        raise HistoryError(
            f"expected a number or null (got {value!r})",
            file=file,
            key=where,
            hint="the file was not written by pytest-hevval or was edited by hand; "
            "restore it from version control or delete it",
        )
    number = float(value)
    return number if math.isfinite(number) else None


def _is_np_number(value: Any) -> bool:
    # numpy scalars arrive straight from the core; accept them without importing numpy here.
    return type(value).__module__ == "numpy" and hasattr(value, "item")


#: Where a value sits in the data, built as the copy descends: (parent, key), None at the top.
_Location = tuple[Any, str | int] | None


def json_safe(value: Any, *, where: str = "") -> Any:
    """Deep-copy ``value`` into plain JSON types; non-finite floats become ``None``.

    Strict JSON (``allow_nan=False``) keeps records readable by every JSON parser, so NaN from a
    degenerate signal is stored as ``null``.
    """
    return _copy(value, (None, where) if where else None)


def _copy(value: Any, location: _Location) -> Any:
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
                raise HistoryError(
                    f"mapping keys must be strings (got {key!r})",
                    key=_key_text(location),
                    hint="convert the result to plain JSON data before recording it",
                )
            out[key] = _copy(item, (location, key))
        return out
    if isinstance(value, (list, tuple)):
        return [_copy(item, (location, i)) for i, item in enumerate(value)]
    if isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):  # numpy's float64
        return value if math.isfinite(value) else None
    if _is_np_number(value):
        return _copy(value.item(), location)
    raise HistoryError(
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


def spec_key(spec: Mapping[str, Any]) -> str:
    """Identity of a spec across runs: its file path when known, else its name."""
    key = spec.get("spec") or spec.get("name")
    return str(key) if key is not None else "?"
