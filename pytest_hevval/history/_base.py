"""Shared vocabulary of the history package: its error class and field names."""

from __future__ import annotations

from ..core.characteristics import CHARACTERISTICS
from ..results.record_schema import HistoryError
from ..results.recorded import spec_key
from ..results.spec_result import PHYSICAL_ERRORS

__all__ = [
    "CHARACTERISTICS",
    "ERROR_FIELDS",
    "HistoryError",
    "spec_key",
]

#: Physical error quantities carried by every signal result (the results' own list).
ERROR_FIELDS: tuple[str, ...] = PHYSICAL_ERRORS
