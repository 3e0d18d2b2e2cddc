"""Signal trees: λ7 (emergent behaviour between levels), Φ (eq. 14), and where an error appears.

A validation is a list of signal sets Γ1…Γn; each set is a tree whose root is an objective
signal (level 1) decomposed into the signals it depends on (level 2, 3, …). Every node carries a
weight α and its six characteristics λ1–λ6; this module adds λ7 and combines everything.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from .registry import FUSED_CHARACTERISTICS, PAPER_CHARACTERISTICS, describe, get_characteristic

__all__ = [
    "EmergentVariant",
    "ScoredNode",
    "TreeNode",
    "emergent_replicates",
    "error_origins",
    "global_metric",
    "global_metric_arrays",
    "iter_nodes",
    "score_tree",
]

EmergentVariant = Literal["V1", "V2"]
FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class TreeNode:
    """One validation signal γ(i, j, k) and the signals it decomposes into."""

    name: str
    alpha: float = 1.0
    children: tuple[TreeNode, ...] = ()

    @property
    def is_leaf(self) -> bool:
        return not self.children


@dataclass(frozen=True)
class ScoredNode:
    """A tree node with all seven characteristics.

    ``path`` is the tuple of names from the set's root; ``level`` is j (root = 1) and
    ``position`` is k (1-based among the signals of that level in the set, depth-first order).
    """

    name: str
    path: tuple[str, ...]
    set_index: int
    level: int
    position: int
    alpha: float
    #: Every characteristic of the node keyed by name, in report order (λ7 ``emergent`` last
    #: of the paper's seven).
    lambdas: Mapping[str, float]
    children: tuple[ScoredNode, ...] = field(default=())

    @property
    def emergent(self) -> float:
        return self.lambdas["emergent"]

    @property
    def path_str(self) -> str:
        return "/".join(self.path)


Lambdas = Sequence[float] | Mapping[str, float]


def _basis(values: Lambdas) -> list[float]:
    """λ1..λ6 of a node, from a mapping by name or a sequence in paper order."""
    if isinstance(values, Mapping):
        return [values[name] for name in FUSED_CHARACTERISTICS]
    return list(values[:6])


def _own_emergent(values: Lambdas) -> float:
    if isinstance(values, Mapping):
        return values["emergent"]
    return values[6]


def emergent(
    parent: Lambdas,
    children: Sequence[tuple[Lambdas, bool]],
    *,
    variant: EmergentVariant = "V2",
) -> float:
    """λ7 of a node from its own λ1..λ6 and its children's λ values (eq. 13).

    λ values are mappings by characteristic name or sequences in paper order. ``children``
    holds, per child, its λ values and whether the child has children of its own (so that its
    λ7 is real, not the leaf placeholder). ``V2`` (default) averages each child's λ1..λ6 plus
    its λ7 where it has one; ``V1`` averages λ1..λ6 only. Returns
    ``1 − |mean(parent λ1..λ6) − mean(children)|`` clipped to [0, 1]; a leaf gets 1. Only the
    paper's λ1..λ6 enter, whatever other characteristics are registered.
    """
    return float(_emergent_rule(parent, children, variant))


def _emergent_rule(parent: Any, children: Sequence[tuple[Any, bool]], variant: str) -> Any:
    """Eq. 13 on floats or, elementwise, on arrays of bootstrap replicates."""
    if not children:
        return 1.0
    parent_mean = sum(_basis(parent)) / 6.0
    values: list[Any] = []
    for lambdas, has_children in children:
        values.extend(_basis(lambdas))
        if variant == "V2" and has_children:
            values.append(_own_emergent(lambdas))
    child_mean = sum(values) / len(values)
    return _emergent_of_means(parent_mean, child_mean)


def _emergent_of_means(parent_mean: Any, child_mean: Any) -> Any:
    """λ7 = 1 − |mean of the parent's λ − mean of its children's|, clipped to [0, 1]."""
    return np.clip(1.0 - np.abs(parent_mean - child_mean), 0.0, 1.0)


def emergent_replicates(
    roots: Iterable[ScoredNode],
    basis_sums: Mapping[tuple[str, ...], FloatArray],
    *,
    variant: EmergentVariant = "V2",
) -> dict[tuple[str, ...], FloatArray]:
    """λ7 of every node that has children, per bootstrap replicate: the rule of
    :func:`emergent`, elementwise, from each node's λ1 + … + λ6 (an array of replicates per
    node path in ``basis_sums``). A leaf's λ7 is the constant 1 and is left out.
    """
    out: dict[tuple[str, ...], FloatArray] = {}

    def visit(node: ScoredNode) -> None:
        if not node.children:
            return
        total: Any = 0.0
        count = 0
        for child in node.children:
            visit(child)
            total = total + basis_sums[child.path]
            count += 6
            if variant == "V2" and child.children:
                total = total + out[child.path]
                count += 1
        out[node.path] = _emergent_of_means(basis_sums[node.path] / 6.0, total / count)

    for root in roots:
        visit(root)
    return out


def score_tree(
    root: TreeNode,
    base: Callable[[tuple[str, ...]], Lambdas],
    *,
    set_index: int = 1,
    variant: EmergentVariant = "V2",
) -> ScoredNode:
    """Attach every characteristic, λ7 included, to every node of one set.

    ``base(path)`` returns the node's per-signal characteristics: a mapping by name holding at
    least λ1..λ6, or the six values λ1..λ6 in paper order.
    """
    positions: dict[int, int] = {}

    def visit(node: TreeNode, path: tuple[str, ...], level: int) -> ScoredNode:
        positions[level] = positions.get(level, 0) + 1
        position = positions[level]
        own = _own_values(base(path), path)
        kids = tuple(visit(child, (*path, child.name), level + 1) for child in node.children)
        lam7 = emergent(own, [(k.lambdas, bool(k.children)) for k in kids], variant=variant)
        return ScoredNode(
            name=node.name,
            path=path,
            set_index=set_index,
            level=level,
            position=position,
            alpha=float(node.alpha),
            lambdas=_ordered({**own, "emergent": lam7}),
            children=kids,
        )

    return visit(root, (root.name,), 1)


def _own_values(values: Lambdas, path: tuple[str, ...]) -> dict[str, float]:
    if isinstance(values, Mapping):
        own = {str(k): float(v) for k, v in values.items()}
        missing = [name for name in FUSED_CHARACTERISTICS if name not in own]
        if missing:
            raise ValueError(f"base() lacks {missing} for {'/'.join(path)}")
        return own
    if len(values) != 6:
        raise ValueError(f"base() must return six values for {'/'.join(path)}")
    return dict(zip(FUSED_CHARACTERISTICS, (float(v) for v in values), strict=True))


def _ordered(values: Mapping[str, float]) -> dict[str, float]:
    return {name: values[name] for name in sorted(values, key=lambda n: describe(n).order)}


def iter_nodes(roots: Iterable[ScoredNode]) -> Iterator[ScoredNode]:
    """Every node of every set, depth first, parents before children."""
    for root in roots:
        yield root
        yield from iter_nodes(root.children)


def global_metric(
    rows: Iterable[tuple[float, Lambdas]],
    beta: Sequence[float] | Mapping[str, float] | None = None,
) -> float:
    """Φ = Σ α·β·λ / Σ α·β over every signal and every characteristic it has (eq. 14).

    ``rows`` are ``(alpha, lambdas)`` pairs, one per signal occurrence; ``lambdas`` maps
    characteristic name to value (every characteristic the spec scores), or is the paper's
    seven values in order. ``beta`` maps name to weight (missing = the characteristic's
    ``default_weight``, 1 for all built-ins), or is seven weights in paper order.
    """
    return float(_weighted_mean(rows, beta))


def global_metric_arrays(
    rows: Iterable[tuple[float, Mapping[str, Any]]],
    beta: Sequence[float] | Mapping[str, float] | None = None,
) -> FloatArray:
    """:func:`global_metric` elementwise: Φ per bootstrap replicate, per window or per cell."""
    return np.asarray(_weighted_mean(rows, beta), dtype=np.float64)


def _weighted_mean(
    rows: Iterable[tuple[float, Any]], beta: Sequence[float] | Mapping[str, float] | None
) -> Any:
    weights = _beta_mapping(beta)
    numerator: Any = 0.0
    denominator = 0.0
    count = 0
    for alpha, lambdas in rows:
        if not isinstance(lambdas, Mapping):
            if len(lambdas) != 7:
                raise ValueError(f"each row needs seven λ values (got {len(lambdas)})")
            lambdas = dict(zip(PAPER_CHARACTERISTICS, lambdas, strict=True))
        if alpha < 0:
            raise ValueError(f"α must be ≥ 0 (got {alpha})")
        count += 1
        for name, lam in lambdas.items():
            b = weights[name] if name in weights else describe(name).default_weight
            numerator += alpha * b * lam
            denominator += alpha * b
    if count == 0:
        raise ValueError("Φ needs at least one signal")
    if denominator <= 0:
        raise ValueError("Φ is undefined: every α·β weight is zero")
    return numerator / denominator


def _beta_mapping(beta: Sequence[float] | Mapping[str, float] | None) -> dict[str, float]:
    if beta is None:
        return {}
    if isinstance(beta, Mapping):
        values = {get_characteristic(str(name)).name: float(b) for name, b in beta.items()}
    else:
        as_tuple = tuple(float(b) for b in beta)
        if len(as_tuple) != 7:
            raise ValueError(f"β needs seven weights (got {len(as_tuple)})")
        values = dict(zip(PAPER_CHARACTERISTICS, as_tuple, strict=True))
    if any(b < 0 for b in values.values()):
        raise ValueError(f"β weights must be ≥ 0 (got {values})")
    return values


def error_origins(node: ScoredNode, failed: Callable[[ScoredNode], bool]) -> tuple[ScoredNode, ...]:
    """Where the error of a failing node appears: the deepest failing nodes below it.

    Follows failing children downwards; a failing node none of whose children fail (or a
    failing leaf) is an origin. A failing node whose children all pass is its own origin: the
    error emerges where those signals combine. Returns () for a passing node.
    """
    if not failed(node):
        return ()
    found: list[ScoredNode] = []
    for child in node.children:
        found.extend(error_origins(child, failed))
    return tuple(found) if found else (node,)
