"""Typed, validated validation specs (frozen dataclasses built by :mod:`.load`)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

from ..core.measurement import MeasurementUncertainty, WithinUncertainty
from ..core.registry import Characteristic, is_registered, select_characteristics
from ..data.quality import QualityLimits
from ..data.record import SourceOptions
from ..defaults import (
    RECORDING_SEPARATOR,
    RUNTIME_CLOCKS,
    RUNTIME_REPEAT,
    WITHIN_UNCERTAINTY,
    split_key,
)
from .expressions import Expression

__all__ = [
    "ID_FIELD",
    "ROLES",
    "AlignmentSpec",
    "CampaignSpec",
    "ConditionSpec",
    "DiagnosisSpec",
    "FmuRun",
    "Interpolation",
    "LocalGate",
    "LocalSpec",
    "MeasurementSpec",
    "ModelKind",
    "RecordingSpec",
    "RegionSpec",
    "Role",
    "RuntimeSpec",
    "SignalSpec",
    "SourceSpec",
    "Spec",
    "model_output_path",
    "split_key",
]

Interpolation = Literal["linear", "previous"]
ModelKind = Literal["file", "callable", "fmu"]
NanPolicy = Literal["raise", "omit"]
#: Calibration recordings fitted the model, so they never count toward a campaign's gate.
Role = Literal["calibration", "validation"]
ROLES: tuple[Role, ...] = ("validation", "calibration")


@dataclass(frozen=True)
class FmuRun:
    """How an FMU model runs (the spec's ``model:`` keys); None: the default."""

    #: "co-simulation" or "model-exchange"; None: co-simulation when the FMU has it.
    interface: str | None = None
    #: The simulation window [s]; None: where the reference starts or ends.
    start_time: float | None = None
    stop_time: float | None = None
    #: Relative tolerance of the solver (model exchange) or the FMU (co-simulation).
    tolerance: float | None = None


@dataclass(frozen=True)
class SourceSpec:
    """Where one side's data comes from: a file, a Python callable or an FMU."""

    kind: ModelKind
    #: Absolute path of the data file or FMU (None for a callable).
    path: str | None
    options: SourceOptions
    line: int
    callable: str | None = None
    params: Mapping[str, Any] = field(default_factory=dict)
    #: Callable: reference channels handed over. FMU: FMU input name → reference channel.
    inputs: tuple[str, ...] = ()
    fmu_inputs: Mapping[str, str] = field(default_factory=dict)
    #: Callable: measured channels the spec scores that the model is meant to be driven by
    #: (a drive cycle's speed), handed over on purpose.
    driven_by: tuple[str, ...] = ()
    #: FMU: signal column → FMU output variable.
    fmu_outputs: Mapping[str, str] = field(default_factory=dict)
    step_size: float | None = None
    fmu_run: FmuRun = field(default_factory=FmuRun)

    @property
    def describe(self) -> str:
        if self.kind == "callable":
            return f"callable {self.callable}"
        return str(self.path)


@dataclass(frozen=True)
class DiagnosisSpec:
    """The spec's ``diagnosis:`` settings (docs/spec.md, docs/diagnosis.md)."""

    #: A significant effect is relevant when it removes at least this share of the residual;
    #: None: the diagnosis default (``core.residual.MIN_SHARE``).
    min_share: float | None = None
    #: Candidate names that echo the scored signal and are never offered as the missing effect.
    responses: tuple[str, ...] = ()
    #: Candidate names that are causes, whatever the response rule says.
    causes: tuple[str, ...] = ()
    #: Named groups of candidates that measure one effect (a heater's current and its power),
    #: as (group name, candidate names) pairs.
    groups: tuple[tuple[str, tuple[str, ...]], ...] = ()


@dataclass(frozen=True)
class AlignmentSpec:
    rate_hz: float | None = None
    window: tuple[float, float] | None = None
    max_lag_s: float | None = None
    offset_s: float = 0.0
    #: (reference channel, model channel) cross-correlated to find the time offset.
    offset_from: tuple[str, str] | None = None
    max_offset_s: float = 30.0
    nan: NanPolicy = "raise"
    #: "time": both records' own time columns; "clock": their absolute start times.
    by: Literal["time", "clock"] = "time"


@dataclass(frozen=True)
class LocalGate:
    """A gate over parts of a record: every window (or cell) must meet ``thresholds``.

    ``share`` is the share of judged windows that must pass (1: every one). A node's own
    ``local_thresholds`` / ``region_thresholds`` override the spec's, as for the record gate.
    """

    thresholds: Mapping[str, float]
    share: float = 1.0
    line: int = 1


@dataclass(frozen=True)
class ConditionSpec:
    """A named condition on the reference: the segments where it holds are scored apart.

    A gated window in which the condition holds for most samples is judged against
    ``thresholds`` instead of the gate's own (a condition-dependent tolerance).
    """

    name: str
    expression: Expression
    line: int
    thresholds: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class LocalSpec:
    """``local:``: characteristics over time windows, driving phases and conditions."""

    window_s: float
    line: int
    #: Speed (km/h) on the reference, from which driving phases are found.
    phases: Expression | None = None
    conditions: tuple[ConditionSpec, ...] = ()
    gate: LocalGate | None = None

    def columns(self) -> set[str]:
        columns: set[str] = set(self.phases.columns) if self.phases else set()
        for condition in self.conditions:
            columns.update(condition.expression.columns)
        return columns


@dataclass(frozen=True)
class RegionSpec:
    """``regions:``: samples binned by one or two operating variables of the reference."""

    by: tuple[Expression, ...]
    #: Per variable: bin edges (the declared operating space) or a count of equal bins over
    #: the measured range.
    bins: tuple[tuple[float, ...] | int, ...]
    min_samples: int
    line: int
    gate: LocalGate | None = None

    def columns(self) -> set[str]:
        columns: set[str] = set()
        for expression in self.by:
            columns.update(expression.columns)
        return columns


@dataclass(frozen=True)
class SignalSpec:
    """One validation signal γ(i, j, k) as written in the spec."""

    name: str
    ref: Expression
    sim: Expression
    line: int
    key: str
    alpha: float = 1.0
    unit: str | None = None
    description: str | None = None
    #: None: the source's own default (zero-order hold for CAN logs, else linear).
    interpolation: Interpolation | None = None
    reference_range: float | None = None
    thresholds: Mapping[str, float] = field(default_factory=dict)
    ref_unit: str | None = None
    sim_unit: str | None = None
    ref_scale: float = 1.0
    ref_offset: float = 0.0
    sim_scale: float = 1.0
    sim_offset: float = 0.0
    children: tuple[SignalSpec, ...] = ()
    #: Overrides of the spec's window and region gate thresholds for this node.
    local_thresholds: Mapping[str, float] = field(default_factory=dict)
    region_thresholds: Mapping[str, float] = field(default_factory=dict)
    #: The sensor's declared accuracy (``uncertainty:``); None: not declared.
    uncertainty: MeasurementUncertainty | None = None
    #: The requirement IDs this signal verifies: the spec's, its ancestors' and its own.
    requirements: tuple[str, ...] = ()


@dataclass(frozen=True)
class MeasurementSpec:
    """The spec's ``measurement:`` settings (docs/uncertainty.md, "Measurement uncertainty")."""

    #: A threshold missed by no more than the measurement uncertainty: "fail" or "pass".
    within_uncertainty: WithinUncertainty = WITHIN_UNCERTAINTY  # type: ignore[assignment]
    line: int = 1


@dataclass(frozen=True)
class RuntimeSpec:
    """The spec's ``runtime:``: how often the model is called per recording, and its gate."""

    #: Simulated seconds per wall-clock second the fastest call must reach.
    min_realtime_factor: float | None = None
    #: Seconds the fastest call may take.
    max_s: float | None = None
    repeat: int = RUNTIME_REPEAT
    #: The clock the limits are judged by: "cpu" (the model's own work) or "wall".
    clock: str = RUNTIME_CLOCKS[0]
    line: int = 1

    @property
    def gated(self) -> bool:
        return self.min_realtime_factor is not None or self.max_s is not None


@dataclass(frozen=True)
class RecordingSpec:
    """One recording of a campaign: its data file, role and the model parameters it adds."""

    id: str
    #: Absolute path of the measured data file.
    path: str
    role: Role
    params: Mapping[str, Any]
    line: int
    #: Absolute path (or URL) of the model's output for this recording, when the model is
    #: exported files rather than a callable or an FMU.
    model_path: str | None = None


#: The placeholder of a campaign's ``model.path`` that each recording's id fills in.
ID_FIELD = "{id}"


def model_output_path(template: str, recording_id: str) -> str:
    """The model output file of one recording: ``template`` with its id in place of ``{id}``."""
    return template.replace(ID_FIELD, recording_id)


@dataclass(frozen=True)
class CampaignSpec:
    """One spec scored over many recordings, and the campaign's own gate."""

    recordings: tuple[RecordingSpec, ...]
    line: int
    #: Share of the validation recordings that must pass every gate of the spec.
    min_pass_rate: float | None = None
    #: (q, minimum): the q-quantile of Φ over the validation recordings must reach the minimum.
    phi_quantile: tuple[float, float] | None = None
    #: Files that follow ``model.path``'s pattern but whose id is no recording's.
    unused_models: tuple[str, ...] = ()


@dataclass(frozen=True)
class Spec:
    """A whole validation spec: data sources, the signal sets and the gates."""

    path: Path
    name: str
    text_hash: str
    reference: SourceSpec
    model: SourceSpec
    sets: tuple[SignalSpec, ...]
    alignment: AlignmentSpec = AlignmentSpec()
    description: str | None = None
    thresholds: Mapping[str, float] = field(default_factory=dict)
    #: β by characteristic name; a scored characteristic missing here weighs its default.
    weights: Mapping[str, float] = field(default_factory=dict)
    #: Characteristics scored beyond those enabled by default (the ``metrics:`` key).
    metrics: tuple[str, ...] = ()
    min_phi: float | None = None
    min_phi_line: int = 1
    #: Which value of Φ's interval ``min_phi`` judges: the point value, or a bound.
    min_phi_on: Literal["value", "lower", "upper"] = "value"
    correlation: Literal["xcorr", "pearson"] = "xcorr"
    emergent: Literal["V1", "V2"] = "V2"
    candidates: Mapping[str, Expression] = field(default_factory=dict)
    diagnosis: DiagnosisSpec = field(default_factory=lambda: DiagnosisSpec())
    #: Limits and action of the data-quality gate on the reference channels.
    data_quality: QualityLimits = field(default_factory=QualityLimits)
    #: Threshold overrides from a ratchet sidecar file, keyed by signal path.
    ratchet: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    #: Where and when the model is wrong: windows, phases, conditions and region cells.
    local: LocalSpec | None = None
    regions: RegionSpec | None = None
    #: The campaign this spec covers (every recording's spec keeps it, to know its siblings).
    campaign: CampaignSpec | None = None
    #: The recording this spec scores, for one recording of a campaign.
    recording: str | None = None
    role: Role = "validation"
    #: What a threshold missed within the measurement uncertainty does.
    measurement: MeasurementSpec = field(default_factory=MeasurementSpec)
    #: The requirement IDs the spec as a whole verifies (``requirements:`` at the top).
    requirements: tuple[str, ...] = ()
    #: How the model's run is timed and gated (a callable or an FMU only).
    runtime: RuntimeSpec = field(default_factory=RuntimeSpec)

    @property
    def key(self) -> str:
        """What names this spec's result: its path, plus ``::recording`` in a campaign."""
        if self.recording is None:
            return str(self.path)
        return f"{self.path}{RECORDING_SEPARATOR}{self.recording}"

    def per_recording(self) -> tuple[Spec, ...]:
        """One spec per recording of the campaign (the spec itself when it has one file)."""
        if self.campaign is None or self.recording is not None:
            return (self,)
        return tuple(
            replace(
                self,
                reference=replace(self.reference, path=recording.path),
                model=replace(
                    self.model,
                    path=recording.model_path or self.model.path,
                    params={**self.model.params, **recording.params},
                ),
                recording=recording.id,
                role=recording.role,
            )
            for recording in self.campaign.recordings
        )

    def walk(self) -> Iterator[tuple[int, tuple[str, ...], SignalSpec]]:
        """(set index from 1, path of names, node) for every signal, parents first."""

        def visit(
            node: SignalSpec, path: tuple[str, ...], index: int
        ) -> Iterator[tuple[int, tuple[str, ...], SignalSpec]]:
            yield index, path, node
            for child in node.children:
                yield from visit(child, (*path, child.name), index)

        for index, root in enumerate(self.sets, start=1):
            yield from visit(root, (root.name,), index)

    def thresholds_for(self, path: tuple[str, ...], node: SignalSpec) -> dict[str, float]:
        """Effective thresholds of one node: spec defaults < node < ratchet (only if stricter)."""
        merged = {**self.thresholds, **node.thresholds}
        for name, value in self.ratchet.get("/".join(path), {}).items():
            if is_registered(name) and value > merged.get(name, -1.0):
                merged[name] = value
        return merged

    def local_thresholds_for(self, node: SignalSpec) -> dict[str, float]:
        """Window-gate thresholds of one node: the spec's ``local.gate`` < the node's own."""
        gate = self.local.gate if self.local else None
        return {**(gate.thresholds if gate else {}), **node.local_thresholds}

    def region_thresholds_for(self, node: SignalSpec) -> dict[str, float]:
        """Cell-gate thresholds of one node: the spec's ``regions.gate`` < the node's own."""
        gate = self.regions.gate if self.regions else None
        return {**(gate.thresholds if gate else {}), **node.region_thresholds}

    def characteristics(self) -> tuple[Characteristic, ...]:
        """What this spec scores: the default characteristics plus its ``metrics``."""
        return select_characteristics(self.metrics)

    def beta(self) -> dict[str, float]:
        """β of every scored characteristic, keyed by name."""
        return {c.name: self.weights.get(c.name, c.default_weight) for c in self.characteristics()}

    def scored_reference_columns(self) -> set[str]:
        """The measured channels the spec's signals are scored on."""
        return {column for _, _, node in self.walk() for column in node.ref.columns}

    def callable_inputs(self) -> list[str]:
        """What a model callable receives: its ``inputs`` and ``driven_by``, and the measured
        channels the spec reads but does not score; never, unasked, a scored signal, which a
        model could pass by copying."""
        scored = self.scored_reference_columns()
        unscored = sorted(self.reference_columns() - scored)
        return list(dict.fromkeys([*self.model.inputs, *self.model.driven_by, *unscored]))

    def reference_columns(self) -> set[str]:
        columns: set[str] = set()
        for _, _, node in self.walk():
            columns.update(node.ref.columns)
        for expression in self.candidates.values():
            columns.update(expression.columns)
        columns.update(self.model.inputs)
        columns.update(self.model.driven_by)
        columns.update(self.model.fmu_inputs.values())
        if self.alignment.offset_from:
            columns.add(self.alignment.offset_from[0])
        if self.local:
            columns.update(self.local.columns())
        if self.regions:
            columns.update(self.regions.columns())
        return columns

    def model_columns(self) -> set[str]:
        columns: set[str] = set()
        for _, _, node in self.walk():
            columns.update(node.sim.columns)
        if self.alignment.offset_from:
            columns.add(self.alignment.offset_from[1])
        return columns
