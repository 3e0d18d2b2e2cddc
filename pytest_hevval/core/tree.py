"""Signal trees: λ7 (emergent behaviour between levels), Φ (eq. 14), and where an error appears.

A validation is a list of signal sets Γ1…Γn; each set is a tree whose root is an objective
signal (level 1) decomposed into the signals it depends on (level 2, 3, …). Every node carries a
weight α and its six characteristics λ1–λ6; this module adds λ7 and combines everything.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

from .characteristics import CHARACTERISTICS

__all__ = [
    "EmergentVariant",
    "ScoredNode",
    "TreeNode",
    "error_origins",
    "global_metric",
    "iter_nodes",
    "score_tree",
]

EmergentVariant = Literal["V1", "V2"]


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
    lambdas: tuple[float, ...]
    children: tuple[ScoredNode, ...] = field(default=())

    @property
    def emergent(self) -> float:
        return self.lambdas[6]

    @property
    def path_str(self) -> str:
        return "/".join(self.path)


def emergent(
    parent: Sequence[float],
    children: Sequence[tuple[Sequence[float], bool]],
    *,
    variant: EmergentVariant = "V2",
) -> float:
    """λ7 of a node from its own λ1..λ6 and its children's λ values (eq. 13).

    ``children`` holds, per child, its seven λ values and whether the child has children of
    its own (so that its λ7 is real, not the leaf placeholder). ``V2`` (default) averages each
    child's λ1..λ6 plus its λ7 where it has one; ``V1`` averages λ1..λ6 only. Returns
    ``1 − |mean(parent λ1..λ6) − mean(children)|`` clipped to [0, 1]; a leaf gets 1.
    """
    if not children:
        return 1.0
    parent_mean = sum(parent[:6]) / 6.0
    values: list[float] = []
    for lambdas, has_children in children:
        values.extend(lambdas[:6])
        if variant == "V2" and has_children:
            values.append(lambdas[6])
    child_mean = sum(values) / len(values)
    return float(min(1.0, max(0.0, 1.0 - abs(parent_mean - child_mean))))


def score_tree(
    root: TreeNode,
    base: Callable[[tuple[str, ...]], Sequence[float]],
    *,
    set_index: int = 1,
    variant: EmergentVariant = "V2",
) -> ScoredNode:
    """Attach λ1..λ7 to every node of one set.

    ``base(path)`` returns λ1..λ6 of the node at ``path`` (a tuple of names from the root).
    """
    positions: dict[int, int] = {}

    def visit(node: TreeNode, path: tuple[str, ...], level: int) -> ScoredNode:
        positions[level] = positions.get(level, 0) + 1
        position = positions[level]
        own = tuple(float(v) for v in base(path))
        if len(own) != 6:
            raise ValueError(f"base() must return six values for {'/'.join(path)}")
        kids = tuple(visit(child, (*path, child.name), level + 1) for child in node.children)
        lam7 = emergent(own, [(k.lambdas, bool(k.children)) for k in kids], variant=variant)
        return ScoredNode(
            name=node.name,
            path=path,
            set_index=set_index,
            level=level,
            position=position,
            alpha=float(node.alpha),
            lambdas=(*own, lam7),
            children=kids,
        )

    return visit(root, (root.name,), 1)


def iter_nodes(roots: Iterable[ScoredNode]) -> Iterator[ScoredNode]:
    """Every node of every set, depth first, parents before children."""
    for root in roots:
        yield root
        yield from iter_nodes(root.children)


def global_metric(
    rows: Iterable[tuple[float, Sequence[float]]],
    beta: Sequence[float] | Mapping[str, float] | None = None,
) -> float:
    """Φ = Σ α·β·λ / Σ α·β over every signal and all seven characteristics (eq. 14).

    ``rows`` are ``(alpha, seven_lambdas)`` pairs, one per signal occurrence. ``beta`` is seven
    weights in paper order, or a mapping from characteristic name to weight (missing = 1).
    """
    weights = _beta_vector(beta)
    numerator = 0.0
    denominator = 0.0
    count = 0
    for alpha, lambdas in rows:
        if len(lambdas) != 7:
            raise ValueError(f"each row needs seven λ values (got {len(lambdas)})")
        if alpha < 0:
            raise ValueError(f"α must be ≥ 0 (got {alpha})")
        count += 1
        for b, lam in zip(weights, lambdas, strict=True):
            numerator += alpha * b * lam
            denominator += alpha * b
    if count == 0:
        raise ValueError("Φ needs at least one signal")
    if denominator <= 0:
        raise ValueError("Φ is undefined: every α·β weight is zero")
    return numerator / denominator


def _beta_vector(beta: Sequence[float] | Mapping[str, float] | None) -> tuple[float, ...]:
    if beta is None:
        return (1.0,) * 7
    if isinstance(beta, Mapping):
        unknown = set(beta) - set(CHARACTERISTICS)
        if unknown:
            raise ValueError(f"unknown characteristic(s) in β: {sorted(unknown)}")
        values = tuple(float(beta.get(name, 1.0)) for name in CHARACTERISTICS)
    else:
        values = tuple(float(b) for b in beta)
        if len(values) != 7:
            raise ValueError(f"β needs seven weights (got {len(values)})")
    if any(b < 0 for b in values):
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
