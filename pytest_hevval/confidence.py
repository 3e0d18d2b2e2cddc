"""Intervals on every λ, λ7 and Φ of a spec, from each signal's block sums.

Each signal's λ1–λ6 get an interval from its own bootstrap block length
(:mod:`pytest_hevval.core.uncertainty`). λ7 and Φ combine several signals, so they are
computed per replicate from every signal drawn with the *same* blocks: one block length for the
spec (the longest any of its signals needs) and one matrix of draws. Their intervals then carry
the dependence between signals, which averaging per-signal intervals would lose.
Characteristics that are not ratios of the block sums (registered ones, the standard metrics)
enter each replicate at their point value.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .core.tree import ScoredNode, global_metric_arrays, iter_nodes, replicate_tree
from .core.uncertainty import (
    BlockSums,
    Interval,
    coarsen,
    percentile_interval,
    percentile_intervals,
    replicate_lambdas,
    resample_counts,
    signal_intervals,
)

__all__ = ["SpecConfidence", "spec_confidence"]

NodePath = tuple[str, ...]


@dataclass(frozen=True)
class SpecConfidence:
    """The intervals of one scored spec."""

    #: Per node path: λ1–λ6 from the signal's own blocks, λ7 from the spec's common blocks.
    signals: dict[NodePath, dict[str, Interval]]
    phi: Interval
    #: Bootstrap block length per node path, in samples.
    block_samples: dict[NodePath, int]


def spec_confidence(
    roots: Sequence[ScoredNode],
    signature_of: Callable[[NodePath], Hashable],
    blocks: Mapping[Any, BlockSums],
    reference_range: Mapping[Any, float],
    phi: float,
    beta: Mapping[str, float],
    *,
    correlation: str = "xcorr",
    variant: str = "V2",
) -> SpecConfidence:
    """Intervals of every node's λ1–λ7 and of Φ.

    ``signature_of(path)`` names the distinct signal a node scores (nodes sharing a signal
    share its sums); ``blocks`` and ``reference_range`` are keyed by that name.
    """
    nodes = list(iter_nodes(roots))
    common = max(blocks[signature_of(node.path)].per_block for node in nodes)
    own: dict[Hashable, dict[str, Interval]] = {}
    replicated: dict[Hashable, dict[str, Any]] = {}
    for node in nodes:
        key = signature_of(node.path)
        if key in own:
            continue
        table = coarsen(blocks[key].table, common)
        counts = resample_counts(table.values.shape[0])
        replicated[key] = replicate_lambdas(
            table, counts, reference_range[key] * blocks[key].scale, correlation
        )
        if blocks[key].per_block == common:  # its own blocks are the common ones
            own[key] = percentile_intervals(node.lambdas, replicated[key])
        else:
            own[key] = signal_intervals(
                blocks[key], node.lambdas, reference_range[key], correlation
            )

    def base(path: NodePath) -> dict[str, Any]:
        node = by_path[path]
        fixed = {name: value for name, value in node.lambdas.items() if name != "emergent"}
        return {**fixed, **replicated[signature_of(path)]}

    by_path = {node.path: node for node in nodes}
    per_node: dict[NodePath, dict[str, Any]] = {}
    for root in roots:
        per_node.update(replicate_tree(root, base, variant="V1" if variant == "V1" else "V2"))
    phi_replicates = global_metric_arrays(
        ((node.alpha, per_node[node.path]) for node in nodes), beta
    )
    signals = {
        node.path: {
            **own[signature_of(node.path)],
            "emergent": percentile_interval(
                node.lambdas["emergent"], np.atleast_1d(per_node[node.path]["emergent"])
            ),
        }
        for node in nodes
    }
    return SpecConfidence(
        signals=signals,
        phi=percentile_interval(phi, phi_replicates),
        block_samples={node.path: blocks[signature_of(node.path)].block_samples for node in nodes},
    )
