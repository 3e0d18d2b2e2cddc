"""The typed result of one spec, assembled from what scoring found.

Signal results from the scored trees, the gate and the local tables; the spec result with its
data sources' identities, its alignment, its intervals and a campaign recording's facts.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..core.characteristics import SignalCharacteristics
from ..core.tree import ScoredNode, error_origins, global_metric, iter_nodes
from ..core.uncertainty import BlockSums
from ..data.align import AlignedData
from ..results.local import LocalFailure, LocalResult
from ..results.spec_result import Failure, SignalResult, SpecResult
from ..spec.model import SignalSpec, Spec
from .confidence import spec_confidence
from .data_cache import DataCache
from .signal_arrays import NodePath, Signature, signature_of

__all__ = ["add_campaign_facts", "add_intervals", "signal_result", "spec_result"]


def signal_result(
    spec: Spec,
    node: SignalSpec,
    scored_node: ScoredNode,
    chars: SignalCharacteristics,
    components: dict[str, dict[str, float]],
    failures: Mapping[NodePath, list[Failure]],
    figures: dict[str, Any] | None,
    local: LocalResult | None,
    missed_locally: Mapping[NodePath, list[LocalFailure]],
) -> SignalResult:
    path = scored_node.path

    def failed(candidate: ScoredNode) -> bool:
        return bool(failures[candidate.path] or missed_locally[candidate.path])

    origins = error_origins(scored_node, failed)
    return SignalResult(
        path="/".join(path),
        name=node.name,
        set=scored_node.set_index,
        level=scored_node.level,
        position=scored_node.position,
        alpha=scored_node.alpha,
        line=node.line,
        lambdas=dict(scored_node.lambdas),
        characteristics=chars,
        components=components,
        thresholds=spec.thresholds_for(path, node),
        failures=failures[path],
        unit=node.unit,
        description=node.description,
        origin=failed(scored_node) and origins == (scored_node,),
        origins=["/".join(o.path) for o in origins],
        children=["/".join(c.path) for c in scored_node.children],
        figures=figures,
        local=local,
        local_failures=missed_locally[path],
        requirements=list(node.requirements),
    )


def spec_result(
    spec: Spec,
    signals: list[SignalResult],
    aligned: AlignedData,
    model_info: dict[str, Any],
    cache: DataCache,
) -> SpecResult:
    weights = spec.beta()
    phi = global_metric(((s.alpha, s.lambdas) for s in signals), weights)
    return SpecResult(
        name=spec.name,
        spec=spec.key,
        spec_hash=spec.text_hash,
        phi=phi,
        min_phi=spec.min_phi,
        min_phi_line=spec.min_phi_line,
        min_phi_on=spec.min_phi_on,
        weights=weights,
        signals=signals,
        requirements=list(spec.requirements),
        data={
            "reference": {
                "path": spec.reference.path,
                **cache.digest(str(spec.reference.path)),
            },
            "model": _with_digest(model_info, cache),
            **(
                {
                    "quality": {
                        "action": spec.data_quality.action,
                        "findings": [f.to_dict() for f in aligned.quality],
                    }
                }
                if aligned.quality
                else {}
            ),
        },
        alignment={
            "rate_hz": aligned.grid.rate_hz,
            "start_s": aligned.grid.start_s,
            "stop_s": aligned.grid.stop_s,
            "n_samples": aligned.grid.n_samples,
            "offset_s": aligned.offset_s,
            "offset_found": aligned.offset_found,
            "coverage": aligned.coverage,
            "by": aligned.by,
            **({"clock_offset_s": aligned.clock_offset_s} if aligned.by == "clock" else {}),
            **(
                {"absolute_start": aligned.absolute_start()}
                if aligned.absolute_start() is not None
                else {}
            ),
        },
    )


def _with_digest(model_info: dict[str, Any], cache: DataCache) -> dict[str, Any]:
    """A model file's entry with its digest after its path (a callable has neither)."""
    if "path" not in model_info:
        return model_info
    path = model_info["path"]
    return {"path": path, **cache.digest(str(path)), **model_info}


def add_intervals(
    spec: Spec,
    result: SpecResult,
    roots: list[ScoredNode],
    node_specs: Mapping[NodePath, SignalSpec],
    fused: Mapping[Signature, SignalCharacteristics],
    blocks: Mapping[Signature, BlockSums],
) -> None:
    """Every λ and Φ of ``result`` gets its bootstrap interval."""
    confidence = spec_confidence(
        roots,
        lambda path: signature_of(node_specs[path]),
        blocks,
        {signature: chars.reference_range for signature, chars in fused.items()},
        result.phi,
        result.weights,
        correlation=spec.correlation,
        variant=spec.emergent,
    )
    result.phi_interval = confidence.phi
    # result.signals were made in iter_nodes order (a name may itself hold a "/").
    for node, signal in zip(iter_nodes(roots), result.signals, strict=True):
        signal.intervals = confidence.signals[node.path]
        signal.block_samples = confidence.block_samples[node.path]


def add_campaign_facts(
    spec: Spec,
    result: SpecResult,
    u_distributions: Mapping[Signature, list[float]],
    node_specs: Mapping[NodePath, SignalSpec],
) -> None:
    """A campaign recording's result names its recording and keeps what pools over them."""
    assert spec.campaign is not None
    result.name = f"{spec.name} · {spec.recording}"
    result.recording = spec.recording
    result.role = spec.role
    result.campaign = {
        "name": spec.name,
        "recordings": [r.id for r in spec.campaign.recordings],
        "min_pass_rate": spec.campaign.min_pass_rate,
        "phi_quantile": list(spec.campaign.phi_quantile) if spec.campaign.phi_quantile else None,
        "line": spec.campaign.line,
    }
    if spec.campaign.unused_models:
        result.campaign["unused_models"] = list(spec.campaign.unused_models)
    for signal in result.signals:
        found = u_distributions.get(signature_of(node_specs[tuple(signal.path.split("/"))]))
        if found is not None:
            signal.u_distribution = found
