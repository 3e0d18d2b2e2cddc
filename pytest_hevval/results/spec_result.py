"""Results as typed objects, converted to and from plain JSON-safe data at process boundaries.

``SpecResult.to_dict()`` is the documented run-result format (``schema_version`` 2: λ values
and β weights keyed by characteristic name). ``from_dict`` also reads schema 1, whose λ values
and weights were lists in paper order.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ..core.characteristics import SignalCharacteristics
from ..core.registry import FUSED_CHARACTERISTICS, describe, order_names
from ..core.uncertainty import Interval, value_text
from .codec import interval_bounds, json_number, keyed_lambdas
from .local_tables import LocalFailure, LocalResult
from .measurement import ErrorCheck
from .runtime import ModelRuntime
from .spec_facts import AlignmentFacts, CampaignFacts, DataSources, LocalGrid

__all__ = [
    "ERROR_KEYS",
    "MEASURED_NUMBERS",
    "PHYSICAL_ERRORS",
    "RESULT_SCHEMA_VERSION",
    "Failure",
    "SignalResult",
    "SpecResult",
    "judged_value",
]

RESULT_SCHEMA_VERSION = 2

#: The physical errors of a signal, in its unit (``lag_s`` in seconds); lower magnitude is
#: better for every one.
PHYSICAL_ERRORS: tuple[str, ...] = ("lag_s", "mae", "rms", "delta_e", "error_std", "mean_error")
#: The numbers measured on a signal's pair besides its λ: the physical errors and the peak of
#: the cross-correlation.
MEASURED_NUMBERS: tuple[str, ...] = (
    PHYSICAL_ERRORS[0],
    "peak_correlation",
    "correlation_at_zero_lag",
    *PHYSICAL_ERRORS[1:],
)
#: The physical errors of a signal, flat in its JSON form beside ``lambdas``.
ERROR_KEYS = (
    *MEASURED_NUMBERS,
    "reference_range",
    "n_samples",
    "dt",
    "correlation",
    # The lag search's half-width in seconds, and whether the lag lies on its edge.
    "max_lag_s",
    "lag_at_bound",
)


@dataclass(frozen=True)
class Failure:
    characteristic: str
    value: float
    threshold: float
    #: An error characteristic's limit and margin in the signal's unit, with the measurement
    #: uncertainty beside them when the signal declares one (see measurement.py).
    check: ErrorCheck | None = None

    @property
    def within_uncertainty(self) -> bool:
        """Missed by no more than the signal's declared measurement uncertainty."""
        return self.check is not None and self.check.within is True

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "characteristic": self.characteristic,
            "value": self.value,
            "threshold": self.threshold,
        }
        if self.check is not None:
            out["measurement"] = self.check.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Failure:
        """The inverse of :meth:`to_dict`; records without ``measurement`` load too."""
        check = data.get("measurement")
        return cls(
            characteristic=data["characteristic"],
            value=float(data["value"]),
            threshold=float(data["threshold"]),
            check=ErrorCheck.from_dict(check) if check else None,
        )


