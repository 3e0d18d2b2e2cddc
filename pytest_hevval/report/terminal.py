"""Text for people: failure reports of items and the signal-tree summary.

Pure functions over :mod:`pytest_hevval.results.spec_result` objects; no pytest, no I/O.
"""

from __future__ import annotations

import shlex
from collections.abc import Iterable, Sequence

from ..core.registry import describe
from ..results.campaign import CampaignVerdict
from ..results.runtime import ModelRuntime
from ..results.spec_result import SignalResult, SpecResult
from ..results.verdict import RunVerdict
from .model import campaigns_of
from .sentences import (
    failure_lines,
    failure_text,
    lag_text,
    outcome_line,
    verdict_line,
    where_lines,
    within_uncertainty_lines,
)

__all__ = [
    "measurement_notes",
    "phi_report",
    "run_summary",
    "signal_failure_report",
    "tree_summary",
    "verdict_lines",
]


def _location(spec: str, line: int) -> str:
    from ..defaults import split_key

    file, recording = split_key(spec)
    return f"{file}:{line}" + (f" (recording {recording})" if recording else "")


def signal_failure_report(
    result: SpecResult,
    signal: SignalResult,
    *,
    diagnosis_line: str | None = None,
    diagnose_target: str | None = None,
) -> str:
    lines = [
        f"{signal.path} missed its thresholds ({_location(result.spec, signal.line)})",
        f"  set {signal.set}, level {signal.level}, position {signal.position}, "
        f"α = {signal.alpha:g}",
    ]
    lines.extend(f"  {text}" for text in failure_lines(signal))
    lines.append(f"  {lag_text(signal.characteristics.as_dict())}")
    lines.extend(f"  {text}" for text in where_lines(signal))
    by_path = {s.path: s for s in result.signals}
    if signal.origins == [signal.path]:
        if signal.children:
            lines.append(
                f"  where the error appears: here, at level {signal.level}: the signals below "
                "it pass, so the error emerges where they combine"
            )
        else:
            lines.append(f"  where the error appears: here, at level {signal.level} (a leaf)")
    elif signal.origins:
        lines.append("  where the error appears:")
        for path in signal.origins:
            origin = by_path.get(path)
            level = f" (level {origin.level}, line {origin.line})" if origin else ""
            worst = ""
            if origin and origin.failures:
                first = min(origin.failures, key=lambda f: f.value - f.threshold)
                worst = f": {first.characteristic} {first.value:.4f} < {first.threshold:g}"
            lines.append(f"    {path}{level}{worst}")
    if diagnosis_line:
        lines.append(f"  diagnosis: {diagnosis_line}")
    target = diagnose_target or (signal.origins[0] if signal.origins else signal.path)
    lines.append(
        "  next: "
        + f"hevval diagnose {shlex.quote(result.spec)} --signal {shlex.quote(target)}"
        + " to trace the residual; fix the model, or adjust the thresholds in the spec"
    )
    return "\n".join(lines)


def _phi_gate(result: SpecResult) -> str:
    """``min_phi 0.9``, or ``min_phi 0.9 on the lower bound`` when a bound is judged."""
    if result.min_phi is None:
        return "no min_phi set"
    on = "" if result.min_phi_on == "value" else f" on the {result.min_phi_on} bound"
    return f"min_phi {result.min_phi:g}{on}"


def phi_report(result: SpecResult) -> str:
    gate = _phi_gate(result)
    lines = [
        f"Φ = {result.phi_text} < {gate} ({_location(result.spec, result.min_phi_line)})"
        if not result.phi_passed
        else f"Φ = {result.phi_text} ({gate})",
        "  signals that pull Φ down most (share of 1 − Φ):",
    ]
    deficit = max(1.0 - result.phi, 1e-12)
    for path, pull in result.phi_contributions()[:5]:
        signal = result.signal(path)
        worst = min(signal.lambdas, key=lambda name: signal.lambdas[name])
        lines.append(
            f"    {path}: {100 * pull / deficit:.0f} % (weakest {worst} "
            f"{signal.lambdas[worst]:.4f})"
        )
    lines.append("  next: improve the signals above, or run hevval diagnose on them")
    return "\n".join(lines)


