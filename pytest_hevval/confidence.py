"""Intervals on every λ, λ7 and Φ of a spec, from each signal's block sums.

λ7 and Φ combine several signals, so they are computed per replicate from every signal drawn
with the *same* blocks: one block length for the spec (the longest any of its signals needs)
and one matrix of draws. Their intervals then carry the dependence between signals, which
averaging per-signal intervals would lose. Each signal's λ1–λ6 get their intervals from those
common blocks too when its own bootstrap block length
(:mod:`pytest_hevval.core.uncertainty`) is within
:data:`~pytest_hevval.core.uncertainty.SHARED_BLOCK_FACTOR` of them, and from its own blocks
otherwise.
Characteristics that are not ratios of the block sums (registered ones, the standard metrics)
enter each replicate at their point value.

The work is batched across the spec's signals: one product with the draws for all signals
that share a block length, λ for all of them at once, and one quantile call for every λ
interval of the spec and one for every λ7 and Φ.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .core.tree import ScoredNode, global_metric_arrays, iter_nodes, replicate_tree
from .core.uncertainty import (
    SHARED_BLOCK_FACTOR,
    BlockSums,
    Interval,
    stacked_intervals,
    stacked_replicates,
)

__all__ = ["SpecConfidence", "resampled_blocks", "spec_confidence"]

NodePath = tuple[str, ...]


@dataclass(frozen=True)
class SpecConfidence:
    """The intervals of one scored spec."""

    #: Per node path: λ1–λ6 (see :func:`resampled_blocks`), λ7 from the spec's common blocks.
    signals: dict[NodePath, dict[str, Interval]]
    phi: Interval
    #: The bootstrap block length of each node path's λ1–λ6 intervals, in samples.
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
    first: dict[Hashable, ScoredNode] = {}
    for node in nodes:
        first.setdefault(signature_of(node.path), node)
    keys = list(first)
    common, used = resampled_blocks({key: blocks[key].per_block for key in keys})
    # Replicate λ at the common block length for every signal (λ7, Φ, and the λ1–λ6 intervals
    # of the signals that share it), and at its own length for every other signal: one product
    # per distinct length, λ for all in one pass.
    others = [key for key in keys if used[key] != common]
    requests = [(key, common) for key in keys] + [(key, used[key]) for key in others]
    lambdas = stacked_replicates(
        [blocks[key].table for key, _ in requests],
        [per_block for _, per_block in requests],
        [reference_range[key] * blocks[key].scale for key, _ in requests],
        correlation,
    )
    common_column = {key: i for i, key in enumerate(keys)}
    own_column = {**common_column, **{key: len(keys) + i for i, key in enumerate(others)}}
    names = list(lambdas)
    # (characteristic, column, replicate): each column's replicates contiguous for the tree.
    replicated = np.ascontiguousarray(np.stack([lambdas[name].T for name in names]))

    own_columns = [own_column[key] for key in keys]
    own_table = replicated[:, own_columns, :].reshape(len(names) * len(keys), -1)
    own_found = stacked_intervals(
        [first[key].lambdas[name] for name in names for key in keys], own_table
    )
    own = {
        key: {name: own_found[a * len(keys) + i] for a, name in enumerate(names)}
        for i, key in enumerate(keys)
    }

    def base(path: NodePath) -> dict[str, Any]:
        node = by_path[path]
        column = common_column[signature_of(path)]
        fixed = {name: value for name, value in node.lambdas.items() if name != "emergent"}
        return {**fixed, **{name: replicated[a, column] for a, name in enumerate(names)}}

    by_path = {node.path: node for node in nodes}
    per_node: dict[NodePath, dict[str, Any]] = {}
    for root in roots:
        per_node.update(replicate_tree(root, base, variant="V1" if variant == "V1" else "V2"))
    phi_replicates = global_metric_arrays(
        ((node.alpha, per_node[node.path]) for node in nodes), beta
    )
    # λ7 of a leaf is the constant 1 (no replicates): its interval is the point.
    varying = [node for node in nodes if np.ndim(per_node[node.path]["emergent"]) > 0]
    found = stacked_intervals(
        [node.lambdas["emergent"] for node in varying] + [phi],
        np.stack([per_node[node.path]["emergent"] for node in varying] + [phi_replicates]),
    )
    emergent = {node.path: found[i] for i, node in enumerate(varying)}
    signals = {
        node.path: {
            **own[signature_of(node.path)],
            "emergent": emergent.get(node.path) or _fixed(node.lambdas["emergent"], 1.0),
        }
        for node in nodes
    }
    samples = {key: used[key] * blocks[key].fine for key in keys}
    return SpecConfidence(
        signals=signals,
        phi=found[-1],
        block_samples={node.path: samples[signature_of(node.path)] for node in nodes},
    )


def resampled_blocks(own: Mapping[Any, int]) -> tuple[int, dict[Any, int]]:
    """The spec's common block length (in fine rows) and the length each signal's λ1–λ6 are
    resampled at: the common one where its ``own`` is at least 1 / SHARED_BLOCK_FACTOR of it."""
    common = max(own.values())
    return common, {
        key: common if length * SHARED_BLOCK_FACTOR >= common else length
        for key, length in own.items()
    }


def _fixed(value: float, replicate: float) -> Interval:
    """The interval of a value whose every replicate is ``replicate``."""
    return Interval(value, min(value, replicate), max(value, replicate))
