"""Threshold ratchet: gated λ thresholds only ever tighten, through a reviewable sidecar file.

The sidecar of ``specs/trip_a01.hevval.yaml`` is ``specs/trip_a01.hevval.thresholds.yaml``::

    # header: how, when, from which model version and with which margin it was produced
    E_batt/P_batt:
      mae: 0.9312
      rms: 0.9125

Precedence when the spec loader merges it: for each signal and characteristic the stricter
(higher) of the spec value and the sidecar value applies, so a sidecar can tighten a spec but
never loosen it. To loosen a threshold, lower it in the spec *and* delete the sidecar entry.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import yaml

from ..core.registry import order_names
from ..files import write_atomic
from ..flags import PYTEST, FrontEnd
from ..results.codec import json_number
from ..results.spec_result import SpecResult
from ..spec.sidecar import Thresholds, load_sidecar, sidecar_path
from ._base import HistoryError
from .records import format_utc

__all__ = [
    "DEFAULT_MARGIN",
    "RatchetOutcome",
    "Thresholds",
    "load_sidecar",
    "merge_thresholds",
    "parse_margin",
    "ratchet_spec",
    "ratchet_thresholds",
    "render_sidecar",
    "sidecar_path",
    "write_sidecar",
]

DEFAULT_MARGIN = 0.01
# Thresholds are stored with four decimals, rounded down so that a proposed threshold never
# exceeds the value that was actually achieved.
_DECIMALS = 4
_SCALE = 10.0**_DECIMALS


def parse_margin(text: str | float, *, front_end: FrontEnd = PYTEST) -> float:
    """Validate a ratchet margin: a number in [0, 1); an error names the option as
    ``front_end`` spells it."""
    option = front_end.flag("ratchet")
    try:
        margin = float(text)
    except (TypeError, ValueError):
        raise HistoryError(
            f"margin must be a number (got {text!r})",
            key=option,
            hint=f"write e.g. {option}=0.01 (λ units; thresholds sit that far below achieved)",
        ) from None
    if not math.isfinite(margin) or not 0.0 <= margin < 1.0:
        raise HistoryError(
            f"margin must be in [0, 1) (got {text!r})",
            key=option,
            hint=f"write e.g. {option}=0.01",
        )
    return margin


def _floor(value: float) -> float:
    # The epsilon keeps 0.93 from flooring to 0.9299 through binary float error.
    steps = math.floor(value * _SCALE + 1e-9)
    if steps / _SCALE > value:
        # ... but must not lift a value just below a step (0.9999999999999999) onto it: the
        # run that set the threshold would then miss it.
        steps -= 1
    return steps / _SCALE


def _stricter(a: Mapping[str, float], b: Mapping[str, float]) -> dict[str, float]:
    merged = dict(a)
    for name, value in b.items():
        merged[name] = max(merged[name], value) if name in merged else value
    return merged


def merge_thresholds(spec: Mapping[str, Mapping[str, float]], sidecar: Thresholds) -> Thresholds:
    """Per signal and characteristic, the stricter (higher) of the spec and sidecar values."""
    merged: Thresholds = {path: dict(values) for path, values in spec.items()}
    for path, values in sidecar.items():
        merged[path] = _stricter(merged.get(path, {}), values)
    return merged


def ratchet_thresholds(
    spec_result: SpecResult,
    current_thresholds: Mapping[str, Mapping[str, float]],
    margin: float,
) -> Thresholds:
    """Propose thresholds: ``max(current, achieved − margin)`` per gated characteristic.

    A characteristic is gated for a signal when it has a threshold in ``current_thresholds``
    or in the signal result's own ``thresholds``; the stricter of the two is "current".
    Ungated characteristics are never added, undefined (NaN) achievements keep the current
    value, and no value ever goes down, so rerunning on the same result changes nothing.
    """
    margin = parse_margin(margin)
    proposed: Thresholds = {}
    by_path = {signal.path: signal for signal in spec_result.signals}
    for path in sorted(set(by_path) | set(current_thresholds)):
        signal = by_path.get(path)
        current = _stricter(
            dict(current_thresholds.get(path, {})),
            {} if signal is None else {k: float(v) for k, v in signal.thresholds.items()},
        )
        if not current:
            continue
        out = {}
        for name in order_names(current):
            # An undefined (NaN) λ, or one the signal does not score, keeps the threshold.
            achieved = None if signal is None else json_number(signal.lambdas.get(name))
            value = current[name]
            if achieved is not None:
                value = max(value, min(1.0, max(0.0, _floor(achieved - margin))))
            out[name] = value
        proposed[path] = out
    return proposed


def render_sidecar(
    thresholds: Thresholds, *, model_version: str, created_utc: datetime, margin: float
) -> str:
    """The sidecar text: an explanatory header, then signals sorted, λ in report order."""
    header = [
        "# λ thresholds ratcheted by pytest-hevval (--hevval-ratchet); review and commit.",
        f"# Produced from model version {model_version} on {format_utc(created_utc)}"
        f" with margin {margin:g}:",
        "# each value is max(previous threshold, achieved λ − margin), rounded down to"
        f" {_DECIMALS} decimals.",
        "# Values only ever rise. The stricter of this file and the spec applies; to loosen a",
        "# threshold, lower it in the spec and delete its line here.",
    ]
    body: dict[str, dict[str, float]] = {}
    for path in sorted(thresholds):
        values = thresholds[path]
        ordered = {name: float(values[name]) for name in order_names(values)}
        if ordered:
            body[path] = ordered
    dumped = yaml.safe_dump(body, sort_keys=False, allow_unicode=True, default_flow_style=False)
    return "\n".join(header) + "\n" + ("" if not body else dumped)


def write_sidecar(
    spec_path: Path | str,
    thresholds: Thresholds,
    *,
    model_version: str,
    created_utc: datetime,
    margin: float,
) -> Path:
    """Write the sidecar atomically, with the usual file mode (it is committed); its path."""
    path = sidecar_path(spec_path)
    text = render_sidecar(
        thresholds, model_version=model_version, created_utc=created_utc, margin=margin
    )
    write_atomic(path, text)
    return path


@dataclass(frozen=True)
class RatchetOutcome:
    """What :func:`ratchet_spec` did: the sidecar path, whether it was written, what rose."""

    path: Path
    written: bool
    tightened: tuple[tuple[str, str, float | None, float], ...]

    def summary(self) -> str:
        if not self.tightened:
            return f"{self.path}: thresholds unchanged"
        lines = [f"{self.path}: {len(self.tightened)} threshold(s) tightened"]
        for signal, name, old, new in self.tightened:
            before = "unset" if old is None else f"{old:.4f}"
            lines.append(f"  {signal} {name}: {before} → {new:.4f}")
        return "\n".join(lines)


def ratchet_spec(
    spec_path: Path | str,
    spec_result: SpecResult,
    spec_thresholds: Mapping[str, Mapping[str, float]],
    *,
    margin: float,
    model_version: str,
    created_utc: datetime,
) -> RatchetOutcome:
    """Ratchet one spec and update its sidecar only when a value rises.

    ``spec_thresholds`` are the thresholds written in the spec itself. Sidecar entries for
    signals absent from this run are kept. An unchanged result leaves the file untouched, so
    reruns are idempotent byte for byte.
    """
    existing = load_sidecar(spec_path)
    current = merge_thresholds(spec_thresholds, existing)
    proposed = ratchet_thresholds(spec_result, current, margin)
    tightened: list[tuple[str, str, float | None, float]] = []
    new_sidecar: Thresholds = {path: dict(values) for path, values in existing.items()}
    for path, values in proposed.items():
        for name, value in values.items():
            before = _effective(current, spec_result, path, name)
            if before is None or value > before:
                tightened.append((path, name, before, value))
            # Only a rise needs recording; a value the spec already enforces stays out, so the
            # sidecar holds nothing but what the ratchet added.
            if value > (before if before is not None else -1.0) or name in existing.get(path, {}):
                new_sidecar.setdefault(path, {})[name] = value
    if new_sidecar == existing:
        return RatchetOutcome(sidecar_path(spec_path), False, tuple(tightened))
    written = write_sidecar(
        spec_path, new_sidecar, model_version=model_version, created_utc=created_utc, margin=margin
    )
    return RatchetOutcome(written, True, tuple(tightened))


def _effective(current: Thresholds, spec_result: SpecResult, path: str, name: str) -> float | None:
    """The threshold in force before ratcheting: the stricter of merged and as-run values."""
    values = [current.get(path, {}).get(name)]
    for signal in spec_result.signals:
        if signal.path == path:
            values.append(json_number(signal.thresholds.get(name)))
    present = [v for v in values if v is not None]
    return max(present) if present else None
