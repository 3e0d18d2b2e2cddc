"""The verdict over a campaign: one spec scored on many recordings.

Pure aggregation of the recordings' :class:`~pytest_hevval.results.spec_result.SpecResult`
objects, so the pytest item, the terminal summary and the reports
give the same verdict from the same data.
Calibration recordings (the ones the model was fitted on) are shown but never count toward the
gate: a model always matches the data it was fitted to.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.uncertainty import Interval, value_text
from ..core.upooling import area_to_uniform, pool
from ..defaults import split_key
from .codec import json_number
from .spec_result import SpecResult

__all__ = [
    "WORST_SHOWN",
    "CampaignVerdict",
    "Distribution",
    "RecordingOutcome",
    "campaign_of",
    "campaign_verdicts",
    "phi_quantile",
    "verdict",
]

#: How many of the lowest-scoring recordings a verdict names.
WORST_SHOWN = 3

#: The quantiles a distribution over recordings is summarised by.
SUMMARY_QUANTILES = (0.1, 0.5, 0.9)


def campaign_of(spec_key: str) -> str:
    """The campaign's spec path in a recording's result key (``spec.yaml::TripB03``)."""
    return split_key(spec_key)[0]


def phi_quantile(phis: Sequence[float], q: float) -> float:
    """The q-quantile of Φ as an observed value: at most a share q of recordings lie below."""
    return float(np.quantile(np.asarray(phis, dtype=np.float64), q, method="inverted_cdf"))


@dataclass(frozen=True)
class Distribution:
    """A value over the counted recordings: its least, quantiles and greatest."""

    minimum: float
    quantiles: dict[float, float]
    maximum: float

    @classmethod
    def of(cls, values: Sequence[float]) -> Distribution:
        finite = [v for v in values if math.isfinite(v)]
        if not finite:
            return cls(math.nan, {q: math.nan for q in SUMMARY_QUANTILES}, math.nan)
        return cls(
            min(finite),
            {q: phi_quantile(finite, q) for q in SUMMARY_QUANTILES},
            max(finite),
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "min": json_number(self.minimum),
            **{f"q{round(q * 100):02d}": json_number(v) for q, v in self.quantiles.items()},
            "max": json_number(self.maximum),
        }


@dataclass(frozen=True)
class RecordingOutcome:
    id: str
    role: str
    phi: float
    passed: bool
    #: The recording's measured data file: the hash used and its digest.
    hash: str
    digest: str
    failed_signals: tuple[str, ...]
    #: Φ's 95 % bootstrap interval (None when the run had intervals off).
    phi_interval: Interval | None = None
    #: The recording's ``min_phi`` (None when its spec has none).
    min_phi: float | None = None

    @property
    def phi_text(self) -> str:
        """``0.9257 [0.9190, 0.9311]``, or the bare value where no interval is known."""
        return value_text(self.phi, self.phi_interval)

    @property
    def within_noise(self) -> bool:
        """Whether ``min_phi`` lies inside Φ's interval: noise alone could flip the Φ gate."""
        interval, minimum = self.phi_interval, self.min_phi
        return (
            interval is not None and minimum is not None and interval.low < minimum <= interval.high
        )


@dataclass
class CampaignVerdict:
    """Every figure of one campaign; ``failures`` says why its gate fails (empty: it passes)."""

    spec: str
    name: str
    recordings: list[RecordingOutcome]
    #: Recordings of the campaign with no result (unreadable data, or not run).
    missing: list[str]
    min_pass_rate: float | None
    phi_quantile: tuple[float, float] | None
    phi: Distribution
    lambdas: dict[str, Distribution]
    #: Share of the counted recordings in which each signal passes, by signal path.
    signal_pass_rates: dict[str, float]
    #: u-pooling area per signal over the counted recordings (0 best, 0.5 worst).
    pooled_area: dict[str, float]
    failures: list[str] = field(default_factory=list)
    #: Model output files that follow the campaign's pattern but no recording's id.
    unused_models: list[str] = field(default_factory=list)

    @property
    def counted(self) -> list[RecordingOutcome]:
        return [r for r in self.recordings if r.role != "calibration"]

    @property
    def excluded(self) -> list[str]:
        return [r.id for r in self.recordings if r.role == "calibration"]

    @property
    def pass_rate(self) -> float:
        counted = self.counted
        return sum(r.passed for r in counted) / len(counted) if counted else math.nan

    @property
    def worst(self) -> list[RecordingOutcome]:
        return sorted(self.counted, key=lambda r: (r.passed, r.phi))[:WORST_SHOWN]

    @property
    def within_noise(self) -> list[RecordingOutcome]:
        """Validation recordings whose Φ interval holds ``min_phi``: their Φ verdict is noise."""
        return [r for r in self.counted if r.within_noise]

    @property
    def passed(self) -> bool:
        return not self.failures

    def to_dict(self) -> dict[str, Any]:
        return {
            "spec": self.spec,
            "name": self.name,
            "passed": self.passed,
            "failures": list(self.failures),
            "pass_rate": json_number(self.pass_rate),
            "min_pass_rate": self.min_pass_rate,
            "phi_quantile": list(self.phi_quantile) if self.phi_quantile else None,
            "excluded": self.excluded,
            "missing": list(self.missing),
            "unused_models": list(self.unused_models),
            "worst": [r.id for r in self.worst],
            "within_noise": [r.id for r in self.within_noise],
            "phi": self.phi.to_dict(),
            "lambdas": {name: d.to_dict() for name, d in self.lambdas.items()},
            "signal_pass_rates": dict(self.signal_pass_rates),
            "pooled_area": {k: json_number(v) for k, v in self.pooled_area.items()},
            "recordings": [
                {
                    "id": r.id,
                    "role": r.role,
                    "phi": json_number(r.phi),
                    **(
                        {"phi_interval": {"low": r.phi_interval.low, "high": r.phi_interval.high}}
                        if r.phi_interval is not None
                        else {}
                    ),
                    "within_noise": r.within_noise,
                    "passed": r.passed,
                    "hash": r.hash,
                    "digest": r.digest,
                    "failed_signals": list(r.failed_signals),
                }
                for r in self.recordings
            ],
        }


