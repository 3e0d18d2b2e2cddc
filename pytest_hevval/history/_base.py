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


class _NotPlain(Exception):
    """A value :func:`_plain_copy` cannot store; :func:`json_safe` then finds where it is."""


def json_safe(value: Any, *, where: str = "") -> Any:
    """Deep-copy ``value`` into plain JSON types; non-finite floats become ``None``.

    Strict JSON (``allow_nan=False``) keeps records readable by every JSON parser, so NaN from a
    degenerate signal is stored as ``null``.
    """
    # A run's record holds tens of thousands of numbers: copy them without building the key
    # path of each, and build the paths only to name the key of a value that cannot be stored.
    try:
        return _plain_copy(value)
    except _NotPlain:
        return _located_copy(value, where)


def _plain_copy(value: Any) -> Any:
    kind = type(value)
    if kind is float:
        return value if math.isfinite(value) else None
    if kind is str or kind is int or kind is bool or value is None:
        return value
    if kind is dict:
        out: dict[str, Any] = {}
        for key, item in value.items():
            if type(key) is not str:
                raise _NotPlain
            out[key] = _plain_copy(item)
        return out
    if kind is list or kind is tuple:
        return [_plain_copy(item) for item in value]
    if isinstance(value, float):  # numpy's float64
        return float(value) if math.isfinite(value) else None
    raise _NotPlain  # other numpy scalars, other mappings, subclasses: the general copy


def _located_copy(value: Any, where: str) -> Any:
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if _is_np_number(value):
        return _located_copy(value.item(), where)
    if isinstance(value, Mapping):
        out: dict[str, Any] = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise HistoryError(
                    f"mapping keys must be strings (got {key!r})",
                    key=where or None,
                    hint="convert the result to plain JSON data before recording it",
                )
            out[key] = _located_copy(item, f"{where}.{key}" if where else key)
        return out
    if isinstance(value, (list, tuple)):
        return [_located_copy(item, f"{where}[{i}]") for i, item in enumerate(value)]
    raise HistoryError(
        f"cannot store a value of type {type(value).__name__} (got {value!r})",
        key=where or None,
        hint="results must be plain JSON data: numbers, strings, lists and mappings",
    )


def spec_key(spec: Mapping[str, Any]) -> str:
    """Identity of a spec across runs: its file path when known, else its name."""
    key = spec.get("spec") or spec.get("name")
    return str(key) if key is not None else "?"
