"""The typed result of one spec, assembled from what scoring found.

Signal results from the scored trees, the gate and the local tables; the spec result with its
data sources' identities, its alignment, its intervals and a campaign recording's facts.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

from ..core.tree import ScoredNode, error_origins, global_metric, iter_nodes
from ..core.uncertainty import BlockSums
from ..data.align import AlignedData
from ..results.local_tables import LocalFailure
from ..results.runtime import ModelRuntime
from ..results.spec_facts import (
    AlignmentFacts,
    CampaignFacts,
    DataQuality,
    DataSources,
    FileData,
    ModelData,
    QualityFinding,
)
from ..results.spec_result import Failure, SignalResult, SpecResult
from ..spec.model import SignalSpec, Spec
from .confidence import SpecConfidence, spec_confidence
from .data_cache import DataCache
from .local import Labels, spec_local_summary
from .signal_arrays import NodePath, Signature, signature_of
from .signal_pass import Scored, SignalPass

__all__ = [
    "SpecScoring",
    "alignment_facts",
    "data_sources",
    "spec_confidence_of",
    "spec_phi",
    "spec_result",
]


@dataclass(frozen=True)
class SpecScoring:
    """What scoring found for one spec, by node: the trees, the pass, the gates."""

    roots: list[ScoredNode]
    node_specs: Mapping[NodePath, SignalSpec]
    found: SignalPass
    registered: Mapping[Signature, Mapping[str, Scored]]
    #: Each node's thresholds missed, and those missed within the measurement uncertainty.
    failures: Mapping[NodePath, list[Failure]]
    within: Mapping[str, list[Failure]]
    missed_locally: Mapping[NodePath, list[LocalFailure]]


def spec_phi(roots: list[ScoredNode], weights: Mapping[str, float]) -> float:
    """Φ of the scored trees."""
    return global_metric(((n.alpha, dict(n.lambdas)) for n in iter_nodes(roots)), weights)


def spec_confidence_of(
    spec: Spec,
    scoring: SpecScoring,
    blocks: Mapping[Signature, BlockSums],
    phi: float,
    weights: Mapping[str, float],
) -> SpecConfidence:
    """The bootstrap interval of every λ and of Φ."""
    return spec_confidence(
        scoring.roots,
        lambda path: signature_of(scoring.node_specs[path]),
        blocks,
        {sig: chars.reference_range for sig, chars in scoring.found.characteristics.items()},
        phi,
        weights,
        correlation=spec.correlation,
        variant=spec.emergent,
    )


def spec_result(
    spec: Spec,
    scoring: SpecScoring,
    phi: float,
    weights: dict[str, float],
    confidence: SpecConfidence | None,
    labels: Labels | None,
    data: DataSources,
    alignment: AlignmentFacts,
    runtime: ModelRuntime | None,
) -> SpecResult:
    """The spec's result, every signal in the trees' order (a name may itself hold a "/")."""
    signals = [
        _signal_result(spec, scoring, node, confidence) for node in iter_nodes(scoring.roots)
    ]
    local = spec_local_summary(
        spec, labels, [(s.alpha, s.local) for s in signals if s.local is not None], weights
    )
    campaign = _campaign_facts(spec)
    return SpecResult(
        name=spec.name if campaign is None else f"{spec.name} · {spec.recording}",
        spec=spec.key,
        spec_hash=spec.text_hash,
        phi=phi,
        min_phi=spec.min_phi,
        min_phi_line=spec.min_phi_line,
        min_phi_on=spec.min_phi_on,
        weights=weights,
        signals=signals,
        requirements=list(spec.requirements),
        data=data,
        alignment=alignment,
        runtime=runtime,
        phi_interval=confidence.phi if confidence is not None else None,
        local=local,
        recording=spec.recording if campaign is not None else None,
        role=spec.role if campaign is not None else "validation",
        campaign=campaign,
    )


def _signal_result(
    spec: Spec, scoring: SpecScoring, scored_node: ScoredNode, confidence: SpecConfidence | None
) -> SignalResult:
    path = scored_node.path
    node = scoring.node_specs[path]
    signature = signature_of(node)
    found = scoring.found

    def failed(candidate: ScoredNode) -> bool:
        return bool(scoring.failures[candidate.path] or scoring.missed_locally[candidate.path])

    origins = error_origins(scored_node, failed)
    joined = "/".join(path)
    return SignalResult(
        path=joined,
        name=node.name,
        set=scored_node.set_index,
        level=scored_node.level,
        position=scored_node.position,
        alpha=scored_node.alpha,
        line=node.line,
        lambdas=dict(scored_node.lambdas),
        characteristics=found.characteristics[signature],
        components={
            name: parts for name, (_, parts) in scoring.registered[signature].items() if parts
        },
        thresholds=spec.thresholds_for(path, node),
        failures=scoring.failures[path],
        unit=node.unit,
        description=node.description,
        origin=failed(scored_node) and origins == (scored_node,),
        origins=["/".join(o.path) for o in origins],
        children=["/".join(c.path) for c in scored_node.children],
        figures=found.figures.get(signature),
        local=found.local.get(signature),
        local_failures=scoring.missed_locally[path],
        u_distribution=found.u_distributions.get(signature),
        intervals=confidence.signals[path] if confidence is not None else {},
        block_samples=confidence.block_samples[path] if confidence is not None else None,
        within_uncertainty=scoring.within.get(joined, []),
        requirements=list(node.requirements),
    )


def data_sources(
    spec: Spec, aligned: AlignedData, model: ModelData, cache: DataCache
) -> DataSources:
    """The measured file and the model with their digests (waited for here), and the quality
    findings."""
    reference = cache.digest(str(spec.reference.path))
    if model.path is not None:
        # A model file's digest after its path (a callable has neither).
        digest = cache.digest(str(model.path))
        model = replace(model, hash=digest.get("hash"), digest=digest.get("digest"))
    findings = tuple(
        QualityFinding(f.channel, f.kind, f.start_s, f.stop_s, f.detail) for f in aligned.quality
    )
    return DataSources(
        reference=FileData(
            path=spec.reference.path, hash=reference.get("hash"), digest=reference.get("digest")
        ),
        model=model,
        quality=DataQuality(spec.data_quality.action, findings) if findings else None,
    )


def alignment_facts(aligned: AlignedData) -> AlignmentFacts:
    """The grid both records were put on."""
    return AlignmentFacts(
        rate_hz=aligned.grid.rate_hz,
        start_s=aligned.grid.start_s,
        stop_s=aligned.grid.stop_s,
        n_samples=aligned.grid.n_samples,
        offset_s=aligned.offset_s,
        offset_found=aligned.offset_found,
        coverage=aligned.coverage,
        by=aligned.by,
        clock_offset_s=aligned.clock_offset_s if aligned.by == "clock" else None,
        absolute_start=aligned.absolute_start(),
    )


def _campaign_facts(spec: Spec) -> CampaignFacts | None:
    """A campaign recording's campaign: what pools over its recordings."""
    if spec.campaign is None:
        return None
    campaign = spec.campaign
    return CampaignFacts(
        name=spec.name,
        recordings=tuple(r.id for r in campaign.recordings),
        min_pass_rate=campaign.min_pass_rate,
        phi_quantile=tuple(campaign.phi_quantile) if campaign.phi_quantile else None,  # type: ignore[arg-type]
        line=campaign.line,
        unused_models=tuple(campaign.unused_models),
    )
