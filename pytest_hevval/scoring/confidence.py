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
import numpy.typing as npt

from ..core.tree import ScoredNode, emergent_replicates, global_metric_arrays, iter_nodes
from ..core.uncertainty import (
    SHARED_BLOCK_FACTOR,
    BlockSums,
    Interval,
    stacked_intervals,
    stacked_replicates,
)

__all__ = ["SpecConfidence", "resampled_blocks", "spec_confidence"]

NodePath = tuple[str, ...]
FloatArray = npt.NDArray[np.float64]


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

    # λ7 and Φ per replicate, at the common blocks. Every node enters through its λ1 + … + λ6
    # (λ7) and its α-weighted λ (Φ), taken for all columns at once.
    columns = np.array([common_column[signature_of(node.path)] for node in nodes])
    basis = replicated.sum(axis=0)  # (column, replicate)
    emergent_found = emergent_replicates(
        roots,
        {node.path: basis[column] for node, column in zip(nodes, columns, strict=True)},
        variant="V1" if variant == "V1" else "V2",
    )
    varying = [node for node in nodes if node.path in emergent_found]
    phi_replicates = _phi_replicates(nodes, columns, names, replicated, emergent_found, beta)
    found = stacked_intervals(
        [node.lambdas["emergent"] for node in varying] + [phi],
        np.stack([emergent_found[node.path] for node in varying] + [phi_replicates]),
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


def _phi_replicates(
    nodes: Sequence[ScoredNode],
    columns: npt.NDArray[np.intp],
    names: Sequence[str],
    replicated: FloatArray,
    emergent_found: Mapping[NodePath, FloatArray],
    beta: Mapping[str, float],
) -> FloatArray:
    """Φ of every replicate: node i's λ1–λ6 are row ``columns[i]`` of ``replicated``
    (characteristic, column, replicate), its λ7 is in ``emergent_found`` (1 for a leaf), and
    every other characteristic keeps its point value.

    Φ's own rule (:func:`~pytest_hevval.core.tree.global_metric_arrays`) is given one row per
    characteristic: the nodes' Σ α and their α-weighted mean of it, which makes the same
    Σ α·β·λ / Σ α·β with a product per characteristic instead of one per node.
    """
    alphas = np.array([node.alpha for node in nodes], dtype=np.float64)
    per_column = np.bincount(columns, weights=alphas, minlength=replicated.shape[1])
    weighted = dict(zip(names, np.tensordot(per_column, replicated, axes=(0, 1)), strict=True))
    leaves = sum(node.alpha for node in nodes if node.path not in emergent_found)
    weighted["emergent"] = sum(
        (node.alpha * emergent_found[node.path] for node in nodes if node.path in emergent_found),
        np.full(replicated.shape[2], float(leaves)),
    )
    fixed: dict[str, tuple[float, float]] = {}  # name: (Σ α·λ, Σ α) of point values
    for node in nodes:
        for name, value in node.lambdas.items():
            if name not in weighted:
                total, alpha = fixed.get(name, (0.0, 0.0))
                fixed[name] = (total + node.alpha * value, alpha + node.alpha)
    total_alpha = float(alphas.sum())
    rows = [(total_alpha, {name: value / total_alpha}) for name, value in weighted.items()]
    rows += [(alpha, {name: total / alpha}) for name, (total, alpha) in fixed.items()]
    # Σ α > 0: the point Φ, computed before, raised otherwise.
    return global_metric_arrays([row for row in rows if row[0] > 0], beta)


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