@dataclass(frozen=True)
class SignalResult:
    """One signal node of one set, scored.

    ``lambdas`` holds every characteristic the spec scores, keyed by name in report order;
    ``characteristics`` the fused pass's physical errors (lag, MAE, …) the λ values explain;
    ``components`` the named parts a registered characteristic reported, by characteristic.
    """

    path: str
    name: str
    set: int
    level: int
    position: int
    alpha: float
    line: int
    lambdas: dict[str, float]
    characteristics: SignalCharacteristics
    thresholds: dict[str, float]
    failures: list[Failure]
    components: dict[str, dict[str, float]] = field(default_factory=dict)
    unit: str | None = None
    description: str | None = None
    origin: bool = False
    origins: list[str] = field(default_factory=list)
    children: list[str] = field(default_factory=list)
    figures: dict[str, Any] | None = None
    diagnosis: dict[str, Any] | None = None
    #: The signal over windows, phases, conditions and region cells (``local:``/``regions:``).
    local: LocalResult | None = None
    #: Window and cell gates missed.
    local_failures: list[LocalFailure] = field(default_factory=list)
    #: A campaign recording's distribution of u = F_model(measured) on core.upooling.U_GRID.
    u_distribution: list[float] | None = None
    #: 95 % bootstrap intervals of λ1–λ7 by name (see core/uncertainty.py); empty when unknown.
    intervals: dict[str, Interval] = field(default_factory=dict)
    #: The bootstrap block length of this signal's λ1–λ6, in samples.
    block_samples: int | None = None
    #: Thresholds missed by no more than the measurement uncertainty that the spec lets pass
    #: (``measurement.within_uncertainty: pass``); kept to be shown, never failing.
    within_uncertainty: list[Failure] = field(default_factory=list)
    #: The requirement IDs this signal verifies (the spec's, its ancestors' and its own).
    requirements: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.failures and not self.local_failures

    @property
    def lag_s(self) -> float:
        return self.characteristics.lag_s

    @property
    def peak_correlation(self) -> float:
        return self.characteristics.peak_correlation

    @property
    def mae(self) -> float:
        return self.characteristics.mae

    @property
    def rms(self) -> float:
        return self.characteristics.rms

    @property
    def delta_e(self) -> float:
        return self.characteristics.delta_e

    @property
    def error_std(self) -> float:
        return self.characteristics.error_std

    @property
    def mean_error(self) -> float:
        return self.characteristics.mean_error

    @property
    def reference_range(self) -> float:
        return self.characteristics.reference_range

    @property
    def n_samples(self) -> int:
        return self.characteristics.n_samples

    def to_dict(self) -> dict[str, Any]:
        errors = self.characteristics.as_dict()
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
            "lambdas": {name: float(v) for name, v in self.lambdas.items()},
            **{key: errors[key] for key in ERROR_KEYS},
            "thresholds": dict(self.thresholds),
            "failures": [f.to_dict() for f in self.failures],
            "passed": self.passed,
            "origin": self.origin,
            "origins": list(self.origins),
            "children": list(self.children),
        }
        if self.components:
            out["components"] = {k: dict(v) for k, v in self.components.items()}
        if self.figures is not None:
            out["figures"] = self.figures
        if self.diagnosis is not None:
            out["diagnosis"] = self.diagnosis
        if self.local is not None:
            out["local"] = self.local.to_dict()
        if self.local_failures:
            out["local_failures"] = [f.to_dict() for f in self.local_failures]
        if self.u_distribution is not None:
            out["u_distribution"] = list(self.u_distribution)
        if self.intervals:
            out["intervals"] = {
                name: {"low": json_number(i.low), "high": json_number(i.high)}
                for name, i in self.intervals.items()
            }
            out["block_samples"] = self.block_samples
        if self.within_uncertainty:
            out["within_uncertainty"] = [f.to_dict() for f in self.within_uncertainty]
        if self.requirements:
            out["requirements"] = list(self.requirements)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SignalResult:
        keyed = keyed_lambdas(data["lambdas"])
        lambdas = {name: float(math.nan if v is None else v) for name, v in keyed.items()}
        fused = {
            **data,
            "lambdas": [lambdas.get(name, math.nan) for name in FUSED_CHARACTERISTICS],
        }
        return cls(
            path=data["path"],
            name=data.get("name", data["path"].rsplit("/", 1)[-1]),
            set=int(data["set"]),
            level=int(data["level"]),
            position=int(data.get("position", 1)),
            alpha=float(data["alpha"]),
            line=int(data.get("line", 0)),
            lambdas={name: lambdas[name] for name in order_names(lambdas)},
            characteristics=SignalCharacteristics.from_dict(fused),
            components={
                str(k): {str(c): float(v) for c, v in parts.items()}
                for k, parts in dict(data.get("components") or {}).items()
            },
            thresholds=dict(data.get("thresholds", {})),
            failures=[Failure.from_dict(f) for f in data.get("failures", [])],
            unit=data.get("unit"),
            description=data.get("description"),
            origin=bool(data.get("origin", False)),
            origins=list(data.get("origins", [])),
            children=list(data.get("children", [])),
            figures=data.get("figures"),
            diagnosis=data.get("diagnosis"),
            local=LocalResult.from_dict(data["local"]) if data.get("local") else None,
            local_failures=[LocalFailure.from_dict(f) for f in data.get("local_failures", [])],
            u_distribution=data.get("u_distribution"),
            intervals=_intervals(data.get("intervals"), lambdas),
            block_samples=data.get("block_samples"),
            within_uncertainty=[Failure.from_dict(f) for f in data.get("within_uncertainty") or []],
            requirements=[str(r) for r in data.get("requirements") or []],
        )


