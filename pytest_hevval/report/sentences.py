"""Results in sentences: a missed threshold in physical units, a window or cell gate missed,
where the error lies. The terminal, the failure reports and the HTML report all say it so."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from ..core.measurement import ERROR_CHARACTERISTICS
from ..core.registry import describe
from ..core.uncertainty import value_text
from ..defaults import UNCERTAINTY_SIGMA
from ..results.campaign import CampaignVerdict, campaign_of, campaign_verdicts
from ..results.codec import number_or_nan
from ..results.local_tables import NAMED_GROUPS, LocalFailure
from ..results.measurement import ErrorCheck
from ..results.spec_result import Failure, SignalResult, SpecResult
from ..results.verdict import RunVerdict

__all__ = [
    "failure_lines",
    "failure_sentence",
    "failure_text",
    "lag_bound_text",
    "lag_text",
    "local_failure_text",
    "outcome_line",
    "verdict_line",
    "where_lines",
    "within_uncertainty_lines",
]


def _quantity(value: float, unit: str | None) -> str:
    return f"{value:.3g}" + (f" {unit}" if unit else "")


def failure_sentence(
    title: str,
    characteristic: str,
    value: float,
    threshold: float,
    check: ErrorCheck,
    unit: str | None,
) -> str:
    """``λ4 RMS = 0.9412 < 0.95: RMS 1.23 kW is 0.21 kW over its limit 1.02 kW; …``.

    ``title`` is the characteristic's heading (``λ4 RMS``), ``characteristic`` its name.
    """
    _, label = ERROR_CHARACTERISTICS.get(characteristic, ("", "error"))
    text = (
        f"{title} = {value:.4f} < {threshold:.4g}: {label} {_quantity(check.error, unit)} is "
        f"{_quantity(check.margin, unit)} over its limit {_quantity(check.limit, unit)}"
    )
    if check.uncertainty is None:
        return text
    sigma = check.sigma if check.sigma is not None else UNCERTAINTY_SIGMA
    verdict = "within" if check.within else "beyond"
    return (
        f"{text}; measurement uncertainty ±{_quantity(check.uncertainty, unit)} ({sigma:g}σ): "
        f"{verdict} measurement uncertainty"
    )


def failure_text(failure: Failure, unit: str | None) -> str | None:
    """The miss in the signal's unit and against the measurement uncertainty, if known."""
    if failure.check is None:
        return None
    return failure_sentence(
        describe(failure.characteristic).title,
        failure.characteristic,
        failure.value,
        failure.threshold,
        failure.check,
        unit,
    )


def local_failure_text(failure: LocalFailure, title: str) -> str:
    """A window or cell gate missed: how many groups, how badly, and the worst by name."""
    noun = "windows" if failure.scope == "windows" else "cells"
    named = ", ".join(failure.where[:NAMED_GROUPS])
    more = (
        f" (+{len(failure.where) - NAMED_GROUPS} more)" if len(failure.where) > NAMED_GROUPS else ""
    )
    need = "every one" if failure.required_share >= 1.0 else f"{failure.required_share:.0%} needed"
    return (
        f"{title} ≥ {failure.threshold:.4g} missed in {len(failure.where)} of {failure.judged} "
        f"{noun} ({failure.passed}/{failure.judged} pass, {need}): worst {failure.value:.4f}; "
        f"{named}{more}"
    )


def lag_bound_text(found: Mapping[str, Any]) -> str:
    """What a lag on the edge of its search means, and the spec change that widens the search.

    ``found`` holds ``lag_at_bound`` and ``max_lag_s`` (a signal's JSON entry, its
    characteristics' ``as_dict``, or a diagnosis payload), and optionally ``n_samples`` and
    ``dt``: the search reaches at most a quarter of the record. '' for a lag inside the search.
    """
    if not found.get("lag_at_bound"):
        return ""
    width = number_or_nan(found.get("max_lag_s"))
    text = f"on the edge of the ±{width:g} s search, so the peak may lie beyond it"
    if not math.isfinite(width) or width <= 0:
        return text
    n, dt = found.get("n_samples"), number_or_nan(found.get("dt"))
    quarter = int(n) // 4 * dt if isinstance(n, int) and math.isfinite(dt) else math.inf
    wider = min(2 * width, quarter)
    if wider > width * (1 + 1e-9):
        return f"{text}: widen it in the spec, alignment: {{max_lag_s: {wider:.4g}}}"
    return (
        f"{text}; the search already spans a quarter of the record, so shift the model's "
        "time in the spec (alignment: {offset_s: …}) or score a longer record"
    )


def lag_text(errors: Mapping[str, Any]) -> str:
    """The lag and the correlation at it, as every output of a scored signal words them.

    ``lag −5 s, where the mean-removed correlation peaks: 0.9912 (0.9880 at zero lag); on the
    edge of the ±5 s search, …``. The correlation is ρ of :mod:`pytest_hevval.core.lag`, which
    the lag maximises, so the value at the lag is never below the one at zero lag. ``errors``
    is a signal's JSON entry or its characteristics' ``as_dict``.
    """
    lag = number_or_nan(errors.get("lag_s"))
    peak = number_or_nan(errors.get("peak_correlation"))
    zero = number_or_nan(errors.get("correlation_at_zero_lag"))
    text = f"lag {lag:+.3g} s, where the mean-removed correlation peaks: {peak:.4f}"
    if math.isfinite(zero):
        text += f" ({zero:.4f} at zero lag)"
    bound = lag_bound_text(errors)
    return f"{text}; {bound}" if bound else text


