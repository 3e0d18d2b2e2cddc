"""What a report shows beside a signal's result: its diagnosis and its history trend.

Neither is part of the result: the diagnosis panel is made after scoring (on the worker that
scored the spec, or in the controller), and the trend is read from the run history by the
publisher. The writers take the typed results and these panels, so that a result is never
copied into a dict to carry them; report.json, the one writer that makes JSON, puts each panel
beside its signal's JSON (:meth:`SignalPanels.decorate`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..results.recorded import RecordedPoint
from ..results.spec_result import SignalResult, SpecResult

__all__ = ["SignalPanels"]

#: A signal's place in a run: its result's ``spec`` key and its path.
SignalKey = tuple[str, str]


@dataclass(frozen=True)
class SignalPanels:
    """Each signal's diagnosis payload and history trend, by (spec key, signal path)."""

    #: Diagnosis payloads (:func:`pytest_hevval.report.diagnosis_text.payload`, or why a signal
    #: could not be diagnosed), as :func:`pytest_hevval.publish.diagnosis_panels` keys them.
    diagnoses: Mapping[SignalKey, Mapping[str, Any]] = field(default_factory=dict)
    #: The recorded runs that hold each signal, oldest first.
    trends: Mapping[SignalKey, Sequence[RecordedPoint]] = field(default_factory=dict)
    #: This run's model version: the trend's last point.
    model_version: str = ""

    def diagnosis(self, result: SpecResult, signal: SignalResult) -> Mapping[str, Any] | None:
        """The signal's diagnosis: its own, else that of the first signal its error appears
        in, else the one its result carries."""
        found = self.diagnoses.get((result.spec, signal.path))
        if found is None and signal.origins:
            found = self.diagnoses.get((result.spec, signal.origins[0]))
        return found if found is not None else signal.diagnosis

    def history(self, result: SpecResult, signal: SignalResult) -> list[RecordedPoint] | None:
        """The signal's recorded runs, then this run; None where the history holds none."""
        recorded = self.trends.get((result.spec, signal.path))
        if not recorded:
            return None
        return [*recorded, RecordedPoint.of(self.model_version, result, signal)]

    def decorate(self, result: SpecResult, data: Mapping[str, Any]) -> dict[str, Any]:
        """``data`` (the JSON of ``result``) with each signal's diagnosis and trend beside it,
        as report.json holds it."""
        signals = []
        for signal, item in zip(result.signals, data["signals"], strict=True):
            entry = dict(item)
            found = self.diagnosis(result, signal)
            if found is not None:
                entry["diagnosis"] = dict(found)
            history = self.history(result, signal)
            if history is not None:
                entry["history"] = [point.to_dict() for point in history]
            signals.append(entry)
        return {**data, "signals": signals}
