"""Shared vocabulary of the history package: its error class and field names."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..core.characteristics import CHARACTERISTICS
from ..results.record_schema import HistoryError
from ..results.spec_result import PHYSICAL_ERRORS

__all__ = [
    "CHARACTERISTICS",
    "ERROR_FIELDS",
    "HistoryError",
    "spec_key",
]

#: Physical error quantities carried by every signal result (the results' own list).
ERROR_FIELDS: tuple[str, ...] = PHYSICAL_ERRORS


def spec_key(spec: Mapping[str, Any]) -> str:
    """Identity of a spec across runs: its file path when known, else its name."""
    key = spec.get("spec") or spec.get("name")
    return str(key) if key is not None else "?"