def failure_lines(signal: SignalResult) -> list[str]:
    """Each characteristic below its threshold, with the physical error behind it."""
    errors = signal.characteristics.as_dict()
    lines = []
    for failure in signal.failures:
        measured = failure_text(failure, signal.unit)
        if measured is not None and failure.check and failure.check.uncertainty is not None:
            lines.append(measured)
            continue
        characteristic = describe(failure.characteristic)
        meaning = characteristic.explain(errors, signal.unit)
        parts = signal.components.get(failure.characteristic)
        if not meaning and parts:
            meaning = ", ".join(f"{k} {v:.4g}" for k, v in parts.items())
        value = value_text(failure.value, signal.intervals.get(failure.characteristic))
        lines.append(
            f"{characteristic.title} = {value} < {failure.threshold:.4g}"
            + (f" ({meaning})" if meaning else "")
        )
    for local in signal.local_failures:
        lines.append(local_failure_text(local, describe(local.characteristic).title))
    return lines


def within_uncertainty_lines(signal: SignalResult) -> list[str]:
    """Thresholds missed within the measurement uncertainty that pass by the spec's choice."""
    return [
        f"{failure_text(f, signal.unit) or describe(f.characteristic).title}; passes by "
        "measurement.within_uncertainty: pass"
        for f in signal.within_uncertainty
    ]


def where_lines(signal: SignalResult) -> list[str]:
    """Where and when the error lies: its concentration and the worst windows."""
    if signal.local is None:
        return []
    lines = [f"where: {signal.local.concentration.get('sentence', '')}"]
    worst = signal.local.worst_windows()
    if worst:
        windows = signal.local.windows
        lines.append(
            "worst windows: "
            + ", ".join(f"{windows.labels[k]} ({windows.error_share[k]:.0%} of Σe²)" for k in worst)
        )
    return lines


def outcome_line(
    results: Sequence[SpecResult],
    verdicts: Sequence[CampaignVerdict] | None = None,
    regressed: Mapping[str, frozenset[str | None]] | None = None,
) -> str:
    """The run's outcome in one line, counted as pytest counts items (a signal, a Φ, a campaign
    gate) and by spec file, so that the terminal, the reports and the docs say one count.

    ``14 spec files, 3 pass; 161 items, 40 fail: 38 of 137 signals, 1 of 23 Φ, 1 of 1
    campaign gate``. A recording of a campaign is a spec of its own (its signals and its Φ);
    its file passes when every recording and the campaign gate do. ``verdicts``: the
    campaigns' verdicts of ``results`` where the caller has them already. ``regressed``: the
    items a regression against the baseline fails, by spec (signal paths, None for Φ), as
    :attr:`~pytest_hevval.results.verdict.RunVerdict.regressed` gives them.
    """
    by_spec = {v.spec: v for v in (campaign_verdicts(results) if verdicts is None else verdicts)}
    regressed = regressed or {}
    files: dict[str, bool] = {}
    failed_signals = failed_phi = by_regression = signal_count = 0
    for result in results:
        worse = regressed.get(result.spec, frozenset())
        key = campaign_of(result.spec)
        files[key] = files.get(key, True) and result.passed and not worse
        for signal in result.signals:
            signal_count += 1
            failed_signals += not signal.passed or signal.path in worse
            by_regression += signal.passed and signal.path in worse
        failed_phi += not result.phi_passed or None in worse
        by_regression += result.phi_passed and None in worse
    for key, verdict in by_spec.items():
        files[key] = files.get(key, True) and verdict.passed
    failed_gates = sum(not v.passed for v in by_spec.values())
    timed = [r.runtime for r in results if r.runtime is not None and r.runtime.gate is not None]
    failed_runtimes = sum(not runtime.passed for runtime in timed)
    items = signal_count + len(results) + len(by_spec) + len(timed)
    failed = failed_signals + failed_phi + failed_gates + failed_runtimes
    counts = [
        f"{failed_signals} of {signal_count} signal{'s' * (signal_count != 1)}",
        f"{failed_phi} of {len(results)} Φ",
    ]
    if by_spec:
        counts.append(f"{failed_gates} of {len(by_spec)} campaign gate{'s' * (len(by_spec) != 1)}")
    if timed:
        counts.append(f"{failed_runtimes} of {len(timed)} runtime gate{'s' * (len(timed) != 1)}")
    passing_files = sum(files.values())
    cause = f" ({by_regression} by regression)" if by_regression else ""
    return (
        f"{len(files)} spec file{'s' * (len(files) != 1)}, {passing_files} pass; "
        f"{items} items, {failed} fail{cause}: " + ", ".join(counts)
    )


def verdict_line(
    results: Sequence[SpecResult],
    verdict: RunVerdict,
    verdicts: Sequence[CampaignVerdict] | None = None,
) -> str:
    """The run's verdict in one line: what failed it beyond the counts (regressions against
    the baseline, specs that could not be scored), then :func:`outcome_line`.

    ``1 regression against v1 (commit 3f2a9c1, 2026-11-28 22:10 UTC); 1 spec file, 0 pass;
    6 items, 1 fail (1 by regression): 1 of 5 signals, 0 of 1 Φ``.
    """
    parts = []
    if verdict.regressions:
        count = len(verdict.regressions)
        against = f" against {verdict.baseline}" if verdict.baseline else ""
        accepted = " (accepted: --hevval-accept)" if verdict.regressions_accepted else ""
        parts.append(f"{count} regression{'s' * (count != 1)}{against}{accepted}")
    if verdict.errors:
        count = len(verdict.errors)
        parts.append(f"{count} spec{'s' * (count != 1)} could not be scored")
    if verdicts is None and verdict.campaigns:
        verdicts = verdict.campaigns
    return "; ".join([*parts, outcome_line(results, verdicts, verdict.regressed)])
