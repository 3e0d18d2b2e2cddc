"""The diagnosis of one scored signal, as a result: where its error appears and what the
residual holds (:class:`~pytest_hevval.core.diagnosis.Diagnosis`)."""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from typing import Any

from ..core.diagnosis import Diagnosis
from .codec import plain_json

__all__ = ["SignalDiagnosis", "candidate_unit"]


@dataclass(frozen=True)
class SignalDiagnosis:
    """One signal of one spec diagnosed; ``diagnosis`` holds the numbers."""

    spec: str
    #: The signal whose residual was diagnosed.
    signal: str
    unit: str | None
    passed: bool
    #: The signal (path, level) where this signal's error appears, and every such origin.
    origin: tuple[str, int]
    origins: tuple[tuple[str, int], ...]
    diagnosis: Diagnosis
    #: The signal a failing test asked about, when a level below it was diagnosed instead.
    asked: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON form: the signal's fields, then every field of the diagnosis."""
        payload: dict[str, Any] = {
            "spec": self.spec,
            "signal": self.signal,
            "unit": self.unit,
            "passed": self.passed,
            "origin": {"path": self.origin[0], "level": self.origin[1]},
            "origins": [{"path": path, "level": level} for path, level in self.origins],
        }
        if self.asked is not None:
            payload["diagnosed"] = self.signal
        payload.update(asdict(self.diagnosis))
        found = plain_json(payload)
        assert isinstance(found, dict)
        return found


def candidate_unit(name: str, kind: str) -> str | None:
    """The unit in a logged column's name (``Heating Power CAN [kW]`` → ``kW``), per second for
    its derivative; None for a declared expression, whose unit the spec does not state."""
    base = name.removeprefix("d/dt ") if kind == "derivative" else name
    match = re.search(r"\[([^\]]+)\]\s*$", base)
    if match is None:
        return None
    return f"{match.group(1)}/s" if kind == "derivative" else match.group(1)