def _identity(result: SpecResult) -> tuple[str, str]:
    """(hash, digest) of a recording's measured data file; empty when it was not hashed."""
    reference = result.data.reference
    return (reference.identity if reference is not None else None) or ("", "")


def _mean_lambda(result: SpecResult, name: str) -> float:
    """α-weighted mean of one characteristic over a recording's signals (Φ's own weighting)."""
    weighted = [(s.alpha, s.lambdas[name]) for s in result.signals if name in s.lambdas]
    total = sum(alpha for alpha, _ in weighted)
    return sum(alpha * value for alpha, value in weighted) / total if total > 0 else math.nan


def verdict(results: Sequence[SpecResult]) -> CampaignVerdict:
    """The verdict over the recordings of one campaign (results of the same campaign spec)."""
    if not results:
        raise ValueError("a campaign verdict needs at least one recording's result")
    first = results[0]
    campaign = first.campaign
    by_id = {r.recording or r.spec: r for r in results}
    listed = campaign.recordings if campaign is not None else None
    declared = [str(r) for r in (listed if listed is not None else by_id)]
    outcomes = [
        RecordingOutcome(
            id=recording,
            role=result.role,
            phi=result.phi,
            passed=result.passed,
            hash=_identity(result)[0],
            digest=_identity(result)[1],
            failed_signals=tuple(s.path for s in result.signals if not s.passed),
            phi_interval=result.phi_interval,
            min_phi=result.min_phi,
        )
        for recording in declared
        if (result := by_id.get(recording)) is not None
    ]
    counted = [by_id[o.id] for o in outcomes if o.role != "calibration"]
    names = [name for name in first.weights if any(name in s.lambdas for s in first.signals)]
    paths = [s.path for s in first.signals]
    quantile = campaign.phi_quantile if campaign is not None else None
    found = CampaignVerdict(
        spec=campaign_of(first.spec),
        name=str(
            campaign.name if campaign is not None and campaign.name is not None else first.name
        ),
        recordings=outcomes,
        missing=[r for r in declared if r not in by_id],
        min_pass_rate=campaign.min_pass_rate if campaign is not None else None,
        phi_quantile=(float(quantile[0]), float(quantile[1])) if quantile else None,
        phi=Distribution.of([r.phi for r in counted]),
        lambdas={n: Distribution.of([_mean_lambda(r, n) for r in counted]) for n in names},
        signal_pass_rates={path: _pass_rate(counted, path) for path in paths},
        pooled_area=_pooled_areas(counted, paths),
        unused_models=[str(p) for p in (campaign.unused_models if campaign is not None else ())],
    )
    found.failures = _gate_failures(found)
    return found


def _pass_rate(results: Sequence[SpecResult], path: str) -> float:
    if not results:
        return math.nan
    return sum(r.signal(path).passed for r in results) / len(results)


def _pooled_areas(results: Sequence[SpecResult], paths: Sequence[str]) -> dict[str, float]:
    areas: dict[str, float] = {}
    for path in paths:
        distributions = [
            r.signal(path).u_distribution
            for r in results
            if r.signal(path).u_distribution is not None
        ]
        if distributions:
            areas[path] = area_to_uniform(pool(distributions))  # type: ignore[arg-type]
    return areas


def _gate_failures(found: CampaignVerdict) -> list[str]:
    """Why the campaign's gate fails, one line per reason."""
    counted = found.counted
    failures: list[str] = []
    if found.missing:
        failures.append(
            "no result for "
            + ", ".join(found.missing)
            + " (deselected in this run, or their data or model failed: see their errors)"
        )
    gated = found.min_pass_rate is not None or found.phi_quantile is not None
    if gated and not counted:
        failures.append(
            "every recording is a calibration recording, so nothing validates the model"
        )
        return failures
    if found.min_pass_rate is not None and found.pass_rate < found.min_pass_rate:
        failed = [r.id for r in counted if not r.passed]
        failures.append(
            f"pass rate {found.pass_rate:.0%} < min_pass_rate {found.min_pass_rate:.0%} "
            f"({len(counted) - len(failed)} of {len(counted)} validation recordings pass; "
            f"failing: {', '.join(failed)})"
        )
    if found.phi_quantile is not None:
        q, minimum = found.phi_quantile
        value = phi_quantile([r.phi for r in counted], q)
        if not value >= minimum:
            failures.append(
                f"Φ {q:.0%}-quantile {value:.4f} < {minimum:.4g} "
                f"(more than {q:.0%} of validation recordings score below {minimum:.4g})"
            )
    return failures


def campaign_verdicts(results: Iterable[SpecResult]) -> list[CampaignVerdict]:
    """A verdict for every campaign among ``results`` (single-file specs are left out)."""
    groups: dict[str, list[SpecResult]] = {}
    for result in results:
        if result.recording is not None:
            groups.setdefault(campaign_of(result.spec), []).append(result)
    return [verdict(groups[key]) for key in sorted(groups)]
