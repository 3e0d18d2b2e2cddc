"""The diagnosis of one scored signal, as a result: where its error appears and what the
residual holds (:class:`~pytest_hevval.core.residual.Diagnosis`)."""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from ..core.residual import Diagnosis
from .codec import plain_json

__all__ = ["SignalAbove", "SignalDiagnosis", "candidate_unit"]


@dataclass(frozen=True)
class SignalAbove:
    """A signal above the diagnosed one whose simulated output is, in the model, the running
    integral of the one below it (an energy of its power): what each finding's fix, integrated
    the same way, does to it as the spec scores it."""

    signal: str
    unit: str | None
    #: It is ``per_second`` × the running integral of the signal below it (over seconds) plus
    #: a constant, on the scored samples: 1/3600 for kWh of a power in kW.
    per_second: float
    #: λ3 and λ4 (by characteristic name) as the spec scores it.
    lambdas: Mapping[str, float]
    #: Its λ3 and λ4 with each finding's fix in the model, by the finding's name.
    predicted: Mapping[str, Mapping[str, float]]


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
    #: The signals above whose λ the findings' fixes predict, nearest first, and why the walk
    #: up stopped short of the top (None when it did not, or the signal is at the top).
    above: tuple[SignalAbove, ...] = ()
    above_note: str | None = None

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
        payload["above"] = [asdict(item) for item in self.above]
        payload["above_note"] = self.above_note
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
