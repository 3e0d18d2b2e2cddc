"""Runs written as JSON in a test, read as a comparison reads them."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from pytest_hevval.results.recorded import RecordedRun

__all__ = ["recorded"]


def recorded(document: Mapping[str, Any] | Sequence[Mapping[str, Any]]) -> RecordedRun:
    """A history record or run document, or a list of spec results' JSON, as a recorded run."""
    if isinstance(document, Mapping):
        return RecordedRun.from_json(document)
    return RecordedRun.from_json({}, list(document))
