"""pytest collectors and items: a spec file, one item per signal node, one ``Phi`` item.

A campaign spec collects one :class:`Recording` per recording (``spec::TripB03::E_batt``), each
holding that recording's signal and ``Phi`` items, and one ``campaign`` item for its gate.

Items override only ``setup``/``runtest``/``repr_failure``/``reportinfo``. Unreadable data
fails in ``setup`` so that pytest reports an ERROR; a missed threshold fails in ``runtest``,
a FAILURE.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from _pytest._code.code import TerminalRepr

from ..core.registry import describe
from ..errors import HevvalError
from ..escape import terminal
from ..flags import PYTEST
from ..report.terminal import phi_report, runtime_report, signal_failure_report
from ..results.spec_result import SignalResult, SpecResult
from ..scoring.engine import Evaluation
from ..spec.load import load_spec
from ..spec.model import Spec
from .session import SPEC_ITEM_PLACE, HevvalSession
from .stash import session_key

__all__ = [
    "CampaignItem",
    "PhiItem",
    "Recording",
    "RuntimeItem",
    "SignalItem",
    "SpecFile",
    "carry_spec_items",
    "defer_campaign_gates",
]


#: JUnit ``<property>`` names that link an item to requirements: Xray's ``requirements``
#: (comma-separated issue keys) and the generic ``requirement``, one property per ID
#: (docs/reports.md, "Requirements in JUnit").
REQUIREMENTS_PROPERTY = "requirements"
REQUIREMENT_PROPERTY = "requirement"


def requirement_properties(requirements: list[str]) -> list[tuple[str, str]]:
    """The JUnit properties that carry ``requirements``, in the importers' conventions."""
    if not requirements:
        return []
    return [
        (REQUIREMENTS_PROPERTY, ",".join(requirements)),
        *((REQUIREMENT_PROPERTY, requirement) for requirement in requirements),
    ]


def junit_property(name: str) -> str:
    """``lambda3_mae`` for the paper's λ values, the bare name for any other characteristic."""
    symbol = describe(name).symbol
    return f"lambda{symbol[1:]}_{name}" if describe(name).builtin else name


class ThresholdMissed(Exception):
    """Raised by an item whose signal (or Φ) misses its gate; carries the report text."""


def _hevval_repr(excinfo: pytest.ExceptionInfo[BaseException]) -> str | None:
    if isinstance(excinfo.value, (HevvalError, ThresholdMissed)):
        return terminal(excinfo.value)
    return None


class SpecFile(pytest.File):
    """A ``*.hevval.yaml`` file."""

    spec: Spec

    def collect(self) -> Iterator[pytest.Item | pytest.Collector]:
        state = self.config.stash[session_key]
        self.spec = load_spec(self.path)
        spec = self.spec
        if spec.campaign is None:
            state.run.register(spec)
            yield from _spec_items(self, spec)
            return
        for recording in spec.per_recording():
            state.run.register(recording)
            name = terminal(recording.recording).replace("\n", "\\n")
            yield Recording.from_parent(self, name=name, spec=recording)
        yield CampaignItem.from_parent(self, name="campaign", spec=spec, line=spec.campaign.line)

    def repr_failure(  # type: ignore[override]
        self, excinfo: pytest.ExceptionInfo[BaseException]
    ) -> str | TerminalRepr:
        text = _hevval_repr(excinfo)
        return text if text is not None else super().repr_failure(excinfo)


def _spec_items(parent: pytest.Collector, spec: Spec) -> Iterator[pytest.Item]:
    for _, path, node in spec.walk():
        name = terminal("/".join(path)).replace("\n", "\\n")
        yield SignalItem.from_parent(parent, name=name, spec=spec, line=node.line)
    yield PhiItem.from_parent(parent, name="Phi", spec=spec, line=spec.min_phi_line)
    if spec.runtime.gated:
        yield RuntimeItem.from_parent(parent, name="runtime", spec=spec, line=spec.runtime.line)


