"""What a spec's result records beside its signals, typed: data sources, alignment, local grid
and campaign.

These were plain dicts filled in by the engine and rewritten by the run; each is now a frozen
type built once, whose ``to_dict`` writes exactly the JSON of a run result (``schema_version``
2) and whose ``from_dict`` reads it back, along with the older forms records hold (entries
missing keys, a data file named by ``sha256`` alone). Keys a reader does not know are kept in
``extra`` and written back after the known ones.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any

from .codec import data_identity

__all__ = [
    "AlignmentFacts",
    "CampaignFacts",
    "DataQuality",
    "DataSources",
    "FileData",
    "LocalGrid",
    "ModelData",
    "QualityFinding",
    "RegionGrid",
]


def _extra(data: Mapping[str, Any], known: Iterable[str]) -> dict[str, Any]:
    """The entries of ``data`` no typed field holds, in their order."""
    taken = set(known)
    return {key: value for key, value in data.items() if key not in taken}


def _present(pairs: Iterable[tuple[str, Any]]) -> dict[str, Any]:
    """The pairs whose value is known (not None), in order."""
    return {key: value for key, value in pairs if value is not None}


def _content_identity(
    hash: str | None, digest: str | None, sha256: str | None
) -> tuple[str, str] | None:
    """(algorithm, digest) of a file's content, as its JSON form names it; None without one."""
    return data_identity(_present(zip(_FILE_KEYS[1:], (hash, digest, sha256), strict=True)))


def _str_or_none(value: Any) -> str | None:
    return None if value is None else str(value)


# -- data sources ----------------------------------------------------------------------------

_FILE_KEYS = ("path", "hash", "digest", "sha256")