@dataclass(frozen=True)
class SpecResult:
    """A whole spec, scored: every signal, Φ and the gate."""

    name: str
    spec: str
    spec_hash: str
    phi: float
    min_phi: float | None
    min_phi_line: int
    #: β of every characteristic the spec scores, keyed by name.
    weights: dict[str, float]
    signals: list[SignalResult]
    #: The measured file, the model and the data-quality findings.
    data: DataSources
    #: The time grid both records were put on.
    alignment: AlignmentFacts
    #: The grid of windows and cells, coverage and Φ per window and per cell.
    local: LocalGrid | None = None
    #: One recording of a campaign: its id, its role and the campaign's gate (see campaign.py).
    recording: str | None = None
    role: str = "validation"
    campaign: CampaignFacts | None = None
    #: Φ's 95 % bootstrap interval; None for results recorded without one.
    phi_interval: Interval | None = None
    #: What ``min_phi`` judges: Φ itself, or the lower or upper bound of its interval.
    min_phi_on: str = "value"
    #: The requirement IDs the spec as a whole verifies (its ``Phi`` item's).
    requirements: list[str] = field(default_factory=list)
    #: What running the model cost; None for a model given as exported files (it ran
    #: elsewhere) and for results recorded before runtimes were.
    runtime: ModelRuntime | None = None

    @property
    def phi_judged(self) -> float:
        """The value ``min_phi`` is compared with (Φ where no interval is known)."""
        return judged_value(self.phi, self.phi_interval, self.min_phi_on)

    @property
    def phi_passed(self) -> bool:
        return self.min_phi is None or self.phi_judged >= self.min_phi

    @property
    def phi_text(self) -> str:
        """``0.9257 [0.9190, 0.9311]``, or the bare value where no interval is known."""
        return value_text(self.phi, self.phi_interval)

    @property
    def runtime_passed(self) -> bool:
        return self.runtime is None or self.runtime.passed

    @property
    def passed(self) -> bool:
        return self.phi_passed and self.runtime_passed and all(s.passed for s in self.signals)

    def signal(self, path: str) -> SignalResult:
        for candidate in self.signals:
            if candidate.path == path:
                return candidate
        raise KeyError(path)

    def phi_contributions(self) -> list[tuple[str, float]]:
        """How much each signal pulls Φ below 1: Σ_q α·β_q·(1 − λ_q) / Σ α·β."""

        def beta(name: str) -> float:
            return self.weights.get(name, describe(name).default_weight)

        total = sum(s.alpha * sum(beta(n) for n in s.lambdas) for s in self.signals) or 1.0
        pulls = [
            (
                s.path,
                s.alpha * sum(beta(n) * (1.0 - v) for n, v in s.lambdas.items()) / total,
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
            **(
                {"phi_interval": {"low": self.phi_interval.low, "high": self.phi_interval.high}}
                if self.phi_interval is not None
                else {}
            ),
            **({"min_phi_on": self.min_phi_on} if self.min_phi_on != "value" else {}),
            "phi_passed": self.phi_passed,
            "passed": self.passed,
            "weights": dict(self.weights),
            "data": self.data.to_dict(),
            "alignment": self.alignment.to_dict(),
            "signals": [s.to_dict() for s in self.signals],
            **({"requirements": list(self.requirements)} if self.requirements else {}),
            **({"runtime": self.runtime.to_dict()} if self.runtime is not None else {}),
            **({"local": self.local.to_dict()} if self.local is not None else {}),
            **(
                {
                    "recording": self.recording,
                    "role": self.role,
                    "campaign": None if self.campaign is None else self.campaign.to_dict(),
                }
                if self.recording is not None
                else {}
            ),
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
            weights={
                name: float(w)
                for name, w in keyed_lambdas(data.get("weights", [1.0] * 7)).items()
                if w is not None
            },
            signals=[SignalResult.from_dict(s) for s in data["signals"]],
            data=DataSources.from_dict(data.get("data") or {}),
            alignment=AlignmentFacts.from_dict(data.get("alignment") or {}),
            local=LocalGrid.from_dict(data["local"]) if data.get("local") else None,
            recording=data.get("recording"),
            role=str(data.get("role", "validation")),
            campaign=CampaignFacts.from_dict(data["campaign"]) if data.get("campaign") else None,
            phi_interval=_interval(float(data["phi"]), data.get("phi_interval")),
            min_phi_on=str(data.get("min_phi_on", "value")),
            requirements=[str(r) for r in data.get("requirements") or []],
            runtime=ModelRuntime.from_dict(data["runtime"]) if data.get("runtime") else None,
        )


def judged_value(value: float, interval: Interval | None, on: str) -> float:
    """The value a gate judges: ``value`` itself, or the ``lower``/``upper`` bound of its interval.

    Where no interval is known the point value is judged whatever ``on`` says.
    """
    if interval is None or on == "value":
        return value
    return interval.low if on == "lower" else interval.high


def _interval(value: float, bounds: Mapping[str, Any] | None) -> Interval | None:
    found = interval_bounds(bounds)
    return None if found is None else Interval(value, *found)


def _intervals(data: Mapping[str, Any] | None, lambdas: Mapping[str, float]) -> dict[str, Interval]:
    out: dict[str, Interval] = {}
    for name, bounds in dict(data or {}).items():
        interval = _interval(lambdas.get(name, math.nan), bounds)
        if interval is not None:
            out[name] = interval
    return out