def runtime_text(runtime: ModelRuntime | None, model_kind: object) -> str:
    """``model 0.21 s (median of 3) for 1413 s simulated: real-time factor 6728, CPU 0.2 s,
    peak +38 MiB``; or why there is no runtime."""
    if runtime is None:
        if model_kind == "file":
            return "none (the model is exported files: it ran elsewhere)"
        return "not recorded"
    calls = f" (median of {runtime.repeats})" if runtime.repeats > 1 else ""
    parts = [
        f"model {runtime.wall_median_s:.3g} s{calls} for {runtime.simulated_s:.4g} s simulated",
        f"real-time factor {runtime.realtime_factor:.4g}",
        f"CPU {runtime.cpu_median_s:.3g} s",
    ]
    if runtime.peak_memory_bytes is not None:
        parts.append(f"peak +{runtime.peak_memory_bytes / 2**20:.1f} MiB")
    if runtime.steps is not None:
        parts.append(f"{runtime.steps} steps")
    if runtime.events is not None:
        parts.append(f"{runtime.events} events")
    return parts[0] + ": " + ", ".join(parts[1:])


def runtime_of(spec: SpecResult) -> tuple[ModelRuntime | None, object]:
    """A spec result's runtime and its model's kind, for :func:`runtime_text`."""
    model = spec.data.model
    return spec.runtime, model.kind if model is not None else None


def runtime_report(result: SpecResult, line: int) -> str:
    """Why the model's runtime misses the spec's ``runtime:`` gate."""
    assert result.runtime is not None
    lines = [
        f"the model's runtime missed its gate ({_location(result.spec, line)})",
        *(f"  {failure}" for failure in result.runtime.failures()),
        f"  {runtime_text(result.runtime, 'callable')}",
        "  next: find what made the model slower (hevval compare shows the runtime against a "
        "recorded run), or, on a loaded machine, let the gate judge more calls (runtime.repeat)",
    ]
    return "\n".join(lines)


def phi_verdict(result: SpecResult) -> str:
    """``Φ = 0.9207 [0.9139, 0.9276] ≥ min 0.9, FAIL on its signals``: Φ against its own
    minimum, then the spec's verdict, which says why it fails when Φ is not the reason."""
    gate = ""
    if result.min_phi is not None:
        on = "" if result.min_phi_on == "value" else f" on the {result.min_phi_on} bound"
        sign = "≥" if result.phi_passed else "<"
        gate = f" {sign} min {result.min_phi:g}{on}"
    if result.passed:
        verdict = "PASS"
    elif result.phi_passed and all(s.passed for s in result.signals):
        verdict = "FAIL on the model's runtime"
    elif result.phi_passed:
        verdict = "FAIL on its signals"
    else:
        verdict = "FAIL"
    return f"Φ = {result.phi_text}{gate}, {verdict}"


def tree_summary(results: Iterable[SpecResult], *, details: bool = False) -> list[str]:
    """The signal tree of every spec with its λ values and Φ."""
    lines: list[str] = []
    for result in results:
        lines.append(f"{result.name}: {phi_verdict(result)}  [{result.spec}]")
        names = list(result.signals[0].lambdas) if result.signals else []
        if details:
            lines.append("    " + " " * 28 + "  ".join(f"{describe(n).symbol:>6}" for n in names))
        for signal in result.signals:
            if not details and signal.passed and not signal.within_uncertainty:
                continue
            indent = "  " * signal.level
            mark = "✓" if signal.passed else "✗"
            origin = "  ← error appears here" if signal.origin else ""
            label = f"{indent}{mark} {signal.name}"
            if details:
                values = "  ".join(
                    f"{signal.lambdas[n]:{max(6, len(describe(n).symbol))}.4f}" for n in names
                )
                lines.append(f"  {label:<30}{values}{origin}")
                lines.extend(_standard_metric_lines(signal, indent))
                lines.extend(f"      {indent}{text}" for text in measurement_notes(signal))
            else:
                failed = ", ".join(
                    [
                        f"{f.characteristic} {f.value:.4f}<{f.threshold:g}"
                        + (" (within measurement uncertainty)" if f.within_uncertainty else "")
                        for f in signal.failures + signal.within_uncertainty
                    ]
                    + [
                        f"{f.characteristic} <{f.threshold:g} in {len(f.where)} {f.scope}"
                        for f in signal.local_failures
                    ]
                )
                lines.append(f"  {label} [{signal.path}] {failed}{origin}")
                lines.extend(f"      {indent}{text}" for text in measurement_notes(signal))
        if not details and result.passed:
            count = len(result.signals)
            lines.append(f"  all {count} signals pass" if count > 1 else "  its signal passes")
        lines.extend(quality_lines(result))
    return lines


