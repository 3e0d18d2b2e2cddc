"""Shared vocabulary of the history package: its error class and field names."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..core.characteristics import CHARACTERISTICS
from ..errors import HevvalError

__all__ = [
    "CHARACTERISTICS",
    "ERROR_FIELDS",
    "HistoryError",
    "spec_key",
]

#: Physical error quantities carried by every signal result, in the signal's unit (``lag_s`` in
#: seconds). Lower magnitude is better for all of them.
ERROR_FIELDS: tuple[str, ...] = ("lag_s", "mae", "rms", "delta_e", "error_std", "mean_error")


class HistoryError(HevvalError, ValueError):
    """A history record, history folder, comparison rule or threshold sidecar is unusable."""


def spec_key(spec: Mapping[str, Any]) -> str:
    """Identity of a spec across runs: its file path when known, else its name."""
    key = spec.get("spec") or spec.get("name")
    return str(key) if key is not None else "?"