@dataclass(frozen=True)
class FileData:
    """The measured data file: where it is and its digest (empty when it could not be read).

    ``sha256`` is how older records named a file's content, before ``hash``/``digest``.
    """

    path: str | None = None
    hash: str | None = None
    digest: str | None = None
    sha256: str | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    @property
    def identity(self) -> tuple[str, str] | None:
        """(algorithm, digest) of the file's content; None when it has none."""
        return _content_identity(self.hash, self.digest, self.sha256)

    def with_paths(self, relative: Callable[[str], str]) -> FileData:
        return replace(self, path=relative(self.path)) if self.path else self

    def to_dict(self) -> dict[str, Any]:
        return {
            **_present(
                zip(_FILE_KEYS, (self.path, self.hash, self.digest, self.sha256), strict=True)
            ),
            **self.extra,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> FileData:
        return cls(
            path=_str_or_none(data.get("path")),
            hash=_str_or_none(data.get("hash")),
            digest=_str_or_none(data.get("digest")),
            sha256=_str_or_none(data.get("sha256")),
            extra=_extra(data, _FILE_KEYS),
        )


_MODEL_KEYS = (
    "path",
    "hash",
    "digest",
    "sha256",
    "callable",
    "params",
    "kind",
    "guid",
    "unscored_outputs",
    "module_file",
    "module_sha256",
)


@dataclass(frozen=True)
class ModelData:
    """What identifies the model: an exported file or an FMU (path and digest), or a callable
    (its reference and the file of its module); ``params`` for the models that run here."""

    kind: str | None = None
    path: str | None = None
    hash: str | None = None
    digest: str | None = None
    sha256: str | None = None
    callable: str | None = None
    params: Mapping[str, Any] | None = None
    #: An FMU's GUID.
    guid: str | None = None
    #: An FMU's outputs without numbers (text, bytes), left out of the scoring.
    unscored_outputs: Mapping[str, Any] | None = None
    #: A callable's module file and its SHA-256.
    module_file: str | None = None
    module_sha256: str | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    @property
    def identity(self) -> tuple[str, str] | None:
        """(algorithm, digest) of the model file's content; None for a callable (its JSON form
        names no digest) and for a file without one."""
        if self.callable is not None:
            return None
        return _content_identity(self.hash, self.digest, self.sha256)

    def with_paths(self, relative: Callable[[str], str]) -> ModelData:
        return replace(
            self,
            path=relative(self.path) if self.path else self.path,
            module_file=relative(self.module_file) if self.module_file else self.module_file,
        )

    def to_dict(self) -> dict[str, Any]:
        params = None if self.params is None else dict(self.params)
        unscored = None if self.unscored_outputs is None else dict(self.unscored_outputs)
        if self.callable is not None:
            head = _present(
                (
                    ("callable", self.callable),
                    ("params", params),
                    ("kind", self.kind),
                    ("path", self.path),
                )
            )
        else:
            head = {
                "path": self.path,
                **_present(
                    (
                        ("hash", self.hash),
                        ("digest", self.digest),
                        ("sha256", self.sha256),
                        ("kind", self.kind),
                        ("params", params),
                    )
                ),
            }
        tail = (
            ("guid", self.guid),
            ("unscored_outputs", unscored),
            ("module_file", self.module_file),
            ("module_sha256", self.module_sha256),
        )
        return {**head, **_present(tail), **self.extra}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ModelData:
        params = data.get("params")
        unscored = data.get("unscored_outputs")
        return cls(
            kind=_str_or_none(data.get("kind")),
            path=_str_or_none(data.get("path")),
            hash=_str_or_none(data.get("hash")),
            digest=_str_or_none(data.get("digest")),
            sha256=_str_or_none(data.get("sha256")),
            callable=_str_or_none(data.get("callable")),
            params=None if params is None else dict(params),
            guid=_str_or_none(data.get("guid")),
            unscored_outputs=None if unscored is None else dict(unscored),
            module_file=_str_or_none(data.get("module_file")),
            module_sha256=_str_or_none(data.get("module_sha256")),
            extra=_extra(data, _MODEL_KEYS),
        )


@dataclass(frozen=True)
class QualityFinding:
    """One stretch of one measured channel the data-quality check found wrong (written as
    its fields, in order)."""

    channel: str
    kind: str
    start_s: float
    stop_s: float
    detail: str

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> QualityFinding:
        return cls(
            channel=str(data["channel"]),
            kind=str(data["kind"]),
            start_s=data["start_s"],
            stop_s=data["stop_s"],
            detail=str(data.get("detail", "")),
        )


@dataclass(frozen=True)
class DataQuality:
    """The data-quality findings on the measurement and what the spec does about them."""

    action: str
    findings: tuple[QualityFinding, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"action": self.action, "findings": [asdict(f) for f in self.findings]}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> DataQuality:
        return cls(
            action=str(data.get("action", "warn")),
            findings=tuple(QualityFinding.from_dict(f) for f in data.get("findings") or []),
        )


@dataclass(frozen=True)
class DataSources:
    """The data a spec was scored on: the measured file, the model, the quality findings.

    Records without them (``"data": {}``) load with neither.
    """

    reference: FileData | None = None
    model: ModelData | None = None
    quality: DataQuality | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def with_paths(self, relative: Callable[[str], str]) -> DataSources:
        """The same sources, each file named by ``relative(path)``."""
        return replace(
            self,
            reference=self.reference.with_paths(relative) if self.reference else None,
            model=self.model.with_paths(relative) if self.model else None,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            **({"reference": self.reference.to_dict()} if self.reference is not None else {}),
            **({"model": self.model.to_dict()} if self.model is not None else {}),
            **({"quality": self.quality.to_dict()} if self.quality is not None else {}),
            **self.extra,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> DataSources:
        reference, model, quality = data.get("reference"), data.get("model"), data.get("quality")
        return cls(
            reference=FileData.from_dict(reference) if isinstance(reference, Mapping) else None,
            model=ModelData.from_dict(model) if isinstance(model, Mapping) else None,
            quality=DataQuality.from_dict(quality)
            if isinstance(quality, Mapping) and quality
            else None,
            extra=_extra(data, ("reference", "model", "quality")),
        )


# -- alignment -------------------------------------------------------------------------------

_ALIGNMENT_KEYS = (
    "rate_hz",
    "start_s",
    "stop_s",
    "n_samples",
    "offset_s",
    "offset_found",
    "coverage",
    "by",
    "clock_offset_s",
    "absolute_start",
)


@dataclass(frozen=True)
class AlignmentFacts:
    """The time grid both records were put on, and how the model's time was shifted to it.

    Every field is None in a record that did not hold it.
    """

    rate_hz: float | None = None
    start_s: float | None = None
    stop_s: float | None = None
    n_samples: int | None = None
    offset_s: float | None = None
    offset_found: bool | None = None
    #: The share of the grid both records cover.
    coverage: float | None = None
    #: "time" or "clock" (recordings aligned by their clock times).
    by: str | None = None
    #: With ``by: clock``: how far the model's clock was shifted.
    clock_offset_s: float | None = None
    #: The grid's start as an ISO timestamp, where the records carry clock times.
    absolute_start: str | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            **_present((key, getattr(self, key)) for key in _ALIGNMENT_KEYS),
            **self.extra,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AlignmentFacts:
        known = {key: data[key] for key in _ALIGNMENT_KEYS if data.get(key) is not None}
        return cls(**known, extra=_extra(data, _ALIGNMENT_KEYS))


# -- the local grid --------------------------------------------------------------------------

_REGION_KEYS = ("by", "edges", "shape", "counts", "labels", "min_samples", "unvisited", "outside")


@dataclass(frozen=True)
class RegionGrid:
    """A spec's ``regions:`` grid: its axes and edges, the samples in each cell, Φ per cell."""

    by: tuple[str, ...]
    edges: tuple[tuple[float, ...], ...]
    shape: tuple[int, ...]
    #: Samples per cell, flat in row-major order.
    counts: tuple[int, ...]
    labels: tuple[str, ...]
    min_samples: int
    unvisited: tuple[tuple[int, ...], ...]
    #: Samples outside every cell.
    outside: int
    #: Φ per cell (None where it is unknown); empty before it is scored.
    phi: tuple[float | None, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "by": list(self.by),
            "edges": [list(e) for e in self.edges],
            "shape": list(self.shape),
            "counts": list(self.counts),
            "labels": list(self.labels),
            "min_samples": self.min_samples,
            "unvisited": [list(index) for index in self.unvisited],
            "outside": self.outside,
            **self.extra,
            "phi": list(self.phi),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RegionGrid:
        return cls(
            by=tuple(str(b) for b in data.get("by") or ()),
            edges=tuple(tuple(e) for e in data.get("edges") or ()),
            shape=tuple(int(n) for n in data.get("shape") or ()),
            counts=tuple(int(n) for n in data.get("counts") or ()),
            labels=tuple(str(label) for label in data.get("labels") or ()),
            min_samples=data.get("min_samples", 0),
            unvisited=tuple(tuple(index) for index in data.get("unvisited") or ()),
            outside=int(data.get("outside", 0)),
            phi=tuple(data.get("phi") or ()),
            extra=_extra(data, (*_REGION_KEYS, "phi")),
        )


@dataclass(frozen=True)
class LocalGrid:
    """The spec's windows and region cells: what the report draws for the whole spec."""

    window_s: float | None
    spans_s: tuple[tuple[float, float], ...]
    #: Φ per window (None where it is unknown).
    phi_windows: tuple[float | None, ...]
    #: Per window, the condition holding for most of it (None: none does); empty without one.
    window_conditions: tuple[str | None, ...] = ()
    regions: RegionGrid | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "window_s": self.window_s,
            "spans_s": [list(span) for span in self.spans_s],
            "phi_windows": list(self.phi_windows),
            **(
                {"window_conditions": list(self.window_conditions)}
                if self.window_conditions
                else {}
            ),
            **({"regions": self.regions.to_dict()} if self.regions is not None else {}),
            **self.extra,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LocalGrid:
        regions = data.get("regions")
        return cls(
            window_s=data.get("window_s"),
            spans_s=tuple((a, b) for a, b in data.get("spans_s") or ()),
            phi_windows=tuple(data.get("phi_windows") or ()),
            window_conditions=tuple(data.get("window_conditions") or ()),
            regions=RegionGrid.from_dict(regions) if isinstance(regions, Mapping) else None,
            extra=_extra(
                data, ("window_s", "spans_s", "phi_windows", "window_conditions", "regions")
            ),
        )


# -- campaign --------------------------------------------------------------------------------

_CAMPAIGN_KEYS = ("name", "recordings", "min_pass_rate", "phi_quantile", "line", "unused_models")


@dataclass(frozen=True)
class CampaignFacts:
    """A campaign recording's campaign: its name, recordings and gate (see campaign.py)."""

    #: None (as ``recordings``) in a record that did not hold it.
    name: str | None
    recordings: tuple[str, ...] | None
    min_pass_rate: float | None
    #: (q, level): at most a share q of the validation recordings may score Φ below level.
    phi_quantile: tuple[float, float] | None
    #: The spec line of the campaign.
    line: int
    #: Model outputs of the campaign's folder that no recording names.
    unused_models: tuple[str, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)

    def with_paths(self, relative: Callable[[str], str]) -> CampaignFacts:
        return replace(self, unused_models=tuple(relative(p) for p in self.unused_models))

    def to_dict(self) -> dict[str, Any]:
        return {
            **_present((("name", self.name),)),
            **({"recordings": list(self.recordings)} if self.recordings is not None else {}),
            "min_pass_rate": self.min_pass_rate,
            "phi_quantile": list(self.phi_quantile) if self.phi_quantile else None,
            "line": self.line,
            **({"unused_models": list(self.unused_models)} if self.unused_models else {}),
            **self.extra,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> CampaignFacts:
        quantile = data.get("phi_quantile")
        recordings = data.get("recordings")
        return cls(
            name=_str_or_none(data.get("name")),
            recordings=None if recordings is None else tuple(str(r) for r in recordings),
            min_pass_rate=data.get("min_pass_rate"),
            phi_quantile=(quantile[0], quantile[1]) if quantile else None,
            line=int(data.get("line", 0)),
            unused_models=tuple(str(p) for p in data.get("unused_models") or ()),
            extra=_extra(data, _CAMPAIGN_KEYS),
        )