def measurement_notes(signal: SignalResult) -> list[str]:
    """Each miss of a signal that declares its measurement uncertainty, against it: the
    failing ones, then those that pass within the uncertainty (the note kept)."""
    lines = [
        str(failure_text(f, signal.unit))
        for f in signal.failures
        if f.check is not None and f.check.uncertainty is not None
    ]
    return lines + [f"note: {text}" for text in within_uncertainty_lines(signal)]


def _standard_metric_lines(signal: SignalResult, indent: str) -> list[str]:
    """One line per standard metric of ``signal`` with its raw values (``--hevval-details``)."""
    lines = []
    for name, value in signal.lambdas.items():
        described = describe(name)
        if not described.standard:
            continue
        parts = ", ".join(f"{k} {v:.4g}" for k, v in signal.components.get(name, {}).items())
        lines.append(
            f"      {indent}{described.label} {value:.4f}" + (f" ({parts})" if parts else "")
        )
    return lines


def quality_lines(result: SpecResult) -> list[str]:
    """The data-quality findings on the measurement, one line each."""
    quality = result.data.quality
    if not quality:
        return []
    action = quality.action
    done = {"warn": "", "omit": ", scored around", "error": ""}.get(action, "")
    findings = quality.findings
    lines = [f"  data quality: {len(findings)} finding(s) in the measurement{done}"]
    for found in findings:
        lines.append(
            f"    {found.channel}: {found.kind} at {found.start_s:.6g}–"
            f"{found.stop_s:.6g} s ({found.detail})"
        )
    return lines


def run_summary(
    results: Sequence[SpecResult], *, details: bool = False, verdict: RunVerdict | None = None
) -> list[str]:
    """The run's summary: every spec's tree, then each campaign's verdict, then the run's
    verdict in one line (``verdict``, else the counts of the results alone)."""
    lines = tree_summary(results, details=details)
    verdicts = campaigns_of(results, verdict)
    for found in verdicts:
        lines.extend(verdict_lines(found))
    if results:
        lines.append(
            outcome_line(results, verdicts)
            if verdict is None
            else verdict_line(results, verdict, verdicts)
        )
    return lines


def verdict_lines(found: CampaignVerdict) -> list[str]:
    """The campaign section of the terminal summary and of ``hevval run``."""
    counted = found.counted
    lines = [
        f"campaign {found.spec} ({found.name}): "
        + ("PASS" if found.passed else "FAIL")
        + (
            f" ({len(found.recordings)} of {len(found.recordings) + len(found.missing)} "
            "recordings scored)"
            if found.missing
            else ""
        )
        + f", {sum(r.passed for r in counted)} of {len(counted)} validation recordings pass"
        + (f" (min_pass_rate {found.min_pass_rate:.0%})" if found.min_pass_rate is not None else "")
    ]
    if found.excluded:
        lines.append("  excluded from the gate (calibration): " + ", ".join(found.excluded))
    if found.unused_models:
        lines.append("  model output files no recording uses: " + ", ".join(found.unused_models))
    phi = found.phi
    lines.append(
        f"  Φ over recordings: min {phi.minimum:.4f}, "
        + ", ".join(f"q{round(q * 100):02d} {v:.4f}" for q, v in phi.quantiles.items())
        + f", max {phi.maximum:.4f}"
    )
    for name, spread in found.lambdas.items():
        lines.append(
            f"  {describe(name).symbol} {name}: min {spread.minimum:.4f}, "
            f"median {spread.quantiles[0.5]:.4f}, max {spread.maximum:.4f}"
        )
    if found.worst:
        lines.append(
            "  worst recordings: "
            + ", ".join(
                f"{r.id} Φ {r.phi_text}" + ("" if r.passed else " FAIL") for r in found.worst
            )
        )
    if found.within_noise:
        lines.append(
            "  Φ within noise of min_phi (the 95 % interval holds it): "
            + ", ".join(f"{r.id} Φ {r.phi_text}" for r in found.within_noise)
        )
    lines.append("  signal pass rate (u-pooling area, 0 best, 0.5 worst):")
    width = max(len(p) for p in found.signal_pass_rates) if found.signal_pass_rates else 0
    for path, rate in found.signal_pass_rates.items():
        area = found.pooled_area.get(path)
        lines.append(
            f"    {path:<{width}}  {rate:5.0%}"
            + (f"  (area {area:.3f})" if area is not None else "")
        )
    lines.extend(f"  gate: {failure}" for failure in found.failures)
    return lines
