"""The run's one verdict, decided once (by :class:`pytest_hevval.run.Run`), and read by every
output: the terminal's last line, the Markdown summary's headline, report.json, report.html,
``hevval run``'s exit code (:attr:`RunVerdict.outcome`) and pytest's, when publishing failed.

A run fails when a spec misses a threshold or its Φ bound, when a campaign misses its pass
rate, when a spec could not be scored, or when a result got worse than the baseline by more
than ``compare-fail`` allows (unless the run accepts its regressions). The pytest items apply
the same rules one by one (a signal's thresholds, Φ, the campaign gate, the regressions of the
signal or Φ), so JUnit XML and pytest's exit code count the same failures.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from .campaign import CampaignVerdict, campaign_verdicts
from .spec_result import SpecResult

__all__ = ["Outcome", "RegressedItem", "RunVerdict"]


class Outcome(enum.Enum):
    """How a run ended, as an exit code says it."""

    #: Every spec scored and passed, and everything was published.
    PASSED = "passed"
    #: A gate failed, or a report or the history record could not be written.
    FAILED = "failed"
    #: A spec could not be scored (bad spec or unreadable data): the input is at fault.
    ERROR = "error"


@dataclass(frozen=True)
class RegressedItem:
    """One quantity that got worse than the baseline by more than a rule allows, on the item
    that reports it: a signal (``signal`` its path) or the spec's Φ (``signal`` None)."""

    spec: str
    signal: str | None
    #: ``phi``, ``lag`` or a characteristic's name.
    field: str
    text: str

    def to_dict(self) -> dict[str, Any]:
        return {"spec": self.spec, "signal": self.signal, "field": self.field, "text": self.text}


@dataclass(frozen=True)
class RunVerdict:
    """Whether the run passed, and what failed it beyond the results' own gates."""

    passed: bool
    #: Every regression against the baseline, in the order the results came.
    regressions: tuple[RegressedItem, ...] = ()
    #: The run accepts its regressions (``--hevval-accept``): listed, failing nothing.
    regressions_accepted: bool = False
    #: The baseline the run was compared with, in words (model version, commit, time).
    baseline: str | None = None
    #: Specs (or recordings) that could not be scored, each with its error's first line.
    errors: tuple[str, ...] = ()
    #: The items failed by a regression: spec → signal paths (None for Φ).
    regressed: Mapping[str, frozenset[str | None]] = field(default_factory=dict)
    #: A step of publishing failed (a report, the ratchet or the history record). Known only
    #: once the run is published, so the files the run wrote do not say it.
    publishing_failed: bool = False
    #: Each campaign's verdict over its recordings, as judged for this verdict.
    campaigns: tuple[CampaignVerdict, ...] = ()

    @property
    def outcome(self) -> Outcome:
        """An error when a spec could not be scored; else a failure when the gates or the
        publishing failed; else a pass."""
        if self.errors:
            return Outcome.ERROR
        return Outcome.PASSED if self.passed and not self.publishing_failed else Outcome.FAILED

    def published(self, *, failed: bool) -> RunVerdict:
        """This verdict, once publishing ran (``failed``: a step of it failed)."""
        return replace(self, publishing_failed=failed)

    @classmethod
    def decide(
        cls,
        results: Sequence[SpecResult],
        *,
        regressions: Sequence[RegressedItem] = (),
        regressions_accepted: bool = False,
        baseline: str | None = None,
        errors: Sequence[str] = (),
    ) -> RunVerdict:
        """The verdict of ``results``: the one rule every output reads."""
        failing = () if regressions_accepted else regressions
        regressed: dict[str, set[str | None]] = {}
        for item in failing:
            regressed.setdefault(item.spec, set()).add(item.signal)
        campaigns = tuple(campaign_verdicts(results))
        passed = (
            all(result.passed for result in results)
            and all(found.passed for found in campaigns)
            and not failing
            and not errors
        )
        return cls(
            passed=passed,
            regressions=tuple(regressions),
            regressions_accepted=regressions_accepted,
            baseline=baseline,
            errors=tuple(errors),
            regressed={spec: frozenset(signals) for spec, signals in regressed.items()},
            campaigns=campaigns,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "passed": self.passed,
            "baseline": self.baseline,
            "regressions": [item.to_dict() for item in self.regressions],
            "regressions_accepted": self.regressions_accepted,
            "errors": list(self.errors),
        }
