"""The spec's trees scored, and each node held against its thresholds.

:func:`gate` finds the characteristics below their thresholds; :func:`measurement_checks` adds
an error threshold's margin and the signal's measurement uncertainty to each miss (and lets a
miss within it pass where the spec says so).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from ..core.characteristics import SignalCharacteristics
from ..core.tree import ScoredNode, TreeNode, iter_nodes, score_tree
from ..results.spec_result import Failure
from ..spec.model import SignalSpec, Spec
from .signal_arrays import NodePath, Signature, signature_of

__all__ = ["gate", "measurement_checks", "score_trees"]

FloatArray = npt.NDArray[np.float64]


def score_trees(
    spec: Spec,
    node_specs: Mapping[NodePath, SignalSpec],
    fused: Mapping[Signature, SignalCharacteristics],
    registered: Mapping[Signature, Mapping[str, tuple[float, dict[str, float]]]],
) -> list[ScoredNode]:
    """Every set scored: each node's characteristics keyed by name, λ7 added on the tree."""

    def base(path: NodePath) -> dict[str, float]:
        signature = signature_of(node_specs[path])
        own = fused[signature].values
        own.update((name, value) for name, (value, _) in registered[signature].items())
        return own

    return [
        score_tree(_tree_of(root), base, set_index=index, variant=spec.emergent)
        for index, root in enumerate(spec.sets, start=1)
    ]


def _tree_of(node: SignalSpec) -> TreeNode:
    return TreeNode(
        name=node.name,
        alpha=node.alpha,
        children=tuple(_tree_of(child) for child in node.children),
    )


def gate(
    spec: Spec, roots: list[ScoredNode], node_specs: Mapping[NodePath, SignalSpec]
) -> dict[NodePath, list[Failure]]:
    """Each node's characteristics below their thresholds."""
    failures: dict[NodePath, list[Failure]] = {}
    for scored_node in iter_nodes(roots):
        thresholds = spec.thresholds_for(scored_node.path, node_specs[scored_node.path])
        failures[scored_node.path] = [
            Failure(name, scored_node.lambdas[name], limit)
            for name, limit in thresholds.items()
            if scored_node.lambdas[name] < limit
        ]
    return failures


def measurement_checks(
    spec: Spec,
    failures: dict[NodePath, list[Failure]],
    node_specs: Mapping[NodePath, SignalSpec],
    fused: Mapping[Signature, SignalCharacteristics],
    values: Mapping[Signature, tuple[FloatArray, FloatArray]],
) -> dict[str, list[Failure]]:
    """Each missed error threshold (λ3–λ6) with its limit, margin and measurement uncertainty.

    Rewrites ``failures`` in place. With ``measurement.within_uncertainty: pass`` a miss within
    the uncertainty leaves ``failures`` and is returned instead, by signal path.
    """
    from ..core.measurement import ERROR_CHARACTERISTICS
    from ..results.measurement import check_error

    passing = spec.measurement.within_uncertainty == "pass"
    within: dict[str, list[Failure]] = {}
    for path, missed in failures.items():
        if not any(f.characteristic in ERROR_CHARACTERISTICS for f in missed):
            continue
        node = node_specs[path]
        signature = signature_of(node)
        errors = fused[signature].as_dict()
        declared = node.uncertainty
        reference_rms = 0.0
        if declared is not None and declared.rel > 0:
            reference = values[signature][0]
            reference_rms = float(np.sqrt(np.mean(np.square(reference))))
        kept: list[Failure] = []
        for failure in missed:
            if failure.characteristic in ERROR_CHARACTERISTICS:
                error_key, _ = ERROR_CHARACTERISTICS[failure.characteristic]
                failure = replace(
                    failure,
                    check=check_error(
                        float(errors[error_key]),  # type: ignore[arg-type]
                        failure.threshold,
                        float(errors["reference_range"]),  # type: ignore[arg-type]
                        declared,
                        reference_rms,
                    ),
                )
                if passing and failure.within_uncertainty:
                    within.setdefault("/".join(path), []).append(failure)
                    continue
            kept.append(failure)
        failures[path] = kept
    return within
