"""Results as plain, JSON-safe data: what crosses process boundaries, reports and history.

``SpecResult.to_dict()`` is the documented run-result format (``schema_version`` 1).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from .core.characteristics import CHARACTERISTIC_LABELS, CHARACTERISTICS

__all__ = ["RESULT_SCHEMA_VERSION", "Failure", "SignalResult", "SpecResult"]

RESULT_SCHEMA_VERSION = 1


def _clean(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


@dataclass(frozen=True)
class Failure:
    characteristic: str
    value: float
    threshold: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "characteristic": self.characteristic,
            "value": self.value,
            "threshold": self.threshold,
        }


@dataclass
class SignalResult:
    """One signal node of one set, scored."""

    path: str
    name: str
    set: int
    level: int
    position: int
    alpha: float
    line: int
    lambdas: tuple[float, ...]
    lag_s: float
    peak_correlation: float
    mae: float
    rms: float
    delta_e: float
    error_std: float
    mean_error: float
    reference_range: float
    n_samples: int
    thresholds: dict[str, float]
    failures: list[Failure]
    unit: str | None = None
    description: str | None = None
    origin: bool = False
    origins: list[str] = field(default_factory=list)
    children: list[str] = field(default_factory=list)
    figures: dict[str, Any] | None = None
    diagnosis: dict[str, Any] | None = None

    @property
    def passed(self) -> bool:
        return not self.failures

    def lambda_of(self, characteristic: str) -> float:
        return self.lambdas[CHARACTERISTICS.index(characteristic)]

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "path": self.path,
            "name": self.name,
            "set": self.set,
            "level": self.level,
            "position": self.position,
            "alpha": self.alpha,
            "line": self.line,
            "unit": self.unit,
            "description": self.description,
            "lambdas": [float(v) for v in self.lambdas],
            "lag_s": self.lag_s,
            "peak_correlation": self.peak_correlation,
            "mae": self.mae,
            "rms": self.rms,
            "delta_e": self.delta_e,
            "error_std": self.error_std,
            "mean_error": self.mean_error,
            "reference_range": self.reference_range,
            "n_samples": self.n_samples,
            "thresholds": dict(self.thresholds),
            "failures": [f.to_dict() for f in self.failures],
            "passed": self.passed,
            "origin": self.origin,
            "origins": list(self.origins),
            "children": list(self.children),
        }
        if self.figures is not None:
            out["figures"] = self.figures
        if self.diagnosis is not None:
            out["diagnosis"] = self.diagnosis
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SignalResult:
        return cls(
            path=data["path"],
            name=data.get("name", data["path"].rsplit("/", 1)[-1]),
            set=int(data["set"]),
            level=int(data["level"]),
            position=int(data.get("position", 1)),
            alpha=float(data["alpha"]),
            line=int(data.get("line", 0)),
            lambdas=tuple(float(v) for v in data["lambdas"]),
            lag_s=float(data["lag_s"]),
            peak_correlation=float(data["peak_correlation"]),
            mae=float(data["mae"]),
            rms=float(data["rms"]),
            delta_e=float(data.get("delta_e", data["rms"] - data["mae"])),
            error_std=float(data.get("error_std", 0.0)),
            mean_error=float(data.get("mean_error", 0.0)),
            reference_range=float(data.get("reference_range", 0.0)),
            n_samples=int(data.get("n_samples", 0)),
            thresholds=dict(data.get("thresholds", {})),
            failures=[Failure(**f) for f in data.get("failures", [])],
            unit=data.get("unit"),
            description=data.get("description"),
            origin=bool(data.get("origin", False)),
            origins=list(data.get("origins", [])),
            children=list(data.get("children", [])),
            figures=data.get("figures"),
            diagnosis=data.get("diagnosis"),
        )

    def failure_lines(self) -> list[str]:
        """Each characteristic below its threshold, with the physical error behind it."""
        unit = f" {self.unit}" if self.unit else ""
        span = f"over a {self.reference_range:.4g}{unit} range"
        physical = {
            "mae": f"MAE {self.mae:.4g}{unit} {span}",
            "rms": f"RMS {self.rms:.4g}{unit} {span}",
            "anomaly": f"RMS−MAE {self.delta_e:.4g}{unit} {span}",
            "error_std": f"σ {self.error_std:.4g}{unit} {span}",
            "lag_correlation": (
                f"zero-lag correlation; peak {self.peak_correlation:.4f} at {self.lag_s:+.3g} s"
            ),
            "derivative_match": "fraction of samples whose derivative signs agree",
            "emergent": "mean λ1–λ6 differs from that of the signals below it",
        }
        return [
            f"{CHARACTERISTIC_LABELS[f.characteristic]} = {f.value:.4f} < {f.threshold:.4g} "
            f"({physical[f.characteristic]})"
            for f in self.failures
        ]


@dataclass
class SpecResult:
    """A whole spec, scored: every signal, Φ and the gate."""

    name: str
    spec: str
    spec_hash: str
    phi: float
    min_phi: float | None
    min_phi_line: int
    weights: tuple[float, ...]
    signals: list[SignalResult]
    data: dict[str, Any]
    alignment: dict[str, Any]

    @property
    def phi_passed(self) -> bool:
        return self.min_phi is None or self.phi >= self.min_phi

    @property
    def passed(self) -> bool:
        return self.phi_passed and all(s.passed for s in self.signals)

    def signal(self, path: str) -> SignalResult:
        for candidate in self.signals:
            if candidate.path == path:
                return candidate
        raise KeyError(path)

    def phi_contributions(self) -> list[tuple[str, float]]:
        """How much each signal pulls Φ below 1: Σ_q α·β_q·(1 − λ_q) / Σ α·β."""
        total = sum(s.alpha * sum(self.weights) for s in self.signals) or 1.0
        pulls = [
            (
                s.path,
                s.alpha
                * sum(b * (1.0 - v) for b, v in zip(self.weights, s.lambdas, strict=True))
                / total,
            )
            for s in self.signals
        ]
        return sorted(pulls, key=lambda item: item[1], reverse=True)

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema_version": RESULT_SCHEMA_VERSION,
            "name": self.name,
            "spec": self.spec,
            "spec_hash": self.spec_hash,
            "phi": self.phi,
            "min_phi": self.min_phi,
            "min_phi_line": self.min_phi_line,
            "passed": self.passed,
            "weights": list(self.weights),
            "data": self.data,
            "alignment": self.alignment,
            "signals": [s.to_dict() for s in self.signals],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SpecResult:
        return cls(
            name=data["name"],
            spec=data["spec"],
            spec_hash=data.get("spec_hash", ""),
            phi=float(data["phi"]),
            min_phi=None if data.get("min_phi") is None else float(data["min_phi"]),
            min_phi_line=int(data.get("min_phi_line", 1)),
            weights=tuple(float(w) for w in data.get("weights", [1.0] * 7)),
            signals=[SignalResult.from_dict(s) for s in data["signals"]],
            data=dict(data.get("data", {})),
            alignment=dict(data.get("alignment", {})),
        )


def worst_first(signals: Sequence[SignalResult]) -> list[SignalResult]:
    return sorted(signals, key=lambda s: (s.passed, min(s.lambdas)))
