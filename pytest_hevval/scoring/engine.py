"""The engine: one spec scored, read → align → score → tree → result.

Used identically by the pytest items, the ``hevval`` CLI and Dask workers. It computes; it
never prints, and it writes nothing. Each step lives in a room of its own: the file cache
(``data_cache``), the model's side (``model_runs``), the grid (``align_spec``,
``signal_arrays``), the scoring pass (``signal_pass``), the trees and the gate (``gating``) and
the result (``result_assembly``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ..core.characteristics import SignalCharacteristics
from ..core.tree import iter_nodes
from ..data import kernel_cache
from ..data.align import AlignedData
from ..errors import HevvalError
from ..results.signal_diagnosis import SignalDiagnosis
from ..results.spec_result import SpecResult
from ..spec.model import Spec
from .align_spec import align_spec, labels_of
from .data_cache import DataCache
from .gating import gate, measurement_checks, score_trees
from .local import local_failures
from .model_runs import check_model_output, load_model
from .result_assembly import (
    SpecScoring,
    alignment_facts,
    data_sources,
    spec_confidence_of,
    spec_phi,
    spec_result,
)
from .signal_arrays import signal_arrays, signature_of
from .signal_pass import fused_characteristics, interval_block_sums, registered_characteristics

__all__ = ["DataCache", "Evaluation", "evaluate_spec"]

FloatArray = npt.NDArray[np.float64]


@dataclass
class Evaluation:
    """A scored spec plus what diagnosis and reports need from the data."""

    spec: Spec
    result: SpecResult
    #: None when the spec was scored elsewhere (a Dask worker): only the result came back.
    aligned: AlignedData | None
    arrays: dict[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)
    characteristics: dict[str, SignalCharacteristics] = field(default_factory=dict)
    #: Diagnoses of the failing signals, by the signal diagnosed for them
    #: (:func:`pytest_hevval.scoring.diagnosis.diagnose_failures`), or why one failed.
    diagnoses: dict[str, SignalDiagnosis | HevvalError] = field(default_factory=dict)
    #: The cache the spec's data were read through; the diagnosis reads its candidates there.
    cache: DataCache | None = None


def evaluate_spec(
    spec: Spec,
    *,
    cache: DataCache | None = None,
    rootdir: Path | None = None,
    figures: bool = False,
    keep_arrays: bool = False,
    workers: int | None = None,
    intervals: bool = True,
) -> Evaluation:
    """Score every signal of ``spec`` against its reference. Raises HevvalError on bad input.

    ``intervals``: give every λ and Φ its bootstrap interval (one more pass per signal).
    """
    try:
        return _evaluate(
            spec, cache or DataCache(), rootdir, figures, keep_arrays, workers, intervals
        )
    except HevvalError as exc:
        raise exc.with_context(file=str(spec.path)) from None


def _evaluate(
    spec: Spec,
    cache: DataCache,
    rootdir: Path | None,
    figures: bool,
    keep_arrays: bool,
    workers: int | None,
    intervals: bool = True,
) -> Evaluation:
    folders = [spec.path.parent] + ([rootdir] if rootdir else [])
    check_model_output(spec)
    reference = cache.read(spec.reference, spec.reference_columns())
    nodes = list(spec.walk())
    kernel_cache.expect(
        len(nodes) * max((c.values.size for c in reference.channels.values()), default=0)
    )
    model_record, model_data, runtime = load_model(spec, reference, cache, folders)
    aligned = align_spec(spec, nodes, reference, model_record, workers)
    unique, values = signal_arrays(nodes, aligned, reference)
    dt = aligned.grid.dt
    labels = labels_of(spec, aligned)
    scored = fused_characteristics(
        spec,
        unique,
        values,
        dt,
        workers,
        labels,
        intervals,
        aligned if figures else None,
    )
    fused, local = scored.characteristics, scored.local
    registered = registered_characteristics(spec, unique, values, dt, scored.standard)
    node_specs = {path: node for _, path, node in nodes}
    roots = score_trees(spec, node_specs, fused, registered)
    failures = gate(spec, roots, node_specs)
    within = measurement_checks(spec, failures, node_specs, fused, values)
    missed_locally = {
        path: local_failures(spec, node, labels, local.get(signature_of(node)))
        for path, node in node_specs.items()
    }
    scoring = SpecScoring(roots, node_specs, scored, registered, failures, within, missed_locally)
    weights = spec.beta()
    phi = spec_phi(roots, weights)
    confidence = None
    if intervals:
        blocks = interval_block_sums(
            {k: values[k] for k in values if k not in scored.blocks}, workers
        )
        confidence = spec_confidence_of(spec, scoring, {**scored.blocks, **blocks}, phi, weights)
    result = spec_result(
        spec,
        scoring,
        phi,
        weights,
        confidence,
        labels,
        data_sources(spec, aligned, model_data, cache),
        alignment_facts(aligned),
        runtime,
    )
    arrays: dict[str, tuple[FloatArray, FloatArray]] = {}
    characteristics: dict[str, SignalCharacteristics] = {}
    for scored_node in iter_nodes(roots):
        signature = signature_of(node_specs[scored_node.path])
        path = "/".join(scored_node.path)
        characteristics[path] = fused[signature]
        if keep_arrays:
            arrays[path] = values[signature]
    return Evaluation(
        spec=spec,
        result=result,
        aligned=aligned,
        arrays=arrays,
        characteristics=characteristics,
        cache=cache,
    )