class Recording(pytest.Collector):
    """One recording of a campaign: its signal items and its ``Phi`` item."""

    def __init__(self, *, spec: Spec, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.spec = spec

    def collect(self) -> Iterator[pytest.Item]:
        yield from _spec_items(self, self.spec)


class _SpecItem(pytest.Item):
    def __init__(self, *, spec: Spec, line: int, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.spec = spec
        self.line = line
        self.evaluation: Evaluation | None = None
        # JSON text for the xdist controller (see HevvalSession.ship).
        self.hevval_payload: str | None = None
        self.hevval_diagnosis: str | None = None
        #: On an xdist worker: the other items of this spec, judged with this one and reported
        #: by the controller from what this item's report carries (:func:`carry_spec_items`).
        self.carried: list[_SpecItem] = []
        self.carried_by: _SpecItem | None = None
        self.hevval_carried: str | None = None

    @property
    def state(self) -> HevvalSession:
        return self.config.stash[session_key]

    def setup(self) -> None:
        try:
            self.evaluation = self.state.evaluate(self.spec)
            return
        except HevvalError as exc:
            # In collection order, so that the spec's first item shows the error, as when
            # every item runs on its own (the items this one carries come before it).
            texts = {
                item.nodeid: terminal(self.state.error_once(self.spec.key, item.nodeid, exc))
                for item in [*self.carried, self]
            }
            message = texts[self.nodeid]
            if self.carried:
                self.hevval_carried = json.dumps(
                    [
                        outcome_of(item, "failed", "setup", texts[item.nodeid])
                        for item in self.carried
                    ]
                )
        # An ERROR (setup), shown as the message alone: the data, not the code, is at fault.
        # Outside the except block, so that pytest does not print it twice as a chain.
        pytest.fail(message, pytrace=False)

    def judge(self) -> None:
        """Pass, or raise :class:`ThresholdMissed` with the report text."""
        raise NotImplementedError

    def runtest(self) -> None:
        missed: ThresholdMissed | None = None
        try:
            self.judge()
        except ThresholdMissed as exc:
            missed = exc
        if self.carried:
            outcomes = []
            for item in self.carried:
                item.evaluation = self.evaluation
                try:
                    item.judge()
                    outcomes.append(outcome_of(item, "passed", "call", None))
                except ThresholdMissed as exc:
                    outcomes.append(outcome_of(item, "failed", "call", str(exc)))
            self.hevval_carried = json.dumps(outcomes)
        if missed is not None:
            raise missed

    @property
    def result(self) -> SpecResult:
        assert self.evaluation is not None
        return self.evaluation.result

    def _record(self, signal: SignalResult | None) -> None:
        result = self.result
        self.user_properties.extend(
            requirement_properties(result.requirements if signal is None else signal.requirements)
        )
        self.user_properties.append(("phi", f"{result.phi:.6f}"))
        if signal is None and result.runtime is not None:
            runtime = result.runtime
            self.user_properties += [
                ("model_wall_s", f"{runtime.wall_median_s:.6g}"),
                ("model_cpu_s", f"{runtime.cpu_median_s:.6g}"),
                ("realtime_factor", f"{runtime.realtime_factor:.6g}"),
            ]
        if signal is not None:
            for name, value in signal.lambdas.items():
                self.user_properties.append((junit_property(name), f"{value:.6f}"))
            self.user_properties.append(("lag_s", f"{signal.lag_s:.6g}"))
        payload = self.state.ship(result)
        self.hevval_payload = payload

    def reportinfo(self) -> tuple[Path, int, str]:
        return self.path, max(self.line - 1, 0), f"{SPEC_ITEM_PLACE}{self.spec.name}: {self.name}"

    def repr_failure(
        self,
        excinfo: pytest.ExceptionInfo[BaseException],
        style: Any = None,
    ) -> str | TerminalRepr:
        text = _hevval_repr(excinfo)
        return text if text is not None else super().repr_failure(excinfo, style=style)


class SignalItem(_SpecItem):
    """One validation signal γ(i, j, k): passes when every gated λ meets its threshold."""

    def judge(self) -> None:
        result = self.result
        signal = result.signal(self.name)
        self._record(signal)
        if signal.within_uncertainty:
            # Passing by the spec's choice; the misses stay visible in the JUnit XML too.
            self.user_properties.append(
                (
                    "within_measurement_uncertainty",
                    ",".join(f.characteristic for f in signal.within_uncertainty),
                )
            )
        diagnosis = self.state.diagnosis_for(self.evaluation, signal)
        if diagnosis is not None:
            self.hevval_diagnosis = self.state.keep_diagnosis(diagnosis)
        if not signal.passed:
            line = diagnosis.get("summary") if diagnosis else None
            target = diagnosis.get("diagnosed") if diagnosis else None
            raise ThresholdMissed(
                signal_failure_report(result, signal, diagnosis_line=line, diagnose_target=target)
            )
        _raise_regressions(self.state.regressions_for(result, signal.path), self.name)


class PhiItem(_SpecItem):
    """The spec's global validation metric Φ against ``min_phi``."""

    def judge(self) -> None:
        result = self.result
        self._record(None)
        if not result.phi_passed:
            raise ThresholdMissed(phi_report(result))
        _raise_regressions(self.state.regressions_for(result, None), "Φ")


class RuntimeItem(_SpecItem):
    """The model's runtime on the recording against the spec's ``runtime:`` gate."""

    def judge(self) -> None:
        result = self.result
        self._record(None)
        runtime = result.runtime
        if runtime is not None and not runtime.passed:
            raise ThresholdMissed(runtime_report(result, self.line))


def _raise_regressions(found: list[str], what: str) -> None:
    if found:
        raise ThresholdMissed(
            f"{what} got worse than the baseline by more than {PYTEST.flag('compare-fail')} "
            "allows:\n"
            + "\n".join(f"  {line}" for line in found)
            + "\n  next: fix the model, or, if the change is intended, accept it as the new "
            f"baseline with a run given {PYTEST.flag('accept')}"
        )


class CampaignItem(_SpecItem):
    """The campaign's gate over its validation recordings (calibration ones never count)."""

    def setup(self) -> None:
        self.outcomes: dict[str, Evaluation | HevvalError] = {}
        for recording in self.spec.per_recording():
            try:
                self.outcomes[str(recording.recording)] = self.state.evaluate(recording)
            except HevvalError as exc:
                self.outcomes[str(recording.recording)] = exc

    def runtest(self) -> None:
        results = [o.result for o in self.outcomes.values() if isinstance(o, Evaluation)]
        # Every recording's result reaches the controller, even those deselected with -k.
        shipped = [self.state.ship(result) for result in results]
        self.hevval_campaign = [payload for payload in shipped if payload is not None]
        pass_rate, failure = self.state.run.judge_campaign(
            {
                name: o.result if isinstance(o, Evaluation) else o
                for name, o in self.outcomes.items()
            }
        )
        self.user_properties.extend(requirement_properties(list(self.spec.requirements)))
        if pass_rate is not None:
            self.user_properties.append(("pass_rate", f"{pass_rate:.6f}"))
        if failure is not None:
            raise ThresholdMissed(failure)


def outcome_of(item: _SpecItem, outcome: str, when: str, text: str | None) -> dict[str, Any]:
    """What the controller needs to report ``item`` as pytest would have (see
    ``session.log_outcome``): JSON data."""
    fspath, lineno, domain = item.location
    return {
        "nodeid": item.nodeid,
        "location": [fspath, lineno, domain],
        "keywords": sorted(item.keywords),
        "outcome": outcome,
        "when": when,
        "longrepr": text,
        "user_properties": [[str(k), str(v)] for k, v in item.user_properties],
        "diagnosis": item.hevval_diagnosis,
    }


def carry_spec_items(items: list[pytest.Item]) -> None:
    """On an xdist worker: the last selected item of each spec (or campaign recording) judges
    the spec's other items with it, and the controller reports them from its report; the
    others are passed over (``pytest_runtest_protocol``).

    A spec's items are judged from one evaluation, so running each as its own pytest item only
    adds pytest's work per item, and under xdist three reports per item crossing to the
    controller: for a campaign of thousands of signals, more than the scoring itself. They
    stay in the collection, so that counts, progress and the scheduler see every item. The
    carrier is a spec's last item: the items it carries come before it in the worker's queue,
    and pytest's setup of the spec's collectors is made and torn down around it alone.
    """
    groups: dict[str, list[_SpecItem]] = {}
    for item in items:
        if isinstance(item, (SignalItem, PhiItem, RuntimeItem)):
            groups.setdefault(item.spec.key, []).append(item)
    for *carried, carrier in groups.values():
        carrier.carried = carried
        for item in carried:
            item.carried_by = carrier


def defer_campaign_gates(items: list[pytest.Item], state: HevvalSession) -> list[pytest.Item]:
    """On an xdist worker: the items without the campaign gates, which the controller judges
    once every worker has scored its share of the recordings (``deferred_gate``)."""
    kept: list[pytest.Item] = []
    gates: list[dict[str, Any]] = []
    for item in items:
        if isinstance(item, CampaignItem):
            fspath, lineno, domain = item.location
            gates.append(
                {
                    "nodeid": item.nodeid,
                    "location": [fspath, lineno, domain],
                    "keywords": sorted(item.keywords),
                    "recordings": [state.relative(r.key) for r in item.spec.per_recording()],
                    # The campaign verifies the spec's own requirements as a whole.
                    "properties": [
                        list(p) for p in requirement_properties(list(item.spec.requirements))
                    ],
                }
            )
        else:
            kept.append(item)
    if gates:
        state.defer(gates)
    return kept
